"""MuJoCo MJCF descriptions: the format registry, three Menagerie arms, records, hostile files."""

from __future__ import annotations

import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import SEED

import fault_tolerance as ft
from fault_tolerance.analysis.inspection import inspect_text
from fault_tolerance.model.arm_record import arm_from_record, arm_record
from fault_tolerance.model.formats import mjcf
from fault_tolerance.model.formats.registry import FORMATS, format_named, format_of

MENAGERIE = Path(__file__).parent / "data" / "robots" / "menagerie"
#: arm -> (file, default tip expected, number of arm joints)
ARMS = {
    "panda": ("franka_emika_panda/panda.xml", "hand", 7),
    "ur5e": ("universal_robots_ur5e/ur5e.xml", "attachment_site", 6),
    "iiwa14": ("kuka_iiwa_14/iiwa14.xml", "attachment_site", 7),
}


def path_of(name: str) -> Path:
    return MENAGERIE / ARMS[name][0]


def load(name: str, **kw) -> ft.Arm:
    with pytest.warns(UserWarning, match="mesh file"):
        return ft.load_arm(str(path_of(name)), **kw)


# -- the registry ----------------------------------------------------------------------------


def test_the_registry_recognises_each_format_by_suffix_and_root(tmp_path):
    """.urdf -> urdf, .xacro -> xacro, .xml with <mujoco> -> mjcf, .xml with <robot> -> urdf."""
    (tmp_path / "a.xml").write_text('<?xml version="1.0"?>\n<!-- c --><robot name="a"/>')
    (tmp_path / "b.urdf.xacro").write_text("<robot/>")
    assert format_of(path_of("ur5e")).name == "mjcf"
    assert format_of(tmp_path / "a.xml").name == "urdf"
    assert format_of(tmp_path / "b.urdf.xacro").name == "xacro"
    assert [f.name for f in FORMATS] == ["urdf", "xacro", "mjcf"]


def test_an_unknown_format_lists_the_known_ones(tmp_path):
    """A file no format recognises, or an unknown format name: UnknownFormat listing them."""
    path = tmp_path / "arm.yaml"
    path.write_text("robot: arm\n")
    with pytest.raises(ft.UnknownFormat, match=r"\['urdf', 'xacro', 'mjcf'\]"):
        format_of(path)
    with pytest.raises(ft.UnknownFormat, match="known formats"):
        ft.load_arm(str(path))
    with pytest.raises(ft.UnknownFormat, match="'sdf'"):
        format_named("sdf")


# -- Menagerie arms --------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(ARMS))
def test_each_menagerie_arm_loads_with_a_sensible_default_tip(name):
    """The arm loads without its meshes (one warning), its tip the chain's end body or site."""
    arm = load(name)
    _, tip, n = ARMS[name]
    assert arm.tip == tip and arm.n == n
    assert arm.built_from.description_format == "mjcf"
    assert all(np.isfinite(arm.model.lowerPositionLimit))


def test_a_site_or_a_body_can_be_the_tip():
    """tip= names a site (OP_FRAME) or a body: the site sits 0.1 m beyond wrist_3_link's origin."""
    site = load("ur5e", tip="attachment_site")
    body = load("ur5e", tip="wrist_3_link")
    rng = np.random.default_rng(SEED)
    for _ in range(5):
        q = rng.uniform(-2, 2, 6)
        gap = np.linalg.norm(site.fk(q) - body.fk(q))
        np.testing.assert_allclose(gap, 0.1, atol=1e-12)


def test_equality_coupled_joints_cannot_be_active():
    """The Panda's finger_joint1 follows finger_joint2 (<equality>): refused as an active joint."""
    with pytest.raises(ft.MJCFError, match=r"finger_joint1.*<equality><joint>"):
        load("panda", tip="left_finger")


@pytest.mark.parametrize("name", sorted(ARMS))
def test_inspect_lists_the_tree_and_the_chain(name):
    """inspect on an MJCF file lists its joints, candidate tips and the chain to the default tip."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        text = inspect_text(str(path_of(name)))
    assert "(MJCF)" in text and "candidate tip frames" in text
    assert f"chain to tip '{ARMS[name][1]}'" in text


def fk_pose(arm: ft.Arm, q: np.ndarray) -> pin.SE3:
    """The tip's placement in the world at ``q``."""
    pin.framesForwardKinematics(arm.model, arm.data, q)
    return arm.data.oMf[arm.model.getFrameId(arm.tip)]


