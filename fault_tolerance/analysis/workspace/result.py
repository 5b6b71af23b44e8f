"""The result of a workspace sweep: masks, maps, areas or volumes, and how it is saved."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fault_tolerance.storage.result_folder import staged_folder

#: Files of a saved workspace (an existing result with these is replaced whole).
WORKSPACE_FILES = ("workspace.json", "workspace.npz", "workspace.png")
#: Entries of a workspace folder that live beside the result: the sweeps' finished chunks.
CHUNKS = ("chunks-*",)

DEFINITION = (
    "FTW(A) = W(A) ∩ ⋂_{i∈F} ⋂_{θ∈[lo_i,hi_i]} W_i(θ): reachable with q in the artificial limits "
    "A, and after joint i of F locks at any θ in [lo_i, hi_i] still reachable by the other joints "
    "within their physical (URDF) limits"
)


@dataclass(frozen=True)
class Workspace:
    """Masks and maps on a grid of task points (axes: one array per task coordinate).

    ``pre`` is W(A), ``ftw`` the failure-tolerant workspace, ``locks[k]`` the points that survive
    any lock of the k-th lockable joint; ``jump`` [(rad/s)² per (m/s)²] and ``rcn`` are the smallest
    direction-averaged JVJA jump and square-sum RCN on the self-motion (NaN outside W(A)).
    ``cell`` is the area [m²] or volume [m³] of one grid cell.
    """

    spec: dict
    axes: tuple
    pre: np.ndarray
    ftw: np.ndarray
    locks: np.ndarray
    jump: np.ndarray
    rcn: np.ndarray
    cell: float
    definition: str
    error: str

    @property
    def spatial(self) -> bool:
        """True for a 3-D (position task) grid."""
        return len(self.axes) == 3

    @property
    def size_pre(self) -> float:
        """Area [m²] or volume [m³] of W(A)."""
        return float(self.pre.sum() * self.cell)

    @property
    def size_ftw(self) -> float:
        """Area [m²] or volume [m³] of the failure-tolerant workspace."""
        return float(self.ftw.sum() * self.cell)

    @property
    def area_pre(self) -> float:
        """Area of W(A) [m²] (planar tasks)."""
        return self.size_pre

    @property
    def area_ftw(self) -> float:
        """Area of the failure-tolerant workspace [m²] (planar tasks)."""
        return self.size_ftw

    def summary(self) -> dict:
        """The ``workspace.json`` record."""
        s = self.spec
        unit = "volume" if self.spatial else "area"
        out = {
            "robot": s["robot"]["source"],
            "tip": s["robot"]["tip"],
            "task": s["robot"]["task"],
            "joints": s["robot"]["joints"],
            "lockable": s["lockable"],
            "limits": s["limits"],
            "grid": s["grid"],
            "method": s["method"],
            f"{unit}_pre": self.size_pre,
            f"{unit}_ftw": self.size_ftw,
            f"{unit}_unit": "m^3" if self.spatial else "m^2",
            "cell": self.cell,
            f"{unit}_tolerant_per_joint": {
                j: float((self.pre & self.locks[k]).sum() * self.cell)
                for k, j in enumerate(s["lockable"])
            },
            "jump_min": _nanmin(self.jump[self.pre]),
            "rcn_min": _nanmin(self.rcn[self.pre]),
            "definition": self.definition,
            "resolution": self.error,
            "spec": s,
        }
        return out

    def save(
        self, folder: str | Path, draw: Callable[[Workspace, Path], object] | None = None
    ) -> Path:
        """Write ``workspace.json``, ``workspace.npz``, and ``workspace.png`` with ``draw``, whole.

        ``draw`` is :func:`fault_tolerance.figures.workspace.plot_workspace` for the usual figure
        (figures sit above the analyses, so the caller passes it). The files are staged in a
        sibling folder with a completion record (SHA-256 of each) and renamed into place
        (:func:`~fault_tolerance.storage.result_folder.staged_folder`): a reader sees the previous
        result or this one, never a mix. Finished chunks (``chunks-*/``) are kept.
        """
        folder = Path(folder)
        names = "xyz"[: len(self.axes)]
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            **{n: a for n, a in zip(names, self.axes, strict=True)},
            pre=self.pre,
            ftw=self.ftw,
            locks=self.locks,
            jump=self.jump,
            rcn=self.rcn,
        )
        with staged_folder(folder, replaceable=WORKSPACE_FILES, aside=CHUNKS) as tmp:
            (tmp / "workspace.npz").write_bytes(buf.getvalue())
            (tmp / "workspace.json").write_text(json.dumps(self.summary(), indent=2) + "\n")
            if draw is not None:
                draw(self, tmp / "workspace.png")
        return folder


def _nanmin(a: np.ndarray) -> float | None:
    a = a[np.isfinite(a)]
    return float(a.min()) if a.size else None
