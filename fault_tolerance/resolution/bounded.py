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
from fault_tolerance.numerics.linalg import PIVOT_EPS, projection, reduced_rates
from fault_tolerance.resolution.box_qp import BOX_TOL, BoxSolution, solve_box
from fault_tolerance.resolution.indices import RESPONSES
from fault_tolerance.resolution.registry import check_task, get, split
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


#: ``ẋ`` is in the range of ``J_S`` when its least-squares residual is below this, relative.
RANGE_RTOL = 1e-12
#: Singular values of ``J_S`` below this times ``σ_max`` are zero in (L4a) (SVD rounding ~1e-16).
EXACT_RANK_RTOL = 1e-13


# Eqn. (L4a): the exact, undamped parametrisation of the reduced robot's task set.
def exact_task_set(Js: np.ndarray, xdot: np.ndarray):
    """``(d, Z, reachable)``: ``J_S d = ẋ`` (least norm, undamped), ``Z`` orthonormal null basis.

    From one SVD ``J_S = U Σ Vᵀ``: singular values below ``EXACT_RANK_RTOL σ_max`` are zero, ``d =
    V_k Σ_k⁻¹ U_kᵀ ẋ`` (large near a singularity: the box, not damping, keeps the rates finite),
    ``Z = V[:, k:]``. ``reachable`` is False when ``ẋ`` leaves the range of ``J_S`` (then only
    ``s = 0`` is feasible, at any box).
    """
    U, sv, Vt = np.linalg.svd(Js, full_matrices=True)
    k = int(np.sum(sv > EXACT_RANK_RTOL * max(float(sv[0]) if len(sv) else 0.0, 1e-300)))
    c = U[:, :k].T @ xdot
    d = Vt[:k].T @ (c / sv[:k])
    resid = float(np.linalg.norm(xdot - U[:, :k] @ c))
    reachable = resid <= RANGE_RTOL * max(float(np.linalg.norm(xdot)), 1e-300)
    return d, Vt[k:].T, reachable


def exact_reduced_least_norm(Js, xdot, lo, hi, target=None) -> BoxSolution:
    """(L4) exactly: ``min ‖v − c‖²`` at the largest ``s`` with ``J_S v = s ẋ`` in ``[lo, hi]``.

    No damping at any ``σ_min(J_S)``: ``s`` is the largest feasible task scaling (the LP's), the
    rates the nearest ones at that ``s``. ``ẋ`` outside the range of ``J_S``: ``s = 0``.
    """
    d, Z, reachable = exact_task_set(Js, xdot)
    p0 = np.zeros(Js.shape[1]) if target is None else Z @ (Z.T @ target)
    if not reachable:
        sol = solve_box(p0, np.zeros_like(d), Z, lo, hi)  # only s = 0 keeps J_S v ∥ ẋ
        return BoxSolution(sol.qd, 0.0, sol.active, sol.iterations)
    return solve_box(p0, d, Z, lo, hi)


def reduced_bounded(J, xdot, S, lo, hi, target=None, guess=None) -> BoxSolution:
    """The reduced robot (joints ``S`` locked) under the box: (L4) with ``J_S``, in full size (n,).

    ``guess``: its exact unbounded rates when known (closed form (G1), undamped); inside the box
    and on its task set they are the answer. ``target`` (n,): the rates it stays nearest to
    (continuation response), else 0. Exact at any ``σ_min(J_S)`` (:func:`exact_reduced_least_norm`).
    """
    n = J.shape[1]
    if guess is not None and _inside(guess, lo, hi) and _on_task(J, guess, xdot, S):
        return BoxSolution(np.clip(guess, lo, hi), 1.0, np.zeros(n, dtype=bool), 0)
    keep = np.array([j for j in range(n) if j not in set(S)], dtype=int)
    c = None if target is None else np.asarray(target)[keep]
    sol = exact_reduced_least_norm(J[:, keep], xdot, lo[keep], hi[keep], c)
    qd = np.zeros(n)
    qd[keep] = sol.qd
    active = np.zeros(n, dtype=bool)
    active[keep] = sol.active
    return BoxSolution(qd, sol.scale, active, sol.iterations)