def relative_motions(arm: ft.Arm, qs) -> list[np.ndarray]:
    """fk(q)·fk(0)⁻¹ for each q, as 4×4 matrices (base and tool offsets cancel up to a similarity)."""
    home = fk_pose(arm, np.zeros(arm.n)).inverse()
    return [(fk_pose(arm, q) * home).homogeneous for q in qs]


@pytest.mark.parametrize("name", ["panda", "ur5e"])
def test_kinematics_match_the_urdf_of_the_same_arm(name):
    """The tip's motion from q = 0, fk(q)·fk(0)⁻¹, in the MJCF arm equals the URDF arm's at random
    q (the worlds may differ by a rotation, found from the joint axes at q = 0): rotations to 1e-6;
    positions to 1e-6 for the Panda, to 2 mm for the UR5e, whose Menagerie model rounds the link
    lengths to the millimetre (d1 0.163 vs 0.1625, a3 0.392 vs 0.3922, d5 0.1 vs 0.0997 m)."""
    if name == "ur5e":
        from real_arms import load as load_real

        ref = load_real("ur5e")  # tests/data/robots/ur5e (ros-industrial ur_description xacro)
        mj = load(name, tip="wrist_3_link")
        position_tol = 2e-3
    else:
        mj = load(name, tip="hand")
        ref = ft.load_arm(
            "panda", tip="panda_hand", joints=[f"panda_joint{i}" for i in range(1, 8)]
        )
        position_tol = 1e-6
    assert mj.n == ref.n
    rng = np.random.default_rng(SEED)
    lo = np.maximum(ref.model.lowerPositionLimit, mj.model.lowerPositionLimit)
    hi = np.minimum(ref.model.upperPositionLimit, mj.model.upperPositionLimit)
    qs = [rng.uniform(lo, hi) for _ in range(20)]
    R = _world_rotation(mj, ref)
    for ma, mb in zip(relative_motions(mj, qs), relative_motions(ref, qs), strict=True):
        np.testing.assert_allclose(ma[:3, :3], R @ mb[:3, :3] @ R.T, atol=1e-6)
        np.testing.assert_allclose(ma[:3, 3], R @ mb[:3, 3], atol=position_tol)


