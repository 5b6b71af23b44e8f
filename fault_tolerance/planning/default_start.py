"""The default start: a configuration that works on any arm when neither ``q0`` nor ``x0`` is given.

``q = 0`` and a description's reference posture are often singular, at a joint limit, or a
configuration where a lockable joint is intolerable (a UR5 at ``q = 0`` is stretched out and
cannot lose its shoulder pan joint; a Panda at its reference posture cannot lose ``panda_joint2``). :func:`default_start` picks the start
the way docs/MATH.md ("The default start") describes:

1. seeds: the mid-range configuration, then configurations drawn from the central half of every
   joint's range (seeded);
2. a seed is used if it is regular: inside the limits with a margin, ``σ_min(J)`` well above zero,
   every lockable scenario tolerable with a margin;
3. ``x0 = x(seed)``; the posture search of :mod:`.posture` (minimum square-sum RCN on the
   self-motion through ``x0``) gives candidates, best first; those outside the limits or not
   regular are dropped, and the seed itself is the last candidate;
4. each candidate runs the default task (a small circle at ``x0``, or the caller's path) with the
   caller's algorithms; it is accepted when every sample stays inside the limits, none is
   near-singular or near-intolerable, and the task error stays below :data:`ERROR_TOL`.
   Among accepted candidates one whose reduced condition numbers stay below
   :data:`~.posture.RCN_THRESHOLD` is preferred (step iii of the paper's planning loop);
5. with joint limits on (the default), a candidate where some lockable scenario cannot keep the
   task's first velocity inside the rate box (it is intolerable *under limits* at ``t = 0``,
   :func:`~.start_checks.under_limits_at_start`) is set aside before it is simulated; only when no
   candidate of any seed is tolerable under limits are they tried, fewest such scenarios first,
   and the choice then names them and offers ``--lockable`` without them
   (:attr:`StartChoice.under_limits`).

:func:`explain_intolerable` turns an intolerable scenario at a given start into an error that says
whether the scenario is intolerable structurally (at every sampled configuration) or only at this
start, and then proposes a start that works.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from fault_tolerance.errors import (
    FaultToleranceError,
    InfeasibleBounds,
    IntolerableAtStart,
    IntolerableFailure,
    IntolerableUnderLimits,
    InvalidInput,
    NoStartFound,
    StructurallyIntolerable,
)
from fault_tolerance.model.arm import Arm
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.planning.posture import initial_posture, joint_distance, lockable_scenarios
from fault_tolerance.planning.start_checks import (
    NEARLY_INTOLERABLE,
    OUT_OF_REACH,
    SINGULAR,
    STRUCTURAL_SAMPLES,
    UNDER_LIMITS,
    Failure,
    FailureTally,
    intolerable_everywhere,
    limit_box,
    run_caveat,
    run_failure,
    singular_task_text,
    start_failure,
    still_joints,
    still_joints_text,
    too_fast_at_start,
    under_limits_at_start,
)
from fault_tolerance.resolution.indices import condition_numbers, reduced_singular_values
from fault_tolerance.resolution.scenarios import Scenarios

#: Radius [m] of the default circle through the start point.
DEFAULT_RADIUS = 0.05
#: Seeds tried at most, and candidates checked by simulation per seed.
MAX_SEEDS = 6
MAX_CANDIDATES = 3
#: Configurations near mid-range drawn to find well-conditioned seeds.
SEED_SAMPLES = 200
#: Longest stretch of the task [s] a candidate start is checked over.
CHECK_HORIZON = 2.0


@dataclass(frozen=True)
class StartChoice:
    """A start chosen by :func:`default_start` and why.

    Attributes:
        q0: Start configuration [rad], shape (n,).
        x0: Task coordinates of the tool there, shape (m,).
        K: Square-sum RCN at ``q0``.
        rcn_max: Largest reduced condition number at ``q0``.
        run_rcn_max: Largest reduced condition number along the checked runs.
        sigma_min: Smallest singular value of J at ``q0``.
        origin: Where ``x0`` came from (``"mid-range configuration"``, ``"given x0"``, ...).
        algorithms: Algorithms whose runs were checked (empty: no path was checked).
        tried: Candidates simulated before this one was accepted (itself included).
        note: A caveat, e.g. that no candidate kept the RCN below the threshold.
        checked: Seconds of the task that were checked when that is less than all of it.
        task_duration: The task's length [s] when only ``checked`` seconds of it were checked.
        runs: The checked runs from ``q0`` by algorithm (reuse them instead of simulating again).
        under_limits: ``None`` when joint limits were not checked (limits off, no task); else the
            scenarios intolerable under the joint limits at ``t = 0`` from ``q0`` (empty: none).
        lockable_without: The lockable joints outside ``under_limits`` (for ``--lockable``).
    """

    q0: np.ndarray
    x0: np.ndarray
    K: float
    rcn_max: float
    run_rcn_max: float
    sigma_min: float
    origin: str
    algorithms: tuple[str, ...]
    tried: int
    note: str = ""
    checked: float | None = None
    task_duration: float | None = None
    runs: dict = field(default_factory=dict, repr=False, compare=False)
    under_limits: tuple[str, ...] | None = None
    lockable_without: tuple[str, ...] = ()

    def limits_claim(self) -> str:
        """What the start claims about the joint limits at ``t = 0`` (empty when not checked)."""
        if self.under_limits is None:
            return ""
        if not self.under_limits:
            return ", also under the joint limits at t = 0 (rate box (L1) at q0)"
        offer = (
            f"--lockable {','.join(self.lockable_without)} leaves out each"
            if self.lockable_without
            else "every lockable joint is among them"
        )
        return (
            f"; but under the joint limits at t = 0 (rate box (L1) at q0) a lock of "
            f"{', '.join(self.under_limits)} cannot keep the task there (intolerable under limits; "
            f"no start tried has every lock tolerable): {offer} of the locks intolerable at the "
            "starts tried; or run a slower path (--radius, --duration) or --no-limits"
        )

    def horizon_note(self) -> str:
        """That only the task's first seconds were checked (empty when all of it was)."""
        if not self.checked:
            return ""
        of = f" of the {self.task_duration:g} s task" if self.task_duration else ""
        return (
            f" (only its first {self.checked:g} s{of} were checked: a start is checked over "
            f"{self.checked:g} s at most, the rest of the run is not)"
        )

    def reason(self) -> str:
        """One line: the start and why it was chosen."""
        checked = (
            f"; the task runs from it with {'/'.join(self.algorithms)} inside the limits, "
            f"regular, largest k_S {self.run_rcn_max:.3g}{self.horizon_note()}"
            if self.algorithms
            else ""
        )
        return (
            f"start q0 = {np.round(self.q0, 4).tolist()} rad: minimum square-sum RCN K = "
            f"{self.K:.4g} on the self-motion through x0 = {np.round(self.x0, 4).tolist()} "
            f"({self.origin}); inside the limits, σ_min(J) = {self.sigma_min:.3g}, every lockable "
            f"joint tolerable{self.limits_claim()}{checked}"
            + (f"; {self.note}" if self.note else "")
        )


