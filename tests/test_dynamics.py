"""model/dynamics.py and simulation/brakes.py: the arm's dynamics against independent oracles."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import DynamicsUnavailable, InvalidInput
from fault_tolerance.model.dynamics import ArmDynamics
from fault_tolerance.simulation.brakes import held_accelerations, ideal_brake
from fault_tolerance.simulation.torque import DynamicsModel, _Arm, _substep

ARMS = ["planar_3r", "spatial_4r", "powercube_3r", "panda"]


def _dyn(name: str, **kw) -> tuple[ft.Arm, ArmDynamics]:
    arm = ft.load_arm(name)
    return arm, ArmDynamics(arm, **kw)


def _state(arm, rng):
    q = np.clip(arm.random_q(rng), -3.0, 3.0)
    return q, rng.normal(size=arm.n), rng.normal(size=arm.n)


@pytest.mark.parametrize("name", ARMS)
def test_rnea_and_aba_invert_each_other(name):
    """τ = RNEA(q, q̇, q̈) fed to ABA gives back q̈, and ABA's q̈ fed to RNEA gives back τ."""
    arm, dyn = _dyn(name)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q, qd, qdd = _state(arm, rng)
        tau = dyn.inverse(q, qd, qdd)
        np.testing.assert_allclose(dyn.forward(q, qd, tau), qdd, atol=1e-8)
        tau2 = rng.normal(size=arm.n)
        np.testing.assert_allclose(dyn.inverse(q, qd, dyn.forward(q, qd, tau2)), tau2, atol=1e-8)


@pytest.mark.parametrize("name", ARMS)
def test_inverse_dynamics_is_mass_matrix_times_acceleration_plus_bias(name):
    """RNEA(q, q̇, q̈) = M(q) q̈ + h(q, q̇), M symmetric positive definite."""
    arm, dyn = _dyn(name)
    q, qd, qdd = _state(arm, np.random.default_rng(2))
    M = dyn.mass_matrix(q)
    np.testing.assert_allclose(M, M.T, atol=1e-14)
    assert np.linalg.eigvalsh(M).min() > 0
    np.testing.assert_allclose(dyn.inverse(q, qd, qdd), M @ qdd + dyn.bias(q, qd), atol=1e-9)


@pytest.mark.parametrize("name", ARMS)
def test_central_differences_of_the_dynamics(name):
    """∂τ/∂q̈ = M, ∂q̈/∂τ = M⁻¹, ∂T/∂q̇ = M q̇, and ∂τ/∂q matches Pinocchio's RNEA derivatives."""
    arm, dyn = _dyn(name)
    q, qd, qdd = _state(arm, np.random.default_rng(3))
    h, n = 1e-6, arm.n
    eye = np.eye(n)
    dtau_dqdd = np.column_stack(
        [(dyn.inverse(q, qd, qdd + h * e) - dyn.inverse(q, qd, qdd - h * e)) / (2 * h) for e in eye]
    )
    M = dyn.mass_matrix(q)
    np.testing.assert_allclose(dtau_dqdd, M, atol=1e-5)
    tau = dyn.inverse(q, qd, qdd)
    dqdd_dtau = np.column_stack(
        [(dyn.forward(q, qd, tau + h * e) - dyn.forward(q, qd, tau - h * e)) / (2 * h) for e in eye]
    )
    np.testing.assert_allclose(
        dqdd_dtau, np.linalg.inv(M), atol=1e-5 * np.abs(np.linalg.inv(M)).max()
    )
    dT = [
        (dyn.kinetic_energy(q, qd + h * e) - dyn.kinetic_energy(q, qd - h * e)) / (2 * h)
        for e in eye
    ]
    np.testing.assert_allclose(dT, M @ qd, atol=1e-5)
    dtau_dq = np.column_stack(
        [(dyn.inverse(q + h * e, qd, qdd) - dyn.inverse(q - h * e, qd, qdd)) / (2 * h) for e in eye]
    )
    pin.computeRNEADerivatives(dyn.model, dyn.data, q, qd, qdd)
    np.testing.assert_allclose(dtau_dq, dyn.data.dtau_dq, atol=1e-4)


# -- the planar 3R by hand ------------------------------------------------------------------
L, A, MASS, IZZ = 0.5, 0.25, 1.0, 0.0208  # link length, centre of mass, mass, I_zz about it


