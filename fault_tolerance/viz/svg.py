"""SVG building blocks of the replay page's plots (ticks, axes, polylines, a panel's frame).

Round ticks, axes that map time and values to a panel's view box (linear or log), polylines with
gaps, and a panel's frame with its cursor.

A panel's view box is :data:`WIDTH` x :data:`HEIGHT`; the plot area leaves :data:`LEFT`,
:data:`RIGHT`, :data:`TOP` and :data:`BOTTOM` for the ticks and the title.
"""

from __future__ import annotations

import html as html_lib
import math

import numpy as np

# view box of one panel [px]: width, height and the plot area's margins
WIDTH, HEIGHT = 460.0, 178.0
LEFT, RIGHT, TOP, BOTTOM = 56.0, 10.0, 24.0, 26.0


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