def default_path(arm: Arm, x0: np.ndarray, radius: float = DEFAULT_RADIUS):
    """The default task at ``x0``: a circle of ``radius`` in the first two task rows, 1 s."""
    from fault_tolerance.simulation.paths import CirclePath

    if arm.m < 2:
        return None
    return CirclePath(np.asarray(x0, dtype=float), radius, 2 * np.pi, 1.0, rows=(0, 1))


def _candidates(
    arm: Arm, x0: np.ndarray, sc: Scenarios, seed_q, tally: FailureTally
) -> list[tuple[float, np.ndarray]]:
    """Posture-search candidates at ``x0`` that are usable starts, best first (then the seed).

    With a seed, only the seed's own self-motion is searched (``r = 1``: its curve; ``r > 1``:
    descent from it); without one, the global search of :func:`~.posture.initial_posture`.
    Those refused by :func:`~.start_checks.start_failure` are counted in ``tally``.
    """
    try:
        starts = None if seed_q is None else [seed_q]
        found = initial_posture(arm, x0, sc, starts=starts).candidates
    except InvalidInput as err:  # no configuration reaches x0
        tally.add(Failure(OUT_OF_REACH, (), str(err)))
        found = []
    kept: list[tuple[float, np.ndarray]] = []
    for K, q in found:
        if len(kept) == MAX_CANDIDATES:
            break
        if any(joint_distance(arm, q, c) <= 0.05 for _, c in kept):
            continue
        failure = start_failure(arm, q, sc)
        if failure is None:
            kept.append((K, q))
        else:
            tally.add(failure)
    if seed_q is not None and all(joint_distance(arm, seed_q, c) > 0.05 for _, c in kept):
        k = condition_numbers(reduced_singular_values(arm.jacobian(seed_q), sc))
        kept.append((float(k @ k), np.asarray(seed_q, dtype=float)))
    return kept


