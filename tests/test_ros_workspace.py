"""ROS workspaces: one ``--package-dir`` finds every package below it; meshes load and replay alike."""

from __future__ import annotations

import os
import shutil
import warnings
from pathlib import Path

import pytest
from headless import launched

import fault_tolerance as ft
from fault_tolerance.errors import MeshNotFound, MeshRefused, PackageNotFound, URDFError
from fault_tolerance.model.arm_record import arm_from_record, arm_record
from fault_tolerance.model.formats import packages
from fault_tolerance.model.formats.packages import find_package, locate_mesh, packages_below

DATA = Path(__file__).resolve().parent / "data" / "robots"

#: The five packages of the mobile manipulator and where they sit below ``ws/`` (depths 2 to 5).
PACKAGES = {
    "mobile_manipulator_description": "src/mobile_manipulator_description",
    "mobile_base_description": "src/bases/mobile_base_description",
    "ur_description": "src/universal_robot/ur_description",
    "franka_description": "src/vendor/franka/franka_description",
    "camera_description": "src/sensors/cameras/depth/camera_description",
}
TIP = "fr3_hand_tcp"
UR_JOINTS = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]

BASE_XACRO = """<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="mobile_base">
    <link name="base_link"><visual><geometry>
      <mesh filename="package://mobile_base_description/meshes/base.stl"/></geometry></visual></link>
    <xacro:macro name="wheel" params="side y">
      <link name="${side}_wheel"><visual><geometry>
        <mesh filename="package://mobile_base_description//meshes/./wheel.stl"/></geometry></visual></link>
      <joint name="${side}_wheel_joint" type="continuous"><parent link="base_link"/>
        <child link="${side}_wheel"/><origin xyz="0 ${y} 0.1"/><axis xyz="0 1 0"/></joint>
    </xacro:macro>
    <xacro:wheel side="left" y="0.25"/>
    <xacro:wheel side="right" y="-0.25"/>
  </xacro:macro>
</robot>
"""
CAMERA_XACRO = """<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="camera" params="parent">
    <link name="camera_link"><visual><geometry>
      <mesh filename="package://camera_description/meshes/camera.stl"/></geometry></visual></link>
    <joint name="camera_joint" type="fixed"><parent link="${parent}"/><child link="camera_link"/>
      <origin xyz="0.3 0 0.5"/></joint>
  </xacro:macro>
</robot>
"""
ROBOT_XACRO = """<?xml version="1.0"?>
<robot name="mobile_manipulator" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:include filename="$(find mobile_base_description)/urdf/base.xacro"/>
  <xacro:include filename="$(find camera_description)/urdf/camera.xacro"/>
  <xacro:include filename="$(find ur_description)/urdf/inc/ur5e_macro.xacro"/>
  <xacro:include filename="$(find franka_description)/end_effectors/common/utils.xacro"/>
  <xacro:include filename="$(find franka_description)/end_effectors/common/franka_hand.xacro"/>
  <xacro:mobile_base/>
  <xacro:camera parent="base_link"/>
  <xacro:ur5e_robot prefix="arm_"/>
  <joint name="base_to_arm" type="fixed"><parent link="base_link"/><child link="arm_base_link"/>
    <origin xyz="0.2 0 0.4"/></joint>
  <xacro:franka_hand connected_to="arm_tool0" arm_id="fr3" ee_id="franka_hand_white"
      ee_inertials="${xacro.load_yaml('$(find franka_description)/end_effectors/franka_hand/inertials.yaml')}"/>
</robot>
"""


def _write_mesh(path: Path) -> None:
    """A small box mesh file, STL or COLLADA by the file's extension."""
    import trimesh

    path.parent.mkdir(parents=True, exist_ok=True)
    box = trimesh.creation.box((0.05, 0.05, 0.05))
    kind = path.suffix.lower().lstrip(".")
    path.write_bytes(box.export(file_type="dae" if kind == "dae" else "stl"))


