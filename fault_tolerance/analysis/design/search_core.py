"""A global search over a box, one round at a time: differential evolution, then a pattern search.

docs/MATH.md (H4).

The caller gives ``evaluate_round(candidates, tag) -> scores`` (minimised; ``inf`` for a refused
candidate). Differential evolution (SciPy's, ``updating="deferred"``, seeded) asks for one whole
generation at a time, and the pattern search for one set of moves at a time, so each round can be
one chunked sweep (:func:`~fault_tolerance.analysis.sweep.run`): on Dask, resumable, and the same
for any number of workers (a round's candidates depend only on the seed and the earlier scores).

Example:
    >>> import numpy as np
    >>> f = lambda U, tag: np.sum((U - 0.3) ** 2, axis=1)  # planted optimum at 0.3
    >>> best = global_search(f, dims=2, seed=1, popsize=8, generations=30, pattern_rounds=6)
    >>> bool(np.allclose(best.u, 0.3, atol=1e-3)), best.evaluations > 100
    (True, True)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InvalidInput

#: ``evaluate_round(U, tag)``: scores (R,) of the candidates ``U`` (R, D) in the unit box.
RoundEvaluator = Callable[[np.ndarray, str], np.ndarray]
#: Largest number of candidates one search may evaluate.
MAX_EVALUATIONS = 200_000


class SearchResult(NamedTuple):
    """The best candidate, its score, and every candidate and score evaluated (in order)."""

    u: np.ndarray  # (D,) unit coordinates of the best candidate
    score: float
    evaluated: np.ndarray  # (E, D)
    scores: np.ndarray  # (E,)
    evaluations: int


def check_budget(dims: int, popsize: int, generations: int, pattern_rounds: int) -> int:
    """The number of evaluations a search will make at most; refused above MAX_EVALUATIONS."""
    for name, v, lo in (("dims", dims, 1), ("popsize", popsize, 4), ("generations", generations, 0),
                        ("pattern_rounds", pattern_rounds, 0)):  # fmt: skip
        if int(v) != v or v < lo:
            raise InvalidInput(f"{name} must be an integer >= {lo}, got {v}")
    total = popsize * dims * (generations + 1) + 4 * dims * pattern_rounds
    if total > MAX_EVALUATIONS:
        raise InvalidInput(
            f"the search would evaluate up to {total} candidates (popsize x dims x generations); "
            f"the limit is {MAX_EVALUATIONS}: lower --popsize or --generations"
        )
    return total


def global_search(
    evaluate_round: RoundEvaluator,
    *,
    dims: int,
    seed: int = 0,
    popsize: int = 10,
    generations: int = 20,
    pattern_rounds: int = 6,
    start: np.ndarray | None = None,
) -> SearchResult:
    """Minimise over ``[0, 1]^dims``: differential evolution, then the pattern search (H4).

    ``start`` (unit coordinates, e.g. the baseline design) is evaluated first and joins DE's
    initial population, so the result is never worse than it.
    """
    from scipy.optimize import differential_evolution

    check_budget(dims, popsize, generations, pattern_rounds)
    seen_u: list[np.ndarray] = []
    seen_s: list[np.ndarray] = []
    rounds = iter(range(10**9))

    def run_round(U: np.ndarray, tag: str) -> np.ndarray:
        s = np.asarray(evaluate_round(np.asarray(U, dtype=float), f"{tag}{next(rounds)}"))
        s = np.where(np.isfinite(s), s, math.inf).astype(float)
        seen_u.append(np.asarray(U, dtype=float))
        seen_s.append(s)
        return s

    def de_map(func, xs):  # SciPy's workers=: one call per generation
        return list(run_round(np.array(list(xs)), "de"))

    init = "sobol" if start is None else _initial(dims, popsize, seed, start)
    if generations > 0:
        differential_evolution(
            lambda u: 0.0, [(0.0, 1.0)] * dims, seed=seed, popsize=popsize, maxiter=generations,
            tol=0.0, atol=0.0, polish=False, updating="deferred", workers=de_map, init=init,
        )  # fmt: skip
    else:
        run_round(np.full((1, dims), 0.5) if isinstance(init, str) else init, "de")
    U, S = np.vstack(seen_u), np.concatenate(seen_s)
    best, best_s = _pattern(run_round, U, S, pattern_rounds)
    U, S = np.vstack(seen_u), np.concatenate(seen_s)
    return SearchResult(best, best_s, U, S, len(S))


def _initial(dims: int, popsize: int, seed: int, start: np.ndarray) -> np.ndarray:
    """DE's first population: ``start`` and a scrambled Sobol' sample of the box."""
    import warnings

    from scipy.stats import qmc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # balance needs n = 2^k; any n is fine here
        U = qmc.Sobol(dims, seed=seed).random(max(popsize * dims, 5) - 1)
    return np.vstack([np.clip(np.asarray(start, dtype=float), 0, 1)[None], U])


def _pattern(run_round, U: np.ndarray, S: np.ndarray, rounds: int) -> tuple[np.ndarray, float]:
    """Coordinate moves of ± step around the two best, the step halved each round."""
    dims = U.shape[1]
    step = np.full(dims, 1 / 8)
    for _ in range(rounds):
        order = np.argsort(S, kind="stable")[:2]
        moves = [
            np.clip(U[b] + s * step[d] * np.eye(dims)[d], 0.0, 1.0)
            for b in order
            if np.isfinite(S[b])
            for d in range(dims)
            for s in (-1, 1)
        ]
        if not moves:
            break
        M = np.unique(np.array(moves), axis=0)
        U = np.vstack([U, M])
        S = np.concatenate([S, run_round(M, "pattern")])
        step = step / 2
    k = int(np.argmin(S))
    return U[k], float(S[k])
