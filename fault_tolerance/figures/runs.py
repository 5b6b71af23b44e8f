"""Figures in the paper's form (matplotlib; imported only when a figure is drawn).

* :func:`plot_comparison`: panel (a) the square-sum jump λ(t), panel (b) the square-sum RCN K(t),
  one curve per algorithm (the paper's Figs. 2, 3, 4, 6, 7).
* :func:`plot_lock`: panel (a) the end-effector path, desired and actual, for each lock moment;
  panel (b) the path (position) error over time (the paper's Figs. 9-10); for tasks with angular
  rows panel (c) the orientation error.

Position errors are drawn in mm and orientation errors in mrad, on separate axes: metres and
radians are never added (docs/MATH.md, "Notation and units").

K is drawn on a log axis when it spans more than two decades (``figures.scales.LOG_DECADES``, the replay
page's rule too); every figure has a title (a default one when none is given).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fault_tolerance.figures.colors import DASHES, joint_colour, run_styles
from fault_tolerance.figures.scales import use_log
from fault_tolerance.figures.text import plain, wrapped
from fault_tolerance.simulation.run import Run
from fault_tolerance.storage.atomic import write_atomic


def style(name: str) -> dict:
    """Colour and label of the curve of algorithm ``name``: one colour in every figure and page.

    The colour is :func:`~fault_tolerance.figures.colors.method_colour`'s, the label the registry's.

    The label is drawn as written (:func:`~fault_tolerance.figures.text.plain`: no mathtext).
    """
    from fault_tolerance.simulation.simulate import algorithm_style

    known = algorithm_style(name)
    label = name if known is None else known[1]
    ((color, _),) = run_styles([name])
    return {"color": color, "label": plain(label)}


def _algorithm(label: str, run: Run) -> str:
    """The method of a run: its recorded algorithm, else the label it is drawn under."""
    return str(run.meta.get("algorithm") or label)


def _run_lines(runs: Mapping[str, Run]) -> list[dict]:
    """Colour and line style per run: its method's colour, dashed for a method's later runs."""
    algorithms = [_algorithm(k, r) for k, r in runs.items()]
    styles = run_styles(algorithms)
    return [
        {"color": c, "ls": DASHES[d][0], "gid": f"method:{a.lower()}"}
        for a, (c, d) in zip(algorithms, styles, strict=True)
    ]


def _suptitle(fig, text: str, fontsize: float = 11) -> None:
    """The figure's title, wrapped to the figure's width (never clipped)."""
    fig.suptitle(wrapped(text, fig.get_figwidth(), fontsize), fontsize=fontsize)


def _subplots(nrows: int, ncols: int, figsize, **kw):
    """A figure outside pyplot's global state: works headless and never changes a notebook's backend."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
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


def _log_when_decades(ax, values) -> None:
    """A log y axis on ``ax`` when the positive ``values`` span more than LOG_DECADES decades."""
    if use_log(np.concatenate([np.ravel(v) for v in values])):
        ax.set_yscale("log")


def _robot(runs) -> str:
    first = next(iter(runs.values()), None)
    return plain((first.meta.get("robot") if first is not None else None) or "arm")


def plot_comparison(runs: Mapping[str, Run], title: str = ""):
    """Panel (a) λ(t), panel (b) K(t), one curve per algorithm; returns the figure.

    K is on a log axis when it spans more than two decades; without ``title`` the figure is
    titled with the robot and the algorithms.
    """
    fig, (ax1, ax2) = _subplots(2, 1, (7.0, 6.2), sharex=True)
    for (name, run), line in zip(runs.items(), _run_lines(runs), strict=True):
        curve = {**style(_algorithm(name, run)), **line, "lw": 1.6}
        if _algorithm(name, run) != name:
            curve["label"] = plain(name)
        ax1.plot(run.t, run.jvj, **curve)
        ax2.plot(run.t, run.K, **curve)
    ax1.set_ylabel(r"square-sum jump $\lambda$ [(rad/s)$^2$]")
    ax1.set_title("(a) joint velocity jump", loc="left", fontsize=10)
    ax2.set_ylabel(r"square-sum RCN $K=\sum_S k_S^2$ [1]")
    ax2.set_title("(b) reduced condition number", loc="left", fontsize=10)
    for ax in (ax1, ax2):
        ax.set_xlabel("time t [s]")
        ax.grid(alpha=0.3)
    ax1.legend(fontsize=8, loc="best")
    _log_when_decades(ax2, [r.K for r in runs.values()])
    _suptitle(fig, title or f"{_robot(runs)}: λ(t) and K(t), {plain(', '.join(runs))}")
    return fig


