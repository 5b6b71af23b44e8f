"""What a Controller's fast step hands back: the planner's (damped) step, and a bad argument named.

:func:`fallback` does a step with the built-in resolvers' reference rates itself (near a
singularity of ``J``, where the planner damps and drops rank) and counts it in the workspace's
``counts[FALLBACKS]``; :func:`bad_call` turns what a step raised on a wrong argument into an
:class:`~fault_tolerance.errors.InvalidInput` that says which argument is wrong.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.control.indices import jacobian_derivatives
from fault_tolerance.control.workspace import FALLBACKS, ControllerWorkspace
from fault_tolerance.errors import InvalidInput
from fault_tolerance.resolution import jvja as jvja_module
from fault_tolerance.resolution import mda as mda_module
from fault_tolerance.resolution.lnva import lnva as lnva_rates

__all__ = [
    "bad_call",
    "fallback",
]


def fallback(
    ws: ControllerWorkspace, name: str, J: np.ndarray, xdot, out: np.ndarray, q=None
) -> np.ndarray:
    """The step ``name`` done by the planner itself (damped near singularities), into ``out``."""
    J = np.array(J, dtype=float)
    xdot = np.asarray(xdot, dtype=float)
    if xdot.shape != (ws.m,):
        raise InvalidInput(f"xdot has shape {xdot.shape}; {ws.arm.name} needs ({ws.m},)")
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(xdot))):
        raise InvalidInput("q and xdot must be finite")
    ws.counts[FALLBACKS] += 1
    if name == "lnva":
        qd = lnva_rates(J, xdot)
    elif name == "jvja":
        qd = jvja_module.jvja(J, xdot, ws.scenarios, tolerate=ws.tolerate)
    else:
        qd = mda_module.mda(
            J,
            xdot,
            ws.scenarios,
            dJ=jacobian_derivatives(ws, q),
            gain=ws.gain,
            max_step=ws.max_step,
        )
    out[...] = qd
    return out


def bad_call(ws: ControllerWorkspace, err: Exception, q, xdot, out) -> InvalidInput:
    """An :class:`InvalidInput` that says which argument of a step is wrong."""
    n, m = ws.n, ws.m
    if not (isinstance(q, np.ndarray) and q.dtype == np.float64):
        return InvalidInput(f"q must be a float64 NumPy array of shape ({n},), got {q!r}")
    for name, value, shape in (("q", q, (n,)), ("xdot", xdot, (m,))):
        if np.shape(value) != shape:
            return InvalidInput(
                f"{name} has shape {np.shape(value)}; {ws.arm.name} needs shape {shape}"
            )
    if out is not None and not (
        isinstance(out, np.ndarray)
        and out.shape == (n,)
        and out.dtype == np.float64
        and out.flags.c_contiguous
    ):
        return InvalidInput(f"out must be a C-contiguous float64 array of shape ({n},)")
    return InvalidInput(f"step failed: {err}")