def _on_task(J, v, xdot, S) -> bool:
    """``J v = ẋ`` to rounding with ``v_S = 0``: a (G1) guess the reduced robot may take as is."""
    if not np.all(np.isfinite(v)) or np.any(v[list(S)] != 0.0):
        return False
    scale = float(np.abs(J).max(initial=0.0) * np.abs(v).sum() + np.abs(xdot).max(initial=0.0))
    return bool(np.abs(J @ v - xdot).max(initial=0.0) <= 1e-10 * max(scale, 1e-300))


def exact_guesses_allowed(proj, pivots) -> bool:
    """The (G1) rates are exact reduced least-norm rates: ``J`` undamped, no pivot damped."""
    return (not proj.damped) and bool(np.min(pivots, initial=np.inf) >= PIVOT_EPS)


def _scenarios(J, lockable, weights, joint_names) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def reduced_under_limits(J, xdot, sc: Scenarios, lo, hi, *, proj=None, tolerate=False):
    """Bounded least-norm rates of every reduced robot (L4), shape (f, n), and their scalings (f,)."""
    proj = proj or projection(J)
    a = proj.Jpinv @ xdot
    pivots = sc.pivots(proj.N) if tolerate else sc.check_tolerable(proj.N)
    guesses: list[np.ndarray | None] = [None] * sc.f  # each reduced robot solved from its J_S
    if exact_guesses_allowed(proj, pivots):
        guesses = [reduced_rates(a, proj.N, S) for S in sc.sets]
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


def _continuation(J, xdot, sc, lo, hi, proj, tolerate, H=None) -> BoxSolution:
    """(L2) with the continuation metric H: ``min q̇ᵀHq̇`` s.t. ``J q̇ = s ẋ`` inside the box.

    ``H``: another metric of that form (jvja_inertia's, docs/MATH.md (D3)); default (G3)'s.
    """
    a = proj.Jpinv @ xdot
    if not tolerate:
        sc.check_tolerable(proj.N)
    if H is None:
        H = _continuation_metric(proj.N, sc, tolerate)
    else:
        H = H + CONTINUATION_EPS * max(float(np.trace(H)) / len(H), 1e-300) * np.eye(len(H))
    Z = _null_basis(proj.N)
    G = Z.T @ H @ Z
    L = np.linalg.cholesky(G)
    x0 = a - Z @ np.linalg.solve(G, Z.T @ (H @ a))
    M = np.linalg.solve(L, Z.T).T  # Z L⁻ᵀ
    return solve_box(np.zeros_like(x0), x0, M, lo, hi, Z=Z, H=H)  # s found with Z, well conditioned


def _jvja_least_norm(J, xdot, sc, lo, hi, proj, tolerate):
    post, scales = reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
    w = sc.relative_weights  # scale-free (5): no overflow, no underflow
    c = w @ post / w.sum()  # the weighted mean of what the reduced robots do
    a = proj.Jpinv @ xdot
    return solve_box(proj.N @ c, a, _null_basis(proj.N), lo, hi), scales


def _nearest_on_task(J, xdot, qd, lo, hi, proj) -> BoundedRates:
    """(L2) with target ``qd``: its rates when inside the box, else the nearest inside on the task."""
    n = J.shape[1]
    if _inside(qd, lo, hi):
        return BoundedRates(np.clip(qd, lo, hi), 1.0, np.zeros(n, dtype=bool), np.zeros(0))
    a, Z = proj.Jpinv @ xdot, _null_basis(proj.N)
    # the scale from the well-conditioned problem (Z=Z): MDA's null step reaches MDA_MAX_STEP
    # (1e4 rad/s) near a reduced singularity, where a scaling search from p₀ itself loses it
    sol = solve_box(proj.N @ (qd - a), a, Z, lo, hi, Z=Z)
    # the damped qd - a is not in the null space exactly; its task part stays in a
    return BoundedRates(sol.qd, sol.scale, sol.active, np.zeros(0))