def _package_xml(name: str) -> str:
    return f'<?xml version="1.0"?><package format="3"><name>{name}</name></package>'


def build_workspace(root: Path) -> Path:
    """``root/ws``: the five packages (two real ones copied from tests/data) and decoys.

    Decoys that a colcon-like search must not see: a package inside a package, a duplicate under a
    COLCON_IGNORE, one under a hidden folder, and one behind a link out of the workspace.
    """
    ws = root / "ws"
    shutil.copytree(DATA / "ur5e" / "ur_description", ws / PACKAGES["ur_description"])
    shutil.copytree(DATA / "fr3" / "franka_description", ws / PACKAGES["franka_description"])
    for name, text in (
        ("mobile_base_description", BASE_XACRO),
        ("camera_description", CAMERA_XACRO),
        ("mobile_manipulator_description", ROBOT_XACRO),
    ):
        pkg = ws / PACKAGES[name]
        (pkg / "urdf").mkdir(parents=True)
        (pkg / "package.xml").write_text(_package_xml(name))
        file = "robot.urdf.xacro" if name == "mobile_manipulator_description" else None
        (pkg / "urdf" / (file or f"{name.split('_')[-2]}.xacro")).write_text(text)
    for decoy in ("build/ur_description", "src/.git/ur_description",
                  "src/bases/mobile_base_description/test/ur_description"):  # fmt: skip
        (ws / decoy).mkdir(parents=True)
        (ws / decoy / "package.xml").write_text(_package_xml("ur_description"))
    (ws / "build" / "COLCON_IGNORE").write_text("")
    outside = root / "elsewhere" / "camera_description"
    outside.mkdir(parents=True)
    (outside / "package.xml").write_text(_package_xml("camera_description"))
    os.symlink(root / "elsewhere", ws / "src" / "linked")
    return ws


def robot_file(ws: Path) -> Path:
    return ws / PACKAGES["mobile_manipulator_description"] / "urdf" / "robot.urdf.xacro"


def mesh_names(ws: Path) -> list[str]:
    """The mesh names of the expanded description (read once, meshes still missing)."""
    from fault_tolerance.model.formats.build import read_description

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = read_description(robot_file(ws), [ws])
    from lxml import etree

    root = etree.fromstring(desc.xml.encode("utf-8"))
    return [m.get("filename") for m in root.findall("link/visual/geometry/mesh")]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """The workspace with every mesh the description names written as a small box."""
    ws = build_workspace(tmp_path_factory.mktemp("ros"))
    for uri in mesh_names(ws):
        assert uri.startswith("package://"), uri
        _write_mesh(Path(locate_mesh_path(uri, ws)))
    return ws


def locate_mesh_path(uri: str, ws: Path) -> Path:
    package, _, rest = uri[len("package://") :].partition("/")
    return find_package(package, [ws]).joinpath(*[p for p in rest.split("/") if p not in ("", ".")])


# -- the search ------------------------------------------------------------------------------


def test_every_package_is_found_below_one_folder(tmp_path):
    """Each of the five packages, at depths 2 to 5, is found from ``ws`` alone; the decoys (in a
    package, under COLCON_IGNORE, hidden, behind a link out of ws) are not seen."""
    ws = build_workspace(tmp_path)
    for name, rel in PACKAGES.items():
        assert find_package(name, [ws]) == (ws / rel).resolve(), name
    found = packages_below(str(ws)).packages
    assert sorted(found) == sorted(PACKAGES)
    assert all(len(v) == 1 for v in found.values())


def test_a_package_twice_in_a_workspace_is_an_error(tmp_path):
    """Two packages of one name below one folder: an error naming both (colcon refuses too);
    a COLCON_IGNORE (or AMENT_IGNORE, CATKIN_IGNORE) file takes one out."""
    for where in ("a/pkg_x", "b/c/pkg_x"):
        (tmp_path / where).mkdir(parents=True)
        (tmp_path / where / "package.xml").write_text(_package_xml("dup"))
    with pytest.raises(URDFError, match=r"package 'dup' is found twice.*pkg_x.*pkg_x"):
        find_package("dup", [tmp_path])
    packages_below.cache_clear()
    (tmp_path / "b" / "AMENT_IGNORE").write_text("")
    assert find_package("dup", [tmp_path]) == (tmp_path / "a" / "pkg_x").resolve()


