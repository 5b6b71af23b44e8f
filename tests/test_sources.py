"""Description sources: xacro files without ROS, package folders, namespaces, meshes, option values."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import PackageNotFound
from fault_tolerance.model.formats.packages import find_package
from fault_tolerance.model.formats.xacro import parse_xacro_args

LIMIT = '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
STL = (
    "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
    "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n"
)


def _joint(name, parent, child, xyz="0.3 0 0"):
    return (
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/><axis xyz="0 0 1"/>{LIMIT}</joint>'
    )


def _package(root: Path, name: str, folder: str | None = None) -> Path:
    """A ROS package ``name`` in ``root/folder`` (default ``root/name``) with a package.xml."""
    pkg = root / (folder or name)
    pkg.mkdir(parents=True)
    (pkg / "package.xml").write_text(f"<package><name>{name}</name></package>")
    return pkg


ARM_MACRO = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="arm" params="prefix length:=0.3">
    <link name="${prefix}base"/>
    <link name="${prefix}l1"/> <link name="${prefix}l2"/> <link name="${prefix}tool"/>
    {joints}
  </xacro:macro>
</robot>
"""


def xacro_package(tmp_path: Path, folder: str | None = None) -> tuple[Path, Path]:
    """``my_arm_description`` with a macro file and a top file that needs the argument ``side``."""
    pkg = _package(tmp_path / "ws", "my_arm_description", folder)
    (pkg / "urdf").mkdir()
    joints = "".join(
        _joint(f"${{prefix}}joint{i}", f"${{prefix}}{a}", f"${{prefix}}{b}", "${length} 0 0")
        for i, (a, b) in enumerate((("base", "l1"), ("l1", "l2"), ("l2", "tool")), 1)
    )
    (pkg / "urdf" / "arm.xacro").write_text(ARM_MACRO.replace("{joints}", joints))
    top = pkg / "urdf" / "arm.urdf.xacro"
    top.write_text(
        '<?xml version="1.0"?>\n<robot name="my_arm" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        '  <xacro:arg name="length" default="0.3"/>\n'
        '  <xacro:include filename="$(find my_arm_description)/urdf/arm.xacro"/>\n'
        '  <xacro:arm prefix="$(arg side)_" length="$(arg length)"/>\n'
        "</robot>\n"
    )
    return tmp_path / "ws", top


# -- xacro ------------------------------------------------------------------------------------


@pytest.mark.parametrize("layout", ["DIR/pkg", "package.xml names it"])
def test_xacro_expands_with_find_through_package_dirs_and_arguments(tmp_path, layout):
    """$(find pkg) resolves through DIR/pkg or a DIR whose package.xml names pkg; xacro_args set
    $(arg ...); the arm is the same as the equivalent URDF."""
    ws, top = xacro_package(tmp_path, folder="checkout" if layout != "DIR/pkg" else None)
    dirs = [str(ws)] if layout == "DIR/pkg" else [str(ws / "checkout")]
    arm = ft.load_arm(
        top, package_dirs=dirs, xacro_args={"side": "left", "length": "0.5"}, task="planar"
    )
    assert arm.joint_names == ["left_joint1", "left_joint2", "left_joint3"]
    assert arm.tip == "left_tool" and arm.xacro_args == {"side": "left", "length": "0.5"}
    np.testing.assert_allclose(arm.fk(np.zeros(3)), [1.5, 0.0], atol=1e-12)


def test_missing_xacro_argument_is_named(tmp_path):
    """A $(arg) without value or default: URDFError naming it and how to pass it."""
    ws, top = xacro_package(tmp_path)
    with pytest.raises(ft.URDFError, match=r"xacro argument 'side' is not set.*--xacro-arg side:="):
        ft.load_arm(top, package_dirs=[str(ws)])


def test_missing_package_is_named(tmp_path):
    """$(find pkg) with no folder holding pkg: URDFError naming the package and the folders."""
    _, top = xacro_package(tmp_path)
    with pytest.raises(
        PackageNotFound, match=r"package 'my_arm_description' not found.*--package-dir"
    ):
        ft.load_arm(top, package_dirs=[str(tmp_path / "elsewhere")], xacro_args={"side": "l"})
    with pytest.raises(ft.URDFError, match=r"'my_arm_description' not found \(no package folder"):
        ft.load_arm(top, xacro_args={"side": "l"})


