"""The built-in resolvers, registered, and the plain :func:`resolve` over the registry.

Every resolver maps a task Jacobian ``J`` (m, n) and task velocity ``ẋ`` (m,) to joint rates
``q̇`` (n,) with ``J q̇ = ẋ`` (up to damping near singularities, see
:mod:`fault_tolerance.numerics.linalg`). Resolvers hold no state. Each is one module
(:mod:`.lnva`, :mod:`.jvja`, :mod:`.mda`, :mod:`.inertia_jvja`) plus one :class:`~.registry.ResolverEntry`, registered
here; :func:`resolve` is the reference of :func:`fault_tolerance.resolve` (which adds ``bounds=``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from fault_tolerance.resolution.bounded import bounded_jvja, bounded_nearest
from fault_tolerance.resolution.indices import jvj
from fault_tolerance.resolution.inertia_jvja import (
    JvjaInertiaOptions,
    bounded_jvja_inertia,
    jvja_inertia,
)
from fault_tolerance.resolution.jvja import JvjaOptions, jvja
from fault_tolerance.resolution.lnva import LnvaOptions, lnva
from fault_tolerance.resolution.mda import MdaOptions, mda
from fault_tolerance.resolution.registry import (
    KERNEL_JVJA,
    KERNEL_LNVA,
    KERNEL_MDA,
    ResolverEntry,
    check_task,
    get,
    register,
    split,
)
from fault_tolerance.resolution.scenarios import scenarios

#: The paper's resolvers' entries, registered when this module is imported (the CLI's default).
BUILTINS = (
    register(
        ResolverEntry(
            "lnva", lnva, LnvaOptions, bounded=bounded_nearest(lnva), compiled=KERNEL_LNVA,
            label="LNVA (least norm)", colour="#1f77b4",
            description="least-norm rates J⁺ẋ",
        ),
        replace=True,
    ),
    register(
        ResolverEntry(
            "jvja", jvja, JvjaOptions, bounded=bounded_jvja, compiled=KERNEL_JVJA,
            label="JVJA (minimum jump)", colour="#d62728",
            description="minimum square-sum joint velocity jump, eq. (5)",
        ),
        replace=True,
    ),
    register(
        ResolverEntry(
            "mda", mda, MdaOptions, bounded=bounded_nearest(mda), compiled=KERNEL_MDA,
            label="MDA (maximum dexterity)", colour="#2ca02c", needs_configuration=True,
            description="maximum dexterity: J⁺ẋ − α N ∇K",
        ),
        replace=True,
    ),
)  # fmt: skip

#: The inertia-weighted JVJA (docs/MATH.md (D3)), registered after the paper's three: it needs the
#: arm's inertias (:class:`~fault_tolerance.model.dynamics.ArmDynamics`), so it is not a default.
JVJA_INERTIA = register(
    ResolverEntry(
        "jvja_inertia", jvja_inertia, JvjaInertiaOptions, bounded=bounded_jvja_inertia,
        label="JVJA, inertia-weighted (minimum energy jump)", colour="#9467bd",
        needs_configuration=True,
        description="minimum square-sum kinetic-energy jump in the metric M(q), (D3)",
    ),
    replace=True,
)  # fmt: skip


def resolve(name: str, J: np.ndarray, xdot: np.ndarray, lockable=None, **options) -> np.ndarray:
    """Joint rates from the registered resolver ``name`` (``registry.names()``), no joint limits.

    Args:
        name: Resolver name (:func:`fault_tolerance.resolution.registry.names`).
        J: Task Jacobian, shape (m, n).
        xdot: Task velocity, shape (m,).
        lockable: Joints that may lock: column indices, names (with ``joint_names=``), tuples for
            multi-joint scenarios, ``None``/``"all"`` for every joint, or a :class:`Scenarios`.
        **options: The resolver's own options (its options dataclass: ``weights``, ``response``
            for jvja; ``gain``, ``max_step`` for mda; ``weights`` for jvja_inertia; none for
            lnva), and the context ``proj``,
            ``tolerate``, ``joint_names``, ``arm``, ``q``, ``dJ``, ``M`` (``registry.CONTEXT``; a
            resolver takes what it needs). An option the resolver does not take raises
            :class:`InvalidInput` naming its options. The joint limits (``bounds=``) are
            :func:`fault_tolerance.resolve`'s (:mod:`fault_tolerance.resolution.api`).

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> arm = ft.load_arm("planar_3r")
        >>> q = np.array([0.3, 1.2, 1.0]); J = arm.jacobian(q); xd = np.array([0.1, 0.0])
        >>> qd = ft.resolve("jvja", J, xd, lockable=[1, 2])
        >>> bool(np.allclose(J @ qd, xd))
        True
    """
    entry = get(name)
    entry.make_options(split(options)[1])  # an unknown option raises before any work
    J, xdot = check_task(J, xdot)
    return entry.call(J, xdot, lockable, **options)


class JumpReduction(NamedTuple):
    """Eq. (14) at one configuration: measured and predicted reduction of the jump."""

    delta: float  # λ(q̇_LN) - λ(q̇_OPT)
    predicted: float  # (Σ w_S) ‖q̇_H‖²
    qd_h: np.ndarray  # null-space part q̇_OPT - q̇_LN


# Eqn. (11)-(14)
def jump_reduction(
    J: np.ndarray, xdot: np.ndarray, lockable=None, *, weights=None, joint_names: Sequence[str] = ()
) -> JumpReduction:
    r"""δ = λ(q̇_LN) − λ(q̇_OPT) and its closed form :math:`f\,\|\dot q_H\|^2`, eq. (14)."""
    J = np.asarray(J, dtype=float)
    m, n = J.shape
    sc = scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)
    ln = lnva(J, xdot)
    opt = jvja(J, xdot, sc)
    delta = jvj(J, xdot, ln, sc) - jvj(J, xdot, opt, sc)
    qd_h = opt - ln
    return JumpReduction(delta, float(sc.weights.sum() * qd_h @ qd_h), qd_h)
