"""Claim 1 from other starts: does "JVJA's jump is smaller" hang on our start posture?

A step of ``reproduce`` beside :mod:`.paper_runs`: :func:`start_sensitivity` reruns LNVA and JVJA
of one case from other dexterous points of its self-motion curves.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.paper.cases import Case
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.simulation.simulate import simulate

#: Starts spread along the self-motion curves for the sensitivity check of claim 1.
SENSITIVITY_STARTS = 6
#: Start-sensitivity candidates tried per start wanted (starts failing the RCN threshold are replaced).
SENSITIVITY_TRIES = 4


def start_sensitivity(
    case: Case,
    result: dict,
    *,
    starts: int = SENSITIVITY_STARTS,
    duration: float | None = None,
    progress=None,
) -> dict:
    """Claim 1 from other starts: LNVA and JVJA from other dexterous points of the self-motion curves.

    The paper gives the start point but not the start posture, so the verdict on "JVJA's jump is
    smaller along the task" should not hang on our choice of posture. The starts are spread over
    the points of the self-motion curves whose K is in its lowest quartile (the starts a planner
    following Sec. III.D would consider; from near-singular starts every algorithm's λ is dominated
    by spikes), with angles wrapped into the joint limits; a start outside them is dropped, and a
    start whose LNVA or JVJA run meets a reduced condition number above
    :data:`~.posture.RCN_THRESHOLD` (Sec. III.D (iii)) is replaced by the next candidate, not
    counted (``replaced``). The runs are the paper's (no joint limits). Returns, per start, the
    time-mean λ of both algorithms, the diagnostics' warnings of their runs and the fraction of
    starts where JVJA's is the smaller. A counted start whose runs have warnings (over the velocity
    limit, near-singular, off the path) is *degenerate*: it is kept in ``starts`` with
    ``"degenerate": True`` and left out of the fraction.
    """
    from fault_tolerance.model.joint_limits import outside_limits
    from fault_tolerance.planning.posture import wrap
    from fault_tolerance.simulation.diagnostics import check_run

    arm, path = result["arm"], case.path(duration)
    curves = result["posture"].curves
    if not curves:
        return {}
    points = np.concatenate(curves)
    K = np.concatenate(result["posture"].curve_K)  # with the case's lockable joints
    good = points[K <= np.quantile(K, 0.25)]  # the starts a Sec. III.D planner would consider
    good = np.array([wrap(arm, q) for q in good])  # angles wrapped into the joint limits
    good = good[~outside_limits(arm, good).any(axis=1)]
    spread = np.linspace(0, len(good) - 1, starts, endpoint=False).astype(int)
    order = list(spread) + [i for i in _stride_order(len(good)) if i not in set(spread)]
    rows, replaced = [], 0
    for i in order[: SENSITIVITY_TRIES * starts]:
        runs = {
            alg: simulate(
                arm,
                path,
                alg,
                q0=good[i],
                lockable=list(case.lockable),
                progress=progress,
                limits=False,
            )
            for alg in ("lnva", "jvja")
        }
        if max(float(np.max(r.rcn)) for r in runs.values()) > RCN_THRESHOLD:
            replaced += 1  # Sec. III.D (iii) would reject this start: replaced, not counted
            continue
        warned = [f"{alg}: {w.message}" for alg, r in runs.items() for w in check_run(r, arm)]
        rows.append(
            {
                "q0": good[i].tolist(),
                "jvj_mean_lnva": float(np.mean(runs["lnva"].jvj)),
                "jvj_mean_jvja": float(np.mean(runs["jvja"].jvj)),
                "degenerate": bool(warned),
                "warnings": warned,
            }
        )
        if len(rows) == starts:
            break
    kept = [r for r in rows if not r["degenerate"]]
    wins = sum(r["jvj_mean_jvja"] <= r["jvj_mean_lnva"] for r in kept)
    return {
        "starts": rows,
        "replaced": replaced,
        "jvja_smaller_fraction": wins / len(kept) if kept else None,
        "degenerate_starts": [i for i, r in enumerate(rows) if r["degenerate"]],
    }


def _stride_order(count: int) -> list[int]:
    """Indices 0..count-1 in a spread-out order (golden-ratio strides)."""
    return list(np.argsort((np.arange(count) * 0.6180339887498949) % 1.0))
