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
* buffers allocated once; pass ``out=`` to get the rates in your own array.

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
  (needs the optional ``numba`` package; compiled once, cached on disk);
* ``"lapack"``: LAPACK/BLAS through ``scipy.linalg`` (``dsyrk``, ``dposv``, ``dtrtri``,
  ``dgemm``, ``dgemv``), a handful of calls per step; what remains allocated per step
  (Pinocchio's Jacobian, the wrappers' small results) is out of reach from Python;
* ``"numpy"``: the same code with NumPy in place of the LAPACK wrappers (no extra dependency);
* ``"auto"`` (default): the first of these that is installed.

MDA and the RCN always use the lapack (or numpy) code; multi-joint JVJA with numba runs
:func:`fault_tolerance.control.fast.multi_step.multi_kernel`. The step kernels (the
LAPACK/NumPy calls, the numba kernel and its compilation) are in :mod:`fault_tolerance.control.lapack_steps`;
this module builds the workspace they run in and hands singular steps to the planner.

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

import numpy as np
import pinocchio as pin

from fault_tolerance.control import lapack_steps as kernels
from fault_tolerance.control.indices import ControllerIndices
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.numerics.linalg import PIVOT_EPS, PIVOT_TOL
from fault_tolerance.resolution import jvja as jvja_module
from fault_tolerance.resolution import mda as mda_module
from fault_tolerance.resolution.lnva import lnva as lnva_rates
from fault_tolerance.resolution.registry import KERNEL_JVJA, KERNEL_LNVA, KERNEL_MDA, get, names
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

__all__ = [
    "BACKENDS",
    "Controller",
    "available_backends",
]

#: Backends of the LNVA / JVJA steps, fastest first.
BACKENDS = ("numba", "lapack", "numpy")

_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD
_INF = float("inf")


def available_backends() -> list[str]:
    """Backends that can run here, fastest first."""
    out = []
    for name, module in (("numba", "numba"), ("lapack", "scipy.linalg")):
        try:
            __import__(module)
            out.append(name)
        except ImportError:
            pass
    return out + ["numpy"]


def _backend(backend: str) -> str:
    """The backend ``backend`` names (``"auto"``: the fastest installed), or InvalidInput."""
    available = available_backends()
    if backend == "auto":
        return available[0]
    if backend not in BACKENDS:
        raise InvalidInput(f"backend '{backend}' is not one of {['auto', *BACKENDS]}")
    if backend not in available:
        package = {"numba": "numba", "lapack": "scipy"}[backend]
        raise InvalidInput(
            f"backend '{backend}' needs the package {package} (pip install {package}); "
            f"available here: {available}"
        )
    return backend


