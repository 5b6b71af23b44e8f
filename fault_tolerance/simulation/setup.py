"""What a run starts from, and the table it fills.

The validated options of :func:`~fault_tolerance.simulation.simulate.simulate`, the servo model, the state
from one sample to the next, and the run table the samples fill.

:func:`_setup` validates every option before any work (a clear :class:`InvalidInput` naming the
problem); :func:`_allocate` lays out the time histories as views of one table, in the order of
:data:`HISTORIES`, so a compiled sample (:mod:`fault_tolerance.simulation.fast.sample`) writes one row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.model.joint_limits import velocity_limits
from fault_tolerance.resolution.indices import RESPONSES
from fault_tolerance.resolution.registry import get
from fault_tolerance.resolution.scenarios import Scenarios, scenarios
from fault_tolerance.simulation.paths import TaskPath
from fault_tolerance.storage.budget import check_run, run_samples

#: The whole-path planner's name (fault_tolerance.planning.wholepath); not a per-step resolver.
GLOBAL = "global"
#: The resolver a tracked path plan hands over to past its end (and whose setup it validates).
TRACKED_PAST_PLAN = "jvja"

#: Largest joint motion MDA's null-space step may make in one time step [rad]. Far from the
#: minimum-K start the gradient of K is steep (‖α N ∇K‖ of 10⁴ rad/s near singular reduced
#: Jacobians); an explicit Euler step that long leaves the self-motion manifold and loses the path.
#: The paper's runs stay below 1e-4 rad per step.
MDA_MAX_ANGLE = 0.01


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
    options: dict | None = None  # the resolver's validated options, by name (every step)
    user_options: dict | None = None  # those given by simulate(options=...), for the record


@dataclass
class _State:
    """What changes from one step to the next."""

    q: np.ndarray
    qd: np.ndarray
    keep: np.ndarray  # the joints that still move
    locked: bool = False
    lock_jump: float | None = None


def _setup(
    arm, path, algorithm, q0, lockable, weights, response, dt, duration, feedback_gain, gain,
    lock_joint, lock_time, servo, limits=True, horizon=None, options=None,
) -> _Setup:  # fmt: skip
    """Validate the options of :func:`simulate` (before any work)."""
    entry = get(algorithm)
    if limits and entry.bounded is None:
        raise InvalidInput(
            f"resolver '{algorithm}' has no bounded variant: it cannot honour the joint limits; "
            "run it with limits=False (--no-limits)"
        )
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
    run = {"response": response, "gain": gain, "max_step": MDA_MAX_ANGLE / dt}
    owned = {"weights": "simulate(weights=...)", "response": "simulate(response=...)"}
    opts = entry.options_with(options, run, owned)  # one it does not take raises
    cap = opts.get("max_step", run["max_step"])  # the compiled sample's cap of MDA's step
    return _Setup(
        arm, path, algorithm, sc, response, dt, duration, steps, feedback_gain,
        float(opts.get("gain", gain)), lock_col, lock_time, servo,
        np.inf if cap is None else float(cap), vmax, bool(limits), h, velocity_limits(arm),
        options=opts, user_options=dict(options or {}),
    )  # fmt: skip


#: The histories a run records per sample, in the order of the run table's columns.
HISTORIES = ("q", "qd", "qd_cmd", "x", "x_des", "error", "jvj", "jvj_parts", "rcn", "K",
             "sigma_min", "flags")  # fmt: skip


_SCALARS = ("error", "jvj", "K", "sigma_min", "flags")  # one number per sample


def _widths(n: int, m: int, f: int) -> dict[str, int]:
    sizes = {"q": n, "qd": n, "qd_cmd": n, "x": m, "x_des": m, "jvj_parts": f, "rcn": f}
    return {h: 1 if h in _SCALARS else sizes[h] for h in HISTORIES}


def _check_limits(arm, q0, limits, horizon, dt) -> float:
    """The rate box's horizon (at least ``dt``), after ``q0`` is checked as a start.

    ``q0`` in radians, inside the limits when they are on
    (:func:`~fault_tolerance.model.joint_limits.check_start`).
    """
    from fault_tolerance.model.joint_limits import RATE_HORIZON, check_start

    h = RATE_HORIZON if horizon is None else float(horizon)
    if not (np.isfinite(h) and h > 0):
        raise InvalidInput(f"horizon must be finite and > 0 [s], got {horizon}")
    check_start(arm, q0, limits)
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
    if s.lock_col is None or s.lock_time is None:  # no lock in this run
        return
    if not state.locked and t >= s.lock_time - 1e-12:
        state.locked = True
        state.keep = np.array([j for j in range(s.arm.n) if j != s.lock_col])
        state.qd[s.lock_col] = 0.0