def test_xacro_including_a_dtd_is_refused(tmp_path):
    """A file xacro includes passes the same byte checks as a URDF: a DOCTYPE is refused."""
    ws, top = xacro_package(tmp_path)
    macro = ws / "my_arm_description" / "urdf" / "arm.xacro"
    macro.write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY e "x">]>\n'
        + macro.read_text().split("\n", 1)[1]
    )
    with pytest.raises(ft.URDFError, match=r"arm.xacro: document type declarations"):
        ft.load_arm(top, package_dirs=[str(ws)], xacro_args={"side": "l"})


def test_malformed_xacro_is_one_error_without_traceback(tmp_path):
    """xacro's own errors become one-line URDFErrors; on the command line exit 2, no traceback."""
    bad = tmp_path / "bad.urdf.xacro"
    bad.write_text(
        '<robot name="b" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="x" value="${1/0}"/><link name="${x}"/></robot>'
    )
    with pytest.raises(ft.URDFError, match=r"bad.urdf.xacro: xacro could not expand it"):
        ft.load_arm(bad)
    p = subprocess.run(
        [sys.executable, "-m", "fault_tolerance", "inspect", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr


def test_xacro_args_for_a_plain_urdf_are_refused(tmp_path):
    """xacro_args given with a .urdf: an error, not silently ignored."""
    path = tmp_path / "a.urdf"
    path.write_text(
        '<robot name="a"><link name="base"/>'
        + _joint("j1", "base", "tool")
        + '<link name="tool"/></robot>'
    )
    with pytest.raises(ft.URDFError, match=r"not a xacro file"):
        ft.load_arm(path, xacro_args={"x": "1"})


def test_parse_xacro_args():
    """name:=value pairs; anything else is refused naming the item."""
    assert parse_xacro_args(["a:=1", "b:=x:=y", "c:="]) == {"a": "1", "b": "x:=y", "c": ""}
    with pytest.raises(ft.InvalidInput, match=r"'a=1' is not name:=value"):
        parse_xacro_args(["a=1"])


def test_find_package_prefers_the_named_folder(tmp_path):
    """A DIR whose package.xml names pkg serves pkg; DIR/pkg too; else PackageNotFound."""
    named = _package(tmp_path, "pkg_a", "some_checkout")
    _package(tmp_path / "ws", "pkg_b")
    assert find_package("pkg_a", [named]) == named.absolute()
    assert find_package("pkg_b", [tmp_path / "ws"]) == (tmp_path / "ws" / "pkg_b").absolute()
    with pytest.raises(PackageNotFound):
        find_package("pkg_c", [named, tmp_path / "ws"])


def test_cli_takes_xacro_args_and_package_dirs(tmp_path):
    """--xacro-arg and --package-dir reach the xacro expansion from the command line."""
    ws, top = xacro_package(tmp_path)
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "fault_tolerance",
            "inspect",
            str(top),
            "--package-dir",
            str(ws),
            "--xacro-arg",
            "side:=right",
            "--task",
            "planar",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    assert "chain to tip 'right_tool': right_joint1 -> right_joint2 -> right_joint3" in p.stdout


# -- namespaces and meshes ------------------------------------------------------------------


def test_undeclared_namespace_prefixes_are_ignored_with_one_warning(tmp_path):
    """<gazebo:plugin> and sensor:ray attributes without xmlns declarations: the arm loads, one
    warning names the prefixes."""
    path = tmp_path / "gz.urdf"
    path.write_text(
        '<robot name="gz"><link name="base"/>'
        + _joint("j1", "base", "l1")
        + '<link name="l1"/>'
        + _joint("j2", "l1", "tool")
        + '<link name="tool"/>'
        '<gazebo reference="tool"><gazebo:plugin name="p"/><sensor:ray sensor:rate="5"/></gazebo>'
        "</robot>"
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        arm = ft.load_arm(path, task="planar")
    texts = [str(w.message) for w in caught]
    assert len(texts) == 1 and "['gazebo', 'sensor'] used without a declaration" in texts[0]
    assert arm.n == 2


def test_a_missing_and_a_broken_mesh_drop_only_their_visuals(tmp_path):
    """One missing and one unreadable mesh: their two visuals are left out, one warning lists
    both, the box, the cylinder and the good mesh stay."""
    (tmp_path / "good.stl").write_text(STL)
    (tmp_path / "broken.stl").write_text("not a mesh")
    path = tmp_path / "meshes.urdf"
    path.write_text(
        '<robot name="m">'
        '<link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
        + _joint("j1", "base", "l1")
        + '<link name="l1"><visual><geometry><mesh filename="broken.stl"/></geometry></visual>'
        '<visual><geometry><cylinder radius="0.05" length="0.2"/></geometry></visual></link>'
        + _joint("j2", "l1", "tool")
        + '<link name="tool"><visual><geometry><mesh filename="package://nowhere/x.stl"/>'
        '</geometry></visual><visual><geometry><mesh filename="good.stl"/></geometry></visual>'
        "</link></robot>"
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        arm = ft.load_arm(path, task="planar")
    texts = [str(w.message) for w in caught]
    assert len(texts) == 1, texts
    assert "2 mesh file(s)" in texts[0] and "broken.stl" in texts[0] and "nowhere/x.stl" in texts[0]
    assert arm.visual_model is not None and arm.visual_model.ngeoms == 3


def test_package_uri_through_a_folder_whose_package_xml_names_it(tmp_path):
    """package://pkg/... resolves through a folder whose package.xml names pkg (Pinocchio alone
    only looks in DIR/pkg)."""
    pkg = _package(tmp_path, "my_meshes", "checkout")
    (pkg / "base.stl").write_text(STL)
    path = tmp_path / "a.urdf"
    path.write_text(
        '<robot name="a"><link name="base"><visual><geometry><mesh filename="package://my_meshes/'
        'base.stl"/></geometry></visual></link>'
        + _joint("j1", "base", "tool")
        + '<link name="tool"/></robot>'
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm = ft.load_arm(path, task="planar", package_dirs=[str(pkg)])
    assert arm.visual_model.ngeoms == 1


# -- option values ----------------------------------------------------------------------------


def _value_options():
    """(subcommand, option, action) of every option that takes one value, over all subcommands."""
    import argparse

    from fault_tolerance.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for cmd, sp in sub.choices.items():
        for action in sp._actions:
            if (
                action.option_strings
                and action.nargs is None
                and not action.const
                and action.choices is None
            ):
                if isinstance(action, (argparse._StoreAction, argparse._AppendAction)):
                    yield cmd, sp, action


def test_every_value_option_takes_a_negative_number_with_and_without_equals():
    """Each option of each subcommand that takes a value accepts '-1' and '-0.21,0.2,0.35'
    (where its type allows), written '--opt VALUE' and '--opt=VALUE'."""
    checked = 0
    for _cmd, sp, action in _value_options():
        opt = action.option_strings[-1]
        values = (
            ["-1"]
            if action.type is int
            else ["-0.25"]
            if action.type is float
            else ["-0.21,0.20,0.35", "-1.5:1.5,-2:2", "-1e-3"]
        )
        positionals = ["x" for a in sp._actions if not a.option_strings and a.nargs is None]
        positionals += [
            s
            for a in sp._actions
            if a.required and a.option_strings and a is not action
            for s in (a.option_strings[-1], "x")
        ]
        for v in values:
            for argv in ([opt, v], [f"{opt}={v}"]):
                ns, _ = sp.parse_known_args([*positionals, *argv])
                got = getattr(ns, action.dest)
                got = got[-1] if isinstance(got, list) else got
                assert str(got) == str(action.type(v) if action.type else v), (opt, argv, got)
                checked += 1
    assert checked > 20


def test_simulate_with_a_negative_x0_runs(tmp_path):
    """The --help example `--x0 -0.21,0.20,0.35` works, with and without '='."""
    for x0 in (["--x0", "-0.21,0.20,0.35"], ["--x0=-0.21,0.20,0.35"]):
        p = subprocess.run(
            [
                sys.executable,
                "-m",
                "fault_tolerance",
                "simulate",
                "--robot",
                "spatial_4r",
                *x0,
                "--algorithms",
                "jvja",
                "--duration",
                "0.05",
                "--no-progress",
            ],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert p.returncode == 0, p.stderr
        assert "jvja" in p.stdout
