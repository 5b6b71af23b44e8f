"""Joint limits: the rate box at ``q`` (L1) and the bounded resolvers, before and after a lock.

Position limits ``[q_lo, q_hi]`` and velocity limits ``v`` give the box of admissible rates

    (L1)   q̇_lo = clip((q_lo − q)/h, −v, v),    q̇_hi = clip((q_hi − q)/h, −v, v)

for a horizon ``h`` (:data:`RATE_HORIZON`, never below the time step): a joint may cover at most
the distance to its limit in ``h``, so with ``h ≥ dt`` an Euler step ``q + q̇ dt`` never passes a
limit, and near a limit the joint slows down with time constant ``h`` instead of stopping in one
step. Each bounded resolver minimises its own objective on the task's affine set inside the box,
(L2) of :mod:`fault_tolerance.resolution.box_qp`:

* LNVA: ``min ‖q̇‖²``; MDA: ``min ‖q̇ + α∇K‖²`` (its unbounded rates are the projection of
  ``−α∇K``, with the same step cap);
* JVJA, least-norm response: ``min Σ_S w_S ‖ˢq̇'_b − q̇‖²`` where ``ˢq̇'_b`` are the rates the reduced
  robot takes under the same box (bounded LNVA of ``J_S``, (L4)): the jump is measured against what
  the reduced robot will actually do;
* JVJA, continuation response: ``min q̇ᵀ (Σ_S w_S E_S N[S,S]⁻¹ E_Sᵀ + εI) q̇`` (the (G3) jump, ε =
  :data:`CONTINUATION_EPS` times its mean diagonal making it strictly convex).

When no rates inside the box reach ``ẋ`` the task is scaled (L3): the largest ``s ≤ 1`` with
``J q̇ = s ẋ`` reachable, reported as :attr:`BoundedRates.scale`. A scenario whose reduced robot
needs ``s_S < 1`` (:attr:`BoundedRates.reduced_scale`) cannot keep the task inside its limits at
``q``: it is intolerable *under limits*.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import damped_pivots, projection, reduced_rates
from fault_tolerance.resolution.box_qp import BOX_TOL, BoxSolution, solve_box
from fault_tolerance.resolution.indices import RESPONSES
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Regularisation of the continuation metric, relative to its mean diagonal.
CONTINUATION_EPS = 1e-10
#: A reduced robot whose task scaling is below 1 − SCALE_TOL is intolerable under limits.
SCALE_TOL = 1e-9


class BoundedRates(NamedTuple):
    """Rates of a bounded resolver, the task scaling it needed, and what bound it met.

    ``qd`` (n,) is inside the box with ``J q̇ = scale · ẋ``; ``active`` (n,) marks joints held at a
    bound; ``reduced_scale`` (f,) is each scenario's own task scaling after its lock (empty for
    LNVA and MDA, which know no scenarios).
    """

    qd: np.ndarray
    scale: float
    active: np.ndarray
    reduced_scale: np.ndarray


def check_bounds(bounds, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` as float arrays of shape (n,) with ``lo ≤ hi``, or :class:`InvalidInput`."""
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise InvalidInput("bounds must be a pair (qd_lo, qd_hi) of rate arrays") from None
    if not (_is_rates(lo, n) and _is_rates(hi, n)):
        try:
            lo = np.broadcast_to(np.asarray(lo, dtype=float), (n,)).copy()
            hi = np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            raise InvalidInput(f"bounds must be two arrays of {n} rates (or scalars)") from None
    if not (lo <= hi).all():  # also False where either is NaN
        if np.isnan(lo).any() or np.isnan(hi).any():
            raise InvalidInput("bounds must not contain NaN (use ±inf for no bound)")
        bad = np.flatnonzero(lo > hi).tolist()
        raise InvalidInput(f"bounds: qd_lo > qd_hi at joint index {bad}; each lower <= upper")
    return lo, hi


def _is_rates(x, n: int) -> bool:
    return isinstance(x, np.ndarray) and x.dtype == np.float64 and x.shape == (n,)


