"""Real-time redundancy resolution: one preallocated workspace per arm, one call per control tick.

:class:`Controller` is built once from an :class:`~fault_tolerance.model.arm.Arm` and a lockable set;
each call of :meth:`Controller.step` computes the task Jacobian with Pinocchio and the LNVA, JVJA
or MDA rates, with the numbers of :func:`fault_tolerance.resolve` (tested to 1e-10) at a fraction
of its cost:

* one Cholesky factorisation of ``G = J Jᵀ`` per step and no pseudo-inverse at all: it gives
  ``B = G⁻¹J``, from which ``a = J⁺ẋ = Bᵀẋ`` and ``N = I - JᵀB``;
* JVJA in closed form (G2), ``q̇ = a - N c / W`` with ``cᵢ = wᵢ aᵢ / Nᵢᵢ``: no per-scenario
  pseudo-inverse; multi-joint scenarios (G1) with one batched solve per scenario size;
* the reduced condition numbers of all scenarios from one batched ``eigvalsh`` of the stack
  ``J_S J_Sᵀ`` (docs/MATH.md, eq. 15), and the MDA gradient from one batched ``eigh``;
* buffers allocated once, in one :class:`~fault_tolerance.control.workspace.ControllerWorkspace`
  (:attr:`Controller.workspace`, frozen: its tables cannot be rebound); pass ``out=`` to get the
  rates in your own array.

Near singularities nothing is approximated. A step first checks a certificate that no damping is
needed: with the Cholesky factor ``G = UᵀU``, ``λ_min(G) ≥ 1 / trace(G⁻¹)`` and
``trace(G⁻¹) = ‖U⁻¹‖_F²``, so ``‖U⁻¹‖_F² ≤ 1 / SIGMA_EPS²`` proves ``σ_min(J) ≥ SIGMA_EPS`` (up
to the factorisation's backward error, ~1e-16 ‖G‖). The certificate is taken from the factor, not
from the solution ``B``: for a numerically singular ``G`` a solve can return a moderate ``B``.
When the certificate fails (or the factorisation does), the step is handed to
:mod:`fault_tolerance.resolution.resolvers` itself, which damps and drops rank as documented in
:mod:`fault_tolerance.numerics.linalg`; :attr:`Controller.fallbacks` counts those steps. An intolerable
scenario raises the same :class:`~fault_tolerance.errors.IntolerableFailure` as the planner.

Backends for the LNVA and single-joint JVJA steps (``backend=``):

* ``"numba"``: the whole step after the Jacobian in one compiled kernel, no allocation at all
  (numba is a core dependency; compiled once, cached on disk);
* ``"numpy"``: the same formulas as a handful of NumPy calls per step (``dsyrk``-, ``dposv``-,
  ``dtrtri``-shaped), the plain route where numba is missing;
* ``"auto"`` (default): the first of these that is installed.

MDA (the paper's baseline) is the reference rates with every backend; the RCN uses the NumPy
code; with numba, multi-joint JVJA runs
:func:`fault_tolerance.control.fast.multi_step.multi_kernel`. The step kernels (the
NumPy calls, the numba kernel and its compilation) are in :mod:`fault_tolerance.control.lapack_steps`;
this module builds the workspace they run in (:mod:`fault_tolerance.control.workspace`);
:mod:`fault_tolerance.control.fallback` hands singular steps to the planner.

Example:
    >>> import numpy as np, fault_tolerance as ft
    >>> from fault_tolerance.control.controller import Controller
    >>> arm = ft.load_arm("planar_3r")
    >>> ctrl = Controller(arm, lockable="all")
    >>> q, xd, qd = np.array([0.3, 1.2, 1.0]), np.array([0.1, 0.0]), np.empty(3)
    >>> _ = ctrl.step(q, xd, out=qd)
    >>> bool(np.allclose(qd, ft.resolve("jvja", arm.jacobian(q), xd, lockable="all")))
    True
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from fault_tolerance.control import indices
from fault_tolerance.control import lapack_steps as kernels
from fault_tolerance.control.workspace import (
    BOUNDED_REFERENCE_STEPS,
    BOUNDED_STEPS,
    FALLBACKS,
    ControllerWorkspace,
    build_workspace,
)
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.numerics.linalg import PIVOT_EPS, PIVOT_TOL
from fault_tolerance.resolution import mda as mda_module
from fault_tolerance.resolution.registry import KERNEL_JVJA, KERNEL_LNVA, KERNEL_MDA, get, names
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

__all__ = [
    "BACKENDS",
    "Controller",
    "available_backends",
]

#: Backends of the LNVA / JVJA steps, fastest first.
BACKENDS = ("numba", "numpy")


def available_backends() -> list[str]:
    """Backends that can run here, fastest first."""
    from fault_tolerance.fast_cache import COMPILED

    return ["numba", "numpy"] if COMPILED else ["numpy"]


def _counter(index: int, doc: str) -> property:
    """A count of the workspace's ``counts[index]``, read and reset through the Controller."""

    def get(self) -> int:
        return int(self.workspace.counts[index])

    def set_(self, value: int) -> None:
        self.workspace.counts[index] = value

    return property(get, set_, doc=doc)


