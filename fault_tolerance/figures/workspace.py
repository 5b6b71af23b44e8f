"""Figures of workspace sweeps (matplotlib, imported here only).

A planar workspace is drawn whole; a spatial one (position task, a 3-D grid) as three slices
through its failure-tolerant region: per axis z, y, x the plane holding the largest FTW area
(:func:`ftw_slices`, docs/MATH.md (FW1)), each titled with its plane and the FTW area on it.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from fault_tolerance.figures.text import plain, wrapped

#: White outside W(A), light blue in W(A) only, dark blue in the failure-tolerant workspace.
MASK_COLOURS = ("white", "#9ecae1", "#08519c")


class Slice(NamedTuple):
    """One plane of a 3-D grid: normal ``axis`` (0 x, 1 y, 2 z) at grid index ``cell``."""

    axis: int
    cell: int  # grid index of the plane along ``axis``
    coordinate: float  # [m]
    area_ftw: float  # FTW area on the plane [m²]
    area_pre: float  # W(A) area on the plane [m²]

    @property
    def name(self) -> str:
        """``z = 0.512 m``."""
        return f"{'xyz'[self.axis]} = {self.coordinate:.3f} m"

    def select(self) -> tuple:
        """The index tuple of the plane in a (Nx, Ny, Nz) array."""
        return tuple(self.cell if k == self.axis else slice(None) for k in range(3))


def _spacing(axis_values: np.ndarray) -> float:
    """Grid step [m] of one axis (the grids are uniform)."""
    return float(axis_values[1] - axis_values[0]) if len(axis_values) > 1 else 1.0


# Eq. (FW1).
def slice_areas(mask: np.ndarray, axis: int, cell: float, step: float) -> np.ndarray:
    """Area [m²] of ``mask`` on every plane normal to ``axis``: count · cell / Δ_axis (FW1)."""
    other = tuple(k for k in range(mask.ndim) if k != axis)
    return mask.sum(axis=other) * (cell / step)


def ftw_slices(ws) -> list[Slice]:
    """Per axis z, y, x the plane with the largest FTW area (ties: nearest the FTW centroid).

    Without any FTW cell, the plane with the largest W(A) area (then its ``area_ftw`` is 0).
    """
    out = []
    for axis in (2, 1, 0):
        step = _spacing(ws.axes[axis])
        ftw = slice_areas(ws.ftw, axis, ws.cell, step)
        pre = slice_areas(ws.pre, axis, ws.cell, step)
        score = ftw if ftw.max() > 0 else pre
        best = np.flatnonzero(score == score.max())
        weights = score if score.sum() > 0 else np.ones_like(score)
        centre = float(np.average(np.arange(len(score)), weights=weights))
        k = int(best[np.argmin(np.abs(best - centre))])
        out.append(Slice(axis, k, float(ws.axes[axis][k]), float(ftw[k]), float(pre[k])))
    return out


def _mask_image(ws, sl):
    """0 outside W(A), 1 in W(A) only, 2 in the failure-tolerant workspace."""
    return np.where(ws.ftw[sl], 2, np.where(ws.pre[sl], 1, 0)).T


def _rows(ws) -> list[tuple]:
    """``(index tuple, (i, j) plotted axes, plane text, mask title)`` per row of the figure."""
    if not ws.spatial:
        text = f"W(A) {ws.size_pre:.3g} m² (light + dark), FTW {ws.size_ftw:.3g} m² (dark)"
        return [((slice(None), slice(None)), (0, 1), "", text)]
    rows = []
    for s in ftw_slices(ws):
        i, j = (k for k in range(3) if k != s.axis)
        what = "largest FTW" if s.area_ftw > 0 else "no FTW on any plane; largest W(A)"
        text = (f"{s.name} ({what}):\nFTW {s.area_ftw:.3g} m² (dark), "
                f"W(A) {s.area_pre:.3g} m² (light + dark)")  # fmt: skip
        rows.append((s.select(), (i, j), s.name, text))
    return rows


def _limits(mask: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple | None:
    """``(x0, x1, y0, y1)`` [m] around the cells of ``mask`` (axes i, j), one cell of margin."""
    ii, jj = np.nonzero(mask)
    if ii.size == 0:
        return None
    dx, dy = _spacing(x), _spacing(y)
    return (x[ii.min()] - dx, x[ii.max()] + dx, y[jj.min()] - dy, y[jj.max()] + dy)


def _heatmap(fig, ax, data: np.ndarray, ext, title: str, label: str) -> None:
    """One map on a log colour scale with a labelled colour bar."""
    from matplotlib.colors import LogNorm

    fin = data[np.isfinite(data) & (data > 0)]
    norm = LogNorm(fin.min(), fin.max()) if fin.size and fin.max() > fin.min() else None
    im = ax.imshow(data, origin="lower", extent=ext, norm=norm, cmap="viridis")
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, shrink=0.8).set_label(label)


def workspace_figure(ws):
    """The figure of ``ws``: per row a plane, its W(A)/FTW mask, smallest JVJA jump, smallest K."""
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    rows = _rows(ws)
    fig = Figure(figsize=(14, 4.3 * len(rows) + 0.6), layout="constrained")
    axs = fig.subplots(len(rows), 3, squeeze=False)
    cmap = ListedColormap(list(MASK_COLOURS))
    for r, (sl, (i, j), plane, text) in enumerate(rows):
        x, y = ws.axes[i], ws.axes[j]
        ext = [x[0], x[-1], y[0], y[-1]]
        a = axs[r, 0]
        a.imshow(_mask_image(ws, sl), origin="lower", extent=ext, cmap=cmap, vmin=0, vmax=2)
        a.set_title(text, fontsize=10)
        at = f", {plane}" if plane else ""
        _heatmap(fig, axs[r, 1], ws.jump[sl].T, ext, f"smallest mean JVJA jump{at}",
                 "jump per unit task speed [(rad/s)²/(m/s)²]")  # fmt: skip
        _heatmap(fig, axs[r, 2], ws.rcn[sl].T, ext, f"smallest square-sum RCN K{at}",
                 r"$K=\sum_S k_S^2$ [1]")  # fmt: skip
        box = _limits(ws.pre[sl], x, y)  # zoom on W(A): the empty rest of the grid says nothing
        for ax in axs[r]:
            if box is not None:
                ax.set_xlim(box[0], box[1])
                ax.set_ylim(box[2], box[3])
            ax.set_xlabel(f"{'xyz'[i]} [m]")
            ax.set_ylabel(f"{'xyz'[j]} [m]")
            ax.set_aspect("equal")
    size = (f"volume W(A) {ws.size_pre:.3g} m³, FTW {ws.size_ftw:.3g} m³" if ws.spatial
            else f"area W(A) {ws.size_pre:.3g} m², FTW {ws.size_ftw:.3g} m²")  # fmt: skip
    title = (f"{plain(ws.spec['robot']['source'])}: failure-tolerant workspace, lockable "
             f"{plain(', '.join(map(str, ws.spec['lockable'])))}; {size}")  # fmt: skip
    fig.suptitle(wrapped(title, fig.get_figwidth(), 12), fontsize=12)
    return fig


def plot_workspace(ws, path: str | Path) -> Path:
    """Write :func:`workspace_figure` of ``ws`` to ``path`` (PNG)."""
    workspace_figure(ws).savefig(path, dpi=90)
    return Path(path)