def _world_rotation(mj: ft.Arm, ref: ft.Arm) -> np.ndarray:
    """The rotation taking the URDF world to the MJCF world: the joint axes at q = 0 agree (Kabsch)."""
    A, B = (np.array(_world_axes(arm)) for arm in (mj, ref))
    U, _, Vt = np.linalg.svd(B.T @ A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    np.testing.assert_allclose(A, B @ R.T, atol=1e-9)  # the same axes, one rotation apart
    return R


def _world_axes(arm: ft.Arm) -> list[np.ndarray]:
    """Each joint's axis in the world at q = 0."""
    pin.forwardKinematics(arm.model, arm.data, np.zeros(arm.n))
    return [
        arm.data.oMi[j].rotation @ _axis(arm.model.joints[j]) for j in range(1, arm.model.njoints)
    ]


def _axis(joint) -> np.ndarray:
    """The unit axis of a revolute joint in its own frame (RX, RY, RZ or an unaligned axis)."""
    short = joint.shortname()
    if short.endswith(("RX", "PX")):
        return np.array([1.0, 0, 0])
    if short.endswith(("RY", "PY")):
        return np.array([0, 1.0, 0])
    if short.endswith(("RZ", "PZ")):
        return np.array([0, 0, 1.0])
    return np.asarray(joint.axis, dtype=float)


# -- runs: simulate, record, replay ----------------------------------------------------------


@pytest.mark.parametrize("name", sorted(ARMS))
def test_a_short_run_from_the_default_start(name):
    """ft.simulate from ft.default_start runs on the MJCF arm and tracks the circle."""
    from fault_tolerance.simulation.paths import CirclePath

    arm = load(name)
    start = ft.default_start(arm)
    path = CirclePath(arm.fk(start.q0), 0.03, 2 * np.pi, 0.1)
    run = ft.simulate(arm, path, "jvja", q0=start.q0)
    assert np.all(np.isfinite(run.q)) and run.q.shape[1] == arm.n
    assert float(np.max(np.abs(run.error))) < 1e-3  # [m]
    assert run.arm_record["description_format"] == "mjcf"
    assert "<mujoco" in run.arm_record["mjcf"] and "urdf" not in run.arm_record


def test_the_record_rebuilds_the_arm_without_the_file(tmp_path):
    """The arm record of an MJCF arm rebuilds the same kinematics with the file gone."""
    src = tmp_path / "ur5e.xml"
    shutil.copy(path_of("ur5e"), src)
    with pytest.warns(UserWarning, match="mesh file"):
        arm = ft.load_arm(str(src))
    record = arm_record(arm)
    src.unlink()
    again = arm_from_record(record)
    assert again.joint_names == arm.joint_names and again.tip == arm.tip
    q = np.random.default_rng(SEED).uniform(-2, 2, arm.n)
    np.testing.assert_allclose(again.fk(q), arm.fk(q), atol=1e-12)


def test_an_old_record_without_a_format_is_a_urdf():
    """A record written before MJCF (no description_format) rebuilds as a URDF."""
    record = arm_record(ft.load_arm("planar_3r"))
    del record["description_format"]
    assert arm_from_record(record).joint_names == ["joint1", "joint2", "joint3"]


def test_a_record_with_an_unknown_format_is_refused():
    """description_format must be one the records store (urdf, mjcf): one line otherwise."""
    record = arm_record(ft.load_arm("planar_3r"))
    record["description_format"] = "xacro"
    with pytest.raises(ft.InvalidInput, match=r"'xacro' is not one of \['mjcf', 'urdf'\]"):
        arm_from_record(record)


def test_a_stored_mjcf_text_may_include_nothing():
    """A tampered record whose MJCF text includes a file is refused before any file is opened."""
    with pytest.warns(UserWarning, match="mesh file"):
        record = arm_record(ft.load_arm(str(path_of("ur5e"))))
    record["mjcf"] = record["mjcf"].replace(
        "<worldbody>", '<include file="/etc/passwd"/><worldbody>'
    )
    with pytest.raises(ft.MJCFError, match="may not <include>"):
        arm_from_record(record)


def test_cli_simulate_then_replay_html_from_the_record(tmp_path, capsys):
    """`simulate --description arm.xml` saves a run; `replay --html` rebuilds it from the record
    after the MJCF file is deleted (exit 0)."""
    from fault_tolerance.cli import main

    src = tmp_path / "iiwa14.xml"
    shutil.copy(path_of("iiwa14"), src)
    out = tmp_path / "out"
    rc = main(["simulate", "--description", str(src), "--no-progress", "--duration", "0.05",
               "--algorithms", "jvja", "--out", str(out)])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    src.unlink()
    page = tmp_path / "r.html"
    capsys.readouterr()
    assert main(["replay", str(out / "jvja"), "--html", str(page)]) == 0, capsys.readouterr().err
    assert page.stat().st_size > 1000


def test_cli_inspect_takes_an_mjcf_file_and_the_urdf_alias(capsys):
    """`inspect arm.xml` and `inspect --urdf arm.xml` (the alias of --description) both work."""
    from fault_tolerance.cli import main

    for argv in (["inspect", str(path_of("ur5e"))], ["inspect", "--urdf", str(path_of("ur5e"))]):
        assert main(argv) == 0
        assert "chain to tip 'attachment_site'" in capsys.readouterr().out


def test_cli_description_help_lists_the_formats(capsys):
    """--description's help names URDF, xacro and MJCF, and --urdf as its alias."""
    from fault_tolerance.cli import main

    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--description PATH, --urdf PATH" in text
    assert all(word in text for word in ("URDF", "xacro", "MJCF", "alias"))


# -- hostile files ---------------------------------------------------------------------------

ARM = """<mujoco model="m">{inc}
  <worldbody><body name="b"><joint name="j1" axis="0 0 1"/><geom size="0.1"/>
    <body name="c" pos="0.3 0 0"><joint name="j2" axis="0 0 1"/><geom size="0.1"/>
      <site name="tcp" pos="0.2 0 0"/></body></body></worldbody>
</mujoco>
"""


def write(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text)
    return folder / name


def test_an_include_inside_the_folder_is_inlined(tmp_path):
    """<include file=...> beside the file is read: its <default> applies to the arm."""
    write(tmp_path, "defaults.xml", '<mujoco><default><joint range="-1 1"/></default></mujoco>')
    path = write(tmp_path, "arm.xml", ARM.format(inc='<include file="defaults.xml"/>'))
    arm = ft.load_arm(str(path), task="planar")
    assert arm.tip == "tcp"
    # MJCF angles are in degrees unless <compiler angle="radian">
    np.testing.assert_allclose(arm.model.upperPositionLimit, np.deg2rad([1.0, 1.0]), atol=1e-15)
    assert b"<include" not in arm.built_from.data


def hostile(tmp_path: Path, case: str) -> tuple[Path, str]:
    """An MJCF file of each hostile kind, and what its error says."""
    arm = tmp_path / "arm"
    if case == "dtd":
        text = '<?xml version="1.0"?>\n<!DOCTYPE m [<!ENTITY x "y">]>\n' + ARM.format(inc="&x;")
        return write(arm, "arm.xml", text), "DOCTYPE"
    if case == "outside":
        write(tmp_path, "secret.xml", "<mujoco/>")
        return write(arm, "arm.xml", ARM.format(inc='<include file="../secret.xml"/>')), "outside"
    if case == "link_outside":
        write(tmp_path, "secret.xml", "<mujoco/>")
        arm.mkdir()
        os.symlink(tmp_path / "secret.xml", arm / "inc.xml")
        return write(arm, "arm.xml", ARM.format(inc='<include file="inc.xml"/>')), "outside"
    if case == "fifo":
        arm.mkdir()
        os.mkfifo(arm / "pipe.xml")
        return write(arm, "arm.xml", ARM.format(inc='<include file="pipe.xml"/>')), "FIFO"
    if case == "device":
        arm.mkdir()
        os.symlink("/dev/zero", arm / "zero.xml")
        return write(arm, "arm.xml", ARM.format(inc='<include file="zero.xml"/>')), "outside"
    if case == "huge":
        text = ARM.format(inc="<!--" + "x" * (mjcf.MAX_URDF_BYTES + 10) + "-->")
        return write(arm, "arm.xml", text), "bytes"
    if case == "many":
        write(arm, "self.xml", '<mujoco><include file="self.xml"/></mujoco>')
        return write(arm, "arm.xml", ARM.format(inc='<include file="self.xml"/>')), "nest deeper"
    raise AssertionError(case)


HOSTILE = ["dtd", "outside", "link_outside", "fifo", "device", "huge", "many"]


@pytest.mark.parametrize("case", HOSTILE)
def test_a_hostile_mjcf_is_refused_with_the_toolkits_error(tmp_path, case):
    """DTD/entities, includes outside the folder (also through a link), a FIFO or device, a huge
    file, endless includes: MJCFError naming the problem, without hanging."""
    path, match = hostile(tmp_path, case)
    with pytest.raises(ft.MJCFError, match=match) as err:
        ft.load_arm(str(path))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("case", HOSTILE)
def test_cli_inspect_of_a_hostile_mjcf_exits_2_with_one_line(tmp_path, case, capsys):
    """`fault-tolerance inspect hostile.xml` exits 2 with one line on stderr."""
    from fault_tolerance.cli import main

    path, match = hostile(tmp_path, case)
    capsys.readouterr()
    assert main(["inspect", str(path)]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1, err


def test_a_free_joint_on_the_chain_is_refused_and_fixed_when_left_out(tmp_path):
    """A <freejoint> base: refused as an active joint (named), held fixed when left out."""
    text = ARM.format(inc="").replace('<body name="b">', '<body name="base"><freejoint name="fj"/>'
                                      '<geom size="0.1"/><body name="b">').replace(
        "</body></body></worldbody>", "</body></body></body></worldbody>")  # fmt: skip
    path = write(tmp_path, "free.xml", text)
    with pytest.raises(ft.URDFError, match=r"'fj' \(floating\)"):
        ft.load_arm(str(path), task="planar")
    arm = ft.load_arm(str(path), task="planar", joints=["j1", "j2"])
    assert arm.joint_names == ["j1", "j2"]


def test_the_descriptions_page_example_runs(monkeypatch, tmp_path):
    """docs/descriptions.md's Python example runs in a fresh folder (it writes ``arm.xml``)."""
    import re

    root = Path(__file__).resolve().parents[1]
    blocks = re.findall(
        r"```python\n(.*?)```", (root / "docs" / "descriptions.md").read_text(), re.S
    )
    assert len(blocks) == 1
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(blocks[0], "descriptions.md", "exec"), ns)  # noqa: S102 - our own documentation
    assert ns["run"].arm_record["description_format"] == "mjcf"
    assert (tmp_path / "arm.xml").is_file()  # written here, not into the checkout
