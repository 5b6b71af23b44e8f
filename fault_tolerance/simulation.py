"""Runs: integrate a resolver along a task path, with or without a joint locking on the way.

:func:`simulate` returns a :class:`~fault_tolerance.run.Run` (time histories and metadata; it
saves to and loads from a folder, see :mod:`fault_tolerance.run`).

Integration is explicit Euler, ``q ← q + q̇·dt`` (the paper: dt = 1 ms). Optional task-space
feedback ``ẋ_cmd = ẋ_des + K_p (x_des − x(q))`` keeps the drift bounded.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .arm import Arm
from .budget import check_run, run_samples
from .carried import arm_record
from .errors import InvalidInput
from .failures import Scenarios, scenarios
from .indices import RESPONSES, condition_numbers, post_failure_rates, reduced_singular_values
from .linalg import PIVOT_EPS, SIGMA_EPS, projection
from .bounded import NO_LIMIT, SCALE_TOL, bounded_least_norm, resolve_bounded
from .limits import arm_rate_box, post_failure_under_limits, velocity_limits, wrap_into_limits
from .planner import MDA_GAIN, RESOLVERS, resolve
from .run import (  # noqa: F401 - re-exported: Run, ARRAYS and the flags used to live here
    ARRAYS,
    FLAG_BOUND_ACTIVE,
    FLAG_INTOLERABLE_UNDER_LIMITS,
    FLAG_LOCKED,
    FLAG_NEAR_INTOLERABLE,
    FLAG_NEAR_SINGULAR,
    FLAG_OVER_SPEED,
    FLAG_SERVO_CLIPPED,
    FLAG_STEP_LIMITED,
    FLAG_TASK_SCALED,
    OPTIONAL_ARRAYS,
    Run,
    output_folder,
    write_atomic,
)
from .task_errors import angular_mask, error_norms
from .trajectories import TaskPath

#: Values of ``simulate(engine=...)``.
ENGINES = ("auto", "fast", "reference")
#: The whole-path planner's name (fault_tolerance.wholepath); not a per-step resolver.
GLOBAL = "global"
#: Every algorithm simulate runs: the resolvers and the global plan.
ALGORITHMS = (*RESOLVERS, GLOBAL)

#: Reduced robots whose smallest N[S, S] pivot falls below this are flagged near-intolerable; the
#: pivots are damped there (``linalg.PIVOT_EPS``), so JVJA's rates and λ stay finite.
NEAR_INTOLERABLE = PIVOT_EPS


#: Largest joint motion MDA's null-space step may make in one time step [rad]. Far from the
#: minimum-K start the gradient of K is steep (‖α N ∇K‖ of 10⁴ rad/s near singular reduced
#: Jacobians); an explicit Euler step that long leaves the self-motion manifold and loses the path.
#: The paper's runs stay below 1e-4 rad per step.
MDA_MAX_ANGLE = 0.01


# -- simulation -----------------------------------------------------------------------------


@dataclass(frozen=True)
class ServoModel:
    """Joint servos that follow commanded rates with a first-order lag.

    ``τ q̈ = q̇_cmd − q̇``, integrated exactly over one step
    (``q̇ ← q̇_cmd + (q̇ − q̇_cmd) e^{−dt/τ}``), with an optional acceleration limit [rad/s²].
    ``tau = 0`` is perfect rate tracking. A locked joint stops at once (a brake) and stays still.
    """

    tau: float = 0.05
    accel_limit: float = float("inf")

    def __post_init__(self) -> None:
        if not (self.tau >= 0 and np.isfinite(self.tau)):
            raise InvalidInput(f"servo tau must be finite and >= 0, got {self.tau}")
        if not self.accel_limit > 0:
            raise InvalidInput(f"servo accel_limit must be > 0, got {self.accel_limit}")

    def follow(self, qd: np.ndarray, qd_cmd: np.ndarray, dt: float) -> np.ndarray:
        """Actual rates one step later."""
        target = qd_cmd if self.tau == 0 else qd_cmd + (qd - qd_cmd) * np.exp(-dt / self.tau)
        if np.isfinite(self.accel_limit):
            step = self.accel_limit * dt
            target = qd + np.clip(target - qd, -step, step)
        return target

    def describe(self) -> str:
        """One line for reports."""
        lim = "" if not np.isfinite(self.accel_limit) else f", |q̈| <= {self.accel_limit} rad/s²"
        return f"first-order lag on commanded joint rates, tau = {self.tau} s{lim}; a locked joint stops at once"


def _check_time(dt: float, duration: float) -> int:
    steps = run_samples(dt, duration) - 1  # refuses non-finite times and too many samples
    if steps < 1:
        raise InvalidInput(
            f"dt = {dt} s is longer than the run ({duration} s); choose dt <= duration"
        )
    return steps


@dataclass(frozen=True)
class _Setup:
    """The validated inputs of one :func:`simulate` call."""

    arm: Arm
    path: TaskPath
    algorithm: str
    sc: Scenarios
    response: str
    dt: float
    duration: float
    steps: int
    feedback_gain: float
    gain: float
    lock_col: int | None
    lock_time: float | None
    servo: ServoModel
    max_step: float  # [rad/s], MDA's null-space step
    vmax: np.ndarray  # joint velocity limits, inf where none is given
    limits: bool = True  # honour the joint limits (rate box L1)
    horizon: float = 0.05  # [s] of the rate box, at least dt
    vlimit: np.ndarray | None = None  # velocity limits of the box, with the documented defaults
    reference: np.ndarray | None = None  # the global plan's configurations, tracked (W3)


@dataclass
class _State:
    """What changes from one step to the next."""

    q: np.ndarray
    qd: np.ndarray
    keep: np.ndarray  # the joints that still move
    locked: bool = False
    lock_jump: float | None = None


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
) -> Run:
    """Integrate ``algorithm`` along ``path`` from ``q0``; optionally lock a joint on the way.

    Args:
        arm: The arm.
        path: Task path with ``m`` coordinates, ``m`` = the arm's task size.
        algorithm: ``"lnva"``, ``"jvja"``, ``"mda"`` or ``"global"`` (the whole-path plan of
            :mod:`fault_tolerance.wholepath`, tracked in the null space, MATH.md (W3)).
        q0: Initial configuration, shape (n,). Required, except for ``"global"``: without it the
            global plan chooses its start on the self-motion of the path's first point.
        lockable: Joints that may lock (default: the arm's default lockable joints).
        weights: Scenario weights (default 1).
        response: Post-failure response, ``"least_norm"`` or ``"continuation"`` (MATH.md G3).
        dt: Time step [s] (paper: 1 ms).
        duration: Length [s] (default: the path's).
        feedback_gain: Task-space feedback ``K_p`` [1/s] (0: open loop, as in the paper).
        gain: MDA gain α.
        lock_joint: Joint that locks at ``lock_time``; from then on the reduced robot tracks the
            path with least-norm rates of the remaining joints (the paper's Sec. V).
        lock_time: When it locks [s].
        servo: Joint servo model; default perfect rate tracking (``tau = 0``) without a lock and
            :class:`ServoModel()` with one.
        progress: A callable ``progress(k, K)`` or a tqdm-like object with ``update``.
        engine: ``"auto"`` (default): the compiled sample (:mod:`.sampler`, the controller's
            workspace) where it applies, the reference code elsewhere (near singularities, at the
            lock, and under joint limits at the samples that meet a bound); ``"fast"``: the
            compiled sample or :class:`InvalidInput` saying why not; ``"reference"``: the plain
            reference code (:mod:`.planner`, :mod:`.indices`, :mod:`.bounded`) at every sample.
            The numbers agree to 1e-9.
        plan_options: Options of the global plan (``objective``, ``method``, ``limits``,
            ``rcn_max``, ``iterations``, ``dp_step``, ``dp_stage``; see
            :func:`fault_tolerance.wholepath.plan_path`); only with ``"global"``.
        limits: Honour the joint position and velocity limits (default): the rates of every step,
            before and after a lock, stay inside the rate box (L1) of ``Arm.rate_bounds``, the
            resolvers minimise their objectives inside it and scale the task when it is out of
            reach (docs/MATH.md "Joint limits"); ``q0`` must be inside the limits. ``False``:
            the paper's unconstrained formulation.
        horizon: Horizon of the rate box [s] (default ``bounded.RATE_HORIZON``; at least ``dt``).

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> from fault_tolerance.trajectories import CirclePath
        >>> arm = ft.load_arm("planar_3r")
        >>> path = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.05)
        >>> run = simulate(arm, path, "jvja", q0=np.array([0.3, 1.2, 1.0]))
        >>> ref = simulate(arm, path, "jvja", q0=np.array([0.3, 1.2, 1.0]), engine="reference")
        >>> bool(np.allclose(run.q, ref.q, rtol=0, atol=1e-12))
        True
    """
    if engine not in ENGINES:
        raise InvalidInput(f"engine {engine!r} is not one of {list(ENGINES)}")
    sim = dict(
        lockable=lockable, weights=weights, response=response, dt=dt, duration=duration,
        feedback_gain=feedback_gain, gain=gain, lock_joint=lock_joint, lock_time=lock_time,
        servo=servo, limits=limits, horizon=horizon,
    )  # fmt: skip
    if algorithm == GLOBAL:
        from .wholepath.run import simulate_global

        return simulate_global(
            arm, path, q0=q0, plan_options=plan_options, progress=progress, loop=_simulate, **sim
        )
    if plan_options is not None:
        raise InvalidInput(f"plan_options are options of algorithm 'global', not of '{algorithm}'")
    if q0 is None:
        raise InvalidInput(
            f"simulate needs q0 for algorithm '{algorithm}' (only 'global' chooses its own start)"
        )
    return _simulate(arm, path, algorithm, q0=q0, progress=progress, engine=engine, **sim)


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
) -> Run:
    """The loop of :func:`simulate`; with ``reference`` (the global plan) the rates track it."""
    setup = _setup(
        arm, path, "jvja" if reference is not None else algorithm, q0, lockable, weights,
        response, dt, duration, feedback_gain, gain, lock_joint, lock_time, servo, limits,
        horizon,
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
    from . import sampler

    # under joint limits the compiled sample is the bounded one while no bound is met; a sample
    # that meets a bound is solved the bounded reference way (bounded.resolve_bounded)
    why = sampler.covers(s.sc, s.algorithm, s.response, s.limits)
    if why is None:
        return sampler.Sampler(s, rec)
    if engine == "fast":
        raise InvalidInput(f"engine 'fast' does not cover this run: {why}; use engine='auto'")
    return None


def _setup(
    arm, path, algorithm, q0, lockable, weights, response, dt, duration, feedback_gain, gain,
    lock_joint, lock_time, servo, limits=True, horizon=None,
) -> _Setup:  # fmt: skip
    """Validate the options of :func:`simulate` (before any work)."""
    if algorithm not in RESOLVERS:
        raise InvalidInput(f"algorithm '{algorithm}' is not one of {list(ALGORITHMS)}")
    if path.m != arm.m:
        raise InvalidInput(
            f"the path has {path.m} coordinates, the task {'/'.join(arm.task)} has {arm.m}"
        )
    duration = path.duration if duration is None else float(duration)
    steps = _check_time(dt, duration)
    if not (np.isfinite(feedback_gain) and feedback_gain >= 0):
        raise InvalidInput(f"feedback gain must be finite and >= 0, got {feedback_gain}")
    arm.check_q(q0)
    sc = scenarios(
        arm.default_lockable if lockable is None else lockable,
        arm.n,
        r=arm.redundancy,
        weights=weights,
        joint_names=arm.joint_names,
    )
    check_run(dt, duration, arm.n, arm.m, sc.f)  # the arrays fit, before they are allocated
    lock_col = None
    if lock_joint is not None:
        lock_col = arm.joint_index(lock_joint)
        if lock_time is None or not np.isfinite(lock_time) or not 0 <= lock_time <= duration:
            raise InvalidInput(f"lock time must be within [0, {duration}] s, got {lock_time}")
        servo = servo or ServoModel()
    servo = servo or ServoModel(tau=0.0)
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {list(RESPONSES)}")
    vmax = arm.velocity_limit
    vmax = np.where(np.isfinite(vmax) & (vmax > 0), vmax, np.inf)  # 0 or inf: no limit given
    h = _check_limits(arm, q0, limits, horizon, dt)
    return _Setup(
        arm, path, algorithm, sc, response, dt, duration, steps, feedback_gain, gain, lock_col,
        lock_time, servo, MDA_MAX_ANGLE / dt, vmax, bool(limits), h, velocity_limits(arm),
    )  # fmt: skip


#: The histories a run records per sample, in the order of the run table's columns.
HISTORIES = ("q", "qd", "qd_cmd", "x", "x_des", "error", "jvj", "jvj_parts", "rcn", "K",
             "sigma_min", "flags")  # fmt: skip


_SCALARS = ("error", "jvj", "K", "sigma_min", "flags")  # one number per sample


def _widths(n: int, m: int, f: int) -> dict[str, int]:
    sizes = {"q": n, "qd": n, "qd_cmd": n, "x": m, "x_des": m, "jvj_parts": f, "rcn": f}
    return {h: 1 if h in _SCALARS else sizes[h] for h in HISTORIES}


def _check_limits(arm, q0, limits, horizon, dt) -> float:
    """The rate box's horizon (at least ``dt``); with limits on, ``q0`` must be inside them."""
    from .bounded import RATE_HORIZON
    from .limits import outside_limits, wrap_into_limits

    h = RATE_HORIZON if horizon is None else float(horizon)
    if not (np.isfinite(h) and h > 0):
        raise InvalidInput(f"horizon must be finite and > 0 [s], got {horizon}")
    out = np.flatnonzero(outside_limits(arm, wrap_into_limits(arm, arm.check_q(q0))))
    if limits and len(out):
        names = [arm.joint_names[i] for i in out]
        raise InvalidInput(
            f"q0 is outside the joint limits at {names} (limits "
            f"{[(float(arm.lower[i]), float(arm.upper[i])) for i in out]}); start inside them, "
            "or run without limits (limits=False, --no-limits)"
        )
    return max(h, dt)


def _allocate(K1: int, n: int, m: int, f: int, dt: float) -> dict[str, np.ndarray]:
    """The time histories of a run of ``K1`` samples, zero-filled: views of one table.

    ``rec["_table"]`` (K1, width) holds them all, ``rec["_offsets"]`` the first column of each
    (in the order of :data:`HISTORIES`), so a compiled sample writes one row.
    """
    widths = _widths(n, m, f)
    offsets = np.cumsum([0] + [widths[h] for h in HISTORIES])
    table = np.zeros((K1, int(offsets[-1])))
    rec = {"t": np.arange(K1) * dt, "_table": table, "_offsets": offsets[:-1].astype(np.int64)}
    for h, lo in zip(HISTORIES, offsets[:-1], strict=True):
        view = table[:, lo : lo + widths[h]]
        rec[h] = view[:, 0] if h in _SCALARS else view
    return rec


def sample_path(path: TaskPath, ts: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(x_des, ẋ_des)`` of the path at the times ``ts``, shape (K, m) each, checked finite.

    Uses the path's own ``sample(ts)`` when it has one (:class:`~.trajectories.CirclePath`).
    """
    if hasattr(path, "sample"):
        X, XD = path.sample(ts)
    else:
        X = np.array([np.asarray(path.x(t), dtype=float).reshape(-1) for t in ts])
        XD = np.array([np.asarray(path.xdot(t), dtype=float).reshape(-1) for t in ts])
    bad = ~(np.all(np.isfinite(X), axis=-1) & np.all(np.isfinite(XD), axis=-1))
    if X.shape != (len(ts), m) or XD.shape != (len(ts), m) or bad.any():
        k = int(np.argmax(bad)) if bad.any() else 0
        x, xd = np.asarray(path.x(ts[k])), np.asarray(path.xdot(ts[k]), dtype=float)
        raise InvalidInput(
            f"the path gives x = {x.tolist()}, ẋ = {xd.tolist()} "
            f"at t = {ts[k]:.6g} s; it must give {m} finite numbers each"
        )
    return X, XD


def _maybe_lock(s: _Setup, state: _State, t: float) -> None:
    """Lock the joint when its time has come (it stops at once: a brake)."""
    if s.lock_col is not None and not state.locked and t >= s.lock_time - 1e-12:
        state.locked = True
        state.keep = np.array([j for j in range(s.arm.n) if j != s.lock_col])
        state.qd[s.lock_col] = 0.0


def _step(s: _Setup, state: _State, k: int, rec: dict, x_des, xd_des) -> None:
    """One sample the reference way: rates at ``q``, indices, record, then ``q ← q + q̇ dt``."""
    arm, q = s.arm, state.q
    J = arm.jacobian(q)
    x, err = arm.fk_and_error(x_des, q)
    xd_cmd = xd_des + s.feedback_gain * err
    proj = projection(J)
    flag = FLAG_NEAR_SINGULAR if proj.sigma_min < SIGMA_EPS else 0
    planned = None
    box = arm_rate_box(arm, q, s.horizon) if s.limits else None
    if s.reference is not None and (not state.locked or state.lock_jump is None):
        planned = _tracking_rates(s, k, q, J, xd_cmd, proj)
        if box is not None:  # the plan's rates, nearest inside the box (L4 with that target)
            sol = bounded_least_norm(J, xd_cmd, box[0], box[1], target=planned, proj=proj)
            planned = sol.qd
            if not state.locked:
                flag |= _box_flags(sol.active, sol.scale)
    elif not state.locked or state.lock_jump is None:
        opts = dict(response=s.response, arm=arm, q=q, gain=s.gain, tolerate=True,
                    max_step=s.max_step, proj=proj)  # fmt: skip
        if box is None:
            planned = resolve(s.algorithm, J, xd_cmd, s.sc, **opts)
        else:
            res = resolve_bounded(s.algorithm, J, xd_cmd, s.sc, bounds=box, **opts)
            planned = res.qd
            if not state.locked:
                flag |= _box_flags(res.active, res.scale)
    if state.locked:
        qd_cmd, lflag = _locked_rates(s, state, J, xd_cmd, planned, box)
        flag = lflag
    else:
        qd_cmd = planned
        if (
            s.algorithm == "mda"
            and np.linalg.norm(qd_cmd - proj.Jpinv @ xd_cmd) >= 0.999 * s.max_step
        ):
            flag |= FLAG_STEP_LIMITED
    if np.any(np.abs(qd_cmd) > s.vmax):
        flag |= FLAG_OVER_SPEED
    k_s = condition_numbers(reduced_singular_values(J, s.sc))
    if state.locked:
        parts = np.zeros(s.sc.f)  # the failure has happened; no jump is pending
    else:
        parts, near = _jump_parts(s, proj, J, xd_cmd, qd_cmd, box)
        flag |= near
    state.qd = qd_cmd.copy() if k == 0 else s.servo.follow(state.qd, qd_cmd, s.dt)
    if state.locked:
        state.qd[s.lock_col] = 0.0
    if box is not None:
        flag |= _clip_to_limits(s, q, state.qd)
    _record(rec, k, q, state.qd, qd_cmd, x, x_des, err, parts, k_s, proj.sigma_min, flag)
    state.q = q + state.qd * s.dt


def _locked_rates(s: _Setup, state: _State, J, xd_cmd, planned, box=None) -> tuple[np.ndarray, int]:
    """Least-norm rates of the reduced robot (inside the box (L4) with limits), its flags; the
    jump the lock causes, once."""
    qd_cmd = np.zeros(s.arm.n)
    keep = state.keep
    reduced = projection(J[:, keep])
    flag = FLAG_LOCKED | (FLAG_NEAR_SINGULAR if reduced.sigma_min < SIGMA_EPS else 0)
    if box is None:
        qd_cmd[keep] = reduced.Jpinv @ xd_cmd
    else:
        sol = bounded_least_norm(J[:, keep], xd_cmd, box[0][keep], box[1][keep], proj=reduced)
        qd_cmd[keep] = sol.qd
        flag |= _box_flags(sol.active, sol.scale)
    if state.lock_jump is None:  # the jump the lock causes: reduced rates minus planned rates
        state.lock_jump = float(np.sum((qd_cmd - planned) ** 2))
    return qd_cmd, flag


def _jump_parts(s: _Setup, proj, J, xd_cmd, qd_cmd, box=None) -> tuple[np.ndarray, int]:
    """The jump the planned rates would suffer if a scenario happened now, eq. (9)/(10).

    With limits, against what each reduced robot does inside the box (L4)-(L5)."""
    sc = s.sc
    flag = FLAG_NEAR_INTOLERABLE if sc.pivots(proj.N).min() < NEAR_INTOLERABLE else 0
    if box is None:
        post = post_failure_rates(proj.Jpinv @ xd_cmd, proj.N, sc, qd_cmd, s.response, damp=True)
    else:
        post, scales = post_failure_under_limits(
            J, xd_cmd, qd_cmd, sc, box[0], box[1], s.response, tolerate=True
        )
        if np.any(scales < 1.0 - SCALE_TOL):
            flag |= FLAG_INTOLERABLE_UNDER_LIMITS
    return sc.weights * np.einsum("fn,fn->f", post - qd_cmd, post - qd_cmd), flag


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


def _box_flags(active: np.ndarray, scale: float) -> int:
    """FLAG_BOUND_ACTIVE / FLAG_TASK_SCALED of a bounded solution."""
    return (FLAG_BOUND_ACTIVE if active.any() else 0) | (
        FLAG_TASK_SCALED if scale < 1.0 - SCALE_TOL else 0
    )


def _clip_to_limits(s: _Setup, q: np.ndarray, qd: np.ndarray) -> int:
    """Keep the executed step inside the limits: a servo that lags its (in-box) command may not
    carry a joint past a position limit or over its velocity limit; FLAG_SERVO_CLIPPED if so."""
    arm = s.arm
    lo = np.where(np.abs(arm.lower) < NO_LIMIT, (arm.lower - q) / s.dt, -np.inf)
    hi = np.where(np.abs(arm.upper) < NO_LIMIT, (arm.upper - q) / s.dt, np.inf)
    v = s.vlimit
    lo, hi = np.maximum(lo, -v), np.minimum(hi, v)
    clipped = np.clip(qd, lo, hi)
    changed = bool(np.any(np.abs(clipped - qd) > 1e-12))
    qd[...] = clipped
    return FLAG_SERVO_CLIPPED if changed else 0


def _record(rec, k, q, qd, qd_cmd, x, x_des, err, parts, k_s, sigma_min, flag) -> None:
    """Sample ``k`` of the time histories."""
    rec["q"][k] = q
    rec["qd"][k] = qd
    rec["qd_cmd"][k] = qd_cmd
    rec["x"][k] = x
    rec["x_des"][k] = x_des
    rec["error"][k] = np.linalg.norm(err)
    rec["jvj_parts"][k] = parts
    rec["jvj"][k] = parts.sum()
    rec["rcn"][k] = k_s
    rec["K"][k] = k_s @ k_s
    rec["sigma_min"][k] = sigma_min
    rec["flags"][k] = flag


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
        "mda_gain": s.gain if s.algorithm == "mda" else None,
        "q0": np.asarray(q0, dtype=float).tolist(),
        "path": s.path.spec(),
        "servo": s.servo.describe() if servo_used else "perfect rate tracking",
        "limits": _limits_meta(s),
    }
    if s.lock_col is not None:
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


# MATH.md (W3): the plan's reference tracked in the null space; J q̇ = ẋ_cmd whatever the reference.
def _tracking_rates(s: _Setup, k: int, q, J, xd_cmd, proj) -> np.ndarray:
    """``J⁺ẋ_cmd + N (q_ref[k+1] − q)/dt``; past the reference's end, JVJA's rates."""
    if k + 1 < len(s.reference):
        return proj.Jpinv @ xd_cmd + proj.N @ ((s.reference[k + 1] - q) / s.dt)
    return resolve("jvja", J, xd_cmd, s.sc, tolerate=True, proj=proj)


def _tick(progress, k: int, total: int) -> None:
    if progress is None:
        return
    if hasattr(progress, "update"):
        progress.update(1)
    else:
        progress(k, total)
