"""The fast path of a simulated sample: a Controller workspace and the compiled sample kernel.

The workspace is a :class:`~fault_tolerance.control.controller.Controller`'s
(:class:`~fault_tolerance.control.workspace.ControllerWorkspace`: scenario tables, rank coefficient,
MDA gradient); the kernel is :func:`~fault_tolerance.simulation.fast.sample.sample_kernel`.

:func:`fault_tolerance.simulation.simulate.simulate` builds one :class:`Sampler` per run (when numba is
installed and the run is one it covers: single-joint scenarios) and calls :meth:`Sampler.step` at
every sample. A step returns False when the sample needs the reference code of the simulation
(near a singularity of ``J`` or of a reduced Jacobian, where the reference damps; at the moment of
a lock; under joint limits, when a bound of the rate box is met and the sample is the bounded
problem of :func:`fault_tolerance.resolution.bounded.resolve_bounded`); the simulation then does that sample
the reference way. Under joint limits every other sample is the compiled one, checked against the
rate box (L1) by the compiled box check of :mod:`fault_tolerance.control.bounded_step`. The numbers are those
of the reference (``tests/test_fastpath.py`` compares whole runs to 1e-9, with and without limits).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from fault_tolerance.control.indices import djac, rcn_gradient
from fault_tolerance.control.lapack_steps import TRACE_MAX
from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.fast import sample_dense as sd
from fault_tolerance.numerics.linalg import PIVOT_EPS
from fault_tolerance.resolution.bounded import SCALE_TOL, bounded_least_norm, reduced_bounded
from fault_tolerance.resolution.indices import RCN_MAX
from fault_tolerance.resolution.registry import get
from fault_tolerance.simulation.fast import sample as sk

if TYPE_CHECKING:
    from fault_tolerance.control.controller import Controller

_TASK_SCALED = 64  # run.FLAG_TASK_SCALED
_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD

#: Kernel modes (a registry entry's ``compiled``) the sample computes itself.
MODES = (sk.LNVA, sk.JVJA, sk.MDA)


def available() -> bool:
    """Whether the compiled kernel can run here (numba installed)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def covers(sc, algorithm: str, response: str, limits: bool = False) -> str | None:
    """Why :class:`Sampler` cannot run this simulation (None: it can)."""
    if not available():
        return "numba is not installed"
    if not sc.singletons:
        return "multi-joint scenarios (the reference handles them)"
    mode = get(algorithm).compiled
    if mode not in MODES:
        return f"algorithm {algorithm!r} (no compiled kernel: its reference rates run)"
    with np.errstate(over="ignore"):
        overflow = not np.isfinite(sc.weights.sum())
    if overflow:
        return "weights whose sum overflows (the reference rescales them)"
    if limits and mode == sk.JVJA and response == "continuation":
        return "JVJA's continuation response under joint limits (a bounded solve at every sample)"
    return None


