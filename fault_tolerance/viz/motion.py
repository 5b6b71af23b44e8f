"""What is replayed: a run's joint positions over time, checked, and the frames that show them.

A run comes as a :class:`~fault_tolerance.simulation.run.Run`, the folder it was saved to, an array of
joint positions (K, n) with a time step, or a pair ``(t, q)``; :func:`_load_motion` turns each into
a :class:`_Motion`. The replay shows it every ``1/fps`` replay seconds, ``speed`` run seconds per
replay second (:func:`_frame_times`), interpolating between the run's samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.model.arm_record import arm_of_run
from fault_tolerance.simulation.run import Run
from fault_tolerance.storage.budget import check_frames


@dataclass
class _Motion:
    """Joint positions over time and what to draw with them."""

    t: np.ndarray  # [s], shape (K,)
    q: np.ndarray  # [rad], shape (K, n)
    x_des: np.ndarray | None  # desired task position, shape (K, m)
    lock: dict | None  # {"joint", "index", "time"}
    meta: dict = field(default_factory=dict)


def _load_motion(
    run, arm: Arm | None, dt: float | None, package_dirs: Sequence[str | Path] = ()
) -> tuple[_Motion, Arm]:
    """A :class:`_Motion` and its arm from a Run, a run folder, an array of q or a pair (t, q).

    A run's arm is rebuilt from the record it carries (:func:`~..carried.arm_of_run`), never from
    a file named in it.
    """
    where = str(run) if isinstance(run, (str, Path)) else "the run"
    if isinstance(run, (str, Path)):
        run = Run.load(run)
    if isinstance(run, Run):
        if arm is None:
            arm = arm_of_run(run, package_dirs, where=where)
        motion = _Motion(
            np.asarray(run.t, dtype=float),
            np.asarray(run.q, dtype=float),
            np.asarray(run.x_des, dtype=float),
            run.meta.get("lock"),
            dict(run.meta),
        )
        names = run.meta.get("joint_names")
        if names and list(names) != list(arm.joint_names):
            raise InvalidInput(
                f"the run was made with joints {list(names)}, the arm has {arm.joint_names}; "
                "pass the arm the run was made with"
            )
    else:
        if arm is None:
            raise InvalidInput("replaying an array of joint positions needs the arm (arm=...)")
        if isinstance(run, tuple) and len(run) == 2:
            t, q = (np.asarray(a, dtype=float) for a in run)
        else:
            q = np.asarray(run, dtype=float)
            if dt is None or not (np.isfinite(dt) and dt > 0):
                raise InvalidInput(
                    f"an array of joint positions needs a time step dt > 0, got {dt}"
                )
            t = np.arange(len(q)) * float(dt)
        if q.ndim != 2 or t.shape != (len(q),) or len(q) < 1:
            raise InvalidInput(
                f"q must have shape (K, n) with K times; got q {q.shape}, t {t.shape}"
            )
        motion = _Motion(t, q, None, None, {"robot": arm.name})
    if motion.q.ndim != 2 or motion.q.shape[1] != arm.n:
        raise InvalidInput(
            f"q has shape {motion.q.shape}; {arm.name} needs ({len(motion.t)}, {arm.n}) "
            f"for joints {arm.joint_names}"
        )
    if not (np.all(np.isfinite(motion.q)) and np.all(np.isfinite(motion.t))):
        raise InvalidInput("the run's times and joint positions must be finite")
    if len(motion.t) > 1 and np.any(np.diff(motion.t) <= 0):
        raise InvalidInput("the run's times must increase strictly")
    return motion, arm


def _check_rate(speed: float, fps: float) -> tuple[float, float]:
    speed, fps = float(speed), float(fps)
    if not (np.isfinite(speed) and speed > 0):
        raise InvalidInput(f"speed must be a finite number > 0, got {speed}")
    if not (np.isfinite(fps) and 0 < fps <= 240):
        raise InvalidInput(f"fps must be within (0, 240], got {fps}")
    return speed, fps


def _frame_times(t: np.ndarray, speed: float, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Replay times ``tau`` [s] every ``1/fps`` and the run times ``t0 + tau·speed`` they show."""
    span = float(t[-1] - t[0])
    check_frames(span, speed, fps)  # before allocating: --speed 1e-9 would be 10¹¹ frames
    length = span / speed
    count = max(1, int(math.ceil(length * fps - 1e-9)))
    tau = np.minimum(np.arange(count + 1) / fps, length)
    return tau, t[0] + tau * speed


def _interp_rows(t_new: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    if len(t) == 1:
        return np.repeat(values[:1], len(t_new), axis=0)
    return np.column_stack([np.interp(t_new, t, values[:, j]) for j in range(values.shape[1])])
