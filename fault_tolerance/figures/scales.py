"""When a plot's value axis is logarithmic: the same rule for the figures and the replay page.

K spans many decades near a singular reduced robot; a linear axis would flatten everything else.
Both the matplotlib figures (:mod:`fault_tolerance.figures.runs`) and the replay page's SVG panels
(:mod:`fault_tolerance.viz.charts`) draw K on a log axis when :func:`use_log` says so:

    >>> import numpy as np
    >>> use_log(np.array([1.0, 99.0])), use_log(np.array([1.0, 101.0]))
    (False, True)
"""

from __future__ import annotations

import math

import numpy as np

#: K is drawn on a log axis when max K / min K exceeds 10**LOG_DECADES.
LOG_DECADES = 2.0


def use_log(values: np.ndarray) -> bool:
    """Whether positive ``values`` span more than :data:`LOG_DECADES` decades."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    return len(v) > 1 and math.log10(v.max() / v.min()) > LOG_DECADES