def _orientation(run: Run):
    """The run's orientation error [rad] per sample, or ``None`` (no angular task rows)."""
    return getattr(run, "orientation_error", None)


def planned_jump(planned: Run, t_lock: float) -> float:
    """λ of the planned run at the sample of ``t_lock``: the number ``lock --at max|min`` prints."""
    k = int(np.argmin(np.abs(planned.t - t_lock)))
    return float(planned.jvj[k])


def plot_lock(runs: Mapping[str, Run], title: str = "", planned: Run | None = None):
    """Lock runs: tool paths with a zoom on each lock, path errors and the planned run's λ.

    Panel (a) desired and actual tool path per lock run, with an inset zoomed on each lock
    moment; (b) position error; (c) orientation error (only for tasks with angular rows); with
    ``planned`` (the run without a lock whose λ chose the lock moments) a last panel: λ(t) of that
    run with its value at each lock moment, the λ ``lock --at max|min`` prints.
    """
    angular = any(_orientation(r) is not None for r in runs.values())
    ncols = 2 + int(angular) + int(planned is not None)
    fig, axes = _subplots(1, ncols, (4.6 * ncols, 4.6))
    ax1, ax2 = axes[0], axes[1]
    first = next(iter(runs.values()))
    ax1.plot(first.x_des[:, 0], first.x_des[:, 1], color="0.35", ls=(0, (1, 1.5)), lw=1.4,
             label="desired path")  # fmt: skip
    lines = _run_lines(runs)
    for (label, run), line in zip(runs.items(), lines, strict=True):
        lock = run.meta.get("lock") or {}
        c = line["color"]
        ax1.plot(run.x[:, 0], run.x[:, 1], **line, lw=1.4, label=f"actual, {plain(label)}")
        ax2.plot(run.t, 1e3 * run.error, **line, lw=1.4, label=plain(label))
        if angular and _orientation(run) is not None:
            axes[2].plot(run.t, 1e3 * _orientation(run), **line, lw=1.4, label=plain(label))
        if lock:
            k = int(np.searchsorted(run.t, lock["time"] - 1e-12))
            ax1.plot(*run.x[k, :2], "o", color=c, ms=7, mfc="none", mew=2)
            for ax in axes[1:]:
                ax.axvline(lock["time"], color=c, ls=":", lw=1.2)
    colors = [line["color"] for line in lines]
    _lock_zooms(ax1, runs, colors)
    if planned is not None:
        _planned_panel(axes[-1], planned, runs, colors, "abcd"[ncols - 1])
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    ax1.set_title("(a) tool path\n(circles: lock moments)", loc="left", fontsize=10)
    ax1.legend(fontsize=8)
    ax2.set_ylabel("position error |p - p_des| [mm]")
    ax2.set_title("(b) path error\n(dotted: lock moments)", loc="left", fontsize=10)
    if angular:
        axes[2].set_ylabel("orientation error (angle) [mrad]")
        axes[2].set_title("(c) orientation error", loc="left", fontsize=10)
    for ax in axes:
        ax.grid(alpha=0.3)
    for ax in axes[1:]:
        ax.set_xlabel("time t [s]")
        ax.legend(fontsize=8)
    locks = [r.meta["lock"] for r in runs.values() if r.meta.get("lock")]
    default = f"{_robot(runs)}: " + (
        ", ".join(f"{plain(lk['joint'])} locks at {lk['time']:.3g} s" for lk in locks)
        or "lock runs"
    )
    _suptitle(fig, title or default)
    return fig