def _backend(backend: str) -> str:
    """The backend ``backend`` names (``"auto"``: the fastest installed), or InvalidInput."""
    available = available_backends()
    if backend == "auto":
        return available[0]
    if backend not in BACKENDS:
        raise InvalidInput(f"backend '{backend}' is not one of {['auto', *BACKENDS]}")
    if backend not in available:
        raise InvalidInput(
            f"backend '{backend}' needs the package numba (pip install numba); "
            f"available here: {available}"
        )
    return backend


class Controller:
    """A preallocated workspace for LNVA / JVJA / MDA steps of one arm and one lockable set.

    Build it once, outside the control loop, then call :attr:`step` (or :attr:`lnva`,
    :attr:`jvja`, :attr:`mda`, :meth:`rcn`) at every tick. The steps take the active-joint
    positions ``q`` [rad], shape (n,), and the task velocity ``xdot``, shape (m,), as float64
    arrays, and return the joint rates [rad/s], shape (n,): written into ``out`` when it is given
    (a C-contiguous float64 array of shape (n,), returned as is), else in a new array. A wrong
    shape or a non-finite input raises :class:`~fault_tolerance.errors.InvalidInput`.

    Args:
        arm: The arm (``ft.load_arm(...)``); the controller keeps its own ``pinocchio.Data``.
        lockable: Joints that may lock, as for :func:`fault_tolerance.resolve`: ``None`` or
            ``"all"`` (every joint), column indices or joint names, tuples for multi-joint
            scenarios (``|S| <= r``), or a :class:`~fault_tolerance.resolution.scenarios.Scenarios`. The
            catalog's choice for an arm is ``arm.default_lockable``.
        method: What :attr:`step` computes: a registered resolver
            (:func:`fault_tolerance.resolution.registry.names`), ``"jvja"`` by default. The
            built-ins step with their compiled kernels; a resolver registered without
            ``compiled`` steps with its reference rates (its ``bounded`` variant under limits),
            through :func:`fault_tolerance.control.generic_step.generic_step`.
        options: The resolver's own options by name (its options dataclass); ``gain`` and
            ``max_step`` below fill options of those names unless given here. An option the
            resolver does not take raises :class:`~fault_tolerance.errors.InvalidInput`.
        weights: One positive weight per scenario (default 1).
        gain: MDA gain α of ``q̇ = J⁺ẋ - α N ∇K`` (default ``mda.MDA_GAIN``).
        max_step: Cap of the norm of MDA's null-space step [rad/s] (``mda.MDA_MAX_STEP``).
        tolerate: As ``planner.jvja(tolerate=True)``: pivots of ``N[S, S]`` below
            ``linalg.PIVOT_EPS`` are damped (by the planner) instead of raising
            :class:`~fault_tolerance.errors.IntolerableFailure`; for loops that may cross a
            singularity of a reduced Jacobian.
        backend: ``"auto"``, ``"numba"`` or ``"numpy"`` (see the module doc).
        limits: Honour the joint limits (default): every step stays inside the rate box (L1) of
            the arm's position and velocity limits at ``q`` (docs/MATH.md "Joint limits"); the
            fast step is checked against it and only a step that meets a bound is solved as the
            bounded problem (:mod:`fault_tolerance.control.bounded_step`). ``False``: the paper's rates.
        horizon: Horizon of the rate box [s] (default ``bounded.RATE_HORIZON``, 0.05 s; at
            least your control period).

    Attributes:
        step: The step chosen by ``method`` (and ``options``): ``step(q, xdot, out=None) -> qd``.
        options: The resolver's options dataclass, as built from ``options``, ``gain`` and
            ``max_step``.
        lnva: ``lnva(q, xdot, out=None) -> qd``, least-norm rates.
        jvja: ``jvja(q, xdot, out=None) -> qd``, minimum-jump rates, eq. (5).
        mda: ``mda(q, xdot, out=None) -> qd``, maximum-dexterity rates.
        scenarios: The validated failure scenarios.
        backend: The backend in use.
        workspace: The :class:`~fault_tolerance.control.workspace.ControllerWorkspace` the steps
            run in (tables, scratch, the last step's state, the counters).
        fallbacks: Number of steps handed to :mod:`~fault_tolerance.resolution.resolvers` (near a singularity
            of ``J``, where the rates are damped).
        last_scale: Task scaling of the last step (1 unless the task was out of reach in the box).
        last_active: Joints held at a bound in the last step, bool (n,).
        bounded_steps: Number of steps that met a bound and were solved as the bounded problem.
        bounded_reference_steps: Those of them solved by the Python reference
            (:func:`fault_tolerance.resolution.bounded.resolve_bounded`) rather than compiled (near a
            singularity, an empty box, the lapack and numpy backends).
    """

    step: Callable[..., np.ndarray]
    lnva: Callable[..., np.ndarray]
    jvja: Callable[..., np.ndarray]
    mda: Callable[..., np.ndarray]

    def __init__(
        self,
        arm: Arm,
        lockable=None,
        *,
        method: str = "jvja",
        weights: Sequence[float] | None = None,
        gain: float = mda_module.MDA_GAIN,
        max_step: float = mda_module.MDA_MAX_STEP,
        tolerate: bool = False,
        backend: str = "auto",
        limits: bool = True,
        horizon: float | None = None,
        options: dict | None = None,
    ) -> None:
        if method not in names():
            raise InvalidInput(f"method '{method}' is not one of {list(names())}")
        entry = get(method)
        if limits and entry.bounded is None:
            raise InvalidInput(
                f"resolver '{method}' has no bounded variant: it cannot honour the joint limits; "
                "build the Controller with limits=False"
            )
        run = {"gain": gain, "max_step": max_step}  # the scenarios' weights are weights=
        self.options = entry.options_with(options, run, {"weights": "Controller(weights=...)"})
        gain = float(gain)
        if not np.isfinite(gain) or gain < 0:
            raise InvalidInput(f"mda gain must be finite and >= 0, got {gain}")
        if arm.redundancy < 1:
            raise InvalidInput(
                f"{arm.name} has n = {arm.n} joints for m = {arm.m} task rows; a controller for "
                "locked-joint failures needs a redundant arm (n > m)"
            )
        backend = _backend(backend)
        self.arm = arm
        self.model = arm.model
        self.frame_id = arm.frame_id
        self.n, self.m = arm.n, arm.m
        self.scenarios: Scenarios = scenarios(
            lockable, arm.n, r=arm.redundancy, weights=weights, joint_names=arm.joint_names
        )
        self.method = method
        self.gain = gain
        self.max_step = float(max_step)
        self.tolerate = bool(tolerate)
        self.backend = backend
        self.limits = bool(limits)
        self.workspace = self._build_workspace()
        self.data = self.workspace.data
        self._build_steps(horizon)
        compiled = {KERNEL_LNVA: self.lnva, KERNEL_JVJA: self.jvja, KERNEL_MDA: self.mda}
        if entry.compiled in compiled and not options:
            self.step = compiled[entry.compiled]
        else:  # its reference rates (a new resolver, or a built-in with options of its own)
            from fault_tolerance.control.generic_step import generic_step

            box_horizon = self.horizon if self.limits else None
            self.step = generic_step(self.workspace, entry, self.options, box_horizon)

    def _build_workspace(self) -> ControllerWorkspace:
        """The tables of this arm and lockable set (and the compiled bounded steps' ones)."""
        ws = build_workspace(
            self.arm,
            self.scenarios,
            rows=kernels.row_selector(self.arm),
            rank_coef=kernels.rank_coefficient(self.arm),
            # Pivots N_ii below this leave the fast path: intolerable (raise), or damped.
            pivot_threshold=PIVOT_EPS if self.tolerate else PIVOT_TOL,
            tolerate=self.tolerate,
            gain=self.gain,
            max_step=self.max_step,
            la=kernels.numpy_linalg(),
        )
        if self.limits and self.backend == "numba":
            from fault_tolerance.control.fast.bounded_step import bounded_tables

            tables, state = bounded_tables(ws)
            ws = replace(ws, box_tables=tables, box_state=state)
        return ws

    def _build_steps(self, horizon: float | None) -> None:
        """The built-ins' steps :attr:`lnva`, :attr:`jvja`, :attr:`mda`, closures over the workspace."""
        ws = self.workspace
        if self.backend == "numba":
            from fault_tolerance.control.fast.step import compiled_step

            self.lnva = compiled_step(ws, KERNEL_LNVA)
            if ws.singletons:
                self.jvja = compiled_step(ws, KERNEL_JVJA)
            else:  # multi-joint scenarios (G1), compiled too
                from fault_tolerance.control.fast.multi_step import compiled_multi_step

                self.jvja = compiled_multi_step(ws)
        else:
            self.lnva = kernels.lapack_lnva(ws)
            self.jvja = kernels.lapack_jvja(ws)
        self.mda = kernels.lapack_mda(ws, self.arm)  # MDA, the paper's baseline: its reference
        if self.limits:  # the fast steps checked against the rate box (L1), bounded when needed
            from fault_tolerance.control.bounded_step import bounded_step
            from fault_tolerance.model.joint_limits import RATE_HORIZON

            self.horizon = float(RATE_HORIZON if horizon is None else horizon)
            self.lnva = bounded_step(ws, "lnva", self.lnva, self.horizon, self.backend)
            self.jvja = bounded_step(ws, "jvja", self.jvja, self.horizon, self.backend)
            self.mda = bounded_step(ws, "mda", self.mda, self.horizon, self.backend)

    # -- state and indices ---------------------------------------------------------------------
    fallbacks = _counter(FALLBACKS, "Steps handed to the planner (near a singularity of ``J``).")
    bounded_steps = _counter(BOUNDED_STEPS, "Steps that met a bound and were solved bounded.")
    bounded_reference_steps = _counter(
        BOUNDED_REFERENCE_STEPS, "Bounded steps solved by the Python reference, not compiled."
    )

    @property
    def last_scale(self) -> float:
        """Task scaling of the last step (1 unless the task was out of reach in the box)."""
        return float(self.workspace.box_state[0])

    @property
    def last_active(self) -> np.ndarray:
        """Joints held at a bound in the last step, bool (n,) (a new array)."""
        return self.workspace.box_state[2:] != 0.0

    @property
    def f(self) -> int:
        """Number of failure scenarios."""
        return self.scenarios.f

    def __repr__(self) -> str:
        return (
            f"Controller({self.arm.name!r}, method={self.method!r}, backend={self.backend!r}, "
            f"n={self.n}, m={self.m}, scenarios={self.f})"
        )

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Task Jacobian at ``q``, shape (m, n), computed as in the steps (no input validation)."""
        return indices.jacobian(self.workspace, q)

    def rcn(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Reduced condition numbers ``k_S`` of all scenarios at ``q``, eq. (15), shape (f,).

        One batched ``eigvalsh`` of the stack ``J_S J_Sᵀ``; capped at ``RCN_MAX`` as
        :func:`fault_tolerance.rcn`.
        """
        return indices.rcn(self.workspace, q, out)

    def rcn_of(self, J: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`rcn`, for a given task Jacobian ``J`` of shape (m, n)."""
        return indices.rcn_of(self.workspace, J, out)

    def jacobian_derivatives(self, q: np.ndarray) -> np.ndarray:
        """``dJ[j] = ∂J/∂q_j``, shape (n, m, n), as :meth:`Arm.jacobian_derivatives`, vectorised."""
        return indices.jacobian_derivatives(self.workspace, q)

    def rcn_gradient(self, J: np.ndarray, dJ: np.ndarray) -> np.ndarray:
        """Gradient of ``K = Σ_S k_S²``, shape (n,), as :func:`fault_tolerance.rcn_gradient`."""
        return indices.rcn_gradient(self.workspace, J, dJ)
