"""The replay page's plots: λ(t) with its parts, K(t) and the joint rates, drawn as SVG.

:func:`chart_data` takes what a run recorded (decimated so a page stays small, every peak kept)
and :func:`plots_html` draws it as three SVG panels for the element ``#ft-plots`` of the replay
page (:mod:`.page`): (a) the square-sum jump λ(t) of eq. (9)/(10) and, dashed, its per-scenario
parts ``w_S ‖ˢq̇' − q̇‖²`` (per joint for the usual one-joint scenarios); (b) the square-sum RCN
K(t) of eq. (15), on a log axis when it spans more than :data:`~fault_tolerance.figures.scales.LOG_DECADES` decades; (c) the joint
rates against their velocity limits (dashed). Lock moments are marked on every panel.

Several runs of one command (e.g. the algorithms of one ``simulate``) share the panels: λ and K of
every run are overlaid, each in its run's colour; the parts and the joint rates are those of the
run shown in the 3D view (the page's selector switches it).

Every panel is an ``<svg class="ft-plot">`` whose ``data-t0``/``data-t1`` (run seconds) and
``data-x0``/``data-x1`` (view-box x) map time to x, so the page's script moves the cursor
(``line.ft-cursor``) with the animation and turns a click into a time. Pure Python: nothing is
fetched, no plotting library is used.
"""

from __future__ import annotations

import html as html_lib
from dataclasses import dataclass

import numpy as np

from fault_tolerance.figures.colors import DASHES, JOINT_COLOURS, run_styles
from fault_tolerance.figures.scales import use_log
from fault_tolerance.viz.svg import (
    BOTTOM,
    HEIGHT,
    LEFT,
    RIGHT,
    TOP,
    WIDTH,
    _Axes,
    _frame,
    _polyline,
    _range,
)

#: Time buckets of the decimation: each keeps the smallest and largest sample of every curve.
BUCKETS = 300
#: Colours of the joints (rates, λ parts, torques): the figures' palette, none a method's.
JOINT_COLORS = JOINT_COLOURS
LOCK_CSS = "#db1adb"  # viz.geometry.LOCK_COLOR as CSS


@dataclass
class ChartRun:
    """One run's curves as the page draws them (decimated samples)."""

    label: str
    color: str
    t: np.ndarray  # [s], shape (P,)
    jvj: np.ndarray | None  # λ [(rad/s)²], shape (P,)
    parts: np.ndarray | None  # shape (P, f)
    part_labels: list[str]
    K: np.ndarray | None  # shape (P,)
    qd: np.ndarray  # [rad/s], shape (P, n)
    joint_names: list[str]
    vmax: list[float | None]  # velocity limit per joint [rad/s], None: none given
    lock: dict | None  # {"joint", "time"}
    tau: np.ndarray | None = None  # applied torques of a dynamics run [N·m], shape (P, n)
    effort: list[float | None] | None = None  # effort limit per joint [N·m], None: none given
    dash: str = ""  # SVG stroke-dasharray of λ and K: a method's later runs are dashed
    method: str = ""  # the run's algorithm (its colour is the method's)


def _keep(t: np.ndarray, curves: list[np.ndarray], must: list[int]) -> np.ndarray:
    """Indices of the samples drawn: per time bucket the min and max of every curve, plus ``must``."""
    count = len(t)
    if count <= 2 * BUCKETS:
        return np.arange(count)
    edges = np.linspace(0, count, BUCKETS + 1).astype(int)
    keep = {0, count - 1, *[m for m in must if 0 <= m < count]}
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        if hi <= lo:
            continue
        for c in curves:
            seg = c[lo:hi]
            finite = np.isfinite(seg)
            if not finite.any():
                keep.add(lo)
                continue
            masked = np.where(finite, seg, np.nan)
            keep.add(lo + int(np.nanargmin(masked)))
            keep.add(lo + int(np.nanargmax(masked)))
    return np.array(sorted(keep))


