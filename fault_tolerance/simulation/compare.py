"""One table of runs, compared fairly: which start each run used, which method won.

A comparison of methods is like for like only when every run starts from the same configuration
(the start alone moves λ by as much as the method, docs/planning.md). :func:`compare_runs` labels
the distinct starts of a set of runs (``A``, ``B``, ... by first appearance, two starts being the
same within :data:`SAME_START` rad), and names the winner on the mean and on the maximum of the
square-sum jump λ(t) (eq. 9/10, (rad/s)²); ties within :data:`TIE` relative are all named.
``simulate``, ``reproduce`` (REPORT.md) and the replay page print its lines under their tables.

Example:
    >>> from fault_tolerance.simulation.compare import compare_runs  # doctest: +SKIP
    >>> compare_runs({"lnva": r1, "jvja": r2}).lines()  # doctest: +SKIP
    ['start: every method from the same q0 = [...] rad', 'winner: λ mean jvja (0.181), λ max jvja (0.202) (rad/s)²']
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput

#: Largest joint-wise difference [rad] of two starts that count as the same configuration.
SAME_START = 1e-9
#: Relative difference of two scores within which methods tie.
TIE = 1e-9


@dataclass(frozen=True)
class Comparison:
    """Starts and winners of a set of runs.

    Attributes:
        start_of: Label of the start each run used (``{"lnva": "A", "global": "B"}``).
        starts: The distinct starts [rad], by label (``{"A": [...], ...}``).
        mean_winners: Methods with the smallest mean λ, and that value [(rad/s)²].
        max_winners: Methods with the smallest max λ, and that value [(rad/s)²].
    """

    start_of: dict
    starts: dict
    mean_winners: tuple[tuple[str, ...], float]
    max_winners: tuple[tuple[str, ...], float]

    @property
    def same_start(self) -> bool:
        """True when every run started from one configuration."""
        return len(self.starts) == 1

    def as_dict(self) -> dict:
        """JSON-able form (``comparison.json``, REPORT.md)."""
        return {
            "same_start": self.same_start,
            "start_of": dict(self.start_of),
            "starts": {k: np.asarray(v).tolist() for k, v in self.starts.items()},
            "winner_jvj_mean": {
                "methods": list(self.mean_winners[0]),
                "value": self.mean_winners[1],
            },
            "winner_jvj_max": {"methods": list(self.max_winners[0]), "value": self.max_winners[1]},
        }

    def lines(self) -> list[str]:
        """The lines printed under a table: the start(s), then the winners."""
        if self.same_start:
            (q,) = self.starts.values()
            head = [f"start: every method from the same q0 = {np.round(q, 4).tolist()} rad"]
        else:
            head = ["start: NOT the same for every method (the start moves λ too):"] + [
                f"  start {k}: q0 = {np.round(q, 4).tolist()} rad, used by "
                + ", ".join(a for a, s in self.start_of.items() if s == k)
                for k, q in self.starts.items()
            ]
        (mw, mv), (xw, xv) = self.mean_winners, self.max_winners
        return head + [
            f"winner: λ mean {'='.join(mw)} ({mv:.4g}), λ max {'='.join(xw)} ({xv:.4g}) (rad/s)²"
            + ("" if self.same_start else " (from different starts)")
        ]


def _winners(scores: Mapping[str, float]) -> tuple[tuple[str, ...], float]:
    best = min(scores.values())
    tol = TIE * max(abs(best), 1e-300)
    return tuple(a for a, v in scores.items() if v <= best + tol), float(best)


def compare_runs(runs: Mapping) -> Comparison:
    """Starts (``run.q[0]``) and the λ-mean / λ-max winners of ``runs`` (name -> Run)."""
    if not runs:
        raise InvalidInput("compare_runs needs at least one run; got none")
    starts: dict = {}
    start_of: dict = {}
    for alg, run in runs.items():
        q = np.asarray(run.q[0], dtype=float)
        label = next(
            (
                k
                for k, s in starts.items()
                if s.shape == q.shape and np.max(np.abs(s - q)) <= SAME_START
            ),
            None,
        )
        if label is None:
            label = chr(ord("A") + len(starts)) if len(starts) < 26 else f"S{len(starts) + 1}"
            starts[label] = q
        start_of[alg] = label
    means = {a: float(np.mean(r.jvj)) for a, r in runs.items()}
    maxes = {a: float(np.max(r.jvj)) for a, r in runs.items()}
    return Comparison(start_of, starts, _winners(means), _winners(maxes))
