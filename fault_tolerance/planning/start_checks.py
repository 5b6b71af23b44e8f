"""The tests a start must pass: limits, regularity, tolerable scenarios, a clean run.

Used by :func:`fault_tolerance.planning.default_start.default_start` (docs/MATH.md, "The default start").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.model.arm import Arm
from fault_tolerance.model.task_errors import error_norms
from fault_tolerance.numerics.linalg import PIVOT_TOL, projection
from fault_tolerance.planning.posture import lockable_scenarios
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.resolution.scenarios import Scenarios

#: Distance a start keeps from every joint limit, as a fraction of the joint's range.
LIMIT_MARGIN = 0.05
#: Smallest singular value of J [task units per rad] a start must have.
SIGMA_REGULAR = 1e-2
#: Smallest pivot of N[S, S] a start must have for every lockable scenario (intolerable: < 1e-9).
PIVOT_MARGIN = 1e-3
#: Largest position error [m] (and orientation error [rad]) a checked run may reach.
ERROR_TOL = 1e-3
#: Random regular configurations at which a scenario must be intolerable to count as structural.
STRUCTURAL_SAMPLES = 50


def limit_box(arm: Arm) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits with infinite ones replaced by ±π (continuous joints are read as ±π)."""
    lo = np.where(np.isfinite(arm.lower), arm.lower, -np.pi)
    hi = np.where(np.isfinite(arm.upper), arm.upper, np.pi)
    return lo, hi


def mid_range(arm: Arm) -> np.ndarray:
    """The configuration halfway between every joint's limits (0 for continuous joints)."""
    lo, hi = limit_box(arm)
    return (lo + hi) / 2