def bounded_nearest(rates):
    """The bounded variant of a resolver whose objective is the distance to its own rates, (L2n).

    LNVA minimises ``‖q̇‖²``, MDA ``‖q̇ + α∇K‖²``: on the task's affine set both are
    ``‖q̇ − q̇*‖²`` up to a constant, ``q̇*`` their unbounded rates, so inside the box their rates
    are (L2) with target ``q̇*``. ``rates(J, xdot, lockable, **keywords)`` is the reference
    resolver; the variant is ``bounded(J, xdot, lockable, lo, hi, **keywords)``, the keywords
    ``rates`` takes (``proj`` is computed once and shared).
    """
    import inspect

    takes = frozenset(inspect.signature(rates).parameters)

    def bounded(J, xdot, lockable, lo, hi, *, proj=None, **keywords) -> BoundedRates:
        proj = proj or projection(J)
        if "proj" in takes:
            keywords["proj"] = proj
        qd = rates(J, xdot, lockable, **{k: v for k, v in keywords.items() if k in takes})
        return _nearest_on_task(J, xdot, qd, lo, hi, proj)

    bounded.__doc__ = (
        f"{getattr(rates, '__name__', 'rates')} inside the box, (L2) (bounded_nearest)."
    )
    # the keywords the registry may pass: those of rates (it filters the context by them)
    bounded.__signature__ = inspect.Signature(
        [inspect.Parameter(p, inspect.Parameter.KEYWORD_ONLY) for p in sorted(takes | {"proj"})]
    )
    return bounded


# Eqn. (L2) with JVJA's objectives (L4)-(L5), and the continuation metric of (G3).
def bounded_jvja(
    J, xdot, lockable, lo, hi, *, proj=None, tolerate=False, joint_names=(), weights=None,
    response="least_norm",
) -> BoundedRates:  # fmt: skip
    """JVJA inside the box ``[lo, hi]``: its least-norm or continuation objective (module doc)."""
    proj = proj or projection(J)
    n = J.shape[1]
    sc = _scenarios(J, lockable, weights, joint_names)
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    if response == "least_norm" and sc.singletons:  # fast path: nothing meets a bound
        N = proj.N
        a = proj.Jpinv @ xdot
        pivots = sc.pivots(N) if tolerate else sc.check_tolerable(N)
        cols = sc.columns
        exact = exact_guesses_allowed(proj, pivots)  # damped (G1) rates are not the reduced LNVA
        post = a - (a[cols] / np.maximum(pivots, PIVOT_EPS))[:, None] * N[cols]  # (G1), N symmetric
        post[np.arange(sc.f), cols] = 0.0
        w = sc.relative_weights
        qd = w @ post / w.sum()  # (G2): the mean is already on the task's set
        if exact and _inside(qd, lo, hi) and _inside(post, lo, hi):
            ones = np.ones(sc.f)
            return BoundedRates(np.clip(qd, lo, hi), 1.0, np.zeros(n, dtype=bool), ones)
    if response == "least_norm":
        sol, scales = _jvja_least_norm(J, xdot, sc, lo, hi, proj, tolerate)
    else:
        _, scales = reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
        sol = _continuation(J, xdot, sc, lo, hi, proj, tolerate)
    return BoundedRates(sol.qd, sol.scale, sol.active, scales)


def resolve_bounded(name: str, J, xdot, lockable=None, *, bounds, **options) -> BoundedRates:
    """Rates of resolver ``name`` under the rate box ``bounds = (qd_lo, qd_hi)``, with task scaling.

    The rates minimise the resolver's own objective subject to ``J q̇ = s ẋ`` and the box, ``s ≤ 1``
    as large as possible (see the module doc; ``s = 1`` whenever ``ẋ`` is reachable): the
    registered entry's ``bounded`` variant (:mod:`fault_tolerance.resolution.registry`; a resolver
    without one raises :class:`InvalidInput`). Options as :func:`fault_tolerance.resolve`. Inside
    the box, the unbounded rates come back unchanged.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> J = np.array([[1.0, 1.0, 1.0]]); xd = np.array([0.3])
        >>> out = ft.resolve_bounded("lnva", J, xd, bounds=([-1, -1, -1], [1, 1, 0.05]))
        >>> [round(float(v), 3) for v in out.qd], out.scale, out.active.tolist()
        ([0.125, 0.125, 0.05], 1.0, [False, False, True])
    """
    entry = get(name)
    entry.make_options(split(options)[1])  # unknown options raise before any work
    J, xdot = check_task(J, xdot)
    lo, hi = check_bounds(bounds, J.shape[1])
    return entry.call_bounded(J, xdot, lockable, lo, hi, **options)


def _inside(x, lo, hi) -> bool:
    return bool((x >= lo - BOX_TOL).all() and (x <= hi + BOX_TOL).all())
