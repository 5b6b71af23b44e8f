"""A run carries its arm: rebuilt from the stored URDF text, meshes only from named package folders."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from conftest import SEED
from test_urdf_safety import billion_laughs, chain3, robot

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput, URDFError
from fault_tolerance.model.arm_record import (
    arm_from_record,
    arm_record,
    check_record,
)
from fault_tolerance.model.formats.build import confine_meshes

STL = """solid t
facet normal 0 0 1
 outer loop
  vertex 0 0 0
  vertex 0.1 0 0
  vertex 0 0.1 0
 endloop
endfacet
endsolid t
"""


@pytest.mark.parametrize(
    "name", ["planar_3r", "spatial_4r", "powercube_3r", "panda", "ur5", "xarm7"]
)
def test_the_rebuilt_arm_has_the_same_kinematics(name):
    """arm_from_record(arm_record(arm)): same joints, tip, task and forward kinematics (1e-12)."""
    arm = ft.load_arm(name)
    record = arm_record(arm)
    assert record is not None and record["joints"] == arm.joint_names
    again = arm_from_record(record)
    assert again.joint_names == arm.joint_names and again.tip == arm.tip
    assert again.task == arm.task
    meshes = [
        g.meshPath for g in (again.visual_model.geometryObjects if again.visual_model else [])
    ]
    if name in ("panda", "ur5", "xarm7"):  # installed robot data is read, nothing else
        assert meshes and all("/example-robot-data/" in p for p in meshes if p)
    rng = np.random.default_rng(SEED)
    for _ in range(5):
        q = arm.random_q(rng)
        np.testing.assert_allclose(again.fk(q), arm.fk(q), atol=1e-12)
        np.testing.assert_allclose(again.jacobian(q), arm.jacobian(q), atol=1e-12)


def meshy_urdf(filenames: list[str]) -> str:
    """The planar 3R test chain with one mesh visual per file name (on links base, l1, l2, tool)."""
    text = robot(*chain3())
    for link, fn in zip(["base", "l1", "l2", "tool"], filenames, strict=False):
        text = text.replace(
            f'<link name="{link}"/>',
            f'<link name="{link}"><visual><geometry><mesh filename="{fn}"/></geometry></visual>'
            f'<collision><geometry><mesh filename="{fn}"/></geometry></collision></link>',
        )
    return text


@pytest.fixture
def package(tmp_path):
    """A package folder ``pkgs/arm_description/meshes/a.stl`` and a secret file outside it."""
    pkg = tmp_path / "pkgs" / "arm_description" / "meshes"
    pkg.mkdir(parents=True)
    (pkg / "a.stl").write_text(STL)
    secret = tmp_path / "secret.stl"
    secret.write_text(STL)
    os.symlink(secret, pkg / "link_out.stl")
    return tmp_path


def _file_arm(tmp_path, filenames, package_dirs):
    path = tmp_path / "arm.urdf"
    path.write_text(meshy_urdf(filenames))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ft.load_arm(str(path), package_dirs=package_dirs)


def test_meshes_resolve_only_inside_the_package_folders_given(package):
    """A package:// mesh is found in a folder named by the caller (as root of packages or as the
    package itself); without that folder, the visual is dropped with a warning naming the mesh."""
    arm = _file_arm(package, ["package://arm_description/meshes/a.stl"], [package / "pkgs"])
    record = arm_record(arm)
    for dirs in ([package / "pkgs"], [package / "pkgs" / "arm_description"]):
        rebuilt = arm_from_record(record, dirs)
        paths = [g.meshPath for g in rebuilt.visual_model.geometryObjects if g.meshPath]
        assert paths == [os.path.realpath(package / "pkgs/arm_description/meshes/a.stl")]
    with pytest.warns(UserWarning, match="not opened.*not found inside the package folders"):
        rebuilt = arm_from_record(record, [])
    assert not [g for g in rebuilt.visual_model.geometryObjects if g.meshPath]


@pytest.mark.parametrize(
    "name, why",
    [
        ("package://arm_description/../../secret.stl", "'..'"),
        ("package://arm_description/meshes/link_out.stl", "outside the folders"),
        ("{secret}", "outside the folders"),
        ("file://{secret}", "outside the folders"),
        ("../secret.stl", "outside the folders"),
        ("package:///{secret}", "empty"),
        ("package://arm_description\\..\\..\\secret.stl", "backslash"),
    ],
)
def test_a_redirected_mesh_is_never_opened(package, name, why):
    """Mesh names that leave the package folder (.., a link out of it, absolute, file://,
    relative, backslashes) are refused: the visual is dropped and no path outside is kept."""
    name = name.format(secret=package / "secret.stl")
    xml, dropped = confine_meshes(meshy_urdf([name]), [package / "pkgs"])
    assert len(dropped) == 1 and why in dropped[0], dropped
    assert "secret" not in xml and "<collision" not in xml


def test_a_record_with_a_redirected_mesh_replays_without_it(package):
    """A run whose carried URDF names the secret file (a tampered run) rebuilds without opening it."""
    arm = ft.load_arm("planar_3r")
    record = arm_record(arm)
    record["urdf"] = meshy_urdf([str(package / "secret.stl")]).replace('name="arm"', 'name="x"')
    record["tip"], record["joints"] = "tool", ["joint1", "joint2", "joint3"]
    record["q_full"] = None
    with pytest.warns(UserWarning, match="outside the folders"):
        rebuilt = arm_from_record(record, [package / "pkgs"])
    paths = (
        [g.meshPath for g in rebuilt.visual_model.geometryObjects] if rebuilt.visual_model else []
    )
    assert not any("secret" in p for p in paths)


def test_a_hostile_carried_urdf_is_checked_like_a_file():
    """The carried text goes through the URDF checks: a DTD is refused before any parser runs."""
    record = arm_record(ft.load_arm("planar_3r"))
    record["urdf"] = billion_laughs()
    with pytest.raises(URDFError, match="DOCTYPE"):
        arm_from_record(record)


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("urdf", 3, "'urdf' must be a str"),
        ("joints", "joint1", "'joints' must be a list"),
        ("task", [1, 2], "lists of names"),
        ("q_full", [0.0, float("nan")], "finite numbers"),
        ("q_full", [0.0, 0.0], "has 2 numbers"),
        ("format", 99, "another version"),
        ("root_joint", "planar", "root_joint"),
        ("joints", ["joint1", "nope"], "joint 'nope' is not in the model"),
    ],
)
def test_a_malformed_record_is_refused_in_one_line(key, value, match):
    """Wrong types or values in the record: InvalidInput / the toolkit's error, one line."""
    record = arm_record(ft.load_arm("planar_3r"))
    record[key] = value
    with pytest.raises(ft.FaultToleranceError, match=match) as info:
        arm_from_record(record)
    assert "\n" not in str(info.value)


