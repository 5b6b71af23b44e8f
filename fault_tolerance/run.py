"""The result of a run: time histories, flags, metadata; saved to and loaded from a folder.

A :class:`Run` holds the time histories (configuration, rates, task position and error, the
square-sum jump λ(t) with its per-scenario parts, the reduced condition numbers and K(t)) and a
``meta`` dict that says how it was made. It saves to and loads from a folder with ``run.npz``,
``run.csv`` and ``summary.json``, each written atomically (:mod:`.files`).
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InvalidInput
from .files import output_folder, to_json, write_atomic

__all__ = [
    "ARRAYS",
    "FLAG_LOCKED",
    "FLAG_NEAR_INTOLERABLE",
    "FLAG_NEAR_SINGULAR",
    "FLAG_OVER_SPEED",
    "FLAG_STEP_LIMITED",
    "OPTIONAL_ARRAYS",
    "Run",
    "output_folder",
    "write_atomic",
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
OPTIONAL_ARRAYS = ("qd_cmd", "orientation_error")

#: Bits of ``Run.flags``.
FLAG_NEAR_SINGULAR = (
    1  # σ_min(J) (after a lock: of the remaining columns) < SIGMA_EPS: rates damped
)
FLAG_NEAR_INTOLERABLE = 2  # a scenario's N[S, S] pivot < NEAR_INTOLERABLE: pivots damped
FLAG_LOCKED = 4  # the arm runs with a locked joint
FLAG_STEP_LIMITED = 8  # MDA's null-space step was capped at MDA_MAX_ANGLE / dt
FLAG_OVER_SPEED = 16  # a commanded joint rate exceeds the joint's velocity limit (URDF <limit>)


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
        orientation_error: Orientation error of the task's angular rows [rad] (with all three:
            the angle of the remaining rotation), shape (K,); None without angular rows.
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
    orientation_error: np.ndarray | None = None

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

    def _orientation_summary(self) -> dict:
        """``orientation_error_max`` / ``_final`` [rad] for tasks with angular rows, else nothing."""
        if self.orientation_error is None:
            return {}
        return {
            "orientation_error_max": float(np.max(self.orientation_error)),
            "orientation_error_final": float(self.orientation_error[-1]),
        }

    # -- files -------------------------------------------------------------------------------
    def save(self, folder: str | Path, *, warnings: list[dict] | None = None) -> Path:
        """Write ``run.npz``, ``run.csv`` and ``summary.json`` into ``folder`` (atomically).

        ``warnings``: what :func:`fault_tolerance.diagnostics.check_run` found (``as_dict()`` of
        each), recorded in summary.json under ``"warnings"`` (absent when not checked).
        """
        folder = output_folder(folder)
        arrays = {k: getattr(self, k) for k in ARRAYS}
        arrays.update(
            {k: getattr(self, k) for k in OPTIONAL_ARRAYS if getattr(self, k) is not None}
        )
        buf = io.BytesIO()
        np.savez_compressed(buf, meta=np.array(to_json(self.meta)), **arrays)
        write_atomic(folder / "run.npz", buf.getvalue())
        write_atomic(folder / "run.csv", self.to_csv())
        record = {"meta": self.meta, "summary": self.summary()}
        if warnings is not None:
            record["warnings"] = list(warnings)
        write_atomic(folder / "summary.json", to_json(record))
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
