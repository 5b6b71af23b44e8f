"""Figures in the paper's form (matplotlib; imported only when a figure is drawn).

* :func:`plot_comparison`: panel (a) the square-sum jump λ(t), panel (b) the square-sum RCN K(t),
  one curve per algorithm (the paper's Figs. 2, 3, 4, 6, 7).
* :func:`plot_lock`: panel (a) the end-effector path, desired and actual, for each lock moment;
  panel (b) the path (position) error over time (the paper's Figs. 9-10); for tasks with angular
  rows panel (c) the orientation error.

Position errors are drawn in mm and orientation errors in mrad, on separate axes: metres and
radians are never added (docs/MATH.md, "Notation and units").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .simulation import Run, write_atomic

COLORS = {"lnva": "#1f77b4", "jvja": "#d62728", "mda": "#2ca02c", "global": "#9467bd"}
LABELS = {
    "lnva": "LNVA (least norm)",
    "jvja": "JVJA (minimum jump)",
    "mda": "MDA (maximum dexterity)",
    "global": "global (whole-path plan)",
}


def _subplots(nrows: int, ncols: int, figsize, **kw):
    """A figure outside pyplot's global state: works headless and never changes a notebook's backend."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    axes = fig.subplots(nrows, ncols, **kw)
    return fig, axes


def save_figure(fig, stem: str | Path, formats: Sequence[str] = ("png", "svg")) -> list[Path]:
    """Save ``fig`` as ``stem.png`` and ``stem.svg`` (atomically)."""
    import io

    out = []
    for fmt in formats:
        buf = io.BytesIO()
        fig.savefig(buf, format=fmt, dpi=130, bbox_inches="tight")
        out.append(write_atomic(Path(f"{stem}.{fmt}"), buf.getvalue()))
    return out


def plot_comparison(runs: Mapping[str, Run], title: str = ""):
    """Panel (a) λ(t), panel (b) K(t), one curve per algorithm; returns the figure."""
    fig, (ax1, ax2) = _subplots(2, 1, (7.0, 6.2), sharex=True)
    for name, run in runs.items():
        style = {"color": COLORS.get(name), "label": LABELS.get(name, name), "lw": 1.6}
        ax1.plot(run.t, run.jvj, **style)
        ax2.plot(run.t, run.K, **style)
    ax1.set_ylabel(r"square-sum jump $\lambda$ [(rad/s)$^2$]")
    ax1.set_title("(a) joint velocity jump", loc="left", fontsize=10)
    ax2.set_ylabel(r"square-sum RCN $K=\sum_S k_S^2$")
    ax2.set_title("(b) reduced condition number", loc="left", fontsize=10)
    ax2.set_xlabel("time t [s]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    ax1.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def _orientation(run: Run):
    """The run's orientation error [rad] per sample, or ``None`` (no angular task rows)."""
    return getattr(run, "orientation_error", None)


def plot_lock(runs: Mapping[str, Run], title: str = ""):
    """Panel (a) desired and actual tool path per lock run, (b) position error, (c) orientation error.

    Panel (c) appears only when a run has angular task rows.
    """
    angular = any(_orientation(r) is not None for r in runs.values())
    fig, axes = _subplots(1, 3 if angular else 2, (16.0 if angular else 11.0, 4.6))
    ax1, ax2 = axes[0], axes[1]
    first = next(iter(runs.values()))
    ax1.plot(first.x_des[:, 0], first.x_des[:, 1], "k--", lw=1.2, label="desired path")
    colors = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd"]
    for (label, run), c in zip(runs.items(), colors, strict=False):
        lock = run.meta.get("lock") or {}
        ax1.plot(run.x[:, 0], run.x[:, 1], color=c, lw=1.4, label=f"actual, {label}")
        ax2.plot(run.t, 1e3 * run.error, color=c, lw=1.4, label=label)
        if angular and _orientation(run) is not None:
            axes[2].plot(run.t, 1e3 * _orientation(run), color=c, lw=1.4, label=label)
        if lock:
            k = int(np.searchsorted(run.t, lock["time"] - 1e-12))
            ax1.plot(*run.x[k, :2], "o", color=c, ms=7, mfc="none", mew=2)
            for ax in axes[1:]:
                ax.axvline(lock["time"], color=c, ls=":", lw=1.2)
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    ax1.set_title("(a) end-effector path (circles: lock moments)", loc="left", fontsize=10)
    ax1.legend(fontsize=8)
    ax2.set_ylabel("position error |p - p_des| [mm]")
    ax2.set_title("(b) path error (dotted: lock moments)", loc="left", fontsize=10)
    if angular:
        axes[2].set_ylabel("orientation error (angle) [mrad]")
        axes[2].set_title("(c) orientation error", loc="left", fontsize=10)
    for ax in axes:
        ax.grid(alpha=0.3)
    for ax in axes[1:]:
        ax.set_xlabel("time t [s]")
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def plot_run(run: Run, title: str = ""):
    """One run: joint rates, λ(t) and K(t), task error; returns the figure."""
    fig, axes = _subplots(2, 2, (10.0, 6.4), sharex=True)
    names = run.meta.get("joint_names") or [f"q{i}" for i in range(run.q.shape[1])]
    for j, name in enumerate(names):
        axes[0, 0].plot(run.t, run.qd[:, j], lw=1.2, label=name)
    axes[0, 0].set_ylabel("joint rates [rad/s]")
    axes[0, 0].legend(fontsize=7, ncol=2)
    axes[0, 1].plot(run.t, run.jvj, color="#d62728")
    axes[0, 1].set_ylabel(r"square-sum jump $\lambda$ [(rad/s)$^2$]")
    axes[1, 0].plot(run.t, run.K, color="#2ca02c")
    axes[1, 0].set_ylabel(r"square-sum RCN $K$")
    axes[1, 1].plot(run.t, 1e3 * run.error, color="k", label="position")
    axes[1, 1].set_ylabel("position error [mm]")
    if _orientation(run) is not None:  # a second axis: mm and mrad are not one quantity
        twin = axes[1, 1].twinx()
        twin.plot(run.t, 1e3 * _orientation(run), color="#9467bd", label="orientation")
        twin.set_ylabel("orientation error [mrad]", color="#9467bd")
        axes[1, 1].legend(
            handles=axes[1, 1].get_lines() + twin.get_lines(), fontsize=7, loc="upper left"
        )
    lock = run.meta.get("lock")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
        if lock:
            ax.axvline(lock["time"], color="0.4", ls=":", lw=1.2)
    for ax in axes[1]:
        ax.set_xlabel("time t [s]")
    fig.suptitle(
        title or f"{run.meta.get('robot', '')} — {run.meta.get('algorithm', '')}", fontsize=11
    )
    fig.tight_layout()
    return fig