def _hand_mass_matrix(q):
    """M(q) of three equal links (L, centre at A, mass m, I about the centre), by hand."""
    c2, c3, c23 = np.cos(q[1]), np.cos(q[2]), np.cos(q[1] + q[2])
    m, i = MASS, IZZ
    m33 = i + m * A**2
    m23 = m33 + m * L * A * c3
    m22 = 2 * i + m * A**2 + m * (L**2 + A**2 + 2 * L * A * c3)
    m13 = m33 + m * L * A * (c3 + c23)
    m12 = (
        2 * i
        + m * (A**2 + L * A * c2)
        + m * (L**2 + A**2 + L**2 * c2 + 2 * L * A * c3 + L * A * c23)
    )
    m11 = (
        3 * i
        + m * A**2
        + m * (L**2 + A**2 + 2 * L * A * c2)
        + m * (2 * L**2 + A**2 + 2 * L**2 * c2 + 2 * L * A * c3 + 2 * L * A * c23)
    )
    return np.array([[m11, m12, m13], [m12, m22, m23], [m13, m23, m33]])


def _hand_mass_derivatives(q):
    """∂M/∂q_k, k = 1..3, by differentiating the entries above by hand."""
    s2, s3, s23 = np.sin(q[1]), np.sin(q[2]), np.sin(q[1] + q[2])
    m = MASS
    d2 = np.zeros((3, 3))
    d2[0, 0] = -m * (2 * L * A * s2) - m * (2 * L**2 * s2 + 2 * L * A * s23)
    d2[0, 1] = d2[1, 0] = -m * L * A * s2 - m * (L**2 * s2 + L * A * s23)
    d2[0, 2] = d2[2, 0] = -m * L * A * s23
    d3 = np.zeros((3, 3))
    d3[0, 0] = -m * (2 * L * A * s3 + 2 * L * A * s23)
    d3[0, 1] = d3[1, 0] = -m * (2 * L * A * s3 + L * A * s23)
    d3[0, 2] = d3[2, 0] = -m * L * A * (s3 + s23)
    d3[1, 1] = -m * 2 * L * A * s3
    d3[1, 2] = d3[2, 1] = -m * L * A * s3
    return [np.zeros((3, 3)), d2, d3]


def _hand_bias(q, qd):
    """Coriolis and centrifugal torques from the Christoffel symbols of the hand M(q)."""
    dM = _hand_mass_derivatives(q)
    return np.array(
        [
            sum(
                (dM[k][i, j] - 0.5 * dM[i][j, k]) * qd[j] * qd[k]
                for j in range(3)
                for k in range(3)
            )
            for i in range(3)
        ]
    )


def _hand_gravity(q, g):
    """Torques of gravity ``g`` (2-vector in the arm's plane): τ_i = −Σ_k m g·∂c_k/∂q_i."""
    t = np.cumsum(q)
    # centre of link k: Σ_{l<k} L (cos t_l, sin t_l) + A (cos t_k, sin t_k)
    out = np.zeros(3)
    for i in range(3):
        for k in range(i, 3):
            grad = A * np.array([-np.sin(t[k]), np.cos(t[k])])
            grad += sum(L * np.array([-np.sin(t[j]), np.cos(t[j])]) for j in range(i, k))
            out[i] -= MASS * g @ grad
    return out


def test_planar_3r_equations_of_motion_by_hand():
    """M(q), C(q, q̇)q̇ and g(q) derived by hand equal Pinocchio's on the shipped planar_3r URDF."""
    arm, dyn = _dyn("planar_3r")
    rng = np.random.default_rng(4)
    for _ in range(5):
        q, qd = rng.uniform(-3, 3, 3), rng.normal(size=3)
        np.testing.assert_allclose(dyn.mass_matrix(q), _hand_mass_matrix(q), atol=1e-12)
        np.testing.assert_allclose(dyn.bias(q, qd), _hand_bias(q, qd), atol=1e-12)
        np.testing.assert_allclose(dyn.gravity(q), 0.0, atol=1e-12)  # z axes, gravity along −z
    dyn.model.gravity = pin.Motion(np.array([0.0, -9.81, 0.0]), np.zeros(3))  # in the plane
    q = rng.uniform(-3, 3, 3)
    np.testing.assert_allclose(dyn.gravity(q), _hand_gravity(q, np.array([0.0, -9.81])), atol=1e-12)


def test_hand_derivatives_match_central_differences():
    """The hand ∂M/∂q agree with central differences of the hand M (the oracle is itself checked)."""
    q, h = np.array([0.3, -1.1, 0.7]), 1e-6
    for k in range(3):
        e = np.eye(3)[k] * h
        fd = (_hand_mass_matrix(q + e) - _hand_mass_matrix(q - e)) / (2 * h)
        np.testing.assert_allclose(_hand_mass_derivatives(q)[k], fd, atol=1e-8)


# -- energy and brakes ----------------------------------------------------------------------
def _energy_drift(arm, h: float, T: float = 0.5) -> float:
    dyn = ArmDynamics(arm, gravity=False)
    st = _Arm(
        q=np.array([0.3, 1.0, -0.8] + [0.2] * (arm.n - 3)), qd=np.ones(arm.n), keep=np.arange(arm.n)
    )
    E0 = dyn.kinetic_energy(st.q, st.qd)
    drift = 0.0
    for _ in range(int(round(T / h))):
        _substep(dyn, st, np.zeros(arm.n), None, DynamicsModel(), h)
        drift = max(drift, abs(dyn.kinetic_energy(st.q, st.qd) - E0) / E0)
    return drift