def _lock_zooms(ax, runs: Mapping[str, Run], colors) -> None:
    """Insets of panel (a) zoomed on each lock moment: desired and actual path around it."""
    spots = [(r, c) for r, c in zip(runs.values(), colors, strict=False) if r.meta.get("lock")]
    # inside the axes by more than the insets' tick labels: they never cover the main ticks
    corners = [[0.12, 0.08, 0.3, 0.3], [0.66, 0.08, 0.3, 0.3], [0.12, 0.6, 0.3, 0.3]]
    for (run, c), box in zip(spots[: len(corners)], corners, strict=False):
        t_lock = run.meta["lock"]["time"]
        k = int(np.searchsorted(run.t, t_lock - 1e-12))
        span = max(float(np.ptp(run.x_des[:, :2], axis=0).max()), 1e-6)
        after = run.t >= t_lock
        peak = float(np.max(run.error[after])) if after.any() else 0.0
        half = min(max(3.0 * peak, 0.04 * span), 0.15 * span)  # [m], the zoom's half width
        near = np.linalg.norm(run.x[:, :2] - run.x[k, :2], axis=1) <= 1.5 * half
        inset = ax.inset_axes(box)
        inset.plot(run.x_des[near, 0], run.x_des[near, 1], color="0.35", ls=(0, (1, 1.5)), lw=1.2)
        inset.plot(run.x[near, 0], run.x[near, 1], color=c, lw=1.3)
        inset.plot(*run.x[k, :2], "o", color=c, ms=6, mfc="none", mew=1.8)
        inset.set_xlim(run.x[k, 0] - half, run.x[k, 0] + half)
        inset.set_ylim(run.x[k, 1] - half, run.x[k, 1] + half)
        inset.set_aspect("equal", adjustable="box")
        inset.tick_params(labelsize=6)
        inset.set_title(f"zoom at {t_lock:.3g} s (±{1e3 * half:.3g} mm)", fontsize=7)


def _planned_panel(ax, planned: Run, runs: Mapping[str, Run], colors, letter: str) -> None:
    """λ(t) of the planned run and its value at each lock moment (the printed numbers)."""
    (line,) = _run_lines({"planned": planned})
    ax.plot(planned.t, planned.jvj, **line, lw=1.3, label="planned run (no lock)")
    for (label, run), c, mark in zip(runs.items(), colors, "os^v", strict=False):
        lock = run.meta.get("lock")
        if not lock:
            continue
        lam = planned_jump(planned, lock["time"])
        ax.plot([lock["time"]], [lam], mark, color=c, mec="k", ms=7,
                label=f"{plain(label)}: λ = {lam:.4g}")  # fmt: skip
    ax.set_ylabel(r"square-sum jump $\lambda$ [(rad/s)$^2$]")
    ax.set_xlabel("time t [s]")
    ax.set_title(
        f"({letter}) λ(t) of the planned run\nat the lock moments", loc="left", fontsize=10
    )


def plot_run(run: Run, title: str = ""):
    """One run: joint rates, λ(t) and K(t), task error; returns the figure."""
    fig, axes = _subplots(2, 2, (10.0, 6.4), sharex=True)
    names = run.meta.get("joint_names") or [f"q{i}" for i in range(run.q.shape[1])]
    for j, name in enumerate(names):
        axes[0, 0].plot(run.t, run.qd[:, j], lw=1.2, color=joint_colour(j), label=plain(name),
                        gid=f"joint:{name}")  # fmt: skip
    axes[0, 0].set_ylabel("joint rates [rad/s]")
    axes[0, 0].legend(fontsize=7, ncol=2)
    alg = str(run.meta.get("algorithm") or "")
    method = {**style(alg), "gid": f"method:{alg.lower()}"}
    axes[0, 1].plot(run.t, run.jvj, **method)
    axes[0, 1].set_ylabel(r"square-sum jump $\lambda$ [(rad/s)$^2$]")
    axes[0, 1].legend(fontsize=7)
    axes[1, 0].plot(run.t, run.K, **method)
    axes[1, 0].set_ylabel(r"square-sum RCN $K$ [1]")
    _log_when_decades(axes[1, 0], [run.K])
    axes[1, 1].plot(run.t, 1e3 * run.error, color="k", label="position")
    axes[1, 1].set_ylabel("position error [mm]")
    if _orientation(run) is not None:  # a second axis: mm and mrad are not one quantity
        twin = axes[1, 1].twinx()
        twin.plot(run.t, 1e3 * _orientation(run), color="0.45", ls="--", label="orientation")
        twin.set_ylabel("orientation error (dashed) [mrad]")
        axes[1, 1].legend(
            handles=axes[1, 1].get_lines() + twin.get_lines(), fontsize=7, loc="upper left"
        )
    lock = run.meta.get("lock")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
        if lock:
            ax.axvline(lock["time"], color="0.4", ls=":", lw=1.2)
    for ax in axes.flat:
        ax.set_xlabel("time t [s]")
    _suptitle(
        fig, title or f"{plain(run.meta.get('robot', ''))} — {plain(run.meta.get('algorithm', ''))}"
    )
    return fig
