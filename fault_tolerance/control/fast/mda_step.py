"""MDA's null step compiled (the simulated sample's MDA): ``q̇ = J⁺ẋ − α N ∇K``, capped.

The gradient ``∇K`` of eq. (15) comes from the NumPy code
(:func:`fault_tolerance.resolution.indices.rcn_gradient`); :func:`null_step` projects it and caps
the step as :func:`fault_tolerance.resolution.mda.mda` does, inside the compiled sample
(:mod:`fault_tolerance.simulation.fast.sample`). The Controller's MDA step is the lapack (or numpy)
code. Plain Python without numba.
"""

from __future__ import annotations

import math

from fault_tolerance.fast_cache import inline as _inline
from fault_tolerance.numerics.fast.dense import null_apply

__all__ = ["null_step"]

_INF = math.inf


# The MDA null step of eq. (15)'s gradient, capped as resolution.mda.mda caps it.
@_inline
def null_step(Y, a, out, grad, u, gain, max_step, n) -> None:  # pragma: no cover - numba
    """``out = a − s α N ∇K`` (``grad ← α N ∇K``, ``N = I − YᵀY``; ``out`` may be ``a``).

    ``s = min(1, max_step / ‖α N ∇K‖)``, 0 when that norm is not finite (no usable direction, as
    :func:`fault_tolerance.resolution.mda.mda`); ``u`` (m) scratch.
    """
    null_apply(Y, grad, u, n)  # ∇K ← N ∇K
    size = 0.0
    for c in range(n):
        grad[c] *= gain
        size += grad[c] * grad[c]
    size = math.sqrt(size)
    scale = 1.0
    if not size < _INF:  # ∇K overflowed: no usable direction (as mda.mda)
        scale = 0.0
    elif size > max_step:
        scale = max_step / size
    for c in range(n):
        out[c] = a[c] - grad[c] * scale if scale != 0.0 else a[c]