@pytest.mark.parametrize("name", ["planar_3r", "spatial_4r"])
def test_free_arm_conserves_energy_to_the_integrators_order(name):
    """Without gravity and torque the energy error is small, and halves with the step (order 1)."""
    arm = ft.load_arm(name)
    coarse, fine = _energy_drift(arm, 2e-3), _energy_drift(arm, 1e-3)
    assert fine < 0.02
    assert 1.6 < coarse / fine < 2.5


@pytest.mark.parametrize("name", ARMS)
def test_ideal_brake_impulse_is_mass_matrix_times_the_velocity_jump(name):
    """M Δq̇ = −Eᵀλ (the impulse acts on the locked joint only), q̇ᵢ⁺ = 0, λ = q̇ᵢ⁻/(M⁻¹)ᵢᵢ, ΔT ≤ 0."""
    arm, dyn = _dyn(name)
    rng = np.random.default_rng(5)
    q, qd, _ = _state(arm, rng)
    M = dyn.mass_matrix(q)
    for i in range(arm.n):
        out = ideal_brake(M, qd, [i])
        p = M @ out.dqd
        expected = np.zeros(arm.n)
        expected[i] = -out.impulse[0]
        np.testing.assert_allclose(p, expected, atol=1e-10 * max(1.0, np.abs(M).max()))
        assert out.qd[i] == 0.0
        np.testing.assert_allclose(out.impulse[0], qd[i] / np.linalg.inv(M)[i, i], rtol=1e-9)
        dT = -0.5 * out.impulse[0] ** 2 * np.linalg.inv(M)[i, i]
        np.testing.assert_allclose(out.energy_jump, dT, rtol=1e-8, atol=1e-12)
        assert out.energy_jump <= 0


def test_held_joint_dynamics_is_the_constrained_solution():
    """With joint 2 held, q̈ solves the KKT system of the constraint q̈₂ = 0."""
    arm, dyn = _dyn("spatial_4r")
    q, qd, _ = _state(arm, np.random.default_rng(6))
    M, h, tau = dyn.mass_matrix(q), dyn.bias(q, qd), np.array([1.0, -2.0, 0.5, 0.3])
    E = np.eye(4)[[1]]
    kkt = np.block([[M, E.T], [E, np.zeros((1, 1))]])
    ref = np.linalg.solve(kkt, np.concatenate([tau - h, [0.0]]))[:4]
    np.testing.assert_allclose(held_accelerations(M, h, tau, np.array([0, 2, 3])), ref, atol=1e-10)


# -- descriptions ---------------------------------------------------------------------------
def _massless_urdf(tmp_path):
    from pathlib import Path

    urdf = (Path(__file__).resolve().parents[1] / "robots" / "planar_3r.urdf").read_text()
    start = urdf.index("<inertial>", urdf.index('<link name="link2">'))
    end = urdf.index("</inertial>", start) + len("</inertial>")
    path = tmp_path / "massless.urdf"
    path.write_text(urdf[:start] + urdf[end:])
    return path


def test_description_without_inertia_is_refused_or_takes_default_masses(tmp_path):
    """A link without <inertial> is refused by name; default_mass gives it a documented sphere."""
    arm = ft.load_arm(str(_massless_urdf(tmp_path)), tip="tool", task="planar")
    with pytest.raises(DynamicsUnavailable, match="link2|joint2.*mass 0"):
        ArmDynamics(arm)
    dyn = ArmDynamics(arm, default_mass=0.5)
    assert dyn.default_masses
    assert float(dyn.model.inertias[2].mass) == pytest.approx(0.5)
    with pytest.raises(InvalidInput, match="default_mass"):
        ArmDynamics(arm, default_mass=-1.0)


@pytest.mark.parametrize("name", ["planar_3r", "spatial_4r", "powercube_3r"])
def test_shipped_arms_have_effort_limits_and_their_documented_masses(name):
    """Every shipped joint has a finite effort limit; the masses are the URDF comments' numbers."""
    arm, dyn = _dyn(name)
    assert np.all(np.isfinite(dyn.effort)) and np.all(dyn.effort > 0)
    masses = [float(dyn.model.inertias[j].mass) for j in range(1, dyn.model.njoints)]
    expected = {
        "planar_3r": [1.0, 1.0, 1.0],
        "spatial_4r": [2.0, 0.5, 1.2, 0.8],
        "powercube_3r": [3.745, 1.96, 1.315],
    }[name]
    np.testing.assert_allclose(masses, expected, atol=1e-9)