class Sampler:
    """Rates, λ parts, k_S, K, σ_min and flags of one sample, written into a run's arrays.

    Args:
        s: The simulation's validated setup (``simulation._Setup``).
        rec: The run's arrays (``simulation._allocate``).
    """

    def __init__(self, s, rec: dict) -> None:
        from fault_tolerance.control.controller import Controller
        from fault_tolerance.simulation import run
        from fault_tolerance.simulation.fast.sample_limits import g1_posts

        arm, sc = s.arm, s.sc
        self.ctrl = Controller(
            arm,
            sc,
            method=s.algorithm,
            gain=s.gain,
            max_step=s.max_step,
            tolerate=True,
            backend="numpy",
            limits=False,
        )  # fmt: skip (its workspace; the box check is the kernel's own)
        self.kernel = sk.compiled_sample_kernel()
        self.model, self.data, self.fid = arm.model, self.ctrl.data, arm.frame_id
        self.cw = self.ctrl.workspace
        self.rows = self.cw.rows
        self.position_only = bool(np.all(np.asarray(arm.rows) < 3))
        self.full_pose = list(arm.rows) == [0, 1, 2, 3, 4, 5]
        self.trans_rows = np.asarray(arm.rows)
        self.arm, self.s, self.kp = arm, s, float(s.feedback_gain)
        mode = get(s.algorithm).compiled
        if mode is None:  # covers() sends such a run to the reference sample
            raise InvalidInput(
                f"algorithm {s.algorithm!r} has no compiled kernel; run it with engine='reference'"
            )
        self.method: int = mode
        self.continuation = s.response == "continuation"
        if self.continuation and self.method == sk.JVJA:
            self.method = sk.GIVEN  # (G3) rates from the planner, the rest compiled
        self.cols = np.ascontiguousarray(sc.columns, dtype=np.int64)
        self.w = np.ascontiguousarray(sc.weights, dtype=float)
        self.vmax = np.ascontiguousarray(s.vmax, dtype=float)
        self.params = np.zeros(sd.N_PARAMS)
        p = self.params
        p[sk.P_TRACE], p[sd.P_PIVOT], p[sd.P_RANK] = TRACE_MAX, PIVOT_EPS, self.cw.rank_coef
        p[sk.P_ALPHA], p[sk.P_GAIN], p[sk.P_MAXSTEP] = self.cw.alpha, s.gain, s.max_step
        p[sk.P_RCN_MAX], p[sk.P_CONT] = RCN_MAX, 1.0 if self.continuation else 0.0
        p[sk.P_LOCK] = -1 if s.lock_col is None else s.lock_col
        p[sk.P_DT] = s.dt
        p[sk.P_DECAY] = -1.0 if s.servo.tau == 0 else float(np.exp(-s.dt / s.servo.tau))
        p[sk.P_ACCEL] = s.servo.accel_limit * s.dt if np.isfinite(s.servo.accel_limit) else np.inf
        p[sk.P_BOUNDED] = 1.0 if s.limits else 0.0
        self.lim, self.prm, self.buf = _box_tables(arm, s)
        self.ws = np.zeros(sk.workspace_size(arm.m, arm.n))
        sk.set_scenarios(self.ws, arm.m, arm.n, self.cw.fw)  # JVJA's weights, as the step's
        self.zeros = np.zeros(arm.n)
        self.table, self.off = rec["_table"], rec["_offsets"]
        self.qd_rows = rec["qd"]
        m, n = arm.m, arm.n
        o = 3 * m * m + m * n
        self.a_ws, self.qd_ws = self.ws[o : o + n], self.ws[o + 4 * n : o + 5 * n]
        self.finish = sk.finish_kernel
        self.boxed: Controller | None = (
            None  # the Controller's bounded step, built at the first sample that needs it
        )
        self.reduced_ws = None  # the compiled reduced robots' workspace (boxsolve), built likewise
        #: Samples handed to the reference code (not certified, the lock, a bound met after it),
        #: and samples that met a bound, solved by the bounded resolvers here.
        self.reference_samples, self.bounded_samples = 0, 0
        #: Reduced robots under the box (L4) solved by the compiled code
        #: (:func:`fault_tolerance.control.fast.bounded_solve.reduced_solve`) and by the reference's
        #: :func:`~fault_tolerance.resolution.bounded.reduced_bounded` where the compiled code refuses.
        self.reduced_compiled, self.reduced_reference = 0, 0
        self.run_flags = (run.FLAG_BOUND_ACTIVE, run.FLAG_INTOLERABLE_UNDER_LIMITS,
                          run.FLAG_STEP_LIMITED, run.FLAG_LOCKED)  # fmt: skip
        self.g1_posts = g1_posts

    def _jacobian(self, q: np.ndarray):
        """``(J, ∇K or zeros)``; the tip placement is then in ``data.oMf[fid]``."""
        model, data, fid = self.model, self.data, self.fid
        if self.method != sk.MDA:
            return pin.computeFrameJacobian(model, data, q, fid, _LWA)[self.rows], self.zeros
        pin.computeJointJacobians(model, data, q)
        Jw = pin.getFrameJacobian(model, data, fid, _WORLD)
        Jl = pin.getFrameJacobian(model, data, fid, _LWA)  # also updates data.oMf[fid]
        J = Jl[self.rows]
        grad = rcn_gradient(self.cw, J, djac(self.cw, Jw, Jl, data.oMf[fid].translation))
        return J, np.ascontiguousarray(grad)

    def _task(self, x_des: np.ndarray):
        """``(x, x_des − x)`` of the tip placement just computed, as ``Arm.fk_and_error``.

        The full pose takes the same Pinocchio calls as ``Arm._coords`` / ``Arm._error`` (the
        rotation vector ``log3 R`` and the error ``log3(exp3(x_des) Rᵀ)``) without their index
        bookkeeping: the same numbers.
        """
        M = self.data.oMf[self.fid]
        if self.position_only:
            x = M.translation[self.trans_rows]
            return x, x_des - x
        if self.full_pose:
            t, R = M.translation, M.rotation
            x, err = np.empty(6), np.empty(6)
            x[:3], x[3:] = t, pin.log3(R)
            err[:3], err[3:] = x_des[:3] - t, pin.log3(pin.exp3(x_des[3:]).dot(R.T))
            return x, err
        return self.arm._coords(M), self.arm._error(x_des, M)

    def step(self, state, k: int, x_des: np.ndarray, xd_des: np.ndarray) -> bool:
        """Sample ``k`` the fast way (and ``q ← q + q̇ dt``); False: do it the reference way."""
        if state.locked and state.lock_jump is None:
            return False  # the moment of the lock: the reference also measures the jump
        q = state.q
        J, grad = self._jacobian(q)
        x, err = self._task(x_des)
        # without feedback ẋ_cmd is ẋ_des itself (the reference adds 0·err: the same numbers)
        xd_cmd = xd_des + self.kp * err if self.kp else xd_des
        method, qd_in = (sk.LOCKED if state.locked else self.method), self.zeros
        if method == sk.GIVEN:
            from fault_tolerance.resolution.jvja import jvja

            qd_in = jvja(J, xd_cmd, self.s.sc, response="continuation", tolerate=True)
        flag = self.kernel(
            J, xd_cmd, qd_in, grad, q, state.qd, x, x_des, err, self.cols, self.w, self.vmax,
            self.params, method, k, self.table, self.off, self.ws, self.lim, self.prm, self.buf,
        )  # fmt: skip
        if flag == sk.BOUNDED:
            flag = self._bounded(state, k, J, xd_cmd, x, x_des, err, method)
        if flag < 0:
            self.reference_samples += 1
            return False
        state.qd = self.qd_rows[k].copy()
        return True

    def _bounded(self, state, k: int, J, xd_cmd, x, x_des, err, method: int) -> int:
        """Sample ``k`` that meets a bound of the rate box: the bounded resolvers, then the kernel.

        The planned rates: the kernel's (clipped into the box) when LNVA's or MDA's are inside it,
        else the :class:`~fault_tolerance.control.controller.Controller`'s bounded step
        (:func:`fault_tolerance.resolution.bounded.resolve_bounded` where a bound is met); the jump against
        the reduced robots' rates under the box (:func:`~fault_tolerance.resolution.limits.post_failure_under_limits`,
        L4-L5); the rest (indices, servo, record) by :func:`~fault_tolerance.simulation.fast.sample.finish_kernel`.
        The numbers are those of ``reference_step._step`` under limits.
        """
        FLAG_BOUND_ACTIVE, FLAG_INTOLERABLE_UNDER_LIMITS, FLAG_STEP_LIMITED, _ = self.run_flags
        s, ws, sc = self.s, self.ws, self.s.sc
        self.bounded_samples += 1
        lo, hi = self.buf[0].copy(), self.buf[1].copy()
        if method == sk.LOCKED:
            return self._locked(state, k, J, xd_cmd, x, x_des, err, lo, hi)
        targets = None
        if ws[sk.W_INSIDE] > 0 and method != sk.JVJA:  # JVJA's objective has the reduced robots'
            qd_cmd, flag = self.qd_ws.copy(), int(ws[sk.W_FLAG])
        else:
            ctrl = self._boxed()
            solved, by_reference = ctrl.bounded_steps, ctrl.bounded_reference_steps
            qd_cmd = ctrl.step(state.q, xd_cmd)
            flag = (FLAG_BOUND_ACTIVE if ctrl.last_active.any() else 0) | (
                _TASK_SCALED if ctrl.last_scale < 1.0 - SCALE_TOL else 0
            )
            if method == sk.MDA and np.linalg.norm(qd_cmd - self.a_ws) >= 0.999 * s.max_step:
                flag |= FLAG_STEP_LIMITED
            if (method == sk.JVJA and ctrl.bounded_steps > solved
                    and ctrl.bounded_reference_steps == by_reference):  # fmt: skip
                targets = self._target_posts(ctrl)
        post, scales = targets or self._posts(J, xd_cmd, qd_cmd, lo, hi)
        if np.any(scales < 1.0 - SCALE_TOL):
            flag |= FLAG_INTOLERABLE_UNDER_LIMITS
        parts = sc.weights * np.einsum("fn,fn->f", post - qd_cmd, post - qd_cmd)
        lo_p = self.off[sk.O_PARTS]
        self.table[k, lo_p : lo_p + sc.f] = parts
        return self.finish(
            J, state.q, state.qd, x, x_des, err, self.cols, self.vmax, self.params, method, k,
            self.table, self.off, ws, self.lim, qd_cmd, parts.sum(), flag,
        )  # fmt: skip

    def _target_posts(self, ctrl: Controller) -> tuple[np.ndarray, np.ndarray] | None:
        """The reduced robots' rates under the box and scalings (L4) JVJA's compiled step just solved.

        The target ``c`` of (L7) is their weighted mean: the same problems in the same box, kept
        by the compiled bounded step (its ``posts``, ``pscale``); None without its workspace.
        """
        tables = ctrl.workspace.box_tables
        if tables is None:
            return None
        views = tables[2]
        self.reduced_compiled += int(views["psolved"].sum())
        return views["posts"].copy(), views["pscale"].copy()

    def _locked(self, state, k: int, J, xd_cmd, x, x_des, err, lo, hi) -> int:
        """After the lock, a sample that meets a bound: the reduced robot's bounded rates.

        Its bounded least-norm rates (L4, :func:`~fault_tolerance.resolution.bounded.bounded_least_norm`),
        as ``reference_step._step``.
        """
        FLAG_BOUND_ACTIVE, _, _, FLAG_LOCKED = self.run_flags
        keep = state.keep
        sol = bounded_least_norm(J[:, keep], xd_cmd, lo[keep], hi[keep])
        qd_cmd = np.zeros(len(lo))
        qd_cmd[keep] = sol.qd
        flag = FLAG_LOCKED | (FLAG_BOUND_ACTIVE if sol.active.any() else 0)
        flag |= _TASK_SCALED if sol.scale < 1.0 - SCALE_TOL else 0
        lo_p = self.off[sk.O_PARTS]
        self.table[k, lo_p : lo_p + len(self.cols)] = 0.0
        return self.finish(
            J, state.q, state.qd, x, x_des, err, self.cols, self.vmax, self.params, sk.LOCKED, k,
            self.table, self.off, self.ws, self.lim, qd_cmd, 0.0, flag,
        )  # fmt: skip

    def _posts(self, J, xd_cmd, qd_cmd, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """Rates each reduced robot takes under the box and its task scaling (L4).

        As :func:`~fault_tolerance.resolution.limits.post_failure_under_limits`: its unbounded rates (G1, G3)
        from the kernel's factors where they are inside the box, the bounded solve
        (:func:`~fault_tolerance.resolution.bounded.reduced_bounded`) for those that are not.
        """
        m, n = J.shape
        cols, f = self.cols, len(self.cols)
        o = 3 * m * m
        Y = self.ws[o : o + m * n].reshape(m, n)  # L⁻¹J, N = I − YᵀY
        piv = self.ws[o + m * n + 3 * n : o + m * n + 4 * n]  # N_ii by column
        base = qd_cmd if self.continuation else self.a_ws
        post, inside, scales = np.empty((f, n)), np.empty(f, dtype=np.int64), np.ones(f)
        if self.g1_posts(Y, Y, base, piv, cols, lo, hi, post, inside) == 0:  # (G1) / (G3), clipped
            return post, scales
        todo = np.flatnonzero(inside == 0)
        target = qd_cmd if self.continuation else None
        codes = self._reduced(J, xd_cmd, target, todo, lo, hi, post, scales)
        for t in todo[codes != 0]:  # refused by the compiled code: the reference's solve
            sol = reduced_bounded(J, xd_cmd, (int(cols[t]),), lo, hi, target=target)
            post[t], scales[t] = sol.qd, sol.scale
        self.reduced_reference += int(np.count_nonzero(codes))
        self.reduced_compiled += len(todo) - int(np.count_nonzero(codes))
        return post, scales

    def _reduced(self, J, xd_cmd, target, todo, lo, hi, post, scales) -> np.ndarray:
        """The reduced robots ``todo`` under the box, compiled (rows of ``post``, ``scales``); codes."""
        F, Iw, buf, rpost, rscale, solve = self._reduced_workspace()
        buf[0], buf[1] = lo, hi
        c = self.zeros if target is None else np.ascontiguousarray(target, dtype=float)
        codes = np.zeros(len(todo), dtype=np.int64)
        if solve(np.ascontiguousarray(J), np.ascontiguousarray(xd_cmd, dtype=float), c, todo, rpost,
                 rscale, codes, F, Iw):  # fmt: skip
            codes[:] = 1  # no certificate of J: all to the reference
            return codes
        ok = codes == 0
        post[todo[ok]] = rpost[: len(todo)][ok]
        scales[todo[ok]] = rscale[: len(todo)][ok]
        return codes

    def _reduced_workspace(self):
        """``(F, Iw, buf, rpost, rscale, reduced_solve)``: the compiled reduced robots' workspace."""
        if self.reduced_ws is None:
            from fault_tolerance.control.fast.bounded_solve import reduced_solve, workspace

            m, n = self.arm.m, self.arm.n
            sets = self.cols.reshape(-1, 1).copy()
            F, Iw, views = workspace(n, m, sets, self.cols, 1)
            views["p3"][:] = TRACE_MAX, self.cw.pivot_threshold, self.cw.rank_coef
            self.reduced_ws = (F, Iw, views["buf"], np.zeros((len(sets), n)), np.zeros(len(sets)),
                               reduced_solve)  # fmt: skip
        return self.reduced_ws

    def _boxed(self) -> Controller:
        """The Controller whose bounded step solves the samples that meet a bound.

        Its fastest backend: with numba, the compiled bounded step of :mod:`fault_tolerance.control.fast.bounded_step`
        (which leaves what it refuses to the reference route, ``bounded_reference_steps``).
        """
        if self.boxed is None:
            from fault_tolerance.control.controller import Controller

            s = self.s
            self.boxed = Controller(
                s.arm, s.sc, method=s.algorithm, gain=s.gain, max_step=s.max_step,
                tolerate=True, backend=_backends()[0], limits=True, horizon=s.horizon,
            )  # fmt: skip
        return self.boxed


def _box_tables(arm, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``lim`` (lower, upper, velocity limits; ±inf: none), ``prm = [1/h, 0, lock]``, ``buf``."""
    from fault_tolerance.model.joint_limits import NO_LIMIT

    lim = np.empty((3, arm.n))
    lim[0] = np.where(np.abs(arm.lower) < NO_LIMIT, arm.lower, -np.inf)
    lim[1] = np.where(np.abs(arm.upper) < NO_LIMIT, arm.upper, np.inf)
    lim[2] = s.vlimit if s.vlimit is not None else np.inf
    prm = np.array([1.0 / s.horizon, 0.0, -1.0 if s.lock_col is None else s.lock_col])
    return lim, prm, np.zeros((4, arm.n))


def _backends() -> list[str]:
    from fault_tolerance.control.controller import available_backends

    return available_backends()
