"""The Controller's workspace: every table and buffer its steps read, in one frozen object.

:class:`ControllerWorkspace` is built once by :class:`~fault_tolerance.control.controller.Controller`
(:func:`build_workspace`) and handed to the step builders (:mod:`fault_tolerance.control.lapack_steps`,
:mod:`fault_tolerance.control.bounded_step`, the compiled steps of :mod:`fault_tolerance.control.fast`)
and to the simulation's sampler. The dataclass is frozen: no field can be rebound after it is
built. The arrays are buffers the steps write into (the scratch, the last step's state, the
counters): their contents change at every step, the objects never do.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pinocchio as pin

from fault_tolerance.model.arm import Arm
from fault_tolerance.resolution.scenarios import Scenarios

__all__ = [
    "BOUNDED_REFERENCE_STEPS",
    "BOUNDED_STEPS",
    "FALLBACKS",
    "ControllerWorkspace",
    "build_workspace",
]

#: Entries of :attr:`ControllerWorkspace.counts`.
FALLBACKS, BOUNDED_STEPS, BOUNDED_REFERENCE_STEPS = 0, 1, 2
_INF = float("inf")


@dataclass(frozen=True)
class ControllerWorkspace:
    """The tables of one Controller (arm, lockable set, thresholds), built once.

    Attributes:
        arm: The arm.
        model: Its ``pinocchio.Model``.
        data: The Controller's own ``pinocchio.Data``.
        frame_id: The tip frame.
        n: Active joints.
        m: Task rows.
        scenarios: The validated failure scenarios.
        rows: Row selector of the 6-row frame Jacobian (a slice when it can be).
        rank_coef: Coefficient of the per-step rank test (0: not needed for this arm).
        pivot_threshold: Pivots ``N_ii`` below it leave the fast path (PIVOT_TOL, or PIVOT_EPS
            with ``tolerate``).
        tolerate: Damp low pivots (by the planner) instead of raising.
        gain: MDA gain α.
        max_step: Cap of MDA's null-space step [rad/s].
        la: The LAPACK/BLAS calls of the steps (scipy's, or NumPy's with their signatures).
        fw: (2, n): ``fw[0]`` 0 on lockable columns and +inf elsewhere, ``fw[1]`` the weights
            ``w_i / W`` on them (1 everywhere with uniform weights).
        alpha: ``-1/f`` with uniform single-joint scenarios, else -1 (eq. 5 in closed form, G2).
        singletons: Every scenario locks one joint.
        uniform: Every scenario has the same weight.
        all_uniform: Uniform single-joint scenarios on every column.
        groups: Scenarios by size for the batched (G1) solve: ``(columns (k, s), w / W (k,))``.
        keep: (f, 1, n): 0 where scenario k locks joint j (``J_S = J * keep[k]``).
        Jm: (f, m, n) scratch: the stack of ``J_S``.
        stack: (f, m, m) scratch: the stack of ``J_S J_Sᵀ``.
        upper: (n, 1, n): 1 where joint j comes before joint k (the kinematic Hessian).
        jvja_factors: ``[P, Q, c]`` of the last JVJA fast step, ``N = I - PᵀQ``, set by the steps.
        box_state: (n + 2): last task scale, 1 after a bounded step, joints at a bound (1.0).
        box_tables: ``(F, Iw, views)`` of the compiled bounded step, or None (other backends,
            no limits); :attr:`box_state` is then its ``views["state"]``.
        counts: Steps handed to the planner, bounded steps, bounded steps by the reference
            (indices :data:`FALLBACKS`, :data:`BOUNDED_STEPS`, :data:`BOUNDED_REFERENCE_STEPS`).
    """

    arm: Arm
    model: pin.Model
    data: pin.Data
    frame_id: int
    n: int
    m: int
    scenarios: Scenarios
    rows: slice | np.ndarray
    rank_coef: float
    pivot_threshold: float
    tolerate: bool
    gain: float
    max_step: float
    la: SimpleNamespace
    fw: np.ndarray
    alpha: float
    singletons: bool
    uniform: bool
    all_uniform: bool
    groups: tuple[tuple[np.ndarray, np.ndarray], ...]
    keep: np.ndarray
    Jm: np.ndarray
    stack: np.ndarray
    upper: np.ndarray
    jvja_factors: list = field(default_factory=lambda: [None] * 3)
    box_state: np.ndarray = field(default_factory=lambda: np.zeros(0))
    box_tables: tuple | None = None
    counts: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))

    @property
    def f(self) -> int:
        """Number of failure scenarios."""
        return self.scenarios.f


def _weight_tables(sc: Scenarios, n: int) -> dict:
    """``fw``, ``alpha``, ``singletons``, ``uniform``, ``all_uniform`` and ``groups`` (eq. 5, G1, G2)."""
    w = sc.weights / sc.weights.max()  # eq. (5) is scale-free; a sum of these cannot overflow
    W = float(w.sum())
    uniform = bool(np.all(sc.weights == sc.weights[0]))
    all_uniform = False
    fw = np.zeros((2, n))
    fw[1] = 1.0
    if sc.singletons:
        cols = sc.columns
        all_uniform = uniform and sorted(cols.tolist()) == list(range(n))
        fw[0] = _INF
        fw[0, cols] = 0.0
        if not uniform:
            fw[1] = 0.0
            fw[1, cols] = w / W
    groups = []
    for size in sorted({len(S) for S in sc.sets}):
        members = [k for k, S in enumerate(sc.sets) if len(S) == size]
        idx = np.array([sc.sets[k] for k in members], dtype=int)
        groups.append((idx, w[members] / W))
    return {
        "fw": fw,
        "alpha": -1.0 / sc.f if (uniform and sc.singletons) else -1.0,
        "singletons": sc.singletons,
        "uniform": uniform,
        "all_uniform": all_uniform,
        "groups": tuple(groups),
    }


def build_workspace(
    arm: Arm,
    sc: Scenarios,
    *,
    rows: slice | np.ndarray,
    rank_coef: float,
    pivot_threshold: float,
    tolerate: bool,
    gain: float,
    max_step: float,
    la: SimpleNamespace,
) -> ControllerWorkspace:
    """The workspace of a Controller for ``arm`` and scenarios ``sc`` (a new ``pinocchio.Data``)."""
    n, m = arm.n, arm.m
    keep = np.ones((sc.f, n))
    for k, S in enumerate(sc.sets):
        keep[k, list(S)] = 0.0
    j = np.arange(n)
    box_state = np.zeros(n + 2)
    box_state[0] = 1.0
    return ControllerWorkspace(
        arm=arm,
        model=arm.model,
        data=arm.model.createData(),
        frame_id=arm.frame_id,
        n=n,
        m=m,
        scenarios=sc,
        rows=rows,
        rank_coef=float(rank_coef),
        pivot_threshold=float(pivot_threshold),
        tolerate=bool(tolerate),
        gain=float(gain),
        max_step=float(max_step),
        la=la,
        keep=keep[:, None, :],
        Jm=np.empty((sc.f, m, n)),
        stack=np.empty((sc.f, m, m)),
        upper=(j[:, None] < j[None, :]).astype(float)[:, None, :],
        box_state=box_state,
        **_weight_tables(sc, n),
    )