def _seeds(arm: Arm, sc: Scenarios, rng, max_seeds: int, tally: FailureTally):
    """Regular seeds ``(q, origin)``: mid-range if regular, then the best conditioned near it.

    The others are the best conditioned (smallest largest ``k_S``) of :data:`SEED_SAMPLES`
    configurations drawn from the central half of every joint's range; those that are not usable
    starts are counted in ``tally`` (until the seeds are found).
    """
    lo, hi = limit_box(arm)
    mid = (lo + hi) / 2
    tally.drawn = SEED_SAMPLES + 1  # the mid-range configuration and the draws near it
    failure = start_failure(arm, mid, sc)
    if failure is not None:
        tally.add_seed(failure)
    else:
        yield mid, "reached from the mid-range configuration"
        max_seeds -= 1
    draws = mid + rng.uniform(-1.0, 1.0, (SEED_SAMPLES, arm.n)) * (hi - lo) / 4
    worst = np.array(
        [condition_numbers(reduced_singular_values(arm.jacobian(q), sc)).max() for q in draws]
    )
    used: list[np.ndarray] = []
    for i in np.argsort(worst, kind="stable"):
        if len(used) == max_seeds:
            return
        q = draws[i]
        failure = start_failure(arm, q, sc)
        if failure is not None:
            tally.add_seed(failure)
            continue
        if any(joint_distance(arm, q, u) < 0.1 * np.linalg.norm(hi - lo) for u in used):
            continue
        used.append(q)
        yield (
            q,
            (
                f"reached from the best conditioned of {SEED_SAMPLES} configurations near mid-range, "
                f"largest k_S {worst[i]:.3g}"
            ),
        )


#: Errors of a run from one candidate start that refuse that candidate only (its solves, its
#: scenarios there); an invalid option or description still ends the command.
CANDIDATE_REFUSALS = (InfeasibleBounds, IntolerableFailure)


def _check(arm, q0, path, algorithms, sc, sim_options):
    """Simulate ``path`` from ``q0``: ``(problem, caveat, largest k_S, runs, flagged at t = 0)``.

    The runs go in the registry's order (the built-ins first, cheapest first: LNVA, JVJA, MDA),
    so a bad start fails fast; ``sim_options["options"]`` gives each resolver those it takes. The
    last is whether a run flagged a lock at its first sample as intolerable under limits.
    """
    from fault_tolerance.resolution.registry import names
    from fault_tolerance.simulation.run import FLAG_INTOLERABLE_UNDER_LIMITS
    from fault_tolerance.simulation.simulate import options_for, simulate

    known = names()
    order = sorted(algorithms, key=lambda a: known.index(a) if a in known else len(known))
    worst, caveat, runs, flagged = 0.0, None, {}, False
    for alg in order:
        own = dict(sim_options)
        if "options" in own:
            own["options"] = options_for(alg, own["options"])
        try:
            run = simulate(arm, path, alg, q0=q0, lockable=sc, **own)
        except CANDIDATE_REFUSALS as err:  # one refused candidate, not the end of the search
            return _refusal(alg, err), None, worst, {}, False
        problem = run_failure(arm, run)
        if problem:
            return replace(problem, text=f"{alg}: {problem.text}"), None, worst, {}, False
        runs[alg] = run
        worst = max(worst, float(np.max(run.rcn)))
        caveat = caveat or (None if run_caveat(run) is None else f"{alg}: {run_caveat(run)}")
        flagged = flagged or bool(run.flags[0] & FLAG_INTOLERABLE_UNDER_LIMITS)
    return None, caveat, worst, runs, flagged


