"""Dynamic programming over the self-motion parameter, for one degree of redundancy (MATH.md (W4)).

At stage times ``t_s`` the configurations that reach ``x_des(t_s)`` form a curve (closed, or an arc
ended by joint limits), sampled by arclength ``σ`` at spacing ``h``. From node ``i`` of stage ``s`` the
range-space motion alone lands at ``σ(p_i)`` on the next curve; going to node ``j`` instead takes the
constant null-space speed ``ν = (σ_j − σ(p_i)) / Δt`` along the unit null vector ``n``. The jump is
quadratic in ``ν`` at every node: ``λ(a + nν) = c₀ − 2c₁ν + Wν²``. The segment costs the trapezoid of
λ (mean objective) or the larger end value (max objective). :func:`solve_banded` finds the exact
optimum over all node sequences of this grid; :func:`brute_force` enumerates them (tests).
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.planning.wholepath.problem import (
    PathProblem,
    kinematics,
    post_rates,
    reduced_condition_numbers,
)

# -- the DP on a banded stage graph ---------------------------------------------------------


def solve_banded(
    costs: list[np.ndarray],
    targets: list[np.ndarray],
    start: int | None = None,
    objective: str = "mean",
) -> tuple[list[int], float]:
    """Exact minimum over node sequences of a stage graph (backward dynamic programming).

    ``costs[s][i, b]`` is the cost of edge ``b`` of node ``i`` at stage ``s``, leading to node
    ``targets[s][i, b]`` of stage ``s + 1`` (``-1``: no edge). The path cost is the sum of its edge
    costs (``objective="mean"``) or their maximum (``"max"``). ``start``: the fixed first node, or
    ``None`` for a free start. Returns the node sequence (one per stage) and its cost (``inf`` if no
    sequence exists).
    """
    if objective not in ("mean", "max"):
        raise InvalidInput(f"objective {objective!r} is not one of ['mean', 'max']")
    S = len(costs)
    V = np.zeros(int(max(targets[-1].max(initial=-1) + 1, 1)) if S else 1)
    best: list[np.ndarray] = [np.empty(0, dtype=np.intp)] * S  # every stage set below
    for s in range(S - 1, -1, -1):
        tgt = targets[s]
        nxt = np.where(tgt >= 0, V[np.maximum(tgt, 0)], np.inf)
        tot = costs[s] + nxt if objective == "mean" else np.maximum(costs[s], nxt)
        tot = np.where(tgt >= 0, tot, np.inf)
        best[s] = np.argmin(tot, axis=1)
        V = tot[np.arange(len(tot)), best[s]]
    first = int(np.argmin(V)) if start is None else int(start)
    value = float(V[first])
    seq = [first]
    for s in range(S):
        seq.append(int(targets[s][seq[-1], best[s][seq[-1]]]))
    return seq, value


def brute_force(
    costs: list[np.ndarray],
    targets: list[np.ndarray],
    start: int | None = None,
    objective: str = "mean",
) -> float:
    """The same minimum by enumerating every node sequence (exponential: tiny graphs only)."""
    best = np.inf
    firsts = range(len(costs[0])) if start is None else [start]
    for first in firsts:
        for edges in itertools.product(*[range(c.shape[1]) for c in costs]):
            node, vals, ok = first, [], True
            for s, b in enumerate(edges):
                j = targets[s][node, b]
                if j < 0 or not np.isfinite(costs[s][node, b]):
                    ok = False
                    break
                vals.append(costs[s][node, b])
                node = j
            if ok:
                best = min(best, sum(vals) if objective == "mean" else max(vals))
    return float(best)


# -- the self-motion grid -------------------------------------------------------------------


class Stage(NamedTuple):
    """Nodes on the self-motion curve of one stage."""

    k: int  # sample index of the stage time
    q: np.ndarray  # (G, n) configurations, ordered along +n
    sigma: np.ndarray  # (G,) arclength coordinate [rad]
    period: float  # curve length when closed, inf when an open arc


def null_vectors(J: np.ndarray) -> np.ndarray:
    """Unit null vectors of (B, m, m+1) Jacobians with a globally consistent sign (cofactors)."""
    B, m, n = J.shape
    cof = np.empty((B, n))
    for i in range(n):
        cols = [c for c in range(n) if c != i]
        cof[:, i] = (-1) ** i * np.linalg.det(J[:, :, cols])
    return cof / np.maximum(np.linalg.norm(cof, axis=1, keepdims=True), 1e-300)


def _correct(prob: PathProblem, Q: np.ndarray, ks: np.ndarray, iters: int = 2) -> np.ndarray:
    """A few Newton steps back onto ``x(q) = x_des[k]`` (range-space moves only)."""
    for _ in range(iters):
        J, E = kinematics(prob, Q, ks)
        Q = Q + np.einsum("bnm,bm->bn", projection(J).Jpinv, E)
    return Q


def _inside(prob: PathProblem, Q: np.ndarray) -> np.ndarray:
    return np.all((Q >= prob.lower) & (Q <= prob.upper), axis=1)


def _wrapped_gap(prob: PathProblem, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a - b
    free = ~np.isfinite(prob.lower)  # full-turn joints: compared modulo 2π
    d[..., free] = (d[..., free] + np.pi) % (2 * np.pi) - np.pi
    return np.linalg.norm(d, axis=-1)


def trace_stages(
    prob: PathProblem,
    ks: np.ndarray,
    seeds: np.ndarray,
    h: float,
    max_nodes: int,
    subdivide: int = 4,
) -> list[Stage]:
    """Trace the self-motion curve through each seed (batched over stages), nodes ``h`` [rad] apart.

    The curve is traced with steps ``subdivide·h`` (predictor along the null vector, Newton
    corrector) and each step is then split into ``subdivide`` nodes.
    """
    h = h * subdivide
    max_nodes = max(1, max_nodes // subdivide)
    seeds = _correct(prob, seeds, ks, iters=4)
    halves = []
    closed = np.zeros(len(ks), bool)
    for direction in (1.0, -1.0):
        pts = [[q] for q in seeds]
        live = np.ones(len(ks), bool) if direction > 0 else ~closed
        q = seeds.copy()
        for it in range(max_nodes):
            idx = np.flatnonzero(live)
            if not len(idx):
                break
            J, _ = kinematics(prob, q[idx], ks[idx])
            step = direction * h * null_vectors(J)
            qn = _correct(prob, q[idx] + step, ks[idx])
            ok = _inside(prob, qn) & np.all(np.isfinite(qn), axis=1)
            back = (it > 4) & (_wrapped_gap(prob, qn, seeds[idx]) < h)
            for j, b in enumerate(idx):
                if not ok[j]:
                    live[b] = False
                elif back[j] and direction > 0:
                    live[b], closed[b] = False, True
                else:
                    pts[b].append(qn[j])
            q[idx] = qn
        halves.append(pts)
    stages = []
    for i, k in enumerate(ks):
        fwd, bwd = halves[0][i], halves[1][i]
        Q = np.array(fwd if closed[i] else bwd[::-1] + fwd[1:])
        if closed[i]:
            Q = np.vstack([Q, Q[:1]])
        Q = _subdivide(prob, Q, k, subdivide, closed[i])
        gaps = np.linalg.norm(np.diff(Q, axis=0), axis=1)
        sigma = np.concatenate([[0.0], np.cumsum(gaps)])
        period = sigma[-1] + float(_wrapped_gap(prob, Q[-1], Q[0])) if closed[i] else np.inf
        stages.append(Stage(int(k), Q, sigma, period))
    return stages


def _subdivide(prob, Q, k, parts: int, closed: bool) -> np.ndarray:
    """Each traced segment split into ``parts`` (linear in q, then corrected onto the curve)."""
    if parts <= 1 or len(Q) < 2:
        return Q[:-1] if closed else Q
    d = Q[1:] - Q[:-1]
    free = ~np.isfinite(prob.lower)
    d[:, free] = (d[:, free] + np.pi) % (2 * np.pi) - np.pi
    s = np.arange(parts) / parts
    fine = (Q[:-1, None, :] + s[None, :, None] * d[:, None, :]).reshape(-1, Q.shape[1])
    if not closed:
        fine = np.vstack([fine, Q[-1:]])
    return _correct(prob, fine, np.full(len(fine), k))


class NodeData(NamedTuple):
    """Per-node quantities of a stage: range rates, null vector, jump coefficients, feasibility."""

    a: np.ndarray  # (G, n) least-norm rates J⁺ẋ
    n: np.ndarray  # (G, n) unit null vector
    c0: np.ndarray  # (G,) λ at ν = 0
    c1: np.ndarray  # (G,)
    ok: np.ndarray  # (G,) node keeps the limits (position, RCN)
    J: np.ndarray  # (G, m, n)


def node_data(prob: PathProblem, st: Stage) -> NodeData:
    """``λ(a + nν) = c₀ − 2c₁ν + Wν²`` at every node of a stage (W = Σ w_S)."""
    ks = np.full(len(st.q), st.k)
    J, E = kinematics(prob, st.q, ks)
    P = projection(J)
    a = np.einsum("bnm,bm->bn", P.Jpinv, prob.xd_des[st.k] + prob.feedback_gain * E)
    nv = null_vectors(J)
    d = post_rates(a, P.N, prob.sc) - a[:, None, :]
    w = prob.sc.weights
    c0 = np.einsum("f,bfn,bfn->b", w, d, d)
    c1 = np.einsum("f,bfn,bn->b", w, d, nv)
    ok = _inside(prob, st.q)
    if prob.rcn_max is not None:
        ok &= np.all(reduced_condition_numbers(J, prob.sc) <= prob.rcn_max, axis=1)
    return NodeData(a, nv, c0, c1, ok, J)


def stage_edges(
    prob: PathProblem,
    st: Stage,
    nd: NodeData,
    nxt: Stage,
    nn: NodeData,
    band: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Edge costs (G, 2·band+1) and targets from stage ``st`` to ``nxt`` (the banded graph)."""
    dts = (nxt.k - st.k) * prob.dt
    ks = np.full(len(st.q), nxt.k)
    _, E = kinematics(prob, st.q, ks)
    p = st.q + np.einsum("bnm,bm->bn", projection(nd.J).Jpinv, E)  # range motion only
    from scipy.spatial import cKDTree  # here: scipy.spatial costs 0.25 s to import

    _, c = cKDTree(nxt.q).query(p)
    sig_p = nxt.sigma[c] + np.einsum("bn,bn->b", nn.n[c], p - nxt.q[c])
    G2 = len(nxt.q)
    offs = np.arange(-band, band + 1)
    j = c[:, None] + offs[None, :]
    if np.isfinite(nxt.period):
        j = j % G2
        dsig = (nxt.sigma[j] - sig_p[:, None] + nxt.period / 2) % nxt.period - nxt.period / 2
    else:
        inside = (j >= 0) & (j < G2)
        j = np.where(inside, j, -1)
        dsig = np.where(inside, nxt.sigma[np.maximum(j, 0)] - sig_p[:, None], 0.0)
    nu = dsig / dts  # [rad/s] null-space speed of the segment
    jj = np.maximum(j, 0)
    W = float(prob.sc.weights.sum())
    lam_i = nd.c0[:, None] - 2 * nd.c1[:, None] * nu + W * nu**2
    lam_j = nn.c0[jj] - 2 * nn.c1[jj] * nu + W * nu**2
    cost = 0.5 * dts * (lam_i + lam_j) if prob.objective == "mean" else np.maximum(lam_i, lam_j)
    qd_i = nd.a[:, None, :] + nd.n[:, None, :] * nu[..., None]
    qd_j = nn.a[jj] + nn.n[jj] * nu[..., None]
    fast = np.any(np.abs(qd_i) > prob.vmax, axis=2) | np.any(np.abs(qd_j) > prob.vmax, axis=2)
    bad = (j < 0) | fast | ~nd.ok[:, None] | ~nn.ok[jj]
    return np.where(bad, np.inf, cost), np.where(bad, -1, j)


