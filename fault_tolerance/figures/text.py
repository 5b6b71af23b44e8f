r"""Names as data in figures: a robot's, a joint's or a run's name is drawn as written.

Matplotlib reads text between two ``$`` as mathtext, so a joint named ``$\frac{a$`` would make
the figure fail to draw (and a name could change what a label says). :func:`plain` escapes every
``$`` of a name before it is put in a label; the labels' own mathtext (``$\lambda$``) is kept.
"""

from __future__ import annotations


def plain(name: object) -> str:
    r"""``name`` as text matplotlib draws literally: each ``$`` becomes ``\$`` (no mathtext)."""
    return str(name).replace("$", r"\$")


def wrapped(text: str, width_in: float, fontsize: float) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` points.

    A character of matplotlib's default sans-serif font is at most about 0.6 em wide on average
    for mixed text; the lines are kept at 90 % of the width so a title never runs off the figure.
    """
    import textwrap

    chars = max(int(0.9 * width_in * 72.0 / (0.6 * fontsize)), 12)
    return "\n".join(textwrap.wrap(str(text), chars, break_on_hyphens=False)) or str(text)