def test_the_search_is_bounded_and_says_so(tmp_path, monkeypatch):
    """A package deeper than MAX_SEARCH_DEPTH, or past MAX_SEARCH_FOLDERS folders, is not found,
    and the error says that the search was cut short and where."""
    deep = tmp_path.joinpath(*[f"d{i}" for i in range(packages.MAX_SEARCH_DEPTH + 1)], "pkg")
    deep.mkdir(parents=True)
    (deep / "package.xml").write_text(_package_xml("deep_pkg"))
    with pytest.raises(PackageNotFound, match=r"deeper than 8 levels were not searched"):
        find_package("deep_pkg", [tmp_path])
    packages_below.cache_clear()
    monkeypatch.setattr(packages, "MAX_SEARCH_DEPTH", 20)
    assert find_package("deep_pkg", [tmp_path]) == deep.resolve()
    packages_below.cache_clear()
    monkeypatch.setattr(packages, "MAX_SEARCH_FOLDERS", 5)
    with pytest.raises(PackageNotFound, match=r"stopped after 5 folders"):
        find_package("deep_pkg", [tmp_path])
    packages_below.cache_clear()


def test_the_old_rules_still_come_first(tmp_path):
    """``DIR/pkg`` and a ``DIR`` whose package.xml names the package win over a walk."""
    (tmp_path / "ws" / "pkg_b").mkdir(parents=True)
    (tmp_path / "ws" / "deep" / "pkg_b").mkdir(parents=True)
    (tmp_path / "ws" / "deep" / "pkg_b" / "package.xml").write_text(_package_xml("pkg_b"))
    assert find_package("pkg_b", [tmp_path / "ws"]) == (tmp_path / "ws" / "pkg_b").absolute()


# -- loading and replaying the mobile manipulator -----------------------------------------------


def test_the_mobile_manipulator_loads_with_one_package_dir_and_every_mesh(workspace):
    """load_arm(..., package_dirs=[ws]) expands the five-package xacro, reads every mesh (no
    warning), and the arm is the UR5e chain to the Franka hand's TCP."""
    names = mesh_names(workspace)
    assert len(names) >= 10 and {n.split("/")[2] for n in names} >= set(PACKAGES) - {
        "mobile_manipulator_description"
    }
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm = ft.load_arm(robot_file(workspace), package_dirs=[workspace], tip=TIP)
    assert arm.joint_names == [f"arm_{j}_joint" for j in UR_JOINTS]
    meshes = [g for g in arm.visual_model.geometryObjects if g.meshPath]
    assert len(meshes) == len(names)
    assert all(Path(g.meshPath).is_relative_to(workspace.resolve()) for g in meshes)