def _null_basis(N: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the range of the projector ``N``, shape (n, r)."""
    w, V = np.linalg.eigh(N)
    return V[:, w > 0.5]


# Eqn. (L4): bounded least-norm rates (LNVA, and the reduced robot after a lock).
def bounded_least_norm(J, xdot, lo, hi, target=None, proj=None) -> BoxSolution:
    """``min ‖q̇ − c‖²`` s.t. ``J q̇ = s ẋ`` inside ``[lo, hi]`` (``c = target``, default 0)."""
    proj = proj or projection(J)
    a = proj.Jpinv @ xdot
    p0 = np.zeros_like(a) if target is None else proj.N @ target
    x = p0 + a
    if np.all(x >= lo - BOX_TOL) and np.all(x <= hi + BOX_TOL):
        return BoxSolution(np.clip(x, lo, hi), 1.0, np.zeros(len(a), dtype=bool), 0)
    return solve_box(p0, a, _null_basis(proj.N), lo, hi)


def reduced_bounded(J, xdot, S, lo, hi, target=None, guess=None) -> BoxSolution:
    """The reduced robot (joints ``S`` locked) under the box: (L4) with ``J_S``, in full size (n,).

    ``guess``: its unbounded rates when known (closed form (G1)); inside the box they are the
    answer. ``target`` (n,): the rates it stays nearest to (continuation response), else 0.
    """
    n = J.shape[1]
    if guess is not None and np.all(guess >= lo - BOX_TOL) and np.all(guess <= hi + BOX_TOL):
        return BoxSolution(np.clip(guess, lo, hi), 1.0, np.zeros(n, dtype=bool), 0)
    keep = np.array([j for j in range(n) if j not in set(S)], dtype=int)
    c = None if target is None else np.asarray(target)[keep]
    sol = bounded_least_norm(J[:, keep], xdot, lo[keep], hi[keep], c)
    qd = np.zeros(n)
    qd[keep] = sol.qd
    active = np.zeros(n, dtype=bool)
    active[keep] = sol.active
    return BoxSolution(qd, sol.scale, active, sol.iterations)


def _scenarios(J, lockable, weights, joint_names) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def reduced_under_limits(J, xdot, sc: Scenarios, lo, hi, *, proj=None, tolerate=False):
    """Bounded least-norm rates of every reduced robot (L4), shape (f, n), and their scalings (f,)."""
    proj = proj or projection(J)
    a = proj.Jpinv @ xdot
    if not tolerate:
        sc.check_tolerable(proj.N)
    guesses = [reduced_rates(a, proj.N, S, damp=tolerate) for S in sc.sets]
    sols = [
        reduced_bounded(J, xdot, S, lo, hi, guess=g) for S, g in zip(sc.sets, guesses, strict=True)
    ]
    return np.array([s.qd for s in sols]), np.array([s.scale for s in sols])


def _continuation_metric(N: np.ndarray, sc: Scenarios, tolerate: bool) -> np.ndarray:
    from fault_tolerance.numerics.linalg import pivot_block

    W = np.zeros_like(N)
    for S, w in zip(sc.sets, sc.relative_weights, strict=True):
        W[np.ix_(S, S)] += w * np.linalg.inv(pivot_block(N, S, tolerate))
    return W + CONTINUATION_EPS * max(float(np.trace(W)) / len(W), 1e-300) * np.eye(len(W))


def _continuation(J, xdot, sc, lo, hi, proj, tolerate) -> BoxSolution:
    """(L2) with the continuation metric H: ``min q̇ᵀHq̇`` s.t. ``J q̇ = s ẋ`` inside the box."""
    a = proj.Jpinv @ xdot
    if not tolerate:
        sc.check_tolerable(proj.N)
    H = _continuation_metric(proj.N, sc, tolerate)
    Z = _null_basis(proj.N)
    G = Z.T @ H @ Z
    L = np.linalg.cholesky(G)
    x0 = a - Z @ np.linalg.solve(G, Z.T @ (H @ a))
    M = np.linalg.solve(L, Z.T).T  # Z L⁻ᵀ
    return solve_box(np.zeros_like(x0), x0, M, lo, hi)


def _jvja_least_norm(J, xdot, sc, lo, hi, proj, tolerate):
    post, scales = reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
    w = sc.relative_weights  # scale-free (5): no overflow, no underflow
    c = w @ post / w.sum()  # the weighted mean of what the reduced robots do
    a = proj.Jpinv @ xdot
    return solve_box(proj.N @ c, a, _null_basis(proj.N), lo, hi), scales


def resolve_bounded(name: str, J, xdot, lockable=None, *, bounds, **options) -> BoundedRates:
    """Rates of resolver ``name`` under the rate box ``bounds = (qd_lo, qd_hi)``, with task scaling.

    The rates minimise the resolver's own objective subject to ``J q̇ = s ẋ`` and the box, ``s ≤ 1``
    as large as possible (see the module doc; ``s = 1`` whenever ``ẋ`` is reachable). Options as
    :func:`fault_tolerance.resolve`. Inside the box, the unbounded rates come back unchanged.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> J = np.array([[1.0, 1.0, 1.0]]); xd = np.array([0.3])
        >>> out = ft.resolve_bounded("lnva", J, xd, bounds=([-1, -1, -1], [1, 1, 0.05]))
        >>> [round(float(v), 3) for v in out.qd], out.scale, out.active.tolist()
        ([0.125, 0.125, 0.05], 1.0, [False, False, True])
    """
    from fault_tolerance.resolution.resolvers import OPTIONS, RESOLVERS, check_task, resolve

    if name not in RESOLVERS or set(options) - OPTIONS:
        resolve(name, J, xdot, lockable, **options)  # raises, naming the allowed names and options
        raise InvalidInput(  # not reached: resolve raises the same (kept for the checker)
            f"resolver {name!r} with options {sorted(options)}: names are {sorted(RESOLVERS)}, "
            f"options {sorted(OPTIONS)}"
        )
    J, xdot = check_task(J, xdot)
    n = J.shape[1]
    lo, hi = check_bounds(bounds, n)
    options = dict(options)
    proj = options.pop("proj", None) or projection(J)
    tolerate = bool(options.get("tolerate", False))
    empty = np.zeros(0)
    if name in ("lnva", "mda"):
        qd = resolve(name, J, xdot, lockable, proj=proj, **options)  # the unbounded optimum
        if _inside(qd, lo, hi):
            return BoundedRates(np.clip(qd, lo, hi), 1.0, np.zeros(n, dtype=bool), empty)
        a = proj.Jpinv @ xdot
        sol = solve_box(proj.N @ (qd - a), a, _null_basis(proj.N), lo, hi)  # near a singularity
        # the damped qd - a is not in the null space exactly; its task part stays in a
        return BoundedRates(sol.qd, sol.scale, sol.active, empty)
    names = options.get("joint_names") or (options["arm"].joint_names if options.get("arm") else ())
    sc = _scenarios(J, lockable, options.pop("weights", None), names)
    response = options.get("response", "least_norm")
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    if response == "least_norm" and sc.singletons:  # fast path: nothing meets a bound
        N = proj.N
        a = proj.Jpinv @ xdot
        pivots = damped_pivots(sc.pivots(N)) if tolerate else sc.check_tolerable(N)
        cols = sc.columns
        post = a - (a[cols] / pivots)[:, None] * N[cols]  # (G1) for every scenario (N symmetric)
        w = sc.relative_weights
        qd = w @ post / w.sum()  # (G2): the mean is already on the task's set
        if _inside(qd, lo, hi) and _inside(post, lo, hi):
            ones = np.ones(sc.f)
            return BoundedRates(np.clip(qd, lo, hi), 1.0, np.zeros(n, dtype=bool), ones)
    if response == "least_norm":
        sol, scales = _jvja_least_norm(J, xdot, sc, lo, hi, proj, tolerate)
    else:
        _, scales = reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
        sol = _continuation(J, xdot, sc, lo, hi, proj, tolerate)
    return BoundedRates(sol.qd, sol.scale, sol.active, scales)


def _inside(x, lo, hi) -> bool:
    return bool((x >= lo - BOX_TOL).all() and (x <= hi + BOX_TOL).all())
