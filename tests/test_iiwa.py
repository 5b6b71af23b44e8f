"""The shipped KUKA LBR iiwa 14 R820 (robots/iiwa.urdf): loading, geometry, Jacobian, JVJA, CLI.

Reference numbers: iiwa_description's iiwa14.xacro (IFL-CAMP/iiwa_stack) gives the joint origins;
the equivalent D-H distances are d1 = 0.36, d3 = 0.42, d5 = 0.40, d7 = 0.126 m (0.045 m flange
included), so the stretched arm (q = 0) reaches 1.306 m straight up. Limits are the data-sheet
values quoted in the URDF's comments.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import IntolerableFailure
from fault_tolerance.model.catalog import catalog
from fault_tolerance.numerics.linalg import projection, reduced_rates

H = 1e-6  # central-difference step [rad]
FD_TOL = 1e-6
NAMES = [f"joint{i}" for i in range(1, 8)]
LOCKABLE = ["joint1", "joint2", "joint3", "joint5", "joint6", "joint7"]


@pytest.fixture(scope="module")
def iiwa() -> ft.Arm:
    return ft.load_arm("iiwa")


def _origins(arm: ft.Arm, q: np.ndarray) -> dict[str, np.ndarray]:
    """World positions of the joint origins and of the tool frame, from Pinocchio."""
    pin.framesForwardKinematics(arm.model, arm.data, q)
    out = {name: arm.data.oMi[arm.model.getJointId(name)].translation.copy() for name in NAMES}
    out["tool"] = arm.data.oMf[arm.model.getFrameId("tool")].translation.copy()
    return out


# -- loading --------------------------------------------------------------------------------


def test_loads_by_name_with_its_catalog_presets(iiwa):
    """`load_arm("iiwa")`: 7 joints joint1…joint7, tip 'tool', pose task, r = 1."""
    assert iiwa.name == "iiwa" and iiwa.source == "iiwa"
    assert iiwa.tip == "tool"
    assert iiwa.joint_names == NAMES
    assert (iiwa.n, iiwa.m, iiwa.redundancy) == (7, 6, 1)
    assert iiwa.task == ("x", "y", "z", "rx", "ry", "rz")
    assert iiwa.default_lockable == LOCKABLE
    assert iiwa.model.existFrame("base_link")
    assert iiwa.visual_model is not None and iiwa.visual_model.ngeoms > 0


def test_position_task_has_redundancy_four():
    arm = ft.load_arm("iiwa", task="position")
    assert (arm.n, arm.m, arm.redundancy) == (7, 3, 4)


def test_limits_are_the_data_sheet_values(iiwa):
    """±170/120/170/120/170/120/175° and 85/85/100/75/130/135/135 °/s."""
    np.testing.assert_allclose(np.degrees(iiwa.upper), [170, 120, 170, 120, 170, 120, 175])
    np.testing.assert_allclose(np.degrees(iiwa.lower), [-170, -120, -170, -120, -170, -120, -175])
    np.testing.assert_allclose(np.degrees(iiwa.velocity_limit), [85, 85, 100, 75, 130, 135, 135])


def test_reference_posture_comes_from_the_catalog_and_is_regular(iiwa):
    """The catalog's q_reference reaches Arm.q_reference; it is inside the limits, not singular,
    and every default-lockable joint is tolerable there (q = 0, the stretched arm, is singular)."""
    q = iiwa.q_reference
    np.testing.assert_array_equal(q, catalog()["iiwa"]["q_reference"])
    assert np.all(q > iiwa.lower) and np.all(q < iiwa.upper)
    proj = projection(iiwa.jacobian(q))
    assert proj.sigma_min > 0.1
    assert min(proj.N[i, i] for i in map(iiwa.joint_index, LOCKABLE)) > 0.05
    assert projection(iiwa.jacobian(np.zeros(7))).sigma_min < 1e-9
    assert iiwa.fk(q)[2] > 0.3  # tool well above the base


def test_a_joint_subset_is_fixed_at_the_reference_posture(iiwa):
    """With `joints=`, the left-out joint is fixed at its catalog reference value."""
    arm = ft.load_arm("iiwa", joints=[n for n in NAMES if n != "joint3"])
    assert arm.joint_names == [n for n in NAMES if n != "joint3"]
    q_ref = iiwa.q_reference
    np.testing.assert_array_equal(arm.q_reference, np.delete(q_ref, 2))
    np.testing.assert_allclose(arm.fk(arm.q_reference), iiwa.fk(q_ref), atol=1e-12)


# -- geometry -------------------------------------------------------------------------------


def test_dh_distances_from_pinocchio_placements(iiwa):
    """d1 = 0.36, d3 = 0.42, d5 = 0.40, d7 = 0.126 m; tool at (0, 0, 1.306) m at q = 0."""
    p = _origins(iiwa, np.zeros(7))
    shoulder, elbow, wrist, tool = p["joint2"], p["joint4"], p["joint6"], p["tool"]
    assert np.linalg.norm(shoulder) == pytest.approx(0.36, abs=1e-12)
    assert np.linalg.norm(elbow - shoulder) == pytest.approx(0.42, abs=1e-12)
    assert np.linalg.norm(wrist - elbow) == pytest.approx(0.40, abs=1e-12)
    assert np.linalg.norm(tool - wrist) == pytest.approx(0.126, abs=1e-12)
    assert np.linalg.norm(wrist - shoulder) == pytest.approx(0.82, abs=1e-12)
    np.testing.assert_allclose(tool, [0, 0, 1.306], atol=1e-12)
    # spherical shoulder (axes 1-3 meet at joint2) and wrist (axes 5-7 meet at joint6)
    np.testing.assert_allclose(p["joint1"][:2], 0, atol=1e-12)
    np.testing.assert_allclose(p["joint3"], [0, 0, 0.36 + 0.2045], atol=1e-12)
    np.testing.assert_allclose(p["joint7"], [0, 0, 1.18 + 0.081], atol=1e-12)


def test_shoulder_wrist_distance_depends_on_joint4_alone(iiwa, rng):
    """|wrist − shoulder|² = 0.42² + 0.40² + 2·0.42·0.40·cos q4 at any q: the SRS structure that
    makes joint4 intolerable for the pose task (N₄₄ = 0), so the catalog leaves it out."""
    for _ in range(20):
        q = iiwa.random_q(rng)
        p = _origins(iiwa, q)
        dist2 = np.sum((p["joint6"] - p["joint2"]) ** 2)
        assert dist2 == pytest.approx(0.42**2 + 0.40**2 + 2 * 0.42 * 0.40 * np.cos(q[3]), abs=1e-12)
        assert abs(projection(iiwa.jacobian(q)).N[3, 3]) < 1e-8


# -- Jacobian and JVJA ----------------------------------------------------------------------


def _fd_jacobian(arm: ft.Arm, q: np.ndarray) -> np.ndarray:
    """Central differences of the tool placement: linear rows from positions, angular rows from
    ``log3(R(q + h e_j) R(q − h e_j)ᵀ) / 2h`` (world axes, as LOCAL_WORLD_ALIGNED)."""
    J = np.zeros((6, arm.n))
    for j in range(arm.n):
        e = np.zeros(arm.n)
        e[j] = H
        Mp, Mm = arm.placement(q + e), arm.placement(q - e)
        J[:3, j] = (Mp.translation - Mm.translation) / (2 * H)
        J[3:, j] = pin.log3(Mp.rotation @ Mm.rotation.T) / (2 * H)
    return J


def test_jacobian_matches_finite_differences_of_fk(iiwa, rng):
    """Pose Jacobian vs central differences of the tool placement, at the reference and random q."""
    for q in [iiwa.q_reference] + [iiwa.random_q(rng) for _ in range(5)]:
        np.testing.assert_allclose(iiwa.jacobian(q), _fd_jacobian(iiwa, q), atol=FD_TOL)
    arm = ft.load_arm("iiwa", task="position")
    q = arm.random_q(rng)
    fd = np.column_stack([(arm.fk(q + H * e) - arm.fk(q - H * e)) / (2 * H) for e in np.eye(7)])
    np.testing.assert_allclose(arm.jacobian(q), fd, atol=FD_TOL)


def test_jvja_rates_track_the_task_at_the_reference_posture(iiwa, rng):
    """JVJA q̇ satisfies J q̇ = ẋ; after any default-lockable joint locks, the reduced rates still
    track ẋ with that joint at rest. Locking joint4 is refused as intolerable."""
    q = iiwa.q_reference
    J = iiwa.jacobian(q)
    proj = projection(J)
    for _ in range(5):
        xdot = rng.normal(size=6) * np.r_[0.1, 0.1, 0.1, 0.3, 0.3, 0.3]
        qd = ft.jvja(J, xdot, LOCKABLE, joint_names=iiwa.joint_names)
        np.testing.assert_allclose(J @ qd, xdot, atol=1e-10)
        a = proj.Jpinv @ xdot
        for i in map(iiwa.joint_index, LOCKABLE):
            qd_i = reduced_rates(a, proj.N, [i])
            assert qd_i[i] == 0.0
            np.testing.assert_allclose(J @ qd_i, xdot, atol=1e-9)
    with pytest.raises(IntolerableFailure):
        ft.jvja(J, xdot, ["joint4"], joint_names=iiwa.joint_names)


def test_jvja_position_task_every_joint_lockable(rng):
    """Position task (r = 4): all seven joints are tolerable at the reference and J q̇ = ẋ."""
    arm = ft.load_arm("iiwa", task="position")
    J = arm.jacobian(arm.q_reference)
    xdot = rng.normal(size=3) * 0.1
    qd = ft.jvja(J, xdot, "all", joint_names=arm.joint_names)
    np.testing.assert_allclose(J @ qd, xdot, atol=1e-10)


# -- CLI ------------------------------------------------------------------------------------


def test_robots_command_lists_the_iiwa(capsys):
    from fault_tolerance.cli import main

    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("iiwa "))
    assert "shipped" in line and "x/y/z/rx/ry/rz" in line and "KUKA LBR iiwa 14" in line
    assert line.split()[2:3] == ["7"]