def _part_labels(meta: dict, f: int) -> list[str]:
    sets = meta.get("lockable") or []
    labels = ["+".join(map(str, s)) if isinstance(s, (list, tuple)) else str(s) for s in sets]
    return labels if len(labels) == f else [f"scenario {i + 1}" for i in range(f)]


def chart_data(run, label: str, color: str, velocity_limit, joint_names) -> ChartRun:
    """The curves of ``run`` (a Run, or a ``(t, q)`` pair: joint rates by differences only)."""
    vmax = [float(v) if np.isfinite(v) and v > 0 else None for v in velocity_limit]
    if isinstance(run, tuple):
        t, q = run
        qd = np.gradient(q, t, axis=0) if len(t) > 1 else np.zeros_like(q)
        idx = _keep(t, list(qd.T), [])
        return ChartRun(
            label, color, t[idx], None, None, [], None, qd[idx], list(joint_names), vmax, None
        )
    lock = run.meta.get("lock")
    must = []
    if lock:
        k = int(np.searchsorted(run.t, lock["time"] - 1e-12))
        must = [k - 1, k, k + 1]
    tau = getattr(run, "tau", None)
    curves = [run.jvj, run.K, *run.jvj_parts.T, *run.qd.T, *([] if tau is None else tau.T)]
    idx = _keep(run.t, curves, must)
    effort = (run.meta.get("dynamics") or {}).get("effort")
    return ChartRun(
        label=label,
        color=color,
        t=run.t[idx],
        jvj=run.jvj[idx],
        parts=run.jvj_parts[idx],
        part_labels=_part_labels(run.meta, run.jvj_parts.shape[1]),
        K=run.K[idx],
        qd=run.qd[idx],
        joint_names=list(joint_names),
        vmax=vmax,
        lock=None if not lock else {"joint": lock["joint"], "time": float(lock["time"])},
        tau=None if tau is None else tau[idx],
        effort=effort,
    )


def run_strokes(algorithms) -> list[tuple[str, str]]:
    """``(colour, SVG dasharray)`` per run: its method's colour, dashed for the method's later runs.

    The colours are :func:`fault_tolerance.figures.colors.run_styles`', as in the figures.
    """
    return [(c, DASHES[d][1]) for c, d in run_styles(algorithms)]


def _stroke(r: ChartRun) -> str:
    dash = f' stroke-dasharray="{r.dash}"' if r.dash else ""
    return f'stroke="{r.color}" stroke-width="1.7"{dash}'


def _locks(ax: _Axes, runs: list[ChartRun]) -> str:
    out = []
    for i, r in enumerate(runs):
        if not r.lock:
            continue
        x = float(ax.x(r.lock["time"]))
        out.append(
            f'<g class="ft-lock" data-run="{i}"><line x1="{x:.1f}" x2="{x:.1f}" y1="{TOP}" '
            f'y2="{HEIGHT - BOTTOM}" stroke="{LOCK_CSS}" stroke-width="1.3" stroke-dasharray="4 3"/>'
            f'<text x="{x + 3:.1f}" y="{TOP + 10}" class="ft-lock-label" fill="{LOCK_CSS}">'
            f"{html_lib.escape(r.lock['joint'])} locks</text></g>"
        )
    return "".join(out)


def _t_range(runs: list[ChartRun]) -> tuple[float, float]:
    return min(float(r.t[0]) for r in runs), max(float(r.t[-1]) for r in runs)


def _part_color(run: ChartRun, i: int) -> str:
    name = run.part_labels[i] if i < len(run.part_labels) else ""
    if name in run.joint_names:
        return JOINT_COLORS[run.joint_names.index(name) % len(JOINT_COLORS)]
    return JOINT_COLORS[(i + 3) % len(JOINT_COLORS)]