def _refusal(alg: str, err: Exception) -> Failure:
    """A run refused by ``err`` as a :class:`~.start_checks.Failure` of its category."""
    text = f"{alg}: refused ({str(err).splitlines()[0][:200]})"
    if isinstance(err, IntolerableUnderLimits):
        return Failure(UNDER_LIMITS, tuple(err.joints), text)
    if isinstance(err, IntolerableFailure):
        return Failure(NEARLY_INTOLERABLE, tuple(err.joints), text)
    return Failure(OUT_OF_REACH, (), text)  # InfeasibleBounds: no rates reach the task


def default_start(
    arm: Arm,
    lockable=None,
    *,
    x0: np.ndarray | Sequence[float] | None = None,
    path: Callable | object | None = None,
    algorithms: Sequence[str] = ("jvja",),
    max_seeds: int = MAX_SEEDS,
    seed: int = 0,
    horizon: float = CHECK_HORIZON,
    **sim_options,
) -> StartChoice:
    """A start inside the limits, regular, with every lockable joint tolerable, that runs the task.

    See the module doc and docs/MATH.md ("The default start").

    Args:
        arm: The arm.
        lockable: Joints that may lock (default: the arm's default lockable joints).
        x0: Start point; without it one is reached from mid-range configurations.
        path: The task to check from each candidate: a callable ``path(x0) -> TaskPath`` (or
            ``None`` for no check), a ``TaskPath`` (then ``x0`` is its start), or ``None`` for
            :func:`default_path` (a 5 cm circle, 1 s).
        algorithms: Algorithms whose runs must stay inside the limits and regular.
        max_seeds: Regular seeds tried at most (without ``x0``).
        seed: Seed of the random seeds (the choice is reproducible).
        horizon: Longest stretch of the task checked [s]; a longer task is checked over its
            first ``horizon`` seconds only (its checked runs are then not kept in ``runs``).
        **sim_options: Passed to :func:`~.simulation.simulate` (``dt``, ``feedback_gain``, ...).

    Raises:
        StructurallyIntolerable: a lockable scenario loses the task at every configuration.
        NoStartFound: no start passed the checks (an :class:`~.errors.InvalidInput`); the
            message counts the candidates by why they failed and names the joints of the
            dominant reasons (``err.reasons``).

    Example:
        >>> import fault_tolerance as ft
        >>> arm = ft.load_arm("ur5")
        >>> start = ft.default_start(arm)
        >>> from fault_tolerance.planning.start_checks import LIMIT_MARGIN, inside_limits
        >>> bool(inside_limits(arm, start.q0, LIMIT_MARGIN))
        True
    """
    sc = lockable_scenarios(arm, lockable)
    _refuse_structural(arm, sc, seed)  # no start can help such a scenario: say so, not search
    make, x0 = _task_maker(arm, path, x0)
    tally = FailureTally()
    sources = _start_points(arm, sc, x0, seed, max_seeds, tally)
    found = _search(arm, sc, sources, make, tuple(algorithms), sim_options, horizon, tally)
    if found is not None:
        return found
    where = f"at x0 = {np.round(x0, 4).tolist()}" if x0 is not None else "from mid-range seeds"
    still, lever = still_joints(arm)
    cause = f"; {still_joints_text(arm, still, lever)}" if still else ""
    singular = singular_task_text(arm) if SINGULAR in (c for c, _, _ in tally.dominant()) else ""
    cause = f"; {singular}{cause}" if singular else cause
    raise NoStartFound(
        f"no start {where} for {arm.name} passed the checks ({tally.summary()}){cause}",
        tally.dominant(),
        still=still,
    )