class DPResult(NamedTuple):
    """The grid optimum: the reference it gives and how the grid was made."""

    q_ref: np.ndarray  # (T+1, n) reference configurations (stage nodes, linearly interpolated)
    value: float  # the grid optimum (∫λ dt, or max λ)
    stages: int
    nodes: int  # total number of grid nodes
    band: int
    h: float
    stage_dt: float


def dp_plan(
    prob: PathProblem,
    seeds: np.ndarray,
    *,
    fixed_start: bool,
    h: float = 0.005,
    stage_dt: float = 0.025,
    nu_max: float | None = None,
    max_nodes: int = 3000,
    progress=None,
) -> DPResult | None:
    """Grid-optimal plan for r = 1 through the self-motion curves of the warm start ``seeds``.

    ``seeds`` (T+1, n): a feasible trajectory (the warm start); stage ``s`` traces the curve through
    ``seeds[k_s]``, so the warm start lies (up to the grid) on the grid. With ``fixed_start`` the
    first stage is the single node ``seeds[0]``, kept exactly. ``None`` when no grid path keeps the
    limits.
    """
    if prob.arm.redundancy != 1:
        raise InvalidInput(
            f"the self-motion DP needs r = 1; {prob.arm.name} has r = {prob.arm.redundancy}"
        )
    T, dt = prob.T, prob.dt
    S = max(1, int(round(T * dt / stage_dt)))
    ks = np.unique(np.round(np.linspace(0, T, S + 1)).astype(int))
    stage_dt = T * dt / (len(ks) - 1)
    traced = ks[1:] if fixed_start else ks
    stages = trace_stages(prob, traced, seeds[traced], h, max_nodes)
    _tick(progress)
    if fixed_start:
        stages = [Stage(0, seeds[:1].copy(), np.zeros(1), np.inf)] + stages
    nds = [node_data(prob, st) for st in stages]
    if nu_max is None:
        v = prob.vmax[np.isfinite(prob.vmax)]
        nu_max = float(np.linalg.norm(v)) if len(v) == prob.n else 10.0
    band = int(np.ceil(nu_max * stage_dt / h))
    costs, targets = [], []
    for s in range(len(stages) - 1):
        c, t = stage_edges(prob, stages[s], nds[s], stages[s + 1], nds[s + 1], band)
        costs.append(c)
        targets.append(t)
    _tick(progress)
    seq, value = solve_banded(
        costs, targets, start=0 if fixed_start else None, objective=prob.objective
    )
    if not np.isfinite(value):
        return None
    Qs = np.array([st.q[i] for st, i in zip(stages, seq, strict=True)])
    free = ~np.isfinite(prob.lower)
    for s in range(1, len(Qs)):  # full-turn joints: no 2π jumps between stages
        d = Qs[s, free] - Qs[s - 1, free]
        Qs[s, free] = Qs[s - 1, free] + (d + np.pi) % (2 * np.pi) - np.pi
    t = np.arange(T + 1)
    q_ref = np.column_stack([np.interp(t, ks, Qs[:, j]) for j in range(prob.n)])
    nodes = int(sum(len(st.q) for st in stages))
    return DPResult(q_ref, value, len(stages), nodes, band, h, stage_dt)


def _tick(progress) -> None:
    if progress is not None:
        progress.update(1)