def inside_limits(arm: Arm, q: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Which rows of ``q`` (shape (..., n)) keep ``margin`` × range from every joint limit."""
    lo, hi = limit_box(arm)
    pad = margin * (hi - lo)
    q = np.asarray(q, dtype=float)
    return np.all((q >= lo + pad - 1e-12) & (q <= hi - pad + 1e-12), axis=-1)


#: Why a candidate start failed, by category (docs/cli.md, "When no start passes").
STRUCTURAL = "structurally intolerable for this tip and task"
UNDER_LIMITS = "intolerable under the joint limits"
NEARLY_INTOLERABLE = "nearly intolerable at the start"
SINGULAR = "singular"
NEAR_LIMIT = "at a joint limit"
OUT_OF_REACH = "path out of reach"
TOO_FAST = "too fast for the velocity limits"
#: Every category, in the order a refusal lists equal counts.
CATEGORIES = (
    STRUCTURAL, UNDER_LIMITS, NEARLY_INTOLERABLE, SINGULAR, OUT_OF_REACH, TOO_FAST, NEAR_LIMIT
)  # fmt: skip


@dataclass(frozen=True)
class Failure:
    """Why one candidate start failed: a category of :data:`CATEGORIES`, the joints, the detail.

    Attributes:
        category: One of :data:`CATEGORIES`.
        joints: The joints concerned (the lockable joints that fail, the joints at their velocity
            or position limit); empty when the failure concerns no joint in particular.
        text: The detail, one line (e.g. ``"near-singular (σ_min(J) = 0 < 0.01)"``).
    """

    category: str
    joints: tuple[str, ...]
    text: str

    def __post_init__(self) -> None:
        if self.category not in CATEGORIES:
            raise ValueError(f"category {self.category!r}: choose among {list(CATEGORIES)}")

    def __str__(self) -> str:
        return self.text


def start_failure(arm: Arm, q: np.ndarray, sc: Scenarios) -> Failure | None:
    """Why ``q`` is not a usable start (limits, singular J, intolerable scenario), or ``None``."""
    if not inside_limits(arm, q, LIMIT_MARGIN):
        lo, hi = limit_box(arm)
        pad = LIMIT_MARGIN * (hi - lo)
        near = np.flatnonzero((q < lo + pad - 1e-12) | (q > hi - pad + 1e-12))
        return Failure(
            NEAR_LIMIT,
            tuple(arm.joint_names[j] for j in near),
            f"within {100 * LIMIT_MARGIN:g} % of a joint limit",
        )
    proj = projection(arm.jacobian(q))
    if proj.sigma_min < SIGMA_REGULAR:
        return Failure(
            SINGULAR, (), f"near-singular (σ_min(J) = {proj.sigma_min:.2g} < {SIGMA_REGULAR:g})"
        )
    pivots = sc.pivots(proj.N)
    k = int(np.argmin(pivots))
    if pivots[k] < PIVOT_MARGIN:
        names = tuple(sc.name(sc.sets[k]))
        return Failure(
            NEARLY_INTOLERABLE,
            names,
            f"locking {', '.join(names)} nearly loses the task there "
            f"(pivot {pivots[k]:.2g} < {PIVOT_MARGIN:g})",
        )
    return None


def start_problem(arm: Arm, q: np.ndarray, sc: Scenarios) -> str | None:
    """:func:`start_failure` as text, or ``None``."""
    found = start_failure(arm, q, sc)
    return None if found is None else found.text


def under_limits_at_start(arm: Arm, q: np.ndarray, task, sc: Scenarios, sim_options: dict):
    """Scenarios that cannot keep the task's first velocity inside the rate box at ``q`` (L1), (L4).

    ``None`` when joint limits are off (``sim_options["limits"] is False``) or there is no task:
    nothing to check. Otherwise the names (``"joint2"``, ``"joint1+joint2"``) of the scenarios
    whose reduced robot needs a task scaling ``s_S < 1`` at ``t = 0``, with the box the run uses
    (horizon ``max(horizon, dt)``) and the velocity it commands there (``ẋ_des(0)``, the start
    being on the path).
    """
    from fault_tolerance.model.joint_limits import RATE_HORIZON, arm_rate_box
    from fault_tolerance.resolution.bounded import SCALE_TOL
    from fault_tolerance.resolution.limits import tolerable_under_limits

    if task is None or not sim_options.get("limits", True):
        return None
    h = sim_options.get("horizon") or RATE_HORIZON
    box = arm_rate_box(arm, q, max(float(h), float(sim_options.get("dt", 0.0) or 0.0)))
    xd = np.asarray(task.xdot(0.0), dtype=float)
    scales = tolerable_under_limits(arm.jacobian(q), xd, sc, bounds=box)
    return tuple(
        "+".join(sc.name(S)) for S, s in zip(sc.sets, scales, strict=True) if s < 1.0 - SCALE_TOL
    )


def too_fast_at_start(arm: Arm, q: np.ndarray, task, sim_options: dict) -> Failure | None:
    """:data:`TOO_FAST` when even the whole arm needs a task scaling ``s < 1`` at ``t = 0`` (L3).

    The box is the run's (as in :func:`under_limits_at_start`); the joints named are those whose
    rate box binds at the velocity limit there. ``None`` without limits, without a task, or when
    the whole arm keeps the task's first velocity.
    """
    from fault_tolerance.model.joint_limits import RATE_HORIZON, arm_rate_box, velocity_limits
    from fault_tolerance.resolution.bounded import SCALE_TOL, bounded_least_norm

    if task is None or not sim_options.get("limits", True):
        return None
    h = sim_options.get("horizon") or RATE_HORIZON
    lo, hi = arm_rate_box(arm, q, max(float(h), float(sim_options.get("dt", 0.0) or 0.0)))
    xd = np.asarray(task.xdot(0.0), dtype=float)
    sol = bounded_least_norm(arm.jacobian(q), xd, lo, hi)
    if sol.scale >= 1.0 - SCALE_TOL:
        return None
    v = velocity_limits(arm)
    at = sol.active & (np.abs(sol.qd) >= (1 - 1e-6) * v)
    return Failure(
        TOO_FAST,
        tuple(n for n, a in zip(arm.joint_names, at, strict=True) if a),
        f"the task's first velocity {np.linalg.norm(xd):.3g} needs a scaling s = {sol.scale:.3g} "
        "< 1 of the whole arm inside its velocity limits at t = 0",
    )


def run_failure(arm: Arm, run) -> Failure | None:
    """Why a checked run disqualifies its start (limits, singular J, task error), or ``None``.

    A task error with samples where the rate box scaled the task (L3) and a joint at its velocity
    limit is :data:`TOO_FAST`; a run that leaves the joint limits, or whose error grows without
    that, is :data:`OUT_OF_REACH` (the joints named are those at a position limit, if any). A run
    that passes near a singularity of J is :data:`SINGULAR`, unless its error grows at a point of
    the path that no configuration reaches (:func:`unreached_point`): then the arm stretched to the
    edge of its workspace because the path leaves it, :data:`OUT_OF_REACH`.
    """
    from fault_tolerance.simulation.run import FLAG_NEAR_SINGULAR

    out = ~inside_limits(arm, run.q)
    if out.any():
        k = int(np.argmax(out))
        lo, hi = limit_box(arm)
        joints = np.flatnonzero((run.q[k] < lo - 1e-12) | (run.q[k] > hi + 1e-12))
        return Failure(
            OUT_OF_REACH,
            tuple(arm.joint_names[j] for j in joints),
            f"leaves the joint limits at t = {run.t[k]:.3f} s",
        )
    text = _error_text(run)
    if np.any(run.flags & FLAG_NEAR_SINGULAR):
        k = int(np.argmax(run.flags & FLAG_NEAR_SINGULAR))
        away = None if text is None else unreached_point(arm, run)
        if away is None:
            return Failure(SINGULAR, (), f"passes near a singularity of J at t = {run.t[k]:.3f} s")
        return Failure(
            OUT_OF_REACH,
            at_position_limit(arm, run),
            f"{text}: the path leaves the workspace (at t = {run.t[away]:.3f} s it asks for "
            f"x = {np.round(run.x_des[away], 4).tolist()}, which no configuration inside the "
            f"limits reaches; the arm stretches to a singularity of J from t = {run.t[k]:.3f} s)",
        )
    if text is None:
        return None
    fast = at_velocity_limit(arm, run)
    if fast:
        return Failure(TOO_FAST, fast, f"{text} (the task is scaled to the velocity limits)")
    return Failure(OUT_OF_REACH, at_position_limit(arm, run), text)


def _error_text(run) -> str | None:
    """The task error of ``run`` beyond :data:`ERROR_TOL`, as text, or ``None``."""
    ori = run.orientation_error
    if run.error.max() > ERROR_TOL:
        return f"position error reaches {1e3 * run.error.max():.3g} mm"
    if ori is not None and ori.max() > ERROR_TOL:
        return f"orientation error reaches {ori.max():.3g} rad"
    return None


def unreached_point(arm: Arm, run) -> int | None:
    """The sample of ``run``'s largest task error if no configuration reaches its desired point.

    :func:`~.posture.reaches` from the run's configuration there (and the usual seeds); ``None``
    when a configuration reaches it: the path is in reach there.
    """
    from fault_tolerance.planning.posture import reaches

    ori = run.orientation_error
    k = int(np.argmax(run.error if ori is None or run.error.max() > ERROR_TOL else ori))
    return None if reaches(arm, run.x_des[k], near=[run.q[k]]) else k


def at_velocity_limit(arm: Arm, run, slack: float = 1e-3) -> tuple[str, ...]:
    """Joints at their velocity limit at samples where the rate box scaled the task (L3)."""
    from fault_tolerance.simulation.run import FLAG_TASK_SCALED

    scaled = (run.flags & FLAG_TASK_SCALED) != 0
    if not scaled.any():
        return ()
    v = np.asarray(arm.velocity_limit, dtype=float)
    qd = run.qd if run.qd_cmd is None else run.qd_cmd
    at = np.any(np.abs(qd[scaled]) >= (1 - slack) * v, axis=0)
    return tuple(n for n, a in zip(arm.joint_names, at, strict=True) if a)


def at_position_limit(arm: Arm, run, margin: float = 1e-3) -> tuple[str, ...]:
    """Joints that come within ``margin`` × range of a position limit during ``run``."""
    lo, hi = limit_box(arm)
    pad = margin * (hi - lo)
    near = np.any((run.q <= lo + pad) | (run.q >= hi - pad), axis=0)
    return tuple(n for n, a in zip(arm.joint_names, near, strict=True) if a)


def run_problem(arm: Arm, run) -> str | None:
    """:func:`run_failure` as text, or ``None``."""
    found = run_failure(arm, run)
    return None if found is None else found.text


def run_caveat(run) -> str | None:
    """What makes a run that passed :func:`run_problem` less than ideal, or ``None``."""
    from fault_tolerance.simulation.run import FLAG_NEAR_INTOLERABLE

    near = int(np.count_nonzero(run.flags & FLAG_NEAR_INTOLERABLE))
    if near:
        return f"{near} samples where a lockable joint is nearly intolerable (pivots damped)"
    worst = float(np.max(run.rcn))
    if worst > RCN_THRESHOLD:
        return f"largest k_S {worst:.3g} > RCN threshold {RCN_THRESHOLD:g}"
    return None


def task_error_parts(task, x_des, x, *, arm: Arm | None = None, q=None):
    """Position error [m] and orientation error [rad] (``None`` without angular rows) per sample.

    With ``arm`` and ``q`` the angular part is the rotation that remains (``Arm.task_error``);
    otherwise the difference of the rotation-vector rows. See :mod:`.task_errors`.
    """
    x_des, x = np.atleast_2d(x_des), np.atleast_2d(x)
    if arm is not None and q is not None:
        err = np.array(
            [arm.task_error(xd, qk) for xd, qk in zip(x_des, np.atleast_2d(q), strict=True)]
        )
    else:
        err = x_des - x
    return error_norms(tuple(task), err)


def intolerable_everywhere(
    arm: Arm, lockable, samples: int = STRUCTURAL_SAMPLES, seed: int = 0
) -> list[tuple[str, ...]]:
    """Scenarios intolerable at every one of ``samples`` random regular configurations (seeded).

    A configuration is regular when ``σ_min(J) >= 1e-3``; intolerable means the smallest pivot of
    ``N[S, S]`` is below ``1e3 · PIVOT_TOL`` there. The spatial 4R's ``joint4`` is one. None when
    no configuration drawn is regular (J singular everywhere, e.g. a task row no joint moves):
    that is a singular task, not a scenario the others cannot make up.
    """
    sc = lockable_scenarios(arm, lockable)
    rng = np.random.default_rng(seed)
    always = set(range(sc.f))
    seen = 0
    for _ in range(20 * samples):
        proj = projection(arm.jacobian(arm.random_q(rng)))
        if proj.sigma_min < 1e-3:
            continue
        pivots = sc.pivots(proj.N)
        always &= {k for k in always if pivots[k] < 1e3 * PIVOT_TOL}
        seen += 1
        if seen == samples or not always:
            break
    return [tuple(sc.name(sc.sets[k])) for k in sorted(always)] if seen else []


#: Largest column norm of the task Jacobian [task units per rad] of a joint that does not move
#: the tip (a tip at the wrist centre: the wrist joints' axes pass through it).
STILL_TOL = 1e-3


def still_joints(arm: Arm, samples: int = 20, seed: int = 0) -> tuple[tuple[str, ...], float]:
    """Joints whose column of the task Jacobian stays below :data:`STILL_TOL` at every sample.

    ``(names, largest such column norm)`` over ``samples`` random configurations (seeded). A
    position task whose tip lies on the axes of the wrist joints is one: those joints do not move
    it, so the task rests on the others alone.
    """
    lever = np.linalg.norm(sampled_jacobians(arm, samples, seed), axis=1).max(axis=0)
    still = np.flatnonzero(lever < STILL_TOL)
    return tuple(arm.joint_names[j] for j in still), float(lever[still].max(initial=0.0))


def sampled_jacobians(arm: Arm, samples: int = 20, seed: int = 0) -> np.ndarray:
    """Task Jacobians at ``samples`` random configurations (seeded), shape (samples, m, n)."""
    rng = np.random.default_rng(seed)
    return np.array([arm.jacobian(arm.random_q(rng)) for _ in range(samples)])


def still_rows(arm: Arm, tol: float = STILL_TOL, samples: int = 20, seed: int = 0):
    """Task rows no joint moves: their row of J stays below ``tol`` at every sample (seeded)."""
    reach = np.abs(sampled_jacobians(arm, samples, seed)).max(axis=(0, 2))
    return tuple(r for r, v in zip(arm.task, reach, strict=True) if v < tol)


def singular_task_text(arm: Arm, samples: int = 20, seed: int = 0) -> str:
    """The cause a refusal names when J is singular at every sample (seeded), else ``""``.

    The rank J keeps at most, and the task rows no joint moves (:func:`still_rows`), if any.
    """
    J = sampled_jacobians(arm, samples, seed)
    sigma = np.linalg.svd(J, compute_uv=False)
    if sigma[:, -1].max() >= SIGMA_REGULAR:
        return ""
    rank = int((sigma >= SIGMA_REGULAR).sum(axis=1).max())
    rows = still_rows(arm, samples=samples, seed=seed)
    which = f": no joint moves the tool along {', '.join(rows)}" if rows else ""
    return (
        f"the task {'/'.join(arm.task)} is singular at every configuration: J has rank at most "
        f"{rank} < {arm.m} at {samples} sampled configurations (σ_min(J) < {SIGMA_REGULAR:g}){which}"
    )


def still_joints_text(arm: Arm, still: tuple[str, ...], lever: float, samples: int = 20) -> str:
    """The cause a refusal names when joints do not move the tip (:func:`still_joints`)."""
    others = ", ".join(n for n in arm.joint_names if n not in still)
    model = arm.model
    kinds = [model.joints[model.getJointId(n)].shortname() for n in still]
    revolute = all(k.startswith("JointModelR") for k in kinds)
    if not revolute:  # a prismatic joint: no axis for the tip to lie on
        where = f"{', '.join(still)} {'does' if len(still) == 1 else 'do'} not move the task"
    elif len(still) > 1:
        where = f"the tip lies at the wrist centre: {', '.join(still)} do not move it"
    else:
        where = f"the tip lies on the axis of {still[0]}: it does not move it"
    columns, stay = ("its column", "stays") if len(still) == 1 else ("their columns", "stay")
    return (
        f"{where} ({columns} of the task Jacobian {stay} below {STILL_TOL:g} per rad or m at "
        f"{samples} sampled configurations, at most {lever:.1g}), so the task rests on {others} "
        "alone"
    )


def often_tolerable(arm: Arm, lockable, samples: int = 20, seed: int = 0) -> tuple[str, ...]:
    """Single lockable joints whose pivot is at least :data:`PIVOT_MARGIN` at most samples.

    Over ``samples`` random regular configurations (``σ_min(J) >= SIGMA_REGULAR``, seeded): the
    joints a start can likely make up, the lockable set a refusal may try instead.
    """
    sc = lockable_scenarios(arm, [n for n in lockable if isinstance(n, str)])
    rng = np.random.default_rng(seed)
    good, seen = np.zeros(sc.f), 0
    for _ in range(20 * samples):
        proj = projection(arm.jacobian(arm.random_q(rng)))
        if proj.sigma_min < SIGMA_REGULAR:
            continue
        good += sc.pivots(proj.N) >= PIVOT_MARGIN
        seen += 1
        if seen == samples:
            break
    return tuple(sc.name(sc.sets[k])[0] for k in range(sc.f) if seen and 2 * good[k] > seen)


class FailureTally:
    """Candidate starts counted by why they failed (:class:`Failure`), and the joints concerned.

    The start search adds one :class:`Failure` per candidate it refuses (``add``) and one per
    configuration drawn for a seed that was not regular (``add_seed``); ``dominant`` and
    ``summary`` then say which check failed for which joints, most frequent first.
    """

    def __init__(self) -> None:
        self.candidates: dict[str, list[Failure]] = {}
        self.seeds: dict[str, list[Failure]] = {}
        self.drawn = 0

    def add(self, failure: Failure) -> None:
        """Count one refused candidate start."""
        self.candidates.setdefault(failure.category, []).append(failure)

    def add_seed(self, failure: Failure) -> None:
        """Count one configuration drawn for a seed that is not a usable start."""
        self.seeds.setdefault(failure.category, []).append(failure)

    @property
    def total(self) -> int:
        """Candidates refused."""
        return sum(len(v) for v in self.candidates.values())

    def _pool(self) -> dict[str, list[Failure]]:
        return self.candidates if self.candidates else self.seeds

    def dominant(self) -> list[tuple[str, int, tuple[str, ...]]]:
        """``(category, count, joints)`` of the categories with at least half the top count."""
        pool = self._pool()
        if not pool:
            return []
        ranked = sorted(pool, key=lambda c: (-len(pool[c]), CATEGORIES.index(c)))
        top = len(pool[ranked[0]])
        return [(c, len(pool[c]), joints_of(pool[c])) for c in ranked if 2 * len(pool[c]) >= top]

    def summary(self) -> str:
        """One line: the counts by category, the dominant ones with their joints and an example."""
        pool = self._pool()
        if not pool:
            return "no candidate start was found to check"
        what = (
            f"{self.total} candidate start{'s' if self.total > 1 else ''} refused"
            if self.candidates
            else f"no regular seed among the {self.drawn} configurations drawn near mid-range"
        )
        ranked = sorted(pool, key=lambda c: (-len(pool[c]), CATEGORIES.index(c)))
        parts = []
        for c in ranked:
            joints = joints_of(pool[c])
            who = f" ({', '.join(joints)})" if joints else ""
            parts.append(f"{len(pool[c])} {c}{who}")
        first = pool[ranked[0]][0].text
        return f"{what}: {'; '.join(parts)}; e.g. {first}"


def joints_of(failures) -> tuple[str, ...]:
    """The joints of ``failures``, most often named first."""
    count: dict[str, int] = {}
    for f in failures:
        for j in f.joints:
            count[j] = count.get(j, 0) + 1
    return tuple(sorted(count, key=lambda j: -count[j]))
