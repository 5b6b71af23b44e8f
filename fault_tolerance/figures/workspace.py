"""Figures of workspace sweeps and designs (matplotlib, imported here only)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fault_tolerance.figures.text import plain


def _mask_image(ws, sl):
    """0 outside W(A), 1 in W(A) only, 2 in the failure-tolerant workspace."""
    return np.where(ws.ftw[sl], 2, np.where(ws.pre[sl], 1, 0)).T


def plot_workspace(ws, path: str | Path) -> Path:
    """Heatmaps of W(A)/FTW, the smallest mean JVJA jump and the smallest K (z slices for 3-D)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap, LogNorm

    if ws.spatial:
        N = len(ws.axes[2])
        zs = sorted({N // 4, N // 2, (3 * N) // 4})
        slices: list[tuple] = [(slice(None), slice(None), k) for k in zs]
        titles = [f"z = {ws.axes[2][k]:.3f} m" for k in zs]
    else:
        slices, titles = [(slice(None), slice(None))], [""]
    x, y = ws.axes[0], ws.axes[1]
    ext = [x[0], x[-1], y[0], y[-1]]
    fig, axs = plt.subplots(len(slices), 3, figsize=(13, 4 * len(slices)), squeeze=False)
    cmap = ListedColormap(["white", "#9ecae1", "#08519c"])
    unit = "m³" if ws.spatial else "m²"
    for r, (sl, tt) in enumerate(zip(slices, titles, strict=True)):
        a = axs[r, 0]
        a.imshow(_mask_image(ws, sl), origin="lower", extent=ext, cmap=cmap, vmin=0, vmax=2)
        a.set_title(
            f"W(A) {ws.size_pre:.3g} {unit} (light), FTW {ws.size_ftw:.3g} {unit} (dark) {tt}"
        )
        for a2, data, name in (
            (axs[r, 1], ws.jump, "min mean JVJA jump"),
            (axs[r, 2], ws.rcn, "min K"),
        ):
            d = data[sl].T
            fin = d[np.isfinite(d) & (d > 0)]
            norm = LogNorm(fin.min(), fin.max()) if fin.size and fin.max() > fin.min() else None
            im = a2.imshow(d, origin="lower", extent=ext, norm=norm, cmap="viridis")
            a2.set_title(f"{name} {tt}")
            fig.colorbar(im, ax=a2, shrink=0.8)
        for a in axs[r]:
            a.set_xlabel("x [m]")
            a.set_ylabel("y [m]")
            a.set_aspect("equal")
    fig.suptitle(
        f"{plain(ws.spec['robot']['source'])}: failure-tolerant workspace, lockable "
        f"{plain(ws.spec['lockable'])}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)