def test_the_record_of_the_mobile_manipulator_replays_its_meshes(workspace):
    """The arm rebuilt from its record with ``[ws]`` has the loader's meshes; without it, none."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = ft.load_arm(robot_file(workspace), package_dirs=[workspace], tip=TIP)
    record = arm_record(arm)
    again = arm_from_record(record, [workspace])
    paths = sorted(g.meshPath for g in again.visual_model.geometryObjects if g.meshPath)
    assert paths == sorted(g.meshPath for g in arm.visual_model.geometryObjects if g.meshPath)
    with pytest.warns(UserWarning, match="not opened"):
        bare = arm_from_record(record, [])
    assert not [g for g in bare.visual_model.geometryObjects if g.meshPath]


def _robot_meshes_in_browser(html: Path) -> list[str]:
    """The three.js meshes the page draws under the robot (their paths), in headless Chromium."""
    with launched() as browser:
        page = browser.new_page(viewport={"width": 800, "height": 600})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(html.as_uri())
        page.wait_for_function(
            "() => window.ftReplay && ftReplay.ready && viewer.animator.duration > 0",
            timeout=60_000,
        )
        drawn = page.evaluate("""() => { const out = [];
            viewer.scene.traverse(o => { if (!o.isMesh) return;
                const path = []; for (let p = o; p; p = p.parent) path.unshift(p.name);
                if (path.includes('robot')) out.push(path.join('/')); });
            return out; }""")
    assert not errors, errors
    return drawn


@pytest.mark.browser
def test_cli_simulates_and_replays_the_workspace_robot_with_its_meshes(workspace, tmp_path):
    """`simulate --urdf robot.urdf.xacro --package-dir ws` runs; `replay --package-dir ws --html`
    draws, in the browser, one three.js mesh per mesh visual of the arm (14, from five packages);
    without `--package-dir` the replay draws none of them (stand-in links only)."""
    from fault_tolerance.cli import main

    out = tmp_path / "out"
    rc = main(["simulate", "--urdf", str(robot_file(workspace)), "--package-dir", str(workspace),
               "--tip", TIP, "--task", "position", "--algorithms", "lnva", "--duration", "0.05",
               "--no-progress", "--out", str(out)])  # fmt: skip
    assert rc == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = ft.load_arm(robot_file(workspace), package_dirs=[workspace], tip=TIP)
    n_meshes = len([g for g in arm.visual_model.geometryObjects if g.meshPath])
    with_dirs, without = tmp_path / "with.html", tmp_path / "without.html"
    assert main(["replay", str(out / "lnva"), "--package-dir", str(workspace),
                 "--html", str(with_dirs)]) == 0  # fmt: skip
    assert main(["replay", str(out / "lnva"), "--html", str(without)]) == 0
    drawn, bare = _robot_meshes_in_browser(with_dirs), _robot_meshes_in_browser(without)
    visuals = {f"robot/visuals/{g.name}/" for g in arm.visual_model.geometryObjects if g.meshPath}
    assert len(visuals) == n_meshes >= 10
    assert {p.split("meshcat/", 1)[1] for p in drawn} == visuals  # every mesh, nothing else
    assert not visuals & {p.split("meshcat/", 1)[1] for p in bare}  # stand-in links only


# -- file:// and other names, inside and outside the folders ------------------------------------


@pytest.fixture
def meshes(tmp_path):
    """``pkgs/arm_description/meshes/a.stl`` inside the package folder, ``secret.stl`` outside."""
    inside = tmp_path / "pkgs" / "arm_description" / "meshes" / "a.stl"
    _write_mesh(inside)
    _write_mesh(tmp_path / "secret.stl")
    return tmp_path


def _one_mesh_urdf(name: str) -> str:
    limit = '<limit lower="-2" upper="2" velocity="2" effort="1"/>'
    return (
        '<robot name="one"><link name="base"/>'
        f'<link name="tool"><visual><geometry><mesh filename="{name}"/></geometry></visual></link>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="tool"/>'
        f'<origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>{limit}</joint></robot>'
    )


@pytest.mark.parametrize(
    "name",
    [
        "file://{pkgs}/arm_description/meshes/a.stl",
        "file://{pkgs}/arm_description//meshes/./a.stl",
        "{pkgs}/arm_description/meshes/a.stl",
        "package://arm_description/meshes/a.stl",
        "package://arm_description//./meshes/a.stl",
    ],
)
def test_a_mesh_inside_the_folder_loads_and_replays_alike(meshes, name):
    """file://, absolute and package:// names inside the package folder, normalised (a//b, ./):
    the loader reads the mesh and the replay (arm record) reads the same file."""
    pkgs = meshes / "pkgs"
    path = meshes / "one.urdf"
    path.write_text(_one_mesh_urdf(name.format(pkgs=pkgs)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm = ft.load_arm(path, package_dirs=[pkgs], tip="tool")
        again = arm_from_record(arm_record(arm), [pkgs])
    expected = [str((pkgs / "arm_description" / "meshes" / "a.stl").resolve())]
    assert [g.meshPath for g in arm.visual_model.geometryObjects] == expected
    assert [g.meshPath for g in again.visual_model.geometryObjects] == expected


@pytest.mark.parametrize(
    "name",
    ["file://{root}/secret.stl", "{root}/secret.stl", "file://{pkgs}/../secret.stl",
     "package://arm_description/../../secret.stl"],
)  # fmt: skip
def test_a_mesh_outside_the_folders_is_refused_by_loader_and_replay_alike(meshes, name):
    """A name leading outside the named folders (the description's folder is ``pkgs/x``): the
    same MeshRefused from locate_mesh; the loader and the replay both warn and drop that visual."""
    pkgs = meshes / "pkgs"
    uri = name.format(root=meshes, pkgs=pkgs)
    (pkgs / "x").mkdir()
    path = pkgs / "x" / "one.urdf"
    path.write_text(_one_mesh_urdf(uri))
    with pytest.raises(MeshRefused, match="outside the folders|'..'") as refused:
        locate_mesh(uri, [path.parent, pkgs], path.parent)
    assert isinstance(refused.value, ft.UnsafeDescription)
    with pytest.warns(UserWarning, match="not opened") as said:
        arm = ft.load_arm(path, package_dirs=[pkgs / "arm_description"], tip="tool")
    assert str(refused.value).split(":")[0] in str(said[0].message)
    with pytest.warns(UserWarning, match="not opened") as said_again:
        again = arm_from_record(arm_record(arm), [pkgs])
    assert str(refused.value).split(":")[0] in str(said_again[0].message)
    for a in (arm, again):
        assert not [g for g in a.visual_model.geometryObjects if g.meshPath]


def test_a_missing_mesh_is_not_found_rather_than_refused(meshes):
    """A name inside the folders that names no file: MeshNotFound, not MeshRefused."""
    pkgs = meshes / "pkgs"
    with pytest.raises(MeshNotFound):
        locate_mesh("package://arm_description/meshes/none.stl", [pkgs])
    with pytest.raises(MeshNotFound):
        locate_mesh(f"file://{pkgs}/none.stl", [pkgs])


def test_a_relative_name_in_a_run_is_tried_against_each_folder(meshes):
    """A run carries no folder of its own: ``meshes/a.stl`` is found in the named folder that
    holds it, and ``../secret.stl`` from there is refused."""
    pkg = meshes / "pkgs" / "arm_description"
    assert (
        locate_mesh("meshes/a.stl", [meshes / "pkgs", pkg]) == (pkg / "meshes" / "a.stl").resolve()
    )
    with pytest.raises(MeshRefused):
        locate_mesh("../../secret.stl", [pkg])


def test_a_package_added_after_a_load_is_found_by_the_next_load(tmp_path):
    """Each load searches the workspace afresh: a package added after a failed load is found."""
    ws = tmp_path / "ws"
    top = ws / "src" / "top"
    (top / "urdf").mkdir(parents=True)
    (top / "package.xml").write_text(_package_xml("top"))
    (top / "urdf" / "r.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find late_pkg)/arm.xacro"/></robot>'
    )
    with pytest.raises(PackageNotFound, match="late_pkg"):
        ft.load_arm(top / "urdf" / "r.urdf.xacro", package_dirs=[ws], tip="tool")
    late = ws / "src" / "later" / "late_pkg"
    late.mkdir(parents=True)
    (late / "package.xml").write_text(_package_xml("late_pkg"))
    (late / "arm.xacro").write_text(
        "<robot>" + _one_mesh_urdf("x.stl")[len('<robot name="one">') :]
    )
    with pytest.warns(UserWarning, match="x.stl"):  # the mesh itself is missing
        arm = ft.load_arm(top / "urdf" / "r.urdf.xacro", package_dirs=[ws], tip="tool")
    assert arm.joint_names == ["j1"]