def _search(arm, sc, sources, make, algorithms, sim_options, horizon, tally):
    """The choice or ``None`` (then ``tally`` says why): steps 3-5 of the module doc."""
    tried, fallback, aside = 0, None, []
    for seed_q, point, origin in sources:
        task = make(point)
        options, checked = _horizon(task, sim_options, horizon)
        for _, q in _candidates(arm, point, sc, seed_q, tally):
            bad = under_limits_at_start(arm, q, task, sc, options)
            if bad:  # intolerable under limits at t = 0: tried only if no other start passes
                aside.append((len(bad), len(aside), q, point, origin, task, options, checked, bad))
                continue
            tried += 1
            choice, caveat = _try(arm, sc, (q, point, origin, task), algorithms, options,
                                  checked, tried, bad, tally)  # fmt: skip
            if choice is not None and caveat is None:
                return choice
            if choice is not None and (
                fallback is None or choice.run_rcn_max < fallback.run_rcn_max
            ):
                fallback = replace(choice, note=f"the best start found has a caveat: {caveat}")
        if fallback is not None:  # this seed gave a usable start: do not search further
            return replace(fallback, tried=tried)
    every = tuple(dict.fromkeys(name for a in aside for name in a[-1]))  # bad at some start tried
    for _, _, q, point, origin, task, options, checked, bad in sorted(aside, key=lambda a: a[:2]):
        tried += 1
        choice, caveat = _try(arm, sc, (q, point, origin, task), algorithms, options,
                              checked, tried, bad, None, every)  # fmt: skip
        if choice is not None:
            note = f"the best start found has a caveat: {caveat}" if caveat else ""
            return replace(choice, note=note)
        tally.add(_aside_failure(arm, q, task, options, bad))
    return None


def _aside_failure(arm, q, task, options, bad) -> Failure:
    """Why a candidate set aside (intolerable under limits at t = 0) failed: too fast, or that."""
    fast = too_fast_at_start(arm, q, task, options)  # the whole arm is too slow for the task
    if fast is not None:
        return replace(fast, text=f"the start {np.round(q, 3).tolist()}: {fast.text}")
    joints = tuple(n for name in bad for n in name.split("+"))
    return Failure(
        UNDER_LIMITS,
        joints,
        f"the start {np.round(q, 3).tolist()}: a lock of {', '.join(bad)} cannot keep the task's "
        "first velocity inside the rate box (L1) at t = 0",
    )


def _try(arm, sc, where, algorithms, options, checked, tried, bad, tally, drop=()):
    """Simulate one candidate: ``(choice or None, caveat)``; a refusal is counted in ``tally``.

    ``bad``: its scenarios intolerable under limits at t = 0; ``drop``: those of every candidate
    set aside, which the offered ``--lockable`` leaves out. ``tally`` ``None``: not counted (the
    caller counts it).
    """
    q, point, origin, task = where
    problem, caveat, worst, runs, flagged = (
        (None, None, 0.0, {}, False)
        if task is None
        else _check(arm, q, task, algorithms, sc, options)
    )
    if not problem and flagged and not bad:  # the run is the judge of what it finds at t = 0
        problem = Failure(
            UNDER_LIMITS, (), "is intolerable under the joint limits at t = 0 in its run"
        )
    if problem:
        if tally is not None:
            text = f"the start {np.round(q, 3).tolist()} {problem.text}"
            tally.add(replace(problem, text=text))
        return None, None
    choice = _choice(arm, q, point, sc, worst, origin, task, algorithms, tried, runs)
    if checked is not None:  # only the first seconds ran: nothing to reuse
        choice = replace(choice, runs={}, checked=checked[0], task_duration=checked[1])
    if bad is not None:
        locked = {n for name in (*bad, *drop) for n in name.split("+")}
        without = tuple(dict.fromkeys(n for S in sc.sets for n in sc.name(S) if n not in locked))
        choice = replace(choice, under_limits=tuple(bad), lockable_without=without)
    return choice, caveat


