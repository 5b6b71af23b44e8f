"""Runs: integrate a resolver along a task path, with or without a joint locking on the way.

A :class:`Run` holds the time histories (configuration, rates, task position and error, the
square-sum jump λ(t) with its per-scenario parts, the reduced condition numbers and K(t)) and a
``meta`` dict that says how it was made. It saves to and loads from a folder with ``run.npz``,
``run.csv`` and ``summary.json``, each written atomically.

Integration is explicit Euler, ``q ← q + q̇·dt`` (the paper: dt = 1 ms). Optional task-space
feedback ``ẋ_cmd = ẋ_des + K_p (x_des − x(q))`` keeps the drift bounded.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .arm import Arm
from .errors import InvalidInput
from .failures import scenarios
from .indices import RESPONSES, condition_numbers, post_failure_rates, reduced_singular_values
from .linalg import PIVOT_EPS, SIGMA_EPS, projection
from .planner import MDA_GAIN, RESOLVERS, resolve
from .trajectories import TaskPath

#: Reduced robots whose smallest N[S, S] pivot falls below this are flagged near-intolerable; the
#: pivots are damped there (``linalg.PIVOT_EPS``), so JVJA's rates and λ stay finite.
NEAR_INTOLERABLE = PIVOT_EPS


# -- atomic files ---------------------------------------------------------------------------


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder and ``os.replace``.

    A reader never sees a half-written file, and an interrupted write leaves the old file intact.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def output_folder(path: str | Path) -> Path:
    """``path`` as a folder that exists and can be written to, or :class:`InvalidInput` saying why."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InvalidInput(f"{path}: exists and is not a folder; choose a folder for the output")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InvalidInput(f"{path}: cannot create the output folder ({err.strerror})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InvalidInput(f"{path}: the output folder is not writable")
    return path


def _json(obj) -> str:
    return json.dumps(obj, indent=2, default=_to_builtin) + "\n"


