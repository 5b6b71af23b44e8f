r"""Names as data in figures: a robot's, a joint's or a run's name is drawn as written.

Matplotlib reads text between two ``$`` as mathtext, so a joint named ``$\frac{a$`` would make
the figure fail to draw (and a name could change what a label says). :func:`plain` escapes every
``$`` of a name before it is put in a label; the labels' own mathtext (``$\lambda$``) is kept.
"""

from __future__ import annotations


def plain(name: object) -> str:
    r"""``name`` as text matplotlib draws literally: each ``$`` becomes ``\$`` (no mathtext)."""
    return str(name).replace("$", r"\$")