def _task_maker(arm: Arm, path, x0):
    """``(make, x0)``: ``make(point)`` is the task checked from ``point``; a TaskPath fixes x0."""
    if hasattr(path, "x") and hasattr(path, "xdot"):  # a ready TaskPath fixes the start point
        fixed, x0 = path, np.asarray(path.x0, dtype=float)
        return (lambda _x0: fixed), x0
    return (path if path is not None else (lambda p: default_path(arm, p))), x0


def _start_points(arm: Arm, sc: Scenarios, x0, seed: int, max_seeds: int, tally: FailureTally):
    """``(seed q or None, start point, origin)``: the given x0, or points of regular seeds."""
    if x0 is not None:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (arm.m,):
            raise InvalidInput(f"x0 must be {arm.m} numbers for task {'/'.join(arm.task)}")
        return [(None, x0, "given x0")]
    rng = np.random.default_rng(seed)
    return ((q, arm.fk(q), why) for q, why in _seeds(arm, sc, rng, max_seeds, tally))


def _refuse_structural(arm: Arm, sc: Scenarios, seed: int) -> None:
    """Raise :class:`~.errors.StructurallyIntolerable` for a scenario intolerable everywhere."""
    structural = intolerable_everywhere(arm, sc)
    if structural:
        S = structural[0]
        k = [tuple(sc.name(T)) for T in sc.sets].index(S)
        J = arm.jacobian(arm.random_q(np.random.default_rng(seed)))
        raise StructurallyIntolerable(S, float(sc.pivots(projection(J).N)[k]), STRUCTURAL_SAMPLES)


def _horizon(task, sim_options: dict, horizon: float):
    """Simulation options that run at most ``horizon`` seconds of ``task``.

    With them ``(horizon, the task's length)`` when the cap acts, else ``None``.
    """
    if task is None:
        return sim_options, None
    duration = sim_options.get("duration") or task.duration
    if duration <= horizon:
        return sim_options, None
    return {**sim_options, "duration": horizon}, (float(horizon), float(duration))


def _choice(arm, q, point, sc, worst, origin, task, algorithms, tried, runs) -> StartChoice:
    J = arm.jacobian(q)
    k = condition_numbers(reduced_singular_values(J, sc))
    return StartChoice(
        q0=np.asarray(q, dtype=float),
        x0=np.asarray(point, dtype=float),
        K=float(k @ k),
        rcn_max=float(k.max()),
        run_rcn_max=worst if task is not None else float(k.max()),
        sigma_min=projection(J).sigma_min,
        origin=origin,
        algorithms=tuple(algorithms) if task is not None else (),
        tried=tried,
        runs=runs,
    )


#: Fixes of a refused start that are tried at most, proposed at most, and their time cap [s].
MAX_FIX_TRIALS = 8
MAX_FIXES = 2
FIX_TIME_CAP = 120.0
#: Seeds each fix's start search tries (fewer than :data:`MAX_SEEDS`: a cheaper search).
FIX_SEEDS = 2


@dataclass(frozen=True)
class FixTrial:
    """One fix tried by :func:`try_fixes`: its option text, whether a start passed, its cost [s]."""

    option: str
    works: bool
    seconds: float
    detail: str = ""


