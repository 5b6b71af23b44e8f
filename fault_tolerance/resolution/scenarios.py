"""Failure scenarios: the sets of joints that may lock together, with weights.

A scenario ``S`` is a set of joint columns that lock at once. The user names the lockable joints
(the paper's "possible failed joints") as column indices, joint names, or tuples of them for
multi-joint scenarios (docs/MATH.md, "Failure scenarios": ``|S| <= r``). Weights ``w_S`` (e.g.
failure probabilities) default to 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fault_tolerance.errors import IntolerableFailure, InvalidScenario
from fault_tolerance.numerics.linalg import PIVOT_TOL, min_pivot

#: Largest ratio of two scenario weights: over the largest, every weight stays a normal float.
MAX_WEIGHT_RATIO = 1e300


@dataclass(frozen=True)
class Scenarios:
    """Validated failure scenarios: ``sets[k]`` are the columns of scenario k, ``weights[k]`` its weight."""

    sets: tuple[tuple[int, ...], ...]
    weights: np.ndarray
    n: int
    joint_names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        if not self.sets:
            raise InvalidScenario(
                "the lockable set is empty; name at least one joint that may lock"
            )
        if len(self.weights) != len(self.sets):
            raise InvalidScenario(
                f"{len(self.weights)} weights for {len(self.sets)} scenarios; give one weight each"
            )
        if not np.all(np.isfinite(self.weights)) or np.any(self.weights <= 0):
            raise InvalidScenario(f"weights must be finite and > 0, got {list(self.weights)}")
        with np.errstate(over="ignore"):
            ratio = float(self.weights.max() / self.weights.min())  # inf for 1e308 / 5e-324
        if not ratio <= MAX_WEIGHT_RATIO:
            raise InvalidScenario(
                f"weights span a ratio of {ratio:.3g} (largest over smallest); over the largest the "
                f"smallest would vanish: give weights within a ratio of {MAX_WEIGHT_RATIO:g}"
            )

    @property
    def relative_weights(self) -> np.ndarray:
        """The weights over the largest (W1), shape (f,), in (0, 1].

        The resolvers (5), (G2), (G3) and (L2) do not change when every weight is multiplied by
        one number, so they use these: no sum or product of them overflows or underflows, and
        1e308 or 5e-324 weights give the same rates as weights 1.
        """
        return self.weights / self.weights.max()

    @property
    def f(self) -> int:
        """Number of scenarios."""
        return len(self.sets)

    @property
    def singletons(self) -> bool:
        """True when every scenario locks exactly one joint (the paper's case)."""
        return all(len(S) == 1 for S in self.sets)

    @property
    def columns(self) -> np.ndarray:
        """For singleton scenarios: the locked column of each, shape (f,)."""
        return np.array([S[0] for S in self.sets], dtype=int)

    def name(self, S: Sequence[int]) -> list[str]:
        """Joint names of a scenario (``joint index i`` when names are unknown)."""
        if self.joint_names:
            return [self.joint_names[i] for i in S]
        return [f"joint index {i}" for i in S]

    def pivots(self, N: np.ndarray) -> np.ndarray:
        """Smallest eigenvalue of ``N[S, S]`` per scenario, shape (f,); ~0 means intolerable.

        A stack of projectors (..., n, n) gives (..., f).
        """
        if self.singletons:
            return N[..., self.columns, self.columns]
        return np.stack([np.asarray(min_pivot(N, S)) for S in self.sets], axis=-1)

    def check_tolerable(self, N: np.ndarray) -> np.ndarray:
        """Smallest pivot of ``N[S, S]`` per scenario; raise :class:`IntolerableFailure` if one is ~0."""
        pivots = self.pivots(N)
        k = int(np.argmin(pivots))
        if pivots[k] < PIVOT_TOL:
            raise IntolerableFailure(self.name(self.sets[k]), float(pivots[k]))
        return pivots


def _column(joint, n: int, names: Sequence[str]) -> int:
    if isinstance(joint, (bool, np.bool_)):
        raise InvalidScenario(f"joint {joint!r} is not a column index or a joint name")
    if isinstance(joint, (int, np.integer)):
        if 0 <= int(joint) < n:
            return int(joint)
        raise InvalidScenario(f"joint index {joint} is out of range; allowed 0..{n - 1}")
    if isinstance(joint, str):
        if joint in names:
            return list(names).index(joint)
        if names:
            raise InvalidScenario(f"joint '{joint}' is not an active joint; they are {list(names)}")
        raise InvalidScenario(f"joint '{joint}' given by name but no joint names are known")
    raise InvalidScenario(f"joint {joint!r} is not a column index or a joint name")


def scenarios(
    lockable,
    n: int,
    *,
    r: int | None = None,
    weights: Sequence[float] | None = None,
    joint_names: Sequence[str] = (),
) -> Scenarios:
    """Validate a lockable set into :class:`Scenarios`.

    Args:
        lockable: ``None`` or ``"all"`` (every joint, one at a time); a list of column indices or
            joint names (singletons); tuples in the list are multi-joint scenarios; a ready
            :class:`Scenarios` is returned as is.
        n: Number of joints (columns of J).
        r: Degree of redundancy; scenarios larger than ``r`` are refused.
        weights: One positive weight per scenario (default 1).
        joint_names: Names of the columns, for messages and name lookup.
    """
    if isinstance(lockable, Scenarios):
        return lockable
    if lockable is None or (isinstance(lockable, str) and lockable == "all"):
        items: list = list(range(n))
    elif isinstance(lockable, str):
        items = [s.strip() for s in lockable.split(",") if s.strip()]
    else:
        items = list(lockable)
    sets: list[tuple[int, ...]] = []
    for item in items:
        group = item if isinstance(item, (tuple, list, set, frozenset)) else (item,)
        cols = tuple(sorted(_column(j, n, joint_names) for j in group))
        if not cols:
            raise InvalidScenario("a scenario is empty; each scenario locks at least one joint")
        if len(set(cols)) != len(cols):
            raise InvalidScenario(f"scenario {item!r} names a joint twice")
        if r is not None and r < 1:
            raise InvalidScenario(
                f"scenario {item!r}: the arm has no redundancy for this task (r = n - m = {r}), so "
                "any locked joint loses it; use a task with fewer rows or an arm with more joints"
            )
        if r is not None and len(cols) > r:
            raise InvalidScenario(
                f"scenario {item!r} locks {len(cols)} joints but the arm has only r = {r} degrees "
                f"of redundancy; at most {r} joints may lock together"
            )
        if cols in sets:
            raise InvalidScenario(f"scenario {item!r} is listed twice in the lockable set")
        sets.append(cols)
    w = np.ones(len(sets)) if weights is None else np.asarray(weights, dtype=float).ravel()
    return Scenarios(tuple(sets), w, n, tuple(joint_names))
