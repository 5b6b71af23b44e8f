"""Runs: integrate a resolver along a task path, with or without a joint locking on the way.

:func:`simulate` returns a :class:`~fault_tolerance.simulation.run.Run` (time histories and metadata; it
saves to and loads from a folder, see :mod:`fault_tolerance.simulation.run`).

Integration is explicit Euler, ``q ← q + q̇·dt`` (the paper: dt = 1 ms). Optional task-space
feedback ``ẋ_cmd = ẋ_des + K_p (x_des − x(q))`` keeps the drift bounded. A run flows from its
validated options (:mod:`fault_tolerance.simulation.setup`) through one sample after another (the compiled
sample of :mod:`fault_tolerance.simulation.fast.sampler`, or the reference one of
:mod:`fault_tolerance.simulation.reference_step`) to the :class:`Run` built here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import cast

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.model.arm_record import arm_record
from fault_tolerance.model.joint_limits import NO_LIMIT, wrap_into_limits
from fault_tolerance.model.task_errors import angular_mask, error_norms
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.resolution.mda import MDA_GAIN
from fault_tolerance.resolution.registry import get, names
from fault_tolerance.simulation.paths import TaskPath
from fault_tolerance.simulation.reference_step import _step
from fault_tolerance.simulation.run import (
    Run,
)
from fault_tolerance.simulation.setup import (
    GLOBAL,
    HISTORIES,
    TRACKED_PAST_PLAN,
    ServoModel,
    _allocate,
    _maybe_lock,
    _Setup,
    _setup,
    _State,
    sample_path,
)
from fault_tolerance.simulation.torque import as_model, track

#: Values of ``simulate(engine=...)``.
ENGINES = ("auto", "fast", "reference")
#: Whole-path planners by algorithm name: ``f(arm, path, *, q0, plan_options, progress, loop, **sim)``
#: returning a :class:`Run`. The planning layer registers ``"global"``
#: (:mod:`fault_tolerance.planning.wholepath.run`), which sits above this one.
PATH_PLANNERS: dict[str, Callable[..., Run]] = {}
#: How plots and the replay page show a path planner: ``(colour, label)``, registered with it.
PATH_PLANNER_STYLES: dict[str, tuple[str, str]] = {}


def algorithms() -> tuple[str, ...]:
    """Every algorithm :func:`simulate` runs: the registered resolvers, then the path planners."""
    return (*names(), *PATH_PLANNERS)


def algorithm_style(algorithm: str | None) -> tuple[str, str] | None:
    """``(colour, label)`` of an algorithm for plots and the replay page; None if unknown."""
    name = str(algorithm or "").lower()
    if name in PATH_PLANNER_STYLES:
        return PATH_PLANNER_STYLES[name]
    if name in names():
        entry = get(name)
        return entry.colour, entry.label
    return None


def option_names(algorithm: str) -> tuple[str, ...]:
    """The ``options=`` :func:`simulate` takes for ``algorithm`` (a path planner: none)."""
    if algorithm in PATH_PLANNERS:
        return ()
    if algorithm not in names():
        raise InvalidInput(f"algorithm {algorithm!r} is not one of {list(algorithms())}")
    return get(algorithm).option_names


def options_for(algorithm: str, options: dict | None) -> dict | None:
    """The part of ``options`` that ``algorithm`` takes (several algorithms share one set)."""
    if not options:
        return None
    own = option_names(algorithm)
    return {k: v for k, v in options.items() if k in own} or None


def simulate(
    arm: Arm,
    path: TaskPath,
    algorithm: str = "jvja",
    *,
    q0: np.ndarray | None = None,
    lockable=None,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    dt: float = 1e-3,
    duration: float | None = None,
    feedback_gain: float = 0.0,
    gain: float = MDA_GAIN,
    lock_joint: str | int | None = None,
    lock_time: float | None = None,
    servo: ServoModel | None = None,
    progress=None,
    engine: str = "auto",
    plan_options: dict | None = None,
    limits: bool = True,
    horizon: float | None = None,
    options: dict | None = None,
    dynamics=None,
) -> Run:
    """Integrate ``algorithm`` along ``path`` from ``q0``; optionally lock a joint on the way.

    Args:
        arm: The arm.
        path: Task path with the arm's ``m`` coordinates.
        algorithm: One of :func:`algorithms`: a registered resolver (``"lnva"``, ``"jvja"``,
            ``"mda"``, ...) or ``"global"`` (the whole-path plan, tracked in the null space, (W3)).
        q0: Initial configuration, shape (n,). Required, except for ``"global"``: without it the
            global plan chooses its start on the self-motion of the path's first point.
        lockable: Joints that may lock (default: the arm's default lockable joints).
        weights: Scenario weights (default 1).
        response: Post-failure response, ``"least_norm"`` or ``"continuation"`` (MATH.md G3).
        dt: Time step [s] (paper: 1 ms).
        duration: Length [s] (default: the path's).
        feedback_gain: Task-space feedback ``K_p`` [1/s] (0: open loop, as in the paper).
        gain: MDA gain α.
        lock_joint: Joint that locks; then the remaining joints track the path (Sec. V).
        lock_time: When it locks [s].
        servo: Joint servo model; default perfect rate tracking (``tau = 0``) without a lock and
            :class:`ServoModel()` with one.
        progress: A callable ``progress(k, K)`` or a tqdm-like object with ``update``.
        engine: ``"auto"`` (default): the compiled sample (:mod:`.sampler`) where it applies;
            ``"fast"``: that or :class:`InvalidInput` saying why not; ``"reference"``: the plain
            code (:mod:`.reference_step`) at every sample. The numbers agree to 1e-9.
        plan_options: Options of the global plan (see :func:`fault_tolerance.planning.wholepath.plan.plan_path`);
            only with ``"global"``.
        limits: Honour the joint position and velocity limits (default): every step, before and
            after a lock, stays inside the rate box (L1), the resolvers minimise their objectives
            inside it and scale the task out of reach (docs/MATH.md "Joint limits"); ``q0`` must
            be inside the limits. ``False``: the paper's unconstrained formulation.
        horizon: Horizon of the rate box [s] (default ``bounded.RATE_HORIZON``; at least ``dt``).
        options: The resolver's own options by name (its options dataclass; ``response`` and
            ``gain`` fill those of the same name unless given here); an unknown one raises.
        dynamics: ``True`` or a :class:`~.torque.DynamicsModel`: the plan tracked by computed
            torques, the lock a brake (docs/dynamics.md); not with ``servo``; adds ``tau``, ``tau_cmd``.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> from fault_tolerance.simulation.paths import CirclePath
        >>> arm = ft.load_arm("planar_3r")
        >>> path = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.05)
        >>> run = simulate(arm, path, "jvja", q0=np.array([0.3, 1.2, 1.0]))
        >>> ref = simulate(arm, path, "jvja", q0=np.array([0.3, 1.2, 1.0]), engine="reference")
        >>> bool(np.allclose(run.q, ref.q, rtol=0, atol=1e-12))
        True
    """
    q0 = _check_call(arm, engine, algorithm, plan_options, q0, options)
    sim = dict(
        lockable=lockable, weights=weights, response=response, dt=dt, duration=duration,
        feedback_gain=feedback_gain, gain=gain, lock_joint=lock_joint, lock_time=lock_time,
        servo=servo, limits=limits, horizon=horizon,
    )  # fmt: skip
    route = dict(progress=progress, engine=engine, plan_options=plan_options, options=options)
    if (model := as_model(dynamics)) is not None:  # a torque-level run
        return _dynamics_run(arm, path, algorithm, model, sim, q0, route)
    return _route(arm, path, algorithm, sim, q0, **route)


def _route(arm, path, algorithm, sim, q0, *, progress, engine, plan_options, options) -> Run:
    """A kinematic run: a whole-path planner, or the loop of the step resolvers."""
    if algorithm in PATH_PLANNERS:
        return PATH_PLANNERS[algorithm](
            arm, path, q0=q0, plan_options=plan_options, progress=progress, loop=_simulate, **sim
        )
    q0 = cast(np.ndarray, q0)  # not None: _check_call refused that
    sim = dict(sim, progress=progress, engine=engine, options=options)
    return _simulate(arm, path, algorithm, q0=q0, **sim)


def _dynamics_run(arm, path, algorithm, model, sim, q0, route: dict) -> Run:
    """A torque-level run: the kinematic plan with perfect rate tracking, tracked by torques."""
    if sim["servo"] is not None:
        raise InvalidInput(
            "servo and dynamics exclude each other: a dynamics run models the joints by their "
            "torques (drop servo=..., or dynamics=...)"
        )
    sim = dict(sim, servo=ServoModel(tau=0.0))
    plan = _route(arm, path, algorithm, sim, q0, **route)
    return track(arm, plan, model)


def _check_call(arm, engine: str, algorithm: str, plan_options, q0, options=None):
    """The options of :func:`simulate` that decide the route, checked before any work; ``q0``."""
    if engine not in ENGINES:
        raise InvalidInput(f"engine {engine!r} is not one of {list(ENGINES)}")
    if q0 is not None:
        q0 = arm.check_q(q0, "q0")
    if algorithm == GLOBAL and GLOBAL not in PATH_PLANNERS:
        raise InvalidInput(
            f"algorithm '{GLOBAL}' needs the whole-path planner: import fault_tolerance"
        )
    if algorithm in PATH_PLANNERS:
        if options:
            raise InvalidInput(
                f"options are a step resolver's; '{algorithm}' takes plan_options instead"
            )
        return q0
    if algorithm not in names():
        raise InvalidInput(f"algorithm {algorithm!r} is not one of {list(algorithms())}")
    if plan_options is not None:
        raise InvalidInput(f"plan_options are options of algorithm 'global', not of '{algorithm}'")
    if q0 is None:
        raise InvalidInput(
            f"simulate needs q0 for algorithm '{algorithm}' (only 'global' chooses its own start)"
        )
    return q0


def _simulate(
    arm: Arm,
    path: TaskPath,
    algorithm: str,
    *,
    q0: np.ndarray,
    lockable=None,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    dt: float = 1e-3,
    duration: float | None = None,
    feedback_gain: float = 0.0,
    gain: float = MDA_GAIN,
    lock_joint: str | int | None = None,
    lock_time: float | None = None,
    servo: ServoModel | None = None,
    progress=None,
    reference: np.ndarray | None = None,
    engine: str = "auto",
    limits: bool = True,
    horizon: float | None = None,
    options: dict | None = None,
) -> Run:
    """The loop of :func:`simulate`; with ``reference`` (the global plan) the rates track it."""
    setup = _setup(
        arm, path, TRACKED_PAST_PLAN if reference is not None else algorithm, q0, lockable,
        weights, response, dt, duration, feedback_gain, gain, lock_joint, lock_time, servo,
        limits, horizon, options,
    )  # fmt: skip
    if reference is not None:
        setup = replace(setup, algorithm=algorithm, reference=np.asarray(reference, dtype=float))
    q = arm.check_q(q0).copy()
    if setup.limits:  # full-turn joints read modulo 2π: the same posture, inside the limits
        q = wrap_into_limits(arm, q)
    # an intolerable scenario is refused before any work; later, a path through a reduced
    # singularity gets damped pivots and FLAG_NEAR_INTOLERABLE instead of an exception
    setup.sc.check_tolerable(projection(arm.jacobian(q)).N)
    K1 = setup.steps + 1
    rec = _allocate(K1, arm.n, arm.m, setup.sc.f, dt)
    X, XD = sample_path(path, rec["t"], arm.m)
    state = _State(q=q, qd=np.zeros(arm.n), keep=np.arange(arm.n))
    # the compiled sample knows the resolvers, not the tracking of a global plan's reference
    fast = None if reference is not None else _sampler(setup, rec, engine)
    for k in range(K1):
        _maybe_lock(setup, state, k * dt)
        if fast is None or not fast.step(state, k, X[k], XD[k]):
            _step(setup, state, k, rec, X[k], XD[k])
        _tick(progress, k, K1)
    return _finish(setup, state, rec, rec["q"][0] if setup.limits else q0)


def _sampler(s: _Setup, rec: dict, engine: str):
    """The compiled sample of :mod:`.sampler` for this run, or None for the reference code."""
    if engine == "reference":
        return None
    from fault_tolerance.simulation.fast import sampler

    # under joint limits the compiled sample is the bounded one while no bound is met; a sample
    # that meets a bound is solved the bounded reference way (bounded.resolve_bounded)
    why = sampler.covers(s.sc, s.algorithm, s.response, s.limits)
    if why is None:
        return sampler.Sampler(s, rec)
    if engine == "fast":
        raise InvalidInput(f"engine 'fast' does not cover this run: {why}; use engine='auto'")
    return None


def _finish(s: _Setup, state: _State, rec: dict, q0) -> Run:
    """The :class:`Run`: time histories and how it was made."""
    arm, sc = s.arm, s.sc
    servo_used = s.lock_col is not None or s.servo.tau > 0
    meta = {
        "robot": arm.name,
        "source": arm.source,
        "package_dirs": arm.package_dirs,
        "xacro_args": arm.xacro_args,
        "tip": arm.tip,
        "task": list(arm.task),
        "joint_names": arm.joint_names,
        "algorithm": s.algorithm,
        "lockable": [[arm.joint_names[i] for i in S] for S in sc.sets],
        "weights": sc.weights.tolist(),
        "response": s.response,
        "dt": s.dt,
        "duration": s.duration,
        "feedback_gain": s.feedback_gain,
        "mda_gain": s.gain if "gain" in (s.options or {}) else None,
        "q0": np.asarray(q0, dtype=float).tolist(),
        "path": s.path.spec(),
        "servo": s.servo.describe() if servo_used else "perfect rate tracking",
        "limits": _limits_meta(s),
    }
    if s.user_options:  # a resolver's own options, as given (absent: its defaults)
        meta["options"] = dict(s.user_options)
    if s.lock_col is not None and s.lock_time is not None:
        meta["lock"] = {
            "joint": arm.joint_names[s.lock_col],
            "index": s.lock_col,
            "time": float(s.lock_time),
            "jump": state.lock_jump,
        }
    arrays = {k: np.ascontiguousarray(rec[k]) for k in ("t", *HISTORIES)}
    arrays["flags"] = arrays["flags"].astype(np.int64)
    qd_cmd = arrays.pop("qd_cmd")
    if angular_mask(arm.task).any():  # metres and radians apart, never added (docs/MATH.md)
        err = np.array(
            [arm.task_error(xd, q) for xd, q in zip(arrays["x_des"], arrays["q"], strict=True)]
        )
        arrays["error"], arrays["orientation_error"] = error_norms(arm.task, err)
    return Run(
        meta=meta,
        qd_cmd=qd_cmd if servo_used else None,
        arm_record=arm_record(arm),
        **arrays,
    )


def _limits_meta(s: _Setup) -> dict:
    """What the run knew of the joint limits (JSON: ``None`` where a limit is absent)."""
    arm = s.arm

    def listed(x):
        return [float(v) if np.isfinite(v) and abs(v) < NO_LIMIT else None for v in x]

    return {
        "enabled": s.limits,
        "horizon": s.horizon,
        "lower": listed(arm.lower),
        "upper": listed(arm.upper),
        "velocity": listed(s.vlimit),
    }


def _tick(progress, k: int, total: int) -> None:
    if progress is None:
        return
    if hasattr(progress, "update"):
        progress.update(1)
    else:
        progress(k, total)
