"""The result of a run: time histories, flags, metadata; saved to and loaded from a folder.

A :class:`Run` holds the time histories (configuration, rates, task position and error, the
square-sum jump λ(t) with its per-scenario parts, the reduced condition numbers and K(t)) and a
``meta`` dict that says how it was made. It saves to and loads from a folder with ``run.npz``,
``run.csv`` and ``summary.json``, whole or not at all (:mod:`.results`): written aside, recorded,
moved into place; a load verifies the record and checks the file as untrusted (:mod:`.runfile`).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.atomic import to_json
from fault_tolerance.storage.result_folder import staged_folder, verify_folder
from fault_tolerance.storage.run_file import read_run_file

__all__ = [
    "ARRAYS",
    "FLAG_BOUND_ACTIVE",
    "FLAG_INTOLERABLE_UNDER_LIMITS",
    "FLAG_LOCKED",
    "FLAG_NEAR_INTOLERABLE",
    "FLAG_NEAR_SINGULAR",
    "FLAG_OVER_SPEED",
    "FLAG_SERVO_CLIPPED",
    "FLAG_STEP_LIMITED",
    "FLAG_TASK_SCALED",
    "OPTIONAL_ARRAYS",
    "Run",
]

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
OPTIONAL_ARRAYS = ("qd_cmd", "orientation_error", "tau", "tau_cmd")
#: Files a run folder may hold (an older run's folder with only these may be replaced).
RUN_FILES = frozenset(
    {"run.npz", "run.csv", "summary.json", "run.png", "run.svg", "lock.png", "lock.svg",
     "replay.html"}
)  # fmt: skip

#: Bits of ``Run.flags``.
FLAG_NEAR_SINGULAR = (
    1  # σ_min(J) (after a lock: of the remaining columns) < SIGMA_EPS: rates damped
)
FLAG_NEAR_INTOLERABLE = 2  # a scenario's N[S, S] pivot < NEAR_INTOLERABLE: pivots damped
FLAG_LOCKED = 4  # the arm runs with a locked joint
FLAG_STEP_LIMITED = 8  # MDA's null-space step was capped at MDA_MAX_ANGLE / dt
FLAG_OVER_SPEED = 16  # a commanded joint rate exceeds the joint's velocity limit (URDF <limit>)
FLAG_BOUND_ACTIVE = 32  # joint limits on: a joint's commanded rate is held at its rate box (L1)
FLAG_TASK_SCALED = 64  # joint limits on: the task velocity was scaled to stay inside the box (L3)
FLAG_INTOLERABLE_UNDER_LIMITS = 128  # a lock now would leave a robot that cannot keep the task (L5)
FLAG_SERVO_CLIPPED = 256  # joint limits on: the servo's rate was clipped at a position limit


@dataclass
class Run:
    """Time histories of one run (K samples, n joints, m task rows, f scenarios) and its metadata.

    Attributes:
        t: Times [s], shape (K,).
        q: Joint positions [rad], shape (K, n).
        qd: Joint rates [rad/s] (actual), shape (K, n).
        x: Task position of the tip, shape (K, m).
        x_des: Desired task position, shape (K, m).
        error: Position error ``‖p − p_des‖`` of the task's linear rows [m], shape (K,) (pose
            tasks: the orientation error is apart, never added; no linear rows: zeros).
        jvj: Square-sum joint velocity jump λ(t), eq. (9)/(10) [(rad/s)²], shape (K,).
        jvj_parts: Its per-scenario parts ``w_S ‖ˢq̇' − q̇‖²``, shape (K, f).
        rcn: Reduced condition numbers, eq. (15), shape (K, f).
        K: Square-sum RCN ``Σ k_S²``, shape (K,).
        sigma_min: Smallest singular value of J, shape (K,).
        flags: Bit flags per sample (:data:`FLAG_NEAR_SINGULAR`, ...), shape (K,).
        meta: How the run was made (robot, algorithm, dt, path, lockable joints, lock, ...).
        qd_cmd: Commanded rates when a servo model is used, shape (K, n), else None.
        arm_record: The arm the run was made with (:func:`~.carried.arm_record`: checked URDF
            text, tip, task, joints), so that a replay needs no file named in the run.
        orientation_error: Orientation error of the task's angular rows [rad] (with all three:
            the angle of the remaining rotation), shape (K,); None without angular rows.
        tau: Applied joint torques [N·m] of a dynamics run (after saturation), shape (K, n).
        tau_cmd: Commanded torques [N·m] of a dynamics run (before saturation), shape (K, n).
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
    arm_record: dict | None = None
    orientation_error: np.ndarray | None = None
    tau: np.ndarray | None = None
    tau_cmd: np.ndarray | None = None

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
            **self._orientation_summary(),
            "near_singular_samples": int(np.count_nonzero(self.flags & FLAG_NEAR_SINGULAR)),
            "near_intolerable_samples": int(np.count_nonzero(self.flags & FLAG_NEAR_INTOLERABLE)),
            "step_limited_samples": int(np.count_nonzero(self.flags & FLAG_STEP_LIMITED)),
            "over_speed_samples": int(np.count_nonzero(self.flags & FLAG_OVER_SPEED)),
            **self._limit_counts(),
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
        s.update(self._dynamics_summary())
        return s

    def _dynamics_summary(self) -> dict:
        """A dynamics run's torque figures (docs/dynamics.md); nothing for a kinematic run."""
        dyn = self.meta.get("dynamics")
        if not dyn or self.tau is None or self.tau_cmd is None:
            return {}
        effort = np.array([np.inf if e is None else e for e in dyn["effort"]], dtype=float)
        ratio = np.abs(self.tau) / effort  # 0 where no limit is given
        lock = dyn.get("lock") or {}
        return {
            "torque_max": float(np.max(np.abs(self.tau))),
            "torque_peak_ratio": float(np.max(ratio)) if np.isfinite(effort).any() else None,
            "torque_saturated_samples": int(
                np.count_nonzero((np.abs(self.tau_cmd) > effort * (1 + 1e-12)).any(axis=1))
            ),
            "torque_jump_max": lock.get("torque_jump_max"),
            "lock_impulse": lock.get("impulse"),
            "kinetic_energy_jump": lock.get("kinetic_energy_jump"),
        }

    def _orientation_summary(self) -> dict:
        """``orientation_error_max`` / ``_final`` [rad] for tasks with angular rows, else nothing."""
        if self.orientation_error is None:
            return {}
        return {
            "orientation_error_max": float(np.max(self.orientation_error)),
            "orientation_error_final": float(self.orientation_error[-1]),
        }

    def _limit_counts(self) -> dict:
        """Samples with an active bound / a scaled task, and (measured) outside the limits."""
        lim = self.meta.get("limits") or {}
        out = {
            "limits": bool(lim.get("enabled", False)),
            "bound_active_samples": int(np.count_nonzero(self.flags & FLAG_BOUND_ACTIVE)),
            "task_scaled_samples": int(np.count_nonzero(self.flags & FLAG_TASK_SCALED)),
            "intolerable_under_limits_samples": int(
                np.count_nonzero(self.flags & FLAG_INTOLERABLE_UNDER_LIMITS)
            ),
            "servo_clipped_samples": int(np.count_nonzero(self.flags & FLAG_SERVO_CLIPPED)),
        }
        if "lower" in lim:  # measured on the recorded q and q̇, whether limits were on or not
            lo = np.array([-np.inf if x is None else x for x in lim["lower"]], dtype=float)
            hi = np.array([np.inf if x is None else x for x in lim["upper"]], dtype=float)
            v = np.array([np.inf if x is None else x for x in lim["velocity"]], dtype=float)
            tol = 1e-9
            out["outside_position_limits_samples"] = int(
                np.count_nonzero(((self.q < lo - tol) | (self.q > hi + tol)).any(axis=1))
            )
            out["over_velocity_limit_samples"] = int(
                np.count_nonzero((np.abs(self.qd) > v + tol).any(axis=1))
            )
        return out

    # -- files -------------------------------------------------------------------------------
    def save(
        self,
        folder: str | Path,
        extras: Callable[[Path], None] | None = None,
        *,
        warnings: list[dict] | None = None,
    ) -> Path:
        """Write the run into ``folder``, whole or not at all (:func:`~.results.staged_folder`).

        ``run.npz`` (arrays, ``meta`` and the carried arm), ``run.csv`` and ``summary.json`` are
        written into a staging folder, then ``extras(staging)`` may add files that belong with the
        run (plots, a replay page); the completion record is written last and the folder moved
        into place. An existing run there is replaced whole; the folder is locked meanwhile.
        ``warnings``: what :func:`fault_tolerance.simulation.diagnostics.check_run` found (``as_dict()`` of
        each), recorded in summary.json under ``"warnings"`` (absent when not checked).
        """
        folder = Path(folder)
        with staged_folder(folder, replaceable=RUN_FILES) as tmp:
            self.write(tmp, warnings=warnings)
            if extras is not None:
                extras(tmp)
        return folder

    def write(self, folder: Path, *, warnings: list[dict] | None = None) -> None:
        """The run's files into an existing ``folder`` (no staging; :meth:`save` stages)."""
        arrays = {k: getattr(self, k) for k in ARRAYS}
        arrays.update(
            {k: getattr(self, k) for k in OPTIONAL_ARRAYS if getattr(self, k) is not None}
        )
        if self.arm_record is not None:
            arrays["arm"] = np.array(json.dumps(self.arm_record))
        buf = io.BytesIO()
        np.savez_compressed(buf, meta=np.array(to_json(self.meta)), **arrays)
        (folder / "run.npz").write_bytes(buf.getvalue())
        (folder / "run.csv").write_text(self.to_csv(), encoding="utf-8")
        record: dict[str, object] = {"meta": self.meta, "summary": self.summary()}
        if warnings is not None:
            record["warnings"] = list(warnings)
        (folder / "summary.json").write_text(to_json(record), encoding="utf-8")

    @classmethod
    def load(cls, folder: str | Path) -> Run:
        """Read a run saved by :meth:`save` (a folder or its ``run.npz``), checked as untrusted.

        The folder must be whole (its completion record matches ``run.npz``); sizes, shapes,
        types and metadata are checked before use (:func:`~.runfile.read_run_file`). Any problem
        is one line of :class:`~.errors.FaultToleranceError`.
        """
        path = Path(folder)
        if path.name == "run.npz" and not path.is_dir():
            path = path.parent
        if not (path / "run.npz").is_file():
            raise InvalidInput(f"{path}: no saved run here (expected a folder with run.npz)")
        verify_folder(path, files=["run.npz"])
        arrays, meta, arm = read_run_file(path / "run.npz", ARRAYS)
        return cls(meta=meta, arm_record=arm, **arrays)

    def to_csv(self) -> str:
        """One row per sample: t, q_*, qd_*, x_*, x_des_*, error, jvj, K, flags.

        ``error`` is the position error [m]; tasks with angular rows add ``orientation_error``
        [rad] after it.
        """
        joints = self.meta.get("joint_names") or [f"j{i}" for i in range(self.q.shape[1])]
        rows = self.meta.get("task") or [f"x{i}" for i in range(self.x.shape[1])]
        ori = [] if self.orientation_error is None else [self.orientation_error]
        header = (
            ["t"]
            + [f"q_{j}" for j in joints]
            + [f"qd_{j}" for j in joints]
            + [f"x_{r}" for r in rows]
            + [f"xdes_{r}" for r in rows]
            + ["error"]
            + ["orientation_error"] * len(ori)
            + ["jvj", "K", "flags"]
        )
        table = np.column_stack(
            [self.t, self.q, self.qd, self.x, self.x_des, self.error, *ori, self.jvj, self.K]
            + [self.flags]
        )
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        for row in table:
            w.writerow([f"{v:.10g}" for v in row])
        return out.getvalue()