def try_fixes(
    fixes: Iterable[tuple[str, Callable[[], object]]],
    *,
    max_fixes: int = MAX_FIXES,
    max_trials: int = MAX_FIX_TRIALS,
    time_cap: float = FIX_TIME_CAP,
) -> list[FixTrial]:
    """Try each fix ``(option text, attempt)`` in order; the trials, those that work marked.

    ``attempt()`` re-runs the start search with the fix applied and raises a
    :class:`~.errors.FaultToleranceError` when no start passes. The trials stop after
    ``max_fixes`` fixes that work, ``max_trials`` fixes, or once ``time_cap`` seconds have passed
    (a trial under way is finished). Only fixes whose trial passed are to be proposed.
    """
    trials: list[FixTrial] = []
    t0 = time.monotonic()
    for option, attempt in fixes:
        if len(trials) == max_trials or sum(t.works for t in trials) == max_fixes:
            break
        if time.monotonic() - t0 > time_cap:
            break
        start = time.monotonic()
        try:
            attempt()
        except FaultToleranceError as err:
            detail = str(err).split("(", 1)[-1][:160]
            trials.append(FixTrial(option, False, time.monotonic() - start, detail))
        else:
            trials.append(FixTrial(option, True, time.monotonic() - start))
    return trials


def fixes_line(trials: Sequence[FixTrial], checked: float | None = None) -> str:
    """What the trials found, one line: the fixes that work (exact option text) and the cost.

    ``checked``: the seconds of a longer task each trial's start search checked, if it was capped.
    """
    if not trials:
        return "no fix was tried"
    cost = sum(t.seconds for t in trials)
    works = [t.option for t in trials if t.works]
    tried = f"{len(trials)} fix{'es' if len(trials) > 1 else ''} tried in {cost:.0f} s"
    if not works:
        return f"none of the {tried} finds a start ({'; '.join(t.option for t in trials)})"
    over = f" over the task's first {checked:g} s only" if checked else ""
    return (
        f"a start passes with {' or with '.join(works)} (that option set so, the others as given; "
        f"{tried}, each a start search{over})"
    )


_EXPLAINING = False


def explain_intolerable(
    arm: Arm, lockable, err: IntolerableFailure, *, x0=None, fallback_path=None, **start_options
) -> IntolerableFailure:
    """``err`` (a scenario intolerable at some start) as a structural or an at-this-start error.

    Structural (:class:`~.errors.StructurallyIntolerable`): the scenario is intolerable at every
    sampled configuration; no start helps. Otherwise (:class:`~.errors.IntolerableAtStart`) a start
    that works is proposed: :func:`default_start` for the same lockable joints, first at the same
    start point ``x0`` (other postures on its self-motion), then, if none works there, anywhere
    (with ``fallback_path``, a callable ``x0 -> TaskPath``, as the task to check). ``start_options``
    (``path``, ``algorithms``, simulation options) are passed on.
    """
    global _EXPLAINING
    if _EXPLAINING:  # the proposal's own checks never explain again
        return err
    joints = tuple(err.joints)
    if joints in intolerable_everywhere(arm, [joints]):
        return StructurallyIntolerable(joints, err.pivot, STRUCTURAL_SAMPLES)
    _EXPLAINING = True
    choice, where = None, ""
    try:
        if x0 is not None:
            choice, where = _try_start(arm, lockable, x0=x0, **start_options), "same start point"
        if choice is None:
            start_options["path"] = fallback_path
            choice = _try_start(arm, lockable, **start_options)
            where = "another start point"
    finally:
        _EXPLAINING = False
    why = "" if choice is None else f"{where}, tool at x0 = {np.round(choice.x0, 4).tolist()}"
    return IntolerableAtStart(
        joints, err.pivot, None if choice is None else choice.q0.tolist(), why
    )


def _try_start(arm, lockable, **options) -> StartChoice | None:
    try:
        return default_start(arm, lockable, **options)
    except FaultToleranceError:
        return None


def check_start(arm: Arm, sc: Scenarios, q0: np.ndarray, **explain_options) -> None:
    """Raise the explained error of :func:`explain_intolerable` if a scenario is intolerable at q0.

    ``explain_options`` go to :func:`explain_intolerable` (``x0``, ``path``, ``fallback_path``,
    ``algorithms``, simulation options) for the start it proposes.
    """
    try:
        sc.check_tolerable(projection(arm.jacobian(q0)).N)
    except IntolerableFailure as err:
        raise explain_intolerable(arm, sc, err, **explain_options) from None