def jump_panel(runs: list[ChartRun]) -> str:
    """Panel (a): λ(t) of every run, and the parts of each run (shown for the selected run)."""
    t0, t1 = _t_range(runs)
    vals = [r.jvj for r in runs if r.jvj is not None]
    ax = _Axes(t0, t1, *_range(vals, False, True), log=False)
    body = []
    for i, r in enumerate(runs):
        if r.parts is not None and r.parts.shape[1] > 1:
            g = [f'<g class="ft-run-only" data-run="{i}">']
            for j in range(r.parts.shape[1]):
                g.append(
                    _polyline(
                        ax,
                        r.t,
                        r.parts[:, j],
                        f'stroke="{_part_color(r, j)}" stroke-width="1" stroke-dasharray="3 2" '
                        f'data-part="{html_lib.escape(r.part_labels[j])}"',
                    )
                )
            body.append("".join(g) + "</g>")
    for i, r in enumerate(runs):
        if r.jvj is None:
            continue
        body.append(
            f'<g class="ft-run" data-run="{i}">' + _polyline(ax, r.t, r.jvj, _stroke(r)) + "</g>"
        )
    head, close = _frame(ax, "(a) jump λ(t), dashed: its parts", "(rad/s)²", "jump")
    return head + "".join(body) + _locks(ax, runs) + close


def rcn_panel(runs: list[ChartRun]) -> str:
    """Panel (b): K(t) of every run; log axis when it spans more than LOG_DECADES decades."""
    t0, t1 = _t_range(runs)
    vals = [r.K for r in runs if r.K is not None]
    log = use_log(np.concatenate(vals))
    ax = _Axes(t0, t1, *_range(vals, log, False), log=log)
    body = [
        f'<g class="ft-run" data-run="{i}">' + _polyline(ax, r.t, r.K, _stroke(r)) + "</g>"
        for i, r in enumerate(runs)
        if r.K is not None
    ]
    title = "(b) square-sum RCN K(t)" + (", log axis" if log else "")
    head, close = _frame(ax, title, "K = Σ k_S²", "rcn")
    return head + "".join(body) + _locks(ax, runs) + close


def rates_panel(runs: list[ChartRun]) -> str:
    """Panel (c): joint rates of each run (selected run shown) and their velocity limits, dashed."""
    t0, t1 = _t_range(runs)
    limits = [v for r in runs for v in r.vmax if v is not None]
    vals = [np.abs(r.qd) for r in runs] + ([np.array(limits)] if limits else [])
    lo, hi = _range(vals, False, True)
    ax = _Axes(t0, t1, -hi, hi, log=False)
    body = []
    first = runs[0]
    same = len(set(v for v in first.vmax if v is not None)) == 1
    for j, v in enumerate(first.vmax):
        if v is None or (same and j > 0):
            continue
        color = "#5a5e68" if same else JOINT_COLORS[j % len(JOINT_COLORS)]
        for s in (v, -v):
            y = float(ax.y(s))
            body.append(
                f'<line class="ft-limit" data-joint="{html_lib.escape(first.joint_names[j])}" '
                f'x1="{LEFT}" x2="{WIDTH - RIGHT}" y1="{y:.1f}" y2="{y:.1f}" stroke="{color}" '
                'stroke-width="1.1" stroke-dasharray="6 3"/>'
            )
    for i, r in enumerate(runs):
        g = [f'<g class="ft-run-only" data-run="{i}">']
        for j, name in enumerate(r.joint_names):
            g.append(
                _polyline(
                    ax,
                    r.t,
                    r.qd[:, j],
                    f'stroke="{JOINT_COLORS[j % len(JOINT_COLORS)]}" stroke-width="1.4" '
                    f'data-joint="{html_lib.escape(name)}"',
                )
            )
        body.append("".join(g) + "</g>")
    head, close = _frame(ax, "(c) joint rates, dashed: velocity limits", "rad/s", "rates")
    return head + "".join(body) + _locks(ax, runs) + close