def test_check_record_needs_an_object():
    """A record that is not a JSON object is refused."""
    with pytest.raises(InvalidInput, match="not an object"):
        check_record([1, 2], "run")


def test_replay_of_a_redirected_run_reads_nothing_it_names(package, tmp_path, capsys):
    """A received run whose meta names another URDF and package folder, and whose carried URDF
    names a secret mesh: `replay` rebuilds the planar arm from the carried text, warns about the
    mesh, and the page embeds nothing of the secret file (exit 0)."""
    import base64
    import json

    from fault_tolerance.cli import main
    from fault_tolerance.simulation.run import Run
    from fault_tolerance.storage.result_folder import write_record

    secret = package / "secret.stl"
    secret.write_text(STL.replace("solid t", "solid TOPSECRET"))
    assert main(["simulate", "--robot", "planar_3r", "--no-progress", "--duration", "0.02",
                 "--algorithms", "lnva", "--out", str(tmp_path / "out")]) == 0  # fmt: skip
    folder = tmp_path / "out" / "lnva"
    run = Run.load(folder)
    run.meta["source"] = str(secret)
    run.meta["package_dirs"] = [str(package), "/"]
    run.arm_record["urdf"] = meshy_urdf([str(secret), "package://arm_description/../../secret.stl"])
    run.arm_record.update(tip="tool", q_full=None, kind="file")
    run.write(folder)
    write_record(folder)
    capsys.readouterr()
    page = tmp_path / "r.html"
    rc = main(["replay", str(folder), "--html", str(page)])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "outside the folders" in err and err.count("\n") == 1
    html = page.read_text()
    assert "TOPSECRET" not in html and str(secret) not in html
    assert base64.b64encode(secret.read_bytes()).decode()[:40] not in html
    assert json.loads(json.dumps(run.meta))["source"] == str(secret)  # kept as information only
