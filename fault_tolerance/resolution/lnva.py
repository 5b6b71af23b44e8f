"""LNVA, the least-norm velocity algorithm: ``q̇ = J⁺ẋ`` (the paper's baseline).

LNVA takes no options; ``lockable`` is accepted and ignored (it knows no scenarios).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.numerics.linalg import Projection, projection


@dataclass(frozen=True)
class LnvaOptions:
    """LNVA has no options."""


# LNVA (MATH.md "Resolvers"): the least-norm solution of J q̇ = ẋ.
def lnva(
    J: np.ndarray, xdot: np.ndarray, lockable=None, *, proj: Projection | None = None
) -> np.ndarray:
    r"""LNVA, least-norm rates :math:`\dot q = J^+\dot x` (``lockable`` is accepted and ignored).

    ``proj``: the :func:`~fault_tolerance.numerics.linalg.projection` of ``J`` when the caller has
    it already. Shape (n,) [rad/s].
    """
    return (proj or projection(J)).Jpinv @ xdot