class Controller(ControllerIndices):
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
        backend: ``"auto"``, ``"numba"``, ``"lapack"`` or ``"numpy"`` (see the module doc).
        limits: Honour the joint limits (default): every step stays inside the rate box (L1) of
            the arm's position and velocity limits at ``q`` (docs/MATH.md "Joint limits"); the
            fast step is checked against it and only a step that meets a bound is solved as the
            bounded problem (:mod:`fault_tolerance.control.bounded_step`). ``False``: the paper's rates.
        horizon: Horizon of the rate box [s] (default ``bounded.RATE_HORIZON``, 0.05 s; at
            least your control period).

    Attributes:
        step: The step chosen by ``method``: ``step(q, xdot, out=None) -> qd``.
        lnva: ``lnva(q, xdot, out=None) -> qd``, least-norm rates.
        jvja: ``jvja(q, xdot, out=None) -> qd``, minimum-jump rates, eq. (5).
        mda: ``mda(q, xdot, out=None) -> qd``, maximum-dexterity rates.
        scenarios: The validated failure scenarios.
        backend: The backend in use.
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
        self.data = arm.model.createData()
        self.frame_id = arm.frame_id
        self.n, self.m = arm.n, arm.m
        self.scenarios: Scenarios = scenarios(
            lockable, arm.n, r=arm.redundancy, weights=weights, joint_names=arm.joint_names
        )
        self.method = method
        self.gain = gain
        self.max_step = float(max_step)
        self.tolerate = bool(tolerate)
        # Pivots N_ii below this leave the fast path: intolerable (raise), or damped by the planner.
        self._pivot_threshold = PIVOT_EPS if self.tolerate else PIVOT_TOL
        self.backend = backend
        self.fallbacks = 0
        self._rows, self._rank_coef = kernels.row_selector(arm), kernels.rank_coefficient(arm)
        # The steps are closures over this workspace, built by the backend's kernels.
        self._la = (
            kernels.numpy_linalg() if backend == "numpy" else kernels.lapack_linalg_or_numpy()
        )
        self._init_scenario_tables()
        self._jvja_ws: list = [None] * 3  # P, Q, c of the last JVJA step: N = I - PᵀQ (kernels)
        self.limits = bool(limits)
        # [last scale, 1 after a bounded step, active joints (1.0)]: the bounded steps write it
        self._box_state = np.zeros(self.n + 2)
        self._box_state[0] = 1.0
        self._box_ws = None  # the compiled bounded steps' workspace (boxfast)
        self.bounded_steps = 0
        self.bounded_reference_steps = 0
        self._build_steps(backend, horizon)
        compiled = {KERNEL_LNVA: self.lnva, KERNEL_JVJA: self.jvja, KERNEL_MDA: self.mda}
        if entry.compiled in compiled and not options:
            self.step = compiled[entry.compiled]
        else:  # its reference rates (a new resolver, or a built-in with options of its own)
            from fault_tolerance.control.generic_step import generic_step

            self.step = generic_step(self, entry, self.options)

    def _build_steps(self, backend: str, horizon: float | None) -> None:
        """The built-ins' steps :attr:`lnva`, :attr:`jvja`, :attr:`mda` on ``backend``'s kernels."""
        if backend == "numba":
            from fault_tolerance.control.fast.step import compiled_step

            self.lnva = compiled_step(self, KERNEL_LNVA)
            if self._singletons:
                self.jvja = compiled_step(self, KERNEL_JVJA)
            else:  # multi-joint scenarios (G1), compiled too
                from fault_tolerance.control.fast.multi_step import compiled_multi_step

                self.jvja = compiled_multi_step(self)
        else:
            self.lnva = kernels.lapack_lnva(self)
            self.jvja = kernels.lapack_jvja(self)
        self.mda = kernels.lapack_mda(self)
        if self.limits:  # the fast steps checked against the rate box (L1), bounded when needed
            from fault_tolerance.control.bounded_step import bounded_step
            from fault_tolerance.model.joint_limits import RATE_HORIZON

            self.horizon = float(RATE_HORIZON if horizon is None else horizon)
            self.lnva = bounded_step(self, "lnva", self.lnva, self.horizon)
            self.jvja = bounded_step(self, "jvja", self.jvja, self.horizon)
            self.mda = bounded_step(self, "mda", self.mda, self.horizon)

    # -- helpers ----------------------------------------------------------------------------
    @property
    def last_scale(self) -> float:
        """Task scaling of the last step (1 unless the task was out of reach in the box)."""
        return float(self._box_state[0])

    @property
    def last_active(self) -> np.ndarray:
        """Joints held at a bound in the last step, bool (n,) (a new array)."""
        return self._box_state[2:] != 0.0

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
        return pin.computeFrameJacobian(self.model, self.data, q, self.frame_id, _LWA)[self._rows]

    def _init_scenario_tables(self) -> None:
        sc, n = self.scenarios, self.n
        w = sc.weights / sc.weights.max()  # eq. (5) is scale-free; a sum of these cannot overflow
        W = float(w.sum())
        self._singletons = sc.singletons
        self._uniform = bool(np.all(sc.weights == sc.weights[0]))
        self._all_uniform = False
        # fw[0]: 0 on lockable columns, +inf elsewhere (a_i / (N_ii + inf) = 0 there);
        # fw[1]: w_i / W on lockable columns (1 everywhere with uniform weights: alpha = -1/f).
        self._fw = np.zeros((2, n))
        self._fw[1] = 1.0
        if sc.singletons:
            cols = sc.columns
            self._all_uniform = self._uniform and sorted(cols.tolist()) == list(range(n))
            self._fw[0] = _INF
            self._fw[0, cols] = 0.0
            if not self._uniform:
                self._fw[1] = 0.0
                self._fw[1, cols] = w / W
        self._alpha = -1.0 / sc.f if (self._uniform and sc.singletons) else -1.0
        # Scenarios grouped by size for the batched (G1) solve: (columns (k, s), w / W (k,)).
        self._groups: list[tuple[np.ndarray, np.ndarray]] = []
        for size in sorted({len(S) for S in sc.sets}):
            members = [k for k, S in enumerate(sc.sets) if len(S) == size]
            idx = np.array([sc.sets[k] for k in members], dtype=int)
            self._groups.append((idx, w[members] / W))
        # keep[k, 0, j] = 0 when joint j is locked in scenario k: J_S = J * keep[k] (column mask).
        keep = np.ones((sc.f, n))
        for k, S in enumerate(sc.sets):
            keep[k, list(S)] = 0.0
        self._keep = keep[:, None, :]
        self._Jm = np.empty((sc.f, self.m, n))
        self._stack = np.empty((sc.f, self.m, self.m))
        j = np.arange(n)
        self._upper = (j[:, None] < j[None, :]).astype(float)[:, None, :]  # (n, 1, n)

    def _fallback(self, name: str, J: np.ndarray, xdot, out: np.ndarray, q=None) -> np.ndarray:
        """The step done by :mod:`.planner` itself (damped near singularities), into ``out``."""
        J = np.array(J, dtype=float)
        xdot = np.asarray(xdot, dtype=float)
        if xdot.shape != (self.m,):
            raise InvalidInput(f"xdot has shape {xdot.shape}; {self.arm.name} needs ({self.m},)")
        if not (np.all(np.isfinite(J)) and np.all(np.isfinite(xdot))):
            raise InvalidInput("q and xdot must be finite")
        self.fallbacks += 1
        if name == "lnva":
            qd = lnva_rates(J, xdot)
        elif name == "jvja":
            qd = jvja_module.jvja(J, xdot, self.scenarios, tolerate=self.tolerate)
        else:
            qd = mda_module.mda(
                J,
                xdot,
                self.scenarios,
                dJ=self.jacobian_derivatives(q),
                gain=self.gain,
                max_step=self.max_step,
            )
        out[...] = qd
        return out

    def _bad_call(self, err: Exception, q, xdot, out) -> InvalidInput:
        """An :class:`InvalidInput` that says which argument of a step is wrong."""
        if not (isinstance(q, np.ndarray) and q.dtype == np.float64):
            return InvalidInput(f"q must be a float64 NumPy array of shape ({self.n},), got {q!r}")
        for name, value, shape in (("q", q, (self.n,)), ("xdot", xdot, (self.m,))):
            if np.shape(value) != shape:
                return InvalidInput(
                    f"{name} has shape {np.shape(value)}; {self.arm.name} needs shape {shape}"
                )
        if out is not None and not (
            isinstance(out, np.ndarray)
            and out.shape == (self.n,)
            and out.dtype == np.float64
            and out.flags.c_contiguous
        ):
            return InvalidInput(f"out must be a C-contiguous float64 array of shape ({self.n},)")
        return InvalidInput(f"step failed: {err}")

    # -- multi-joint JVJA (G1), called by kernels.lapack_jvja ---------------------------------
    def _shift_general(self, J: np.ndarray, B: np.ndarray, a: np.ndarray, c: np.ndarray) -> bool:
        """``c = Σ_S (w_S/W) E_S N[S,S]⁻¹ a[S]`` (G1), one batched solve per scenario size.

        ``N[S, S] = I - J_Sᵀ B_S`` (``B = G⁻¹J``): N itself is never formed. False when a pivot
        needs the planner's damping (``tolerate``); raises when intolerable.
        """
        c[:] = 0.0
        for idx, wrel in self._groups:
            NSS = -np.einsum("rks,rkt->kst", J[:, idx], B[:, idx])  # (k, s, s)
            NSS[:, range(idx.shape[1]), range(idx.shape[1])] += 1.0
            if idx.shape[1] == 1:
                piv = NSS[:, 0, 0]
                if piv.min() < self._pivot_threshold:
                    if self.tolerate:
                        return False
                    self.scenarios.check_tolerable(np.eye(self.n) - J.T @ B)
                np.add.at(c, idx[:, 0], wrel * a[idx[:, 0]] / piv)
                continue
            if np.linalg.eigvalsh(NSS)[:, 0].min() < self._pivot_threshold:
                if self.tolerate:
                    return False
                self.scenarios.check_tolerable(np.eye(self.n) - J.T @ B)
            sol = np.linalg.solve(NSS, a[idx][:, :, None])[:, :, 0]  # (k, s)
            np.add.at(c, idx.ravel(), (wrel[:, None] * sol).ravel())
        return True