def torque_panel(runs: list[ChartRun]) -> str:
    """Panel (d) of dynamics runs: applied torques τ(t) around the lock, dashed: effort limits."""
    t0, t1 = _t_range(runs)
    have = [r for r in runs if r.tau is not None]
    taus = [np.abs(r.tau) for r in have if r.tau is not None]
    limits = [v for r in have for v in (r.effort or []) if v is not None]
    lo, hi = _range(taus + ([np.array(limits)] if limits else []), False, True)
    ax = _Axes(t0, t1, -hi, hi, log=False)
    body = []
    for j, v in enumerate(have[0].effort or []):
        if v is None:
            continue
        for sign in (v, -v):
            y = float(ax.y(sign))
            body.append(
                f'<line class="ft-effort" data-joint="{html_lib.escape(have[0].joint_names[j])}" '
                f'x1="{LEFT}" x2="{WIDTH - RIGHT}" y1="{y:.1f}" y2="{y:.1f}" '
                f'stroke="{JOINT_COLORS[j % len(JOINT_COLORS)]}" stroke-width="1.1" '
                'stroke-dasharray="6 3"/>'
            )
    for i, r in enumerate(runs):
        if r.tau is None:
            continue
        g = [f'<g class="ft-run-only" data-run="{i}">']
        for j, name in enumerate(r.joint_names):
            style = (f'stroke="{JOINT_COLORS[j % len(JOINT_COLORS)]}" stroke-width="1.4" '
                     f'data-joint="{html_lib.escape(name)}"')  # fmt: skip
            g.append(_polyline(ax, r.t, r.tau[:, j], style))
        body.append("".join(g) + "</g>")
    head, close = _frame(ax, "(d) joint torques, dashed: effort limits", "N·m", "torques")
    return head + "".join(body) + _locks(ax, runs) + close


def _legend(runs: list[ChartRun]) -> str:
    esc = html_lib.escape
    items = []
    if len(runs) > 1:
        for i, r in enumerate(runs):
            look = (f"background:repeating-linear-gradient(90deg,{r.color} 0 5px,transparent 5px 8px)"
                    if r.dash else f"background:{r.color}")  # fmt: skip
            items.append(
                f'<span class="ft-key" data-run="{i}" data-method="{esc(r.method)}" '
                f'data-color="{r.color}"><span class="ft-swatch" '
                f'style="{look}"></span>{esc(r.label)}</span>'
            )
    first = runs[0]
    for j, name in enumerate(first.joint_names):
        c = JOINT_COLORS[j % len(JOINT_COLORS)]
        items.append(
            f'<span class="ft-key" data-joint="{esc(name)}" data-color="{c}"><span '
            f'class="ft-swatch ft-thin" style="background:{c}"></span>{esc(name)}</span>'
        )
    return '<div class="ft-keys">' + "".join(items) + "</div>"


def plots_html(runs: list[ChartRun], warnings: list[list[str]] | None = None) -> str:
    """The content of ``#ft-plots``: a run selector (several runs), legend, three SVG panels."""
    esc = html_lib.escape
    head = []
    if len(runs) > 1:
        options = "".join(
            f'<option value="{i}">{esc(r.label)}</option>' for i, r in enumerate(runs)
        )
        head.append(
            '<label class="ft-select">arm shown: <select id="ft-run">' + options + "</select>"
            "</label>"
        )
    head.append(_legend(runs))
    panels = []
    if any(r.jvj is not None for r in runs):
        panels.append(jump_panel(runs))
        panels.append(rcn_panel(runs))
    panels.append(rates_panel(runs))
    if any(r.tau is not None for r in runs):
        panels.append(torque_panel(runs))
    notes = []
    for i, items in enumerate(warnings or []):
        for w in items:
            notes.append(f'<li class="ft-warning" data-run="{i}">{esc(w)}</li>')
    foot = f'<ul class="ft-warnings">{"".join(notes)}</ul>' if notes else ""
    return "".join(head) + "".join(panels) + foot
