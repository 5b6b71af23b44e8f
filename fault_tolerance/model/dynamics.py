"""Rigid-body dynamics of an arm: inertias, gravity and effort limits from its description.

:class:`ArmDynamics` wraps a copy of the arm's Pinocchio model (the active joints; the others
fixed by ``pin.buildReducedModel``, which merges their inertias into the bodies that carry them)
and answers the questions a torque-level simulation asks: the joint-space inertia ``M(q)`` (CRBA),
the bias ``h(q, q̇) = C(q, q̇) q̇ + g(q)`` and gravity ``g(q)`` (RNEA), inverse dynamics
``τ = M q̈ + h`` (RNEA), forward dynamics ``q̈ = M⁻¹(τ − h)`` (ABA), the kinetic energy
``½ q̇ᵀ M q̇`` and the effort limits of the URDF's ``<limit effort=...>``.

A description without usable inertias (a moving body of zero or non-finite mass, an inertia
that is not positive definite, a singular ``M(q)``) is refused for dynamics with
:class:`~fault_tolerance.errors.DynamicsUnavailable`, unless the caller asks for documented
default masses (``default_mass=`` [kg]): each such body then becomes a solid sphere of that mass
and radius :data:`DEFAULT_RADIUS` at its joint origin (docs/dynamics.md).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import DynamicsUnavailable, InvalidInput

#: Radius [m] of the solid sphere a massless body becomes with ``default_mass=``.
DEFAULT_RADIUS = 0.05
#: Bodies lighter than this [kg] carry no usable inertia.
MIN_MASS = 1e-9


def _body_problems(model: pin.Model) -> list[str]:
    """The moving bodies whose inertia cannot serve dynamics, one phrase each."""
    out = []
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        mass = float(inertia.mass)
        if not np.isfinite(mass) or mass < MIN_MASS:
            out.append(f"'{model.names[j]}' carries mass {mass:g} kg")
            continue
        eig = np.linalg.eigvalsh(np.asarray(inertia.inertia))
        if not np.all(np.isfinite(eig)) or eig.min() < -1e-12:
            out.append(f"'{model.names[j]}' has an inertia tensor with eigenvalues {eig.tolist()}")
    return out


def _with_default_masses(model: pin.Model, mass: float) -> pin.Model:
    """A copy of ``model`` whose massless bodies are solid spheres of ``mass`` [kg]."""
    if not (np.isfinite(mass) and mass > 0):
        raise InvalidInput(f"default_mass must be a finite mass > 0 [kg], got {mass}")
    model = pin.Model(model)
    sphere = pin.Inertia.FromSphere(mass, DEFAULT_RADIUS)
    for j in range(1, model.njoints):
        if not float(model.inertias[j].mass) >= MIN_MASS:
            model.inertias[j] = sphere
    return model


class ArmDynamics:
    """Joint-space dynamics of an arm's active joints (a plain wrapper of ``pin.Model``/``Data``).

    Args:
        arm: The arm (:class:`~fault_tolerance.model.arm.Arm`); its model is copied.
        default_mass: Mass [kg] given to every moving body without one (None: refuse them).
        gravity: Gravity on (the model's, ``(0, 0, −9.81)`` m/s² for a URDF) or off.

    Raises:
        DynamicsUnavailable: a moving body has no usable inertia and no ``default_mass`` is given,
            or ``M(q)`` is not positive definite at the arm's reference posture.
    """

    def __init__(self, arm, *, default_mass: float | None = None, gravity: bool = True) -> None:
        model = pin.Model(arm.model)
        label = arm.source or arm.name
        bad = _body_problems(model)
        if bad and default_mass is None:
            raise DynamicsUnavailable(
                f"{label}: no usable inertias for dynamics: {'; '.join(bad)}; give every moving "
                "link an <inertial> block with mass > 0, or ask for default masses "
                "(default_mass=KG, --default-mass KG: solid spheres of radius "
                f"{DEFAULT_RADIUS} m at the joint origins)"
            )
        if bad and default_mass is not None:
            model = _with_default_masses(model, float(default_mass))
        if not gravity:
            model.gravity = pin.Motion.Zero()
        self.model = model
        self.data = model.createData()
        self.n = model.nv
        self.default_masses = bool(bad)
        effort = np.asarray(model.effortLimit, dtype=float).copy()
        #: Effort limits [N·m or N]; inf where the description gives none (0 or not finite).
        self.effort = np.where(np.isfinite(effort) & (effort > 0), effort, np.inf)
        M = self.mass_matrix(np.asarray(arm.q_reference, dtype=float))
        if not np.all(np.isfinite(M)) or np.linalg.eigvalsh(M).min() <= 0:
            raise DynamicsUnavailable(
                f"{label}: the joint-space inertia M(q) is not positive definite at the "
                "reference posture (a joint moves no mass); check the <inertial> blocks"
            )

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """``M(q)`` [kg·m²], shape (n, n), symmetric (CRBA fills the upper triangle)."""
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """``h(q, q̇) = C(q, q̇) q̇ + g(q)`` [N·m], shape (n,)."""
        return np.asarray(pin.nonLinearEffects(self.model, self.data, q, qd)).copy()

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """``g(q)`` [N·m], shape (n,)."""
        return np.asarray(pin.computeGeneralizedGravity(self.model, self.data, q)).copy()

    def inverse(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Inverse dynamics ``τ = M(q) q̈ + h(q, q̇)`` by RNEA [N·m], shape (n,)."""
        return np.asarray(pin.rnea(self.model, self.data, q, qd, qdd)).copy()

    def forward(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Forward dynamics ``q̈ = M(q)⁻¹(τ − h(q, q̇))`` by ABA [rad/s²], shape (n,)."""
        return np.asarray(pin.aba(self.model, self.data, q, qd, tau)).copy()

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """``½ q̇ᵀ M(q) q̇`` [J]."""
        return float(0.5 * qd @ self.mass_matrix(q) @ qd)

    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy [J] (zero with gravity off)."""
        return float(pin.computePotentialEnergy(self.model, self.data, q))