def _to_builtin(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


# -- the run --------------------------------------------------------------------------------

ARRAYS = (
    "t",
    "q",
    "qd",
    "x",
    "x_des",
    "error",
    "jvj",
    "jvj_parts",
    "rcn",
    "K",
    "sigma_min",
    "flags",
)
OPTIONAL_ARRAYS = ("qd_cmd",)

#: Bits of ``Run.flags``.
FLAG_NEAR_SINGULAR = (
    1  # σ_min(J) (after a lock: of the remaining columns) < SIGMA_EPS: rates damped
)
FLAG_NEAR_INTOLERABLE = 2  # a scenario's N[S, S] pivot < NEAR_INTOLERABLE: pivots damped
FLAG_LOCKED = 4  # the arm runs with a locked joint
FLAG_STEP_LIMITED = 8  # MDA's null-space step was capped at MDA_MAX_ANGLE / dt
FLAG_OVER_SPEED = 16  # a commanded joint rate exceeds the joint's velocity limit (URDF <limit>)

#: Largest joint motion MDA's null-space step may make in one time step [rad]. Far from the
#: minimum-K start the gradient of K is steep (‖α N ∇K‖ of 10⁴ rad/s near singular reduced
#: Jacobians); an explicit Euler step that long leaves the self-motion manifold and loses the path.
#: The paper's runs stay below 1e-4 rad per step.
MDA_MAX_ANGLE = 0.01


@dataclass
class Run:
    """Time histories of one run (K samples, n joints, m task rows, f scenarios) and its metadata.

    Attributes:
        t: Times [s], shape (K,).
        q: Joint positions [rad], shape (K, n).
        qd: Joint rates [rad/s] (actual), shape (K, n).
        x: Task position of the tip, shape (K, m).
        x_des: Desired task position, shape (K, m).
        error: Task-space error ``‖x − x_des‖`` [m], shape (K,).
        jvj: Square-sum joint velocity jump λ(t), eq. (9)/(10) [(rad/s)²], shape (K,).
        jvj_parts: Its per-scenario parts ``w_S ‖ˢq̇' − q̇‖²``, shape (K, f).
        rcn: Reduced condition numbers, eq. (15), shape (K, f).
        K: Square-sum RCN ``Σ k_S²``, shape (K,).
        sigma_min: Smallest singular value of J, shape (K,).
        flags: Bit flags per sample (:data:`FLAG_NEAR_SINGULAR`, ...), shape (K,).
        meta: How the run was made (robot, algorithm, dt, path, lockable joints, lock, ...).
        qd_cmd: Commanded rates when a servo model is used, shape (K, n), else None.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    x: np.ndarray
    x_des: np.ndarray
    error: np.ndarray
    jvj: np.ndarray
    jvj_parts: np.ndarray
    rcn: np.ndarray
    K: np.ndarray
    sigma_min: np.ndarray
    flags: np.ndarray
    meta: dict = field(default_factory=dict)
    qd_cmd: np.ndarray | None = None

    # -- summary -----------------------------------------------------------------------------
    def summary(self) -> dict:
        """Scalar results: λ and K statistics, tracking error, flags, lock figures."""
        s = {
            "jvj_mean": float(np.mean(self.jvj)),
            "jvj_max": float(np.max(self.jvj)),
            "rcn_mean": float(np.mean(self.K)),
            "rcn_max": float(np.max(self.K)),
            "tracking_error_max": float(np.max(self.error)),
            "tracking_error_final": float(self.error[-1]),
            "near_singular_samples": int(np.count_nonzero(self.flags & FLAG_NEAR_SINGULAR)),
            "near_intolerable_samples": int(np.count_nonzero(self.flags & FLAG_NEAR_INTOLERABLE)),
            "step_limited_samples": int(np.count_nonzero(self.flags & FLAG_STEP_LIMITED)),
            "over_speed_samples": int(np.count_nonzero(self.flags & FLAG_OVER_SPEED)),
        }
        lock = self.meta.get("lock")
        if lock:
            after = self.t >= lock["time"]
            before = ~after
            s["path_error_peak_after_lock"] = (
                float(np.max(self.error[after])) if after.any() else 0.0
            )
            s["path_error_max_before_lock"] = (
                float(np.max(self.error[before])) if before.any() else 0.0
            )
            s["jump_at_lock"] = lock.get("jump")
        return s

    # -- files -------------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """Write ``run.npz``, ``run.csv`` and ``summary.json`` into ``folder`` (atomically)."""
        folder = output_folder(folder)
        arrays = {k: getattr(self, k) for k in ARRAYS}
        arrays.update(
            {k: getattr(self, k) for k in OPTIONAL_ARRAYS if getattr(self, k) is not None}
        )
        buf = io.BytesIO()
        np.savez_compressed(buf, meta=np.array(_json(self.meta)), **arrays)
        write_atomic(folder / "run.npz", buf.getvalue())
        write_atomic(folder / "run.csv", self.to_csv())
        write_atomic(folder / "summary.json", _json({"meta": self.meta, "summary": self.summary()}))
        return folder

    @classmethod
    def load(cls, folder: str | Path) -> Run:
        """Read a run saved by :meth:`save` (a folder or its ``run.npz``)."""
        path = Path(folder)
        if path.is_dir():
            path = path / "run.npz"
        if not path.is_file():
            raise InvalidInput(f"{path}: no saved run here (expected a folder with run.npz)")
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files if k != "meta"}
                meta = json.loads(str(z["meta"]))
        except (OSError, ValueError, KeyError) as err:
            raise InvalidInput(f"{path}: not a readable run file ({err})") from err
        missing = [k for k in ARRAYS if k not in arrays]
        if missing:
            raise InvalidInput(f"{path}: run file lacks arrays {missing}")
        return cls(meta=meta, **arrays)

    def to_csv(self) -> str:
        """One row per sample: t, q_*, qd_*, x_*, x_des_*, error, jvj, K, flags."""
        joints = self.meta.get("joint_names") or [f"j{i}" for i in range(self.q.shape[1])]
        rows = self.meta.get("task") or [f"x{i}" for i in range(self.x.shape[1])]
        header = (
            ["t"]
            + [f"q_{j}" for j in joints]
            + [f"qd_{j}" for j in joints]
            + [f"x_{r}" for r in rows]
            + [f"xdes_{r}" for r in rows]
            + ["error", "jvj", "K", "flags"]
        )
        table = np.column_stack(
            [self.t, self.q, self.qd, self.x, self.x_des, self.error, self.jvj, self.K, self.flags]
        )
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        for row in table:
            w.writerow([f"{v:.10g}" for v in row])
        return out.getvalue()


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
    if not (np.isfinite(dt) and dt > 0):
        raise InvalidInput(f"dt must be a finite number > 0, got {dt}")
    if not (np.isfinite(duration) and duration > 0):
        raise InvalidInput(f"duration must be a finite number > 0, got {duration}")
    steps = int(round(duration / dt))
    if steps < 1:
        raise InvalidInput(
            f"dt = {dt} s is longer than the run ({duration} s); choose dt <= duration"
        )
    return steps


def simulate(
    arm: Arm,
    path: TaskPath,
    algorithm: str = "jvja",
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
) -> Run:
    """Integrate ``algorithm`` along ``path`` from ``q0``; optionally lock a joint on the way.

    Args:
        arm: The arm.
        path: Task path with ``m`` coordinates, ``m`` = the arm's task size.
        algorithm: ``"lnva"``, ``"jvja"`` or ``"mda"``.
        q0: Initial configuration, shape (n,).
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
    """
    if algorithm not in RESOLVERS:
        raise InvalidInput(f"algorithm '{algorithm}' is not one of {sorted(RESOLVERS)}")
    if path.m != arm.m:
        raise InvalidInput(
            f"the path has {path.m} coordinates, the task {'/'.join(arm.task)} has {arm.m}"
        )
    duration = path.duration if duration is None else float(duration)
    steps = _check_time(dt, duration)
    if not (np.isfinite(feedback_gain) and feedback_gain >= 0):
        raise InvalidInput(f"feedback gain must be finite and >= 0, got {feedback_gain}")
    q = arm.check_q(q0).copy()
    sc = scenarios(
        arm.default_lockable if lockable is None else lockable,
        arm.n,
        r=arm.redundancy,
        weights=weights,
        joint_names=arm.joint_names,
    )
    lock_col = None
    if lock_joint is not None:
        lock_col = arm.joint_index(lock_joint)
        if lock_time is None or not np.isfinite(lock_time) or not 0 <= lock_time <= duration:
            raise InvalidInput(f"lock time must be within [0, {duration}] s, got {lock_time}")
        servo = servo or ServoModel()
    servo = servo or ServoModel(tau=0.0)
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {list(RESPONSES)}")
    # an intolerable scenario is refused before any work; later, a path through a reduced
    # singularity gets damped pivots and FLAG_NEAR_INTOLERABLE instead of an exception
    sc.check_tolerable(projection(arm.jacobian(q)).N)
    f, n, m = sc.f, arm.n, arm.m
    max_step = MDA_MAX_ANGLE / dt  # [rad/s], MDA's null-space step
    vmax = arm.velocity_limit
    vmax = np.where(np.isfinite(vmax) & (vmax > 0), vmax, np.inf)  # 0 or inf: no limit given
    K1 = steps + 1
    rec = {
        "t": np.arange(K1) * dt,
        "q": np.zeros((K1, n)),
        "qd": np.zeros((K1, n)),
        "qd_cmd": np.zeros((K1, n)),
        "x": np.zeros((K1, m)),
        "x_des": np.zeros((K1, m)),
        "error": np.zeros(K1),
        "jvj": np.zeros(K1),
        "jvj_parts": np.zeros((K1, f)),
        "rcn": np.zeros((K1, f)),
        "K": np.zeros(K1),
        "sigma_min": np.zeros(K1),
        "flags": np.zeros(K1, dtype=np.int64),
    }
    qd = np.zeros(n)
    keep = np.arange(n)
    locked = False
    lock_jump = None
    for k in range(K1):
        t = k * dt
        if lock_col is not None and not locked and t >= lock_time - 1e-12:
            locked = True
            keep = np.array([j for j in range(n) if j != lock_col])
            qd[lock_col] = 0.0
        J = arm.jacobian(q)
        x_des = path.x(t)
        xd_des = np.asarray(path.xdot(t), dtype=float)
        if not (
            np.all(np.isfinite(x_des)) and xd_des.shape == (m,) and np.all(np.isfinite(xd_des))
        ):
            raise InvalidInput(
                f"the path gives x = {np.asarray(x_des).tolist()}, ẋ = {xd_des.tolist()} "
                f"at t = {t:.6g} s; it must give {m} finite numbers each"
            )
        x, err = arm.fk_and_error(x_des, q)
        xd_cmd = xd_des + feedback_gain * err
        proj = projection(J)
        flag = FLAG_NEAR_SINGULAR if proj.sigma_min < SIGMA_EPS else 0
        planned = None
        if not locked or lock_jump is None:
            planned = resolve(
                algorithm,
                J,
                xd_cmd,
                sc,
                response=response,
                arm=arm,
                q=q,
                gain=gain,
                tolerate=True,
                max_step=max_step,
                proj=proj,
            )
        if locked:
            qd_cmd = np.zeros(n)
            reduced = projection(J[:, keep])
            qd_cmd[keep] = reduced.Jpinv @ xd_cmd
            flag = FLAG_LOCKED | (FLAG_NEAR_SINGULAR if reduced.sigma_min < SIGMA_EPS else 0)
            if lock_jump is None:  # the jump the lock causes: reduced rates minus planned rates
                lock_jump = float(np.sum((qd_cmd - planned) ** 2))
        else:
            qd_cmd = planned
            if (
                algorithm == "mda"
                and np.linalg.norm(qd_cmd - proj.Jpinv @ xd_cmd) >= 0.999 * max_step
            ):
                flag |= FLAG_STEP_LIMITED
        if np.any(np.abs(qd_cmd) > vmax):
            flag |= FLAG_OVER_SPEED
        k_s = condition_numbers(reduced_singular_values(J, sc))
        if locked:
            parts = np.zeros(f)  # the failure has happened; no jump is pending
        else:
            # the jump the planned rates would suffer if a scenario happened now, eq. (9)/(10)
            if sc.pivots(proj.N).min() < NEAR_INTOLERABLE:
                flag |= FLAG_NEAR_INTOLERABLE
            post = post_failure_rates(proj.Jpinv @ xd_cmd, proj.N, sc, qd_cmd, response, damp=True)
            parts = sc.weights * np.einsum("fn,fn->f", post - qd_cmd, post - qd_cmd)
        qd = qd_cmd.copy() if k == 0 else servo.follow(qd, qd_cmd, dt)
        if locked:
            qd[lock_col] = 0.0
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
        rec["sigma_min"][k] = proj.sigma_min
        rec["flags"][k] = flag
        q = q + qd * dt
        _tick(progress, k, K1)
    meta = {
        "robot": arm.name,
        "source": arm.source,
        "package_dirs": arm.package_dirs,
        "tip": arm.tip,
        "task": list(arm.task),
        "joint_names": arm.joint_names,
        "algorithm": algorithm,
        "lockable": [[arm.joint_names[i] for i in S] for S in sc.sets],
        "weights": sc.weights.tolist(),
        "response": response,
        "dt": dt,
        "duration": duration,
        "feedback_gain": feedback_gain,
        "mda_gain": gain if algorithm == "mda" else None,
        "q0": np.asarray(q0, dtype=float).tolist(),
        "path": path.spec(),
        "servo": servo.describe()
        if (lock_col is not None or servo.tau > 0)
        else "perfect rate tracking",
    }
    if lock_col is not None:
        meta["lock"] = {
            "joint": arm.joint_names[lock_col],
            "index": lock_col,
            "time": float(lock_time),
            "jump": lock_jump,
        }
    qd_cmd_arr = rec.pop("qd_cmd") if (lock_col is not None or servo.tau > 0) else None
    rec.pop("qd_cmd", None)
    return Run(meta=meta, qd_cmd=qd_cmd_arr, **rec)


def _tick(progress, k: int, total: int) -> None:
    if progress is None:
        return
    if hasattr(progress, "update"):
        progress.update(1)
    else:
        progress(k, total)
