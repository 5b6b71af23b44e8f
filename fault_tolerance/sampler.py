"""The fast path of a simulated sample: a Controller workspace and the compiled sample kernel.

The workspace is a :class:`~fault_tolerance.realtime.Controller`'s (scenario tables, rank
coefficient, MDA gradient); the kernel is :func:`~fault_tolerance.sample_kernel.sample_kernel`.

:func:`fault_tolerance.simulation.simulate` builds one :class:`Sampler` per run (when numba is
installed and the run is one it covers: single-joint scenarios) and calls :meth:`Sampler.step` at
every sample. A step returns False when the sample needs the reference code of the simulation
(near a singularity of ``J`` or of a reduced Jacobian, where the reference damps; at the moment of
a lock); the simulation then does that sample the reference way. The numbers are those of the
reference (``tests/test_fastpath.py`` compares whole runs to 1e-9).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from . import sample_kernel as sk
from .indices import RCN_MAX
from .kernels import TRACE_MAX
from .linalg import PIVOT_EPS

_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD

#: Algorithms of :func:`~fault_tolerance.simulation.simulate` the kernel computes itself.
METHODS = {"lnva": sk.LNVA, "jvja": sk.JVJA, "mda": sk.MDA}


def available() -> bool:
    """Whether the compiled kernel can run here (numba installed)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def covers(sc, algorithm: str, response: str) -> str | None:
    """Why :class:`Sampler` cannot run this simulation (None: it can)."""
    if not available():
        return "numba is not installed"
    if not sc.singletons:
        return "multi-joint scenarios (the reference handles them)"
    if algorithm not in METHODS:
        return f"algorithm {algorithm!r}"
    with np.errstate(over="ignore"):
        overflow = not np.isfinite(sc.weights.sum())
    if overflow:
        return "weights whose sum overflows (the reference rescales them)"
    return None


class Sampler:
    """Rates, λ parts, k_S, K, σ_min and flags of one sample, written into a run's arrays.

    Args:
        s: The simulation's validated setup (``simulation._Setup``).
        rec: The run's arrays (``simulation._allocate``).
    """

    def __init__(self, s, rec: dict) -> None:
        from .realtime import Controller

        arm, sc = s.arm, s.sc
        self.ctrl = Controller(
            arm, sc, method=s.algorithm, gain=s.gain, max_step=s.max_step, tolerate=True,
            backend="lapack" if "lapack" in _backends() else "numpy",
        )  # fmt: skip
        self.kernel = sk.compiled_sample_kernel()
        self.model, self.data, self.fid = arm.model, self.ctrl.data, arm.frame_id
        self.rows = self.ctrl._rows
        self.position_only = bool(np.all(np.asarray(arm.rows) < 3))
        self.trans_rows = np.asarray(arm.rows)
        self.arm, self.s = arm, s
        self.method = METHODS[s.algorithm]
        self.continuation = s.response == "continuation"
        if self.continuation and s.algorithm == "jvja":
            self.method = sk.GIVEN  # (G3) rates from the planner, the rest compiled
        self.cols = np.ascontiguousarray(sc.columns, dtype=np.int64)
        self.w = np.ascontiguousarray(sc.weights, dtype=float)
        self.vmax = np.ascontiguousarray(s.vmax, dtype=float)
        self.params = np.zeros(sk.N_PARAMS)
        p = self.params
        p[sk.P_TRACE], p[sk.P_PIVOT], p[sk.P_RANK] = TRACE_MAX, PIVOT_EPS, self.ctrl._rank_coef
        p[sk.P_WSUM], p[sk.P_GAIN], p[sk.P_MAXSTEP] = float(sc.weights.sum()), s.gain, s.max_step
        p[sk.P_RCN_MAX], p[sk.P_CONT] = RCN_MAX, 1.0 if self.continuation else 0.0
        p[sk.P_LOCK] = -1 if s.lock_col is None else s.lock_col
        p[sk.P_DT] = s.dt
        p[sk.P_DECAY] = -1.0 if s.servo.tau == 0 else float(np.exp(-s.dt / s.servo.tau))
        p[sk.P_ACCEL] = s.servo.accel_limit * s.dt if np.isfinite(s.servo.accel_limit) else np.inf
        self.ws = np.zeros(sk.workspace_size(arm.m, arm.n))
        self.zeros = np.zeros(arm.n)
        self.table, self.off = rec["_table"], rec["_offsets"]
        self.qd_rows = rec["qd"]

    def _jacobian(self, q: np.ndarray):
        """``(J, ∇K or zeros)``; the tip placement is then in ``data.oMf[fid]``."""
        model, data, fid = self.model, self.data, self.fid
        if self.method != sk.MDA:
            return pin.computeFrameJacobian(model, data, q, fid, _LWA)[self.rows], self.zeros
        pin.computeJointJacobians(model, data, q)
        Jw = pin.getFrameJacobian(model, data, fid, _WORLD)
        Jl = pin.getFrameJacobian(model, data, fid, _LWA)  # also updates data.oMf[fid]
        J = Jl[self.rows]
        grad = self.ctrl.rcn_gradient(J, self.ctrl._djac(Jw, Jl, data.oMf[fid].translation))
        return J, np.ascontiguousarray(grad)

    def _task(self, x_des: np.ndarray):
        """``(x, x_des − x)`` of the tip placement just computed, as ``Arm.fk_and_error``."""
        M = self.data.oMf[self.fid]
        if self.position_only:
            x = M.translation[self.trans_rows]
            return x, x_des - x
        return self.arm._coords(M), self.arm._error(x_des, M)

    def step(self, state, k: int, x_des: np.ndarray, xd_des: np.ndarray) -> bool:
        """Sample ``k`` the fast way (and ``q ← q + q̇ dt``); False: do it the reference way."""
        if state.locked and state.lock_jump is None:
            return False  # the moment of the lock: the reference also measures the jump
        q = state.q
        J, grad = self._jacobian(q)
        x, err = self._task(x_des)
        xd_cmd = xd_des + self.s.feedback_gain * err
        method, qd_in = (sk.LOCKED if state.locked else self.method), self.zeros
        if method == sk.GIVEN:
            from .planner import jvja

            qd_in = jvja(J, xd_cmd, self.s.sc, response="continuation", tolerate=True)
        flag = self.kernel(
            J, xd_cmd, qd_in, grad, q, state.qd, x, x_des, err, self.cols, self.w, self.vmax,
            self.params, method, k, self.table, self.off, self.ws,
        )  # fmt: skip
        if flag < 0:
            return False
        state.qd = self.qd_rows[k].copy()
        return True


def _backends() -> list[str]:
    from .realtime import available_backends

    return available_backends()
