"""MDA, the maximum-dexterity algorithm: ``q̇ = J⁺ẋ − α N ∇K`` (the paper's comparison).

It needs the configuration (``arm`` and ``q``, or the Jacobian derivatives ``dJ``). Its options
(:class:`MdaOptions`): the ``gain`` α and the cap ``max_step`` of the null-space step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import Projection, projection
from fault_tolerance.resolution.indices import rcn_gradient

#: Default MDA gain α [rad² per unit of K per s]: q̇ = J⁺ẋ − α N ∇K.
MDA_GAIN = 1e-2
#: Largest norm of MDA's null-space step α N ∇K [rad/s]: a numerical guard, not a speed limit.
#: Near a singularity of J or of a reduced Jacobian ∇K grows like k³ (k up to indices.RCN_MAX ≈ 1e8,
#: steps up to ~1e21 rad/s that no longer satisfy J q̇ = ẋ); the step keeps its direction and is
#: capped here. Ordinary steps are far below it (the paper's cases: < 0.1 rad/s).
MDA_MAX_STEP = 1e4


@dataclass(frozen=True)
class MdaOptions:
    """MDA's options: the gain α >= 0 and the cap of its null-space step [rad/s] (None: none)."""

    gain: float = MDA_GAIN
    max_step: float | None = MDA_MAX_STEP

    def __post_init__(self) -> None:
        if not np.isfinite(self.gain) or self.gain < 0:
            raise InvalidInput(f"mda gain must be finite and >= 0, got {self.gain}")
        if self.max_step is not None and not self.max_step > 0:
            raise InvalidInput(f"mda max_step must be > 0 [rad/s] or None, got {self.max_step}")


# MDA (MATH.md "Resolvers"), the gradient of K from eq. (15).
def mda(
    J: np.ndarray,
    xdot: np.ndarray,
    lockable=None,
    *,
    arm=None,
    q: np.ndarray | None = None,
    gain: float = MDA_GAIN,
    dJ: np.ndarray | None = None,
    joint_names: Sequence[str] = (),
    max_step: float | None = MDA_MAX_STEP,
    proj: Projection | None = None,
) -> np.ndarray:
    r"""MDA, maximum dexterity: :math:`\dot q = J^+\dot x - \alpha N \nabla_q K(q)`.

    ``K = Σ_S k_S²`` is the square-sum reduced condition number (15); its gradient uses the
    Jacobian derivatives of ``arm`` at ``q`` (or ``dJ`` given directly, shape (n, m, n)).
    Default gain :data:`MDA_GAIN`. The null-space step is capped at ``max_step`` [rad/s]
    (:data:`MDA_MAX_STEP`; ``None``: no cap), so the rates stay finite and in the null space near
    singularities; a step that is not finite is dropped.
    """
    if dJ is None:
        if arm is None or q is None:
            raise InvalidInput("mda needs the configuration: pass arm=... and q=... (or dJ=...)")
        dJ = arm.jacobian_derivatives(q)
    if not np.isfinite(gain) or gain < 0:
        raise InvalidInput(f"mda gain must be finite and >= 0, got {gain}")
    proj = proj or projection(J)
    grad = rcn_gradient(J, dJ, lockable, joint_names=joint_names)
    step = gain * proj.N @ grad  # [rad/s], shape (n,)
    size = float(np.linalg.norm(step))
    if not np.isfinite(size):  # ∇K overflowed at a reduced singularity: no usable direction
        step = np.zeros_like(step)
    elif max_step is not None and size > max_step:
        step *= max_step / size
    return proj.Jpinv @ xdot - step
