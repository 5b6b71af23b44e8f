"""Figure of a design: the chosen design's workspace and the search (Pareto front for jvj/rcn)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fault_tolerance.figures.text import plain, wrapped
from fault_tolerance.figures.workspace import MASK_COLOURS

#: The chosen design's marker (neither a method's nor a joint's colour).
CHOSEN = "#e6550d"


def plot_design(d, path: str | Path) -> Path:
    """Write :func:`design_figure` of ``d`` to ``path`` (PNG)."""
    design_figure(d).savefig(path, dpi=90)
    return Path(path)


def design_figure(d):
    """Two panels: W(A)/FTW of the chosen design; candidates (mean λ vs mean K, or area)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    rec, seen, ws = d.record, d.evaluated, d.workspace
    fig = Figure(figsize=(12, 5.0), layout="constrained")
    a, b = fig.subplots(1, 2)
    x, y = ws.axes
    img = np.where(ws.ftw, 2, np.where(ws.pre, 1, 0)).T
    cmap = ListedColormap(list(MASK_COLOURS))
    a.imshow(img, origin="lower", extent=[x[0], x[-1], y[0], y[-1]], cmap=cmap, vmin=0, vmax=2)
    a.set_title(f"chosen design: W(A) {ws.area_pre:.3g} m², FTW {ws.area_ftw:.3g} m²", fontsize=10)
    t = rec["task"]
    ang = np.linspace(0, 2 * np.pi, 200)
    cx, cy = t["x0"][0] + t["sign"] * t["radius"], t["x0"][1]
    a.plot(cx - t["sign"] * t["radius"] * np.cos(ang), cy + t["radius"] * np.sin(ang), "-",
           color=CHOSEN, lw=1.2, label="task circle")  # fmt: skip
    a.legend(handles=[*a.get_lines(), Patch(color=MASK_COLOURS[1], label="W(A) only"),
                      Patch(color=MASK_COLOURS[2], label="FTW")], fontsize=7, loc="upper right")  # fmt: skip
    a.set_xlabel("x [m]")
    a.set_ylabel("y [m]")
    a.set_aspect("equal")
    if rec["objective"] == "ftw-area":
        b.plot(-seen["score"], ".", color=MASK_COLOURS[2], ms=3, label="candidate")
        b.axhline(rec["area_ftw"], color=CHOSEN, lw=1.0, label="chosen")
        b.set_xlabel("evaluation number [1]")
        b.set_ylabel("FTW area on the search grid [m²]")
        b.legend(fontsize=8)
        b.set_title(f"{rec['evaluations']} designs evaluated", fontsize=10)
    else:
        ok = seen["feasible"]
        met = np.isfinite(seen["score"])
        b.loglog(
            seen["jvj"][~ok], seen["rcn"][~ok], ".", color="0.75", ms=3, label="leaves its limits"
        )
        b.loglog(
            seen["jvj"][ok & ~met],
            seen["rcn"][ok & ~met],
            ".",
            color="orange",
            ms=4,
            label="over the RCN requirement",
        )
        b.loglog(seen["jvj"][met], seen["rcn"][met], ".", color=MASK_COLOURS[2], ms=4,
                 label="feasible")  # fmt: skip
        fr = sorted((p["jvj"], p["rcn"]) for p in rec["pareto"])
        if fr:
            b.loglog(*zip(*fr, strict=True), "k-", lw=1, label="Pareto front")
        b.loglog([rec["jvj"]], [rec["rcn"]], "*", color=CHOSEN, ms=12, label="chosen")
        if "jvj" in rec["baseline"]:
            b.loglog([rec["baseline"]["jvj"]], [rec["baseline"]["rcn"]], "ks", label="no limits")
        b.set_xlabel("mean JVJ λ [(rad/s)²]")
        b.set_ylabel("mean square-sum RCN K [1]")
        b.legend(fontsize=8)
        b.set_title(f"{rec['evaluations']} designs, objective {rec['objective']}", fontsize=10)
    title = f"{plain(rec['robot'])}: design ({plain(rec['vary'])})"
    fig.suptitle(wrapped(title, fig.get_figwidth(), 12), fontsize=12)
    return fig


def plot_dh_design(d, path: str | Path) -> Path:
    """Write :func:`dh_design_figure` of ``d`` to ``path`` (PNG)."""
    dh_design_figure(d).savefig(path, dpi=120)
    return Path(path)


def dh_design_figure(d):
    """The search of a DH design: every candidate's mean λ against its largest k_S.

    With the Pareto front, the chosen design and the baseline (the table the search started from).
    """
    from matplotlib.figure import Figure

    rec, seen = d.record, d.evaluated
    ok = seen["feasible"].astype(bool)
    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.subplots()
    ax.scatter(seen["rcn_max"][ok], seen["mean_jvj"][ok], s=12, c="#9ecae1", label="candidates")
    bad = ~ok & np.isfinite(seen["rcn_max"])
    if bad.any():
        ax.scatter(seen["rcn_max"][bad], seen["mean_jvj"][bad], s=12, c="#d9d9d9",
                   label=f"over rcn_max {rec['settings']['rcn_max']:g}")  # fmt: skip
    front = sorted((p["rcn_max"], p["mean_jvj"]) for p in rec["pareto"])
    if front:
        ax.plot(*zip(*front, strict=True), "-", c=MASK_COLOURS[2], lw=1.2, label="Pareto front")
    base = rec["baseline"]
    if base.get("mean_jvj") is not None:
        ax.plot(base["rcn_max"], base["mean_jvj"], "s", c="k", ms=8, label="baseline")
    ax.plot(rec["rcn_max"], rec["mean_jvj"], "*", c=CHOSEN, ms=14, label="chosen")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"largest reduced condition number $k_S$ along the task [1]")
    ax.set_ylabel("mean square-sum jump λ [(rad/s)²]")
    names = ", ".join(f"{k} = {v:.3g}" for k, v in rec["parameters"].items())
    title = f"DH design ({rec['objective']}): {names}"
    ax.set_title(wrapped(title, fig.get_figwidth(), 10), fontsize=10)
    ax.legend(fontsize=8)
    return fig
