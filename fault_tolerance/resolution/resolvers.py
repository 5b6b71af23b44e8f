"""Redundancy resolution: LNVA, JVJA and MDA, one small function each, and a registry by name.

Every resolver maps a task Jacobian ``J`` (m, n) and task velocity ``ẋ`` (m,) to joint rates
``q̇`` (n,) with ``J q̇ = ẋ`` (up to damping near singularities, see :mod:`.linalg`). Resolvers hold
no state.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.checks import finite
from fault_tolerance.numerics.linalg import Projection, damped_pivots, pivot_block, projection
from fault_tolerance.resolution.indices import RESPONSES, jvj, rcn_gradient
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Default MDA gain α [rad² per unit of K per s]: q̇ = J⁺ẋ − α N ∇K.
MDA_GAIN = 1e-2
#: Largest norm of MDA's null-space step α N ∇K [rad/s]: a numerical guard, not a speed limit.
#: Near a singularity of J or of a reduced Jacobian ∇K grows like k³ (k up to indices.RCN_MAX ≈ 1e8,
#: steps up to ~1e21 rad/s that no longer satisfy J q̇ = ẋ); the step keeps its direction and is
#: capped here. Ordinary steps are far below it (the paper's cases: < 0.1 rad/s).
MDA_MAX_STEP = 1e4


def _scenarios(J: np.ndarray, lockable, weights, joint_names) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def _unit_weights(sc: Scenarios) -> np.ndarray:
    """The weights over the largest: eq. (5) does not change, and their sum cannot overflow."""
    return sc.weights / sc.weights.max()


def lnva(
    J: np.ndarray, xdot: np.ndarray, lockable=None, *, proj: Projection | None = None
) -> np.ndarray:
    """LNVA, least-norm rates ``q̇ = J⁺ẋ`` (``lockable`` is accepted and ignored)."""
    return (proj or projection(J)).Jpinv @ xdot


# Eqn. (5), in closed form (G2); (G3) for the continuation response.
def jvja(
    J: np.ndarray,
    xdot: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    joint_names: Sequence[str] = (),
    tolerate: bool = False,
    proj: Projection | None = None,
) -> np.ndarray:
    r"""JVJA, minimum square-sum joint velocity jump, eq. (5).

    Least-norm response (the paper's): :math:`\dot q = a - \frac{1}{W}\sum_S w_S N_{:,S}
    N_{S,S}^{-1} a_S`, :math:`a = J^+\dot x`, :math:`W = \sum_S w_S`; for single-joint scenarios
    (G2) :math:`\dot q = a - N c / W`, :math:`c_i = w_i a_i / N_{ii}`. One pseudo-inverse per step.

    Continuation response (G3): :math:`\dot q = a + N z`, :math:`z = -(N W N)^+ N W a` with
    :math:`W = \sum_S w_S E_S N_{S,S}^{-1} E_S^T`.

    ``proj``: the :func:`~.linalg.projection` of ``J`` when the caller has it already.

    ``tolerate=True`` (used by the simulation after its first step) damps the pivots of ``N[S, S]``
    below ``linalg.PIVOT_EPS`` instead of raising: the rates stay finite when the path crosses a
    singularity of a reduced Jacobian (the scenario is intolerable only there).

    Raises:
        IntolerableFailure: a scenario's ``N[S, S]`` is singular (locking it loses the task), unless
            ``tolerate``.
    """
    sc = _scenarios(J, lockable, weights, joint_names)
    proj = proj or projection(J)
    N = proj.N
    a = proj.Jpinv @ xdot
    w = _unit_weights(sc)
    pivots = damped_pivots(sc.pivots(N)) if tolerate else sc.check_tolerable(N)
    if response == "least_norm":
        if sc.singletons:
            c = np.zeros_like(a)
            c[sc.columns] = w * a[sc.columns] / pivots
            return a - N @ c / w.sum()
        shift = sum(
            wS * N[:, list(S)] @ np.linalg.solve(pivot_block(N, S, tolerate), a[list(S)])
            for S, wS in zip(sc.sets, w, strict=True)
        )
        return a - shift / w.sum()
    if response == "continuation":
        W = np.zeros_like(N)
        for S, wS in zip(sc.sets, w, strict=True):
            W[np.ix_(S, S)] += wS * np.linalg.inv(pivot_block(N, S, tolerate))
        z = -np.linalg.pinv(N @ W @ N, rcond=1e-10, hermitian=True) @ (N @ W @ a)
        return a + N @ z
    raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")


# Eqn. (5) the explicit way: one pseudo-inverse per scenario (reference, slow).
def jvja_explicit(J: np.ndarray, xdot: np.ndarray, lockable=None, *, weights=None) -> np.ndarray:
    """Eq. (5) with ``ˢq̇' = E_S J_S⁺ ẋ`` from NumPy's SVD pseudo-inverse for every scenario."""
    from fault_tolerance.numerics.linalg import reduced_rates_explicit

    sc = _scenarios(J, lockable, weights, ())
    Jp = np.linalg.pinv(J)
    N = np.eye(J.shape[1]) - Jp @ J
    post = np.array([reduced_rates_explicit(J, xdot, S) for S in sc.sets])
    w = _unit_weights(sc)
    mean = w @ post / w.sum()
    return Jp @ xdot + N @ mean


def mda(
    J: np.ndarray,
    xdot: np.ndarray,
    lockable=None,
    *,
    arm=None,
    q: np.ndarray | None = None,
    gain: float = MDA_GAIN,
    dJ: np.ndarray | None = None,
    joint_names: Sequence[str] = (),
    max_step: float | None = MDA_MAX_STEP,
    proj: Projection | None = None,
) -> np.ndarray:
    r"""MDA, maximum dexterity: :math:`\dot q = J^+\dot x - \alpha N \nabla_q K(q)`.

    ``K = Σ_S k_S²`` is the square-sum reduced condition number (15); its gradient uses the
    Jacobian derivatives of ``arm`` at ``q`` (or ``dJ`` given directly, shape (n, m, n)).
    Default gain :data:`MDA_GAIN`. The null-space step is capped at ``max_step`` [rad/s]
    (:data:`MDA_MAX_STEP`; ``None``: no cap), so the rates stay finite and in the null space near
    singularities; a step that is not finite is dropped.
    """
    if dJ is None:
        if arm is None or q is None:
            raise InvalidInput("mda needs the configuration: pass arm=... and q=... (or dJ=...)")
        dJ = arm.jacobian_derivatives(q)
    if not np.isfinite(gain) or gain < 0:
        raise InvalidInput(f"mda gain must be finite and >= 0, got {gain}")
    proj = proj or projection(J)
    grad = rcn_gradient(J, dJ, lockable, joint_names=joint_names)
    step = gain * proj.N @ grad  # [rad/s], shape (n,)
    size = float(np.linalg.norm(step))
    if not np.isfinite(size):  # ∇K overflowed at a reduced singularity: no usable direction
        step = np.zeros_like(step)
    elif max_step is not None and size > max_step:
        step *= max_step / size
    return proj.Jpinv @ xdot - step


def check_task(J, xdot) -> tuple[np.ndarray, np.ndarray]:
    """``J`` (m, n) and ``ẋ`` (m,) as finite float arrays, or :class:`InvalidInput`."""
    J = np.asarray(J, dtype=float)
    xdot = np.asarray(xdot, dtype=float)
    if J.ndim != 2 or xdot.shape != (J.shape[0],):
        raise InvalidInput(f"J must be (m, n) and xdot (m,); got {J.shape} and {xdot.shape}")
    return finite(J, "J"), finite(xdot, "xdot")


RESOLVERS: dict[str, Callable[..., np.ndarray]] = {"lnva": lnva, "jvja": jvja, "mda": mda}

#: Keyword options each resolver takes (its signature after ``J, xdot, lockable``).
RESOLVER_OPTIONS: dict[str, frozenset[str]] = {
    name: frozenset(list(inspect.signature(f).parameters)[3:]) for name, f in RESOLVERS.items()
}
#: Every option :func:`resolve` accepts: those of some resolver.
OPTIONS = frozenset().union(*RESOLVER_OPTIONS.values())


def resolve(name: str, J: np.ndarray, xdot: np.ndarray, lockable=None, **options) -> np.ndarray:
    """Joint rates from the resolver ``name`` (``"lnva"``, ``"jvja"`` or ``"mda"``).

    Args:
        name: Resolver name.
        J: Task Jacobian, shape (m, n).
        xdot: Task velocity, shape (m,).
        lockable: Joints that may lock: column indices, names (with ``joint_names=``), tuples for
            multi-joint scenarios, ``None``/``"all"`` for every joint, or a :class:`Scenarios`.
        **options: ``weights``, ``response`` (jvja); ``arm``, ``q``, ``gain``, ``dJ``,
            ``max_step`` (mda); ``proj``, ``tolerate``; ``joint_names`` to name lockable joints
            (taken from ``arm`` when it is given). Each resolver gets the options it takes; an
            option no resolver takes raises :class:`InvalidInput`. The joint limits
            (``bounds=``) are :func:`fault_tolerance.resolve`'s (:mod:`fault_tolerance.resolution.api`).

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> arm = ft.load_arm("planar_3r")
        >>> q = np.array([0.3, 1.2, 1.0]); J = arm.jacobian(q); xd = np.array([0.1, 0.0])
        >>> qd = ft.resolve("jvja", J, xd, lockable=[1, 2])
        >>> bool(np.allclose(J @ qd, xd))
        True
    """
    if name not in RESOLVERS:
        raise InvalidInput(f"resolver '{name}' is not one of {sorted(RESOLVERS)}")
    unknown = sorted(set(options) - OPTIONS)
    if unknown:
        raise InvalidInput(
            f"resolve: unknown option(s) {unknown}; allowed options are {sorted(OPTIONS)}"
            + (" (bounds=: use fault_tolerance.resolve)" if "bounds" in unknown else "")
        )
    J, xdot = check_task(J, xdot)
    if options.get("arm") is not None and not options.get("joint_names"):
        options["joint_names"] = options["arm"].joint_names  # lockable joints by name
    own = RESOLVER_OPTIONS[name]
    return RESOLVERS[name](J, xdot, lockable, **{k: v for k, v in options.items() if k in own})


class JumpReduction(NamedTuple):
    """Eq. (14) at one configuration: measured and predicted reduction of the jump."""

    delta: float  # λ(q̇_LN) - λ(q̇_OPT)
    predicted: float  # (Σ w_S) ‖q̇_H‖²
    qd_h: np.ndarray  # null-space part q̇_OPT - q̇_LN


# Eqn. (11)-(14)
def jump_reduction(
    J: np.ndarray, xdot: np.ndarray, lockable=None, *, weights=None, joint_names: Sequence[str] = ()
) -> JumpReduction:
    r"""δ = λ(q̇_LN) − λ(q̇_OPT) and its closed form :math:`f\,\|\dot q_H\|^2`, eq. (14)."""
    J = np.asarray(J, dtype=float)
    sc = _scenarios(J, lockable, weights, joint_names)
    ln = lnva(J, xdot)
    opt = jvja(J, xdot, sc)
    delta = jvj(J, xdot, ln, sc) - jvj(J, xdot, opt, sc)
    qd_h = opt - ln
    return JumpReduction(delta, float(sc.weights.sum() * qd_h @ qd_h), qd_h)
