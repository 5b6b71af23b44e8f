"""The replay page's plots: λ(t) with its parts, K(t) and the joint rates, drawn as SVG.

:func:`chart_data` takes what a run recorded (decimated so a page stays small, every peak kept)
and :func:`plots_html` draws it as three SVG panels for the element ``#ft-plots`` of the replay
page (:mod:`.page`): (a) the square-sum jump λ(t) of eq. (9)/(10) and, dashed, its per-scenario
parts ``w_S ‖ˢq̇' − q̇‖²`` (per joint for the usual one-joint scenarios); (b) the square-sum RCN
K(t) of eq. (15), on a log axis when it spans more than :data:`LOG_DECADES` decades; (c) the joint
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
import math
from dataclasses import dataclass

import numpy as np

#: K is drawn on a log axis when max K / min K exceeds 10**LOG_DECADES (the figures use the same).
LOG_DECADES = 2.0
#: Time buckets of the decimation: each keeps the smallest and largest sample of every curve.
BUCKETS = 300
#: Colours of runs by algorithm (as in the figures of plots.py), then a palette for the rest.
RUN_COLORS = {"lnva": "#1f77b4", "jvja": "#d62728", "mda": "#2ca02c", "global": "#9467bd"}
PALETTE = (
    "#1f77b4",
    "#d62728",
    "#2ca02c",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
    "#ff7f0e",
)
#: Colours of the joints (rates, λ parts), apart from the runs' blue, red and green.
JOINT_COLORS = (
    "#ff7f0e",
    "#9467bd",
    "#17becf",
    "#8c564b",
    "#bcbd22",
    "#e377c2",
    "#7f7f7f",
    "#393b79",
    "#637939",
    "#843c39",
)
LOCK_CSS = "#db1adb"  # viz.geometry.LOCK_COLOR as CSS

# view box of one panel [px]: width, height and the plot area's margins
WIDTH, HEIGHT = 460.0, 178.0
LEFT, RIGHT, TOP, BOTTOM = 56.0, 10.0, 24.0, 26.0


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
    curves = [run.jvj, run.K, *run.jvj_parts.T, *run.qd.T]
    idx = _keep(run.t, curves, must)
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
    )


def run_color(algorithm: str | None, index: int, taken: set[str]) -> str:
    """The colour of a run: its algorithm's if still free, else the next free palette colour."""
    c = RUN_COLORS.get(str(algorithm or "").lower())
    if c and c not in taken:
        return c
    for c in PALETTE[index:] + PALETTE[:index]:
        if c not in taken:
            return c
    return PALETTE[index % len(PALETTE)]


# -- axes -----------------------------------------------------------------------------------


def nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """Round tick values (1, 2, 5 × 10^k apart) covering [lo, hi]."""
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(count - 1, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(s * mag for s in (1, 2, 2.5, 5, 10) if s * mag >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    ticks = []
    v = first
    while v <= hi + 1e-9 * step:
        ticks.append(0.0 if abs(v) < 1e-12 * step else v)
        v += step
    return ticks


def use_log(values: np.ndarray) -> bool:
    """Whether positive ``values`` span more than :data:`LOG_DECADES` decades."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    return len(v) > 1 and math.log10(v.max() / v.min()) > LOG_DECADES


def _fmt(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e4 or a < 1e-3:
        mant, exp = f"{v:.0e}".split("e")
        return f"{mant}e{int(exp)}"
    return f"{v:.4g}"


class _Axes:
    """Maps time and values to view-box coordinates of one panel."""

    def __init__(self, t0: float, t1: float, y0: float, y1: float, log: bool) -> None:
        self.t0, self.t1 = t0, (t1 if t1 > t0 else t0 + 1.0)
        self.log = log
        if log:
            y0, y1 = math.log10(y0), math.log10(y1)
        if not y1 > y0:
            y0, y1 = y0 - 1.0, y1 + 1.0
        self.y0, self.y1 = y0, y1

    def x(self, t):
        return LEFT + (np.asarray(t) - self.t0) / (self.t1 - self.t0) * (WIDTH - LEFT - RIGHT)

    def y(self, v):
        v = np.asarray(v, dtype=float)
        if self.log:
            with np.errstate(divide="ignore", invalid="ignore"):
                v = np.log10(v)
        return TOP + (self.y1 - v) / (self.y1 - self.y0) * (HEIGHT - TOP - BOTTOM)


def _polyline(ax: _Axes, t, v, style: str) -> str:
    """SVG polylines of a curve; gaps where it is not finite (or not positive on a log axis)."""
    t, v = np.asarray(t, float), np.asarray(v, float)
    ok = np.isfinite(v) & ((v > 0) if ax.log else True)
    out = []
    start = None
    for i in range(len(v) + 1):
        good = i < len(v) and ok[i]
        if good and start is None:
            start = i
        if not good and start is not None:
            xs, ys = ax.x(t[start:i]), np.clip(ax.y(v[start:i]), -2 * HEIGHT, 3 * HEIGHT)
            pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(xs, ys, strict=True))
            out.append(f'<polyline fill="none" {style} points="{pts}"/>')
            start = None
    return "".join(out)


def _frame(ax: _Axes, title: str, ylabel: str, kind: str, extra: str = "") -> tuple[str, str]:
    """Opening of a panel's SVG (axes, ticks, grid, title) and its closing (cursor, end tag)."""
    esc = html_lib.escape
    x0, x1 = LEFT, WIDTH - RIGHT
    yb, yt = HEIGHT - BOTTOM, TOP
    parts = [
        f'<svg class="ft-plot" data-kind="{kind}" data-scale="{"log" if ax.log else "linear"}" '
        f'data-t0="{ax.t0:.9g}" data-t1="{ax.t1:.9g}" data-x0="{x0:.1f}" data-x1="{x1:.1f}" '
        f'viewBox="0 0 {WIDTH:.0f} {HEIGHT:.0f}" xmlns="http://www.w3.org/2000/svg" '
        f'role="img" aria-label="{esc(title)}">',
        f"<title>{esc(title)} (click to seek)</title>",
        f'<rect class="ft-area" x="{x0}" y="{yt}" width="{x1 - x0}" height="{yb - yt}" '
        'fill="#ffffff" stroke="#b9bcc4"/>',
    ]
    if ax.log:
        ticks = [10.0**e for e in range(math.floor(ax.y0), math.ceil(ax.y1) + 1)]
        ticks = [v for v in ticks if ax.y0 - 1e-9 <= math.log10(v) <= ax.y1 + 1e-9]
    else:
        ticks = nice_ticks(ax.y0, ax.y1, 4)
    for v in ticks:
        y = float(ax.y(v))
        parts.append(
            f'<line x1="{x0}" x2="{x1}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e6e7eb"/>'
            f'<text x="{x0 - 4}" y="{y + 3.5:.1f}" text-anchor="end" class="ft-tick">'
            f"{_fmt(v)}</text>"
        )
    for v in nice_ticks(ax.t0, ax.t1, 6):
        x = float(ax.x(v))
        parts.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{yb}" y2="{yb + 3}" stroke="#7d818b"/>'
            f'<text x="{x:.1f}" y="{yb + 14}" text-anchor="middle" class="ft-tick">'
            f"{_fmt(v)}</text>"
        )
    parts.append(
        f'<text x="{x1}" y="{HEIGHT - 2}" text-anchor="end" class="ft-tick">t [s]</text>'
        f'<text x="{x0}" y="14" class="ft-title">{esc(title)}</text>'
        f'<text x="{x1}" y="14" text-anchor="end" class="ft-unit">{esc(ylabel)}</text>'
    )
    parts.append(
        f'<clipPath id="ft-clip-{kind}"><rect x="{x0}" y="{yt}" width="{x1 - x0}" '
        f'height="{yb - yt}"/></clipPath><g clip-path="url(#ft-clip-{kind})">{extra}'
    )
    close = (
        "</g>"
        f'<line class="ft-cursor" x1="{x0}" x2="{x0}" y1="{yt}" y2="{yb}" '
        'stroke="#1d1f24" stroke-width="1.4"/>'
        "</svg>"
    )
    return "".join(parts), close


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


def _range(values: list[np.ndarray], log: bool, floor0: bool) -> tuple[float, float]:
    v = np.concatenate([np.ravel(a) for a in values]) if values else np.zeros(1)
    v = v[np.isfinite(v) & ((v > 0) if log else True)]
    if not len(v):
        return (1.0, 10.0) if log else (0.0, 1.0)
    lo, hi = float(v.min()), float(v.max())
    if log:
        return 10 ** math.floor(math.log10(lo) + 1e-9), 10 ** math.ceil(math.log10(hi) - 1e-9)
    if floor0:
        lo = min(lo, 0.0)
    pad = 0.06 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
    return lo - (0 if floor0 and lo == 0 else pad), hi + pad


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
            f'<g class="ft-run" data-run="{i}">'
            + _polyline(ax, r.t, r.jvj, f'stroke="{r.color}" stroke-width="1.7"')
            + "</g>"
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
        f'<g class="ft-run" data-run="{i}">'
        + _polyline(ax, r.t, r.K, f'stroke="{r.color}" stroke-width="1.7"')
        + "</g>"
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


def _legend(runs: list[ChartRun]) -> str:
    esc = html_lib.escape
    items = []
    if len(runs) > 1:
        for i, r in enumerate(runs):
            items.append(
                f'<span class="ft-key" data-run="{i}"><span class="ft-swatch" '
                f'style="background:{r.color}"></span>{esc(r.label)}</span>'
            )
    first = runs[0]
    for j, name in enumerate(first.joint_names):
        items.append(
            f'<span class="ft-key"><span class="ft-swatch ft-thin" '
            f'style="background:{JOINT_COLORS[j % len(JOINT_COLORS)]}"></span>{esc(name)}</span>'
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
    notes = []
    for i, items in enumerate(warnings or []):
        for w in items:
            notes.append(f'<li class="ft-warning" data-run="{i}">{esc(w)}</li>')
    foot = f'<ul class="ft-warnings">{"".join(notes)}</ul>' if notes else ""
    return "".join(head) + "".join(panels) + foot
