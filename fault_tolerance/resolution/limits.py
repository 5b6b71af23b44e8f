"""Joint limits at the arm and in the indices: the arm's box, the jump and tolerance under limits.

The box (L1) of an :class:`~fault_tolerance.model.arm.Arm` with the documented velocity defaults; the
jump (1), (9)/(10) measured against the rates the reduced robots take under the box (L4)-(L5); the
scenarios that are intolerable *under limits* (a reduced robot that cannot keep the task inside its
box at ``q``), for a given task velocity (:func:`tolerable_under_limits`) or for every direction
(:func:`guaranteed_speed`, used by ``inspect``). See docs/MATH.md "Joint limits".
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from fault_tolerance.errors import IntolerableUnderLimits, InvalidInput
from fault_tolerance.model.joint_limits import RATE_HORIZON, arm_rate_box
from fault_tolerance.numerics.linalg import projection, reduced_rates
from fault_tolerance.resolution.bounded import (
    SCALE_TOL,
    _scenarios,
    check_bounds,
    exact_guesses_allowed,
    reduced_bounded,
    reduced_under_limits,
)
from fault_tolerance.resolution.indices import RESPONSES, square_sum_jump
from fault_tolerance.resolution.scenarios import Scenarios


def post_failure_under_limits(
    J, xdot, qd, sc: Scenarios, lo, hi, response="least_norm", *, tolerate=False
):
    """Rates each reduced robot takes under the box (f, n) and its task scaling (f,) (L4).

    Least-norm response: bounded LNVA of ``J_S``; continuation: the rates nearest to ``qd``.
    """
    J = np.asarray(J, dtype=float)
    proj = projection(J)
    if response == "least_norm":
        return reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
    if response != "continuation":
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    pivots = sc.pivots(proj.N) if tolerate else sc.check_tolerable(proj.N)
    exact = exact_guesses_allowed(proj, pivots)  # else every reduced robot is solved from J_S
    sols = []
    for S in sc.sets:
        guess = reduced_rates(qd, proj.N, S) if exact else None  # (G3), unbounded
        sols.append(reduced_bounded(J, xdot, S, lo, hi, target=qd, guess=guess))
    return np.array([s.qd for s in sols]), np.array([s.scale for s in sols])


# Eqn. (9), (10) under limits (L5)
def jvj_under_limits(
    J,
    xdot,
    qd,
    lockable=None,
    *,
    bounds,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    per_joint: bool = False,
    joint_names: Sequence[str] = (),
):
    """Square-sum jump (9)/(10) of ``qd`` against the rates the reduced robots take under ``bounds``.

    With ``per_joint=True`` the (f, n) jumps of eq. (1). Raises :class:`IntolerableUnderLimits`
    when a reduced robot cannot keep the task inside the box (:func:`tolerable_under_limits` gives
    the scalings instead).
    """
    J = np.asarray(J, dtype=float)
    lo, hi = check_bounds(bounds, J.shape[1])
    sc = _scenarios(J, lockable, weights, joint_names)
    qd = np.asarray(qd, dtype=float)
    post, scales = post_failure_under_limits(
        J, np.asarray(xdot, dtype=float), qd, sc, lo, hi, response
    )
    check_tolerable_under_limits(sc, scales)
    if per_joint:
        return np.abs(post - qd)
    return square_sum_jump(post, qd, sc.weights)


def tolerable_under_limits(J, xdot, lockable=None, *, bounds, joint_names: Sequence[str] = ()):
    """Task scaling ``s_S`` each reduced robot needs under ``bounds`` (f,); ``s_S < 1``: intolerable.

    The largest feasible scaling of each reduced robot's LP (L4), at any ``σ_min(J_S)``: a scenario
    that loses the task (``N[S, S]`` singular) has ``s_S = 0`` (or what its box still allows).
    """
    J = np.asarray(J, dtype=float)
    lo, hi = check_bounds(bounds, J.shape[1])
    sc = _scenarios(J, lockable, None, joint_names)
    _, scales = reduced_under_limits(J, np.asarray(xdot, dtype=float), sc, lo, hi, tolerate=True)
    return scales


def check_tolerable_under_limits(sc: Scenarios, scales: np.ndarray) -> None:
    """Raise :class:`IntolerableUnderLimits` for the first scenario whose scaling is below 1."""
    bad = np.flatnonzero(scales < 1.0 - SCALE_TOL)
    if len(bad):
        k = int(bad[np.argmin(scales[bad])])
        raise IntolerableUnderLimits(sc.name(sc.sets[k]), float(scales[k]))


#: Above this many candidate facets, guaranteed_speed samples directions instead.
MAX_FACETS = 20000


def _facet_normals(G: np.ndarray) -> np.ndarray:
    """Unit normals (both signs) of the zonotope spanned by the columns of ``G`` (m, k)."""
    m, k = G.shape
    if m == 1:
        return np.array([[1.0], [-1.0]])
    normals = []
    for sub in itertools.combinations(range(k), m - 1):
        U, s, _ = np.linalg.svd(G[:, sub], full_matrices=True)
        if s[-1] < 1e-12 * max(s[0], 1e-300):
            continue  # these generators span less than a hyperplane
        normals += [U[:, -1], -U[:, -1]]
    return np.array(normals).reshape(-1, m)


def guaranteed_speed(J, lo, hi, samples: int = 4000) -> float:
    """Largest ``ρ`` such that every task velocity with ``‖ẋ‖ ≤ ρ`` is ``J q̇`` for ``q̇`` in the box.

    The image of the box is a zonotope; ``ρ`` is the smallest support value ``h(y) = Σ_j max(c_j
    lo_j, c_j hi_j)``, ``c = Jᵀy``, over its unit facet normals (exact; sampled directions when
    there are more than :data:`MAX_FACETS`). ``ρ ≤ 0``: some direction cannot be followed at all.
    Task units mix for pose tasks (m/s and rad/s in one norm).
    """
    J = np.asarray(J, dtype=float)
    m, k = J.shape
    lo, hi = check_bounds((lo, hi), k)
    from math import comb

    if np.linalg.matrix_rank(J) < m:
        return 0.0  # the image of any box lies in a subspace: some direction is never reached
    if comb(k, m - 1) <= MAX_FACETS:
        Y = _facet_normals(J)
        if not len(Y):  # numerically no m-1 columns span a hyperplane: J is (nearly) rank-deficient
            return 0.0
    else:
        Y = np.random.default_rng(0).normal(size=(samples, m))
        Y /= np.linalg.norm(Y, axis=1, keepdims=True)
    C = Y @ J  # (d, k)
    return float(np.maximum(C * lo, C * hi).sum(axis=1).min())


def reduced_speeds(J, lo, hi, sc: Scenarios) -> np.ndarray:
    """:func:`guaranteed_speed` of every reduced robot (joints ``S`` locked), shape (f,)."""
    J = np.asarray(J, dtype=float)
    n = J.shape[1]
    out = []
    for S in sc.sets:
        keep = [j for j in range(n) if j not in set(S)]
        out.append(guaranteed_speed(J[:, keep], lo[keep], hi[keep]))
    return np.array(out)


def inspect_lines(arm, q, columns) -> list[str]:
    """``inspect``'s lines on limits at ``q``: the task speed each lockable joint's lock leaves.

    A joint whose reduced robot cannot follow some task direction at all inside the box (L1) at
    ``q`` (:func:`guaranteed_speed` ≤ 0) is intolerable under limits there.
    """
    from fault_tolerance.numerics.linalg import PIVOT_TOL

    lo, hi = arm_rate_box(arm, q)
    n = arm.n
    J = arm.jacobian(q)
    N = projection(J).N
    full = guaranteed_speed(J, lo, hi)
    speeds = {}
    for i in columns:
        keep = [j for j in range(n) if j != i]
        speeds[arm.joint_names[i]] = guaranteed_speed(J[:, keep], lo[keep], hi[keep])
    bad = [  # tolerable without limits (N_ii regular), not inside the box
        arm.joint_names[i]
        for i in columns
        if speeds[arm.joint_names[i]] <= 1e-9 and N[i, i] >= PIVOT_TOL
    ]
    units = "m/s" if all(r in "xyz" for r in arm.task) else "task units/s"
    return [
        f"under joint limits there (rate box, horizon {RATE_HORIZON} s): every task direction is "
        f"reachable up to {full:.3g} {units}; with one joint locked: "
        + ", ".join(f"{k} {v:.3g}" for k, v in speeds.items()),
        "intolerable under limits only (tolerable without; some direction unreachable inside the "
        "box): " + (", ".join(bad) if bad else "none"),
    ]
