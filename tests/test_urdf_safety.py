"""URDF input: hostile XML (entities, XInclude, huge files) and malformed or unsupported robots.

Every hostile file is generated in ``tmp_path``. What each parser on the loading path does with
them (measured with pin 4.1 / urdfdom 6 on tinyxml2, lxml 6, yourdfpy 0.0.60):

* urdfdom/tinyxml2 (Pinocchio) skips a DTD and leaves ``&name;`` unexpanded: no expansion, no
  file read, no network; UTF-16 is not read at all.
* lxml's default parser (yourdfpy) resolves internal entities, stops billion laughs with libxml2's
  amplification limit and loads no external entity; when it fails, yourdfpy retries with a
  *recovering* parser that silently drops what it cannot read.
* The toolkit refuses every DTD/entity before either sees the file, and hands both only the bytes it
  checked (``urdf.read_urdf``).
"""

from __future__ import annotations

import re
import socket
import time
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis.inspection import inspect_text
from fault_tolerance.model.formats import urdf as urdf_mod
from fault_tolerance.model.formats.urdf import read_urdf
from fault_tolerance.model.formats.xml_safety import MAX_URDF_BYTES, check_urdf_file

SECRET = "TOPSECRET-4242"
LIMIT = '<limit lower="-3" upper="3" effort="10" velocity="2"/>'


def joint(name, parent, child, kind="revolute", extra=LIMIT, axis="0 0 1", xyz="0.4 0 0"):
    """One URDF joint element."""
    ax = f'<axis xyz="{axis}"/>' if axis is not None else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/>{ax}{extra}</joint>'
    )


def robot(*parts, name="arm", head='<?xml version="1.0"?>\n') -> str:
    """A URDF document from link/joint elements."""
    return f'{head}<robot name="{name}">' + "".join(parts) + "</robot>\n"


def chain3(last="tool") -> list[str]:
    """A planar 3R chain base -> l1 -> l2 -> ``last`` (joints joint1..joint3)."""
    return [
        '<link name="base"/>',
        joint("joint1", "base", "l1", xyz="0 0 0"),
        '<link name="l1"/>',
        joint("joint2", "l1", "l2"),
        '<link name="l2"/>',
        joint("joint3", "l2", last),
        f'<link name="{last}"/>',
    ]


def write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    """Write a file into tmp_path and return its path."""
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


@pytest.fixture
def secret(tmp_path) -> Path:
    """A local file an external entity may try to read."""
    path = tmp_path / "secret.txt"
    path.write_text(SECRET)
    return path


@pytest.fixture
def listener():
    """A TCP socket on 127.0.0.1 that records whether anything connects to it."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    srv.settimeout(0.2)
    yield srv

    srv.close()


def connected(srv: socket.socket) -> bool:
    """Whether a connection is pending on the listener."""
    try:
        conn, _ = srv.accept()
    except TimeoutError:
        return False
    conn.close()
    return True


def billion_laughs() -> str:
    """Ten levels of ten-fold entity expansion (10⁹ 'lol's) in the robot's name."""
    ents = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{i} "{f"&lol{i - 1};" * 10}">' for i in range(1, 10)
    ]
    head = '<?xml version="1.0"?>\n<!DOCTYPE robot [\n' + "\n".join(ents) + "\n]>\n"
    return robot(*chain3(), name="&lol9;", head=head)


def hostile_files(tmp_path: Path, secret: Path, port: int) -> dict[str, Path]:
    """The hostile URDFs, by name."""
    body = chain3()
    xxe = '<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY xxe SYSTEM "{}">]>\n'
    files = {
        "billion_laughs": billion_laughs(),
        "xxe_local_file": robot(*body, name="&xxe;", head=xxe.format(f"file://{secret}")),
        "xxe_http_port_9": robot(*body, name="&xxe;", head=xxe.format("http://127.0.0.1:9/")),
        "xxe_http_listener": robot(
            *body, name="&xxe;", head=xxe.format(f"http://127.0.0.1:{port}/x")
        ),
        "parameter_entity": robot(
            *body,
            head='<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY % p '
            f'SYSTEM "http://127.0.0.1:{port}/p.dtd"> %p;]>\n',
        ),
        "external_dtd": robot(
            *body,
            head='<?xml version="1.0"?>\n<!DOCTYPE robot SYSTEM '
            f'"http://127.0.0.1:{port}/robot.dtd">\n',
        ),
        "xxe_in_utf16": robot(*body, name="&xxe;", head=xxe.format(f"file://{secret}"))
        .replace('<?xml version="1.0"?>', '<?xml version="1.0" encoding="UTF-16"?>')
        .encode("utf-16"),
        "xxe_in_utf7": (
            '<?xml version="1.0" encoding="UTF-7"?>\n'
            "+ADw-+ACE-DOCTYPE robot +AFs-+ADw-+ACE-ENTITY xxe SYSTEM "
            f"+ACI-file://{secret}+ACI-+AD4-+AF0-+AD4-\n" + robot(*body, name="&xxe;", head="")
        ),
    }
    return {k: write(tmp_path, f"{k}.urdf", v) for k, v in files.items()}


# -- hostile XML ----------------------------------------------------------------------------

HOSTILE = [
    "billion_laughs",
    "xxe_local_file",
    "xxe_http_port_9",
    "xxe_http_listener",
    "parameter_entity",
    "external_dtd",
    "xxe_in_utf16",
    "xxe_in_utf7",
]


@pytest.mark.parametrize("name", HOSTILE)
@pytest.mark.parametrize("entry", ["load_arm", "inspect", "check"])
def test_hostile_xml_is_refused_quickly_without_reading_or_connecting(
    name, entry, tmp_path, secret, listener
):
    """Entity bombs and external entities (file, http, parameter, DTD, other encodings) are refused:
    URDFError naming the file, within a second, no secret in the message, no connection made."""
    path = hostile_files(tmp_path, secret, listener.getsockname()[1])[name]
    call = {
        "load_arm": lambda: ft.load_arm(str(path)),
        "inspect": lambda: inspect_text(str(path)),
        "check": lambda: check_urdf_file(path),
    }[entry]
    start = time.perf_counter()
    with pytest.raises(ft.URDFError) as err:
        call()
    assert time.perf_counter() - start < 2.0
    msg = str(err.value)
    assert str(path) in msg
    assert SECRET not in msg
    assert "DOCTYPE" in msg or "UTF-8" in msg or "well-formed" in msg
    assert not connected(listener)


def test_pinocchio_parser_alone_neither_expands_nor_reads_entities(tmp_path, secret, listener):
    """Defence in depth: urdfdom/tinyxml2 ignores the DTD, so even unchecked text expands nothing,
    reads no file and opens no connection (the name keeps the literal entity reference)."""
    files = hostile_files(tmp_path, secret, listener.getsockname()[1])
    for name in ("billion_laughs", "xxe_local_file", "xxe_http_listener", "parameter_entity"):
        start = time.perf_counter()
        model = pin.buildModelFromXML(files[name].read_text())
        assert time.perf_counter() - start < 1.0
        assert SECRET not in model.name and len(model.name) < 20, name
        assert model.nv == 3
    assert not connected(listener)


def test_yourdfpy_only_ever_sees_the_checked_bytes(monkeypatch, tmp_path):
    """inspect hands yourdfpy a file object with the checked bytes, never the path (yourdfpy's
    fallback parser recovers from errors silently and its default one resolves entities)."""
    import yourdfpy

    path = write(tmp_path, "arm.urdf", robot(*chain3()))
    seen = []
    real = yourdfpy.URDF.load

    def spy(arg, **kw):
        seen.append(arg)
        return real(arg, **kw)

    monkeypatch.setattr(yourdfpy.URDF, "load", staticmethod(spy))
    inspect_text(str(path))
    assert len(seen) == 1 and not isinstance(seen[0], (str, Path))
    assert seen[0].getvalue() == path.read_bytes()


def test_xinclude_is_inert(tmp_path, secret):
    """An XInclude element is not processed by any parser: the arm loads, the secret appears
    nowhere (model names, inspect text)."""
    parts = chain3()
    parts[0] = (
        f'<link name="base"><xi:include xmlns:xi="http://www.w3.org/2001/XInclude" '
        f'href="file://{secret}" parse="text"/></link>'
    )
    path = write(tmp_path, "xinclude.urdf", robot(*parts))
    arm = ft.load_arm(str(path), task="planar")
    assert arm.n == 3
    assert not any(SECRET in n for n in list(arm.model.names) + arm.frame_names)
    assert SECRET not in inspect_text(str(path), task="planar")


def test_huge_file_is_refused_before_it_is_read(tmp_path, monkeypatch):
    """A file over MAX_URDF_BYTES is refused from its size alone (sparse file, nothing read)."""
    path = tmp_path / "huge.urdf"
    with path.open("wb") as fh:
        fh.truncate(MAX_URDF_BYTES + 1)
    monkeypatch.setattr(Path, "read_bytes", lambda self: pytest.fail("the huge file was read"))
    with pytest.raises(ft.URDFError, match="larger than"):
        check_urdf_file(path)


def test_too_many_joints_are_refused(tmp_path):
    """More joints than MAX_URDF_JOINTS are refused before Pinocchio (whose reader recurses along
    the chain and crashes the process on a few thousand joints)."""
    n = urdf_mod.MAX_URDF_JOINTS + 1
    parts = ['<link name="l0"/>'] + [
        joint(f"j{i}", f"l{i - 1}", f"l{i}") + f'<link name="l{i}"/>' for i in range(1, n + 1)
    ]
    path = write(tmp_path, "long.urdf", robot(*parts))
    with pytest.raises(ft.URDFError, match=f"{n} joints; at most {urdf_mod.MAX_URDF_JOINTS}"):
        ft.load_arm(str(path))


def test_deeply_nested_xml_is_refused(tmp_path):
    """XML nested 10 000 deep is refused by the checking parser (tinyxml2 never sees it)."""
    path = write(
        tmp_path, "deep.urdf", '<robot name="d">' + "<a>" * 10_000 + "</a>" * 10_000 + "</robot>"
    )
    with pytest.raises(ft.URDFError, match="not well-formed"):
        ft.load_arm(str(path))


# -- malformed files ------------------------------------------------------------------------

MALFORMED = {
    "empty": ("", "not well-formed"),
    "binary": (bytes(range(256)) * 4, "UTF-8"),
    "latin1": ('<robot name="caf\xe9"/>'.encode("latin-1"), "UTF-8"),
    "plain_text": ("this is not XML at all\n", "not well-formed"),
    "unclosed": ('<robot name="a"><link name="base">', "not well-formed"),
    "undeclared_entity": ('<robot name="&oops;"><link name="a"/></robot>', "not well-formed"),
    "html": ("<html><body>404</body></html>", "root element is <html>"),
    "unnamed_robot": ("<robot><link name='a'/></robot>", "has no name"),
    "no_links": ('<robot name="a"/>', "no <link>"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_raise_urdf_error_naming_the_file(case, tmp_path):
    """Not XML, malformed XML, wrong root or an empty robot: URDFError naming file and problem."""
    text, match = MALFORMED[case]
    path = write(tmp_path, f"{case}.urdf", text)
    with pytest.raises(ft.URDFError, match=match) as err:
        ft.load_arm(str(path))
    assert str(path) in str(err.value)


def test_missing_file_raises_urdf_error(tmp_path):
    """A URDF path that does not exist: URDFError naming it (load_arm and inspect)."""
    path = tmp_path / "nope.urdf"
    for call in (lambda: ft.load_arm(str(path)), lambda: inspect_text(str(path))):
        with pytest.raises(ft.URDFError, match="no such URDF file") as err:
            call()
        assert str(path) in str(err.value)


def test_pinocchio_rejection_carries_urdfdoms_reason_and_prints_nothing(tmp_path, capfd):
    """A URDF urdfdom rejects (an origin that is not numbers): the error carries urdfdom's reason,
    which would otherwise only be printed on stderr, and nothing reaches stderr."""
    path = write(
        tmp_path,
        "badorigin.urdf",
        robot(
            '<link name="base"/>',
            joint("joint1", "base", "tool", xyz="0.4 abc 0"),
            '<link name="tool"/>',
        ),
    )
    with pytest.raises(ft.URDFError, match=r"Pinocchio could not build.*abc"):
        ft.load_arm(str(path))
    assert capfd.readouterr().err == ""


STRUCTURE = {
    "unknown_joint_type": (
        [*chain3()[:-2], joint("joint3", "l2", "tool", kind="hinge"), '<link name="tool"/>'],
        r"type 'hinge'; URDF joint types are",
    ),
    "unknown_child_link": ([*chain3(), joint("j4", "tool", "ghost")], "child link 'ghost'"),
    "two_parents": ([*chain3(), joint("j4", "base", "l2")], "child of two joints"),
    "not_connected": (
        [*chain3(), '<link name="island"/>', joint("j9", "island", "reef"), '<link name="reef"/>'],
        r"not connected: links \['base', 'island'\]",
    ),
    "cycle": (
        ['<link name="a"/>', '<link name="b"/>', joint("j1", "a", "b"), joint("j2", "b", "a")],
        "cycle",
    ),
    "detached_cycle": (
        [
            *chain3(),
            '<link name="p"/>',
            '<link name="r"/>',
            joint("j8", "p", "r"),
            joint("j9", "r", "p"),
        ],
        "not connected to the root link",
    ),
    "zero_axis": (
        [
            '<link name="base"/>',
            joint("joint1", "base", "tool", axis="0 0 0"),
            '<link name="tool"/>',
        ],
        "zero axis",
    ),
    "duplicate_link": ([*chain3(), '<link name="l1"/>'], r"\['l1'\] defined more than once"),
    "duplicate_joint": (
        [*chain3(), joint("joint1", "tool", "t2"), '<link name="t2"/>'],
        "joint 'joint1' is defined more than once",
    ),
}


@pytest.mark.parametrize("case", sorted(STRUCTURE))
def test_broken_trees_are_refused_with_a_clear_message(case, tmp_path):
    """Unknown joint types or links, a link with two parents (which Pinocchio would silently
    mis-build), a tree that is not connected, cycles, zero axes, duplicate names: URDFError
    naming the file and the element, for load_arm and inspect alike."""
    parts, match = STRUCTURE[case]
    path = write(tmp_path, f"{case}.urdf", robot(*parts))
    for call in (lambda: ft.load_arm(str(path)), lambda: inspect_text(str(path))):
        with pytest.raises(ft.URDFError, match=match) as err:
            call()
        assert str(path) in str(err.value)


# -- unsupported and special joints -----------------------------------------------------------


def floating_base(tmp_path) -> Path:
    """A 3R chain on a floating joint world -> base."""
    parts = [
        '<link name="world"/>',
        joint("float", "world", "base", kind="floating", extra="", axis=None),
    ] + chain3()
    return write(tmp_path, "floating.urdf", robot(*parts))


def test_floating_base_on_the_chain_is_refused_naming_the_joint(tmp_path):
    """A floating joint among the active joints: URDFError naming it and saying how to fix it."""
    with pytest.raises(ft.URDFError, match=r"'float' \(floating\).*joints=") as err:
        ft.load_arm(str(floating_base(tmp_path)), task="planar")
    assert "floating.urdf" in str(err.value)


def test_floating_base_held_fixed_when_left_out_of_the_active_joints(tmp_path):
    """With joints= naming only the arm's joints the floating base is fixed and the arm loads."""
    arm = ft.load_arm(
        str(floating_base(tmp_path)), task="planar", joints=["joint1", "joint2", "joint3"]
    )
    assert arm.joint_names == ["joint1", "joint2", "joint3"]


def test_planar_joint_on_the_chain_is_refused(tmp_path):
    """A planar joint among the active joints is refused naming it."""
    parts = [
        '<link name="world"/>',
        joint("slide", "world", "base", kind="planar", extra="", axis="0 0 1"),
    ] + chain3()
    path = write(tmp_path, "planar.urdf", robot(*parts))
    with pytest.raises(ft.URDFError, match=r"'slide' \(planar\)"):
        ft.load_arm(str(path), task="planar")


@pytest.mark.parametrize(
    "parts",
    [
        ['<link name="base"/>'],
        [
            '<link name="base"/>',
            joint("weld", "base", "tool", kind="fixed", extra="", axis=None),
            '<link name="tool"/>',
        ],
    ],
    ids=["single_link", "all_fixed"],
)
def test_zero_dof_models_are_refused(parts, tmp_path):
    """A robot without a moving joint: URDFError naming the file and saying there is none."""
    path = write(tmp_path, "rigid.urdf", robot(*parts))
    with pytest.raises(ft.URDFError, match="no moving joint") as err:
        ft.load_arm(str(path))
    assert str(path) in str(err.value)


def test_tip_before_every_moving_joint_is_refused(tmp_path):
    """A tip frame with no moving joint between it and the root: the error lists the moving joints."""
    path = write(tmp_path, "arm.urdf", robot(*chain3()))
    with pytest.raises(
        ft.URDFError, match=r"no moving joint between the root and frame 'base'.*joint1"
    ):
        ft.load_arm(str(path), tip="base")


def mimic_arm(tmp_path) -> Path:
    """A 3R chain whose joint2 mimics joint1, and a finger mimicking joint3 off the chain."""
    parts = chain3()
    parts[3] = joint("joint2", "l1", "l2", extra=LIMIT + '<mimic joint="joint1" multiplier="2"/>')
    parts += [
        joint("finger", "l2", "fingertip", extra=LIMIT + '<mimic joint="joint3"/>'),
        '<link name="fingertip"/>',
    ]
    return write(tmp_path, "mimic.urdf", robot(*parts))


def test_active_mimic_joint_is_refused(tmp_path):
    """A mimic joint on the chain to the tip would move independently: refused, naming it."""
    with pytest.raises(ft.URDFError, match=r"\['joint2'\] follow other joints \(<mimic>\)"):
        ft.load_arm(str(mimic_arm(tmp_path)), tip="tool", task="planar")


def test_mimic_joint_off_the_chain_is_held_fixed(tmp_path):
    """A mimic joint that is not active (a finger) is fixed like any other inactive joint."""
    path = mimic_arm(tmp_path)
    arm = ft.load_arm(str(path), tip="tool", task="planar", joints=["joint1", "joint3"])
    assert arm.joint_names == ["joint1", "joint3"]
    assert "finger follows joint3" in inspect_text(
        str(path), tip="tool", task="planar", joints=["joint1", "joint3"]
    )


@pytest.mark.parametrize("with_limit", [True, False])
def test_continuous_joints_load_as_revolute_with_wrapping_limits(with_limit, tmp_path, rng):
    """Continuous joints become revolute with limits ±π: same kinematics as the revolute arm,
    angles wrap (the posture search treats them as full-turn joints); without <limit> the
    velocity limit stays infinite."""
    ref_path = write(tmp_path, "rev.urdf", robot(*chain3()))
    extra = '<limit effort="10" velocity="2"/>' if with_limit else ""
    parts = chain3()
    parts[1] = joint("joint1", "base", "l1", kind="continuous", extra=extra, xyz="0 0 0")
    path = write(tmp_path, "cont.urdf", robot(*parts))
    arm = ft.load_arm(str(path), task="planar")
    ref = ft.load_arm(str(ref_path), task="planar")
    np.testing.assert_allclose(arm.lower[0], -np.pi, atol=1e-12)
    np.testing.assert_allclose(arm.upper[0], np.pi, atol=1e-12)
    assert arm.velocity_limit[0] == (2.0 if with_limit else np.inf)
    for _ in range(5):
        q = rng.uniform(-3, 3, 3)
        np.testing.assert_allclose(arm.jacobian(q), ref.jacobian(q), atol=1e-12)
        np.testing.assert_allclose(arm.fk(q + [2 * np.pi, 0, 0]), ref.fk(q), atol=1e-12)
    assert "read as revolute with limits ±π: joint1" in inspect_text(str(path), task="planar")


def test_missing_package_mesh_loads_without_visuals_and_warns(tmp_path):
    """A package:// mesh that cannot be found: the arm loads without visual geometry and a
    warning names the file, the mesh and --package-dir."""
    parts = chain3()
    parts[0] = (
        '<link name="base"><visual><geometry><mesh filename="package://no_pkg/base.stl"/>'
        "</geometry></visual></link>"
    )
    path = write(tmp_path, "meshy.urdf", robot(*parts))
    with pytest.warns(
        UserWarning, match=r"meshy.urdf: 1 mesh file\(s\) not found.*no_pkg.*package-dir"
    ):
        arm = ft.load_arm(str(path), task="planar")
    assert arm.visual_model.ngeoms == 0 and arm.n == 3  # its only visual was that mesh


def test_package_mesh_found_through_package_dirs(tmp_path):
    """With package_dirs naming the folder of the package, the mesh loads."""
    mesh = tmp_path / "pkgs" / "my_pkg" / "base.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
        "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n"
    )
    parts = chain3()
    parts[0] = (
        '<link name="base"><visual><geometry><mesh filename="package://my_pkg/base.stl"/>'
        "</geometry></visual></link>"
    )
    path = write(tmp_path, "meshy.urdf", robot(*parts))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arm = ft.load_arm(str(path), task="planar", package_dirs=[str(tmp_path / "pkgs")])
    assert arm.visual_model is not None and arm.visual_model.ngeoms == 1


# -- tip frames ---------------------------------------------------------------------------------


def gripper(tmp_path) -> Path:
    """A 3R chain ending in two finger links: two leaf links."""
    parts = chain3(last="palm") + [
        joint("fa", "palm", "finger_a", kind="fixed", extra="", axis=None),
        '<link name="finger_a"/>',
        joint("fb", "palm", "finger_b", kind="fixed", extra="", axis=None),
        '<link name="finger_b"/>',
    ]
    return write(tmp_path, "gripper.urdf", robot(*parts))


def test_tip_defaults_to_the_only_leaf_link(tmp_path):
    """Without tip=, a URDF whose tree has one leaf link uses it."""
    assert (
        ft.load_arm(str(write(tmp_path, "arm.urdf", robot(*chain3("flange")))), task="planar").tip
        == "flange"
    )


def test_several_leaf_links_need_a_tip(tmp_path):
    """Without tip= and with several leaf links: URDFError listing them; inspect lists them too."""
    path = gripper(tmp_path)
    with pytest.raises(ft.URDFError, match=r"2 leaf links \['finger_a', 'finger_b'\].*--tip"):
        ft.load_arm(str(path))
    text = inspect_text(str(path))
    assert "finger_a, finger_b" in text and "--tip" in text
    assert ft.load_arm(str(path), tip="finger_b", task="planar").n == 3


def test_unknown_tip_lists_the_frames(tmp_path):
    """An unknown tip frame: FrameNotFound listing the frames."""
    with pytest.raises(ft.FrameNotFound, match=r"'hand'.*'finger_a'"):
        ft.load_arm(str(gripper(tmp_path)), tip="hand")


def test_tip_name_shared_by_a_link_and_a_joint_elsewhere_is_the_link(tmp_path):
    """A link 'tool' and an unrelated joint 'tool' at another place (as in real descriptions,
    e.g. the SO-100's 'gripper'): the tip is the link, with a warning naming both frames."""
    parts = chain3()
    parts[3] = joint("tool", "l1", "l2")
    path = write(tmp_path, "clash.urdf", robot(*parts))
    with pytest.warns(
        UserWarning, match=r"clash.urdf: frame name 'tool' is carried by 2 frames.*the link 'tool'"
    ):
        arm = ft.load_arm(str(path), tip="tool", task="planar")
    ref = ft.load_arm(str(write(tmp_path, "plain.urdf", robot(*chain3()))), task="planar")
    q = np.array([0.3, -0.7, 1.1])
    np.testing.assert_allclose(arm.fk(q), ref.fk(q), atol=1e-12)  # the link, not the joint
    assert arm.joint_names == ["joint1", "tool", "joint3"]


def test_same_name_on_two_non_link_frames_is_ambiguous():
    """Two frames of one name at different places, neither of them a link:
    AmbiguousFrame (a FrameNotFound) naming both, instead of silently taking the first."""
    import pinocchio as pin

    from fault_tolerance.model.chains import frame_id

    model = pin.buildSampleModelManipulator()
    for joint_id, kind in ((1, pin.FrameType.OP_FRAME), (2, pin.FrameType.SENSOR)):
        model.addFrame(pin.Frame("tcp", joint_id, 0, pin.SE3.Identity(), kind))
    with pytest.raises(ft.FrameNotFound, match=r"'tcp' is ambiguous.*OP_FRAME.*SENSOR") as err:
        frame_id(model, "tcp")
    assert type(err.value).__name__ == "AmbiguousFrame"


def test_one_joint_arm_has_a_two_dimensional_jacobian(tmp_path):
    """A single moving joint gives J of shape (m, 1) (eigenpy returns a 1-D array otherwise)."""
    path = write(
        tmp_path,
        "one.urdf",
        robot('<link name="base"/>', joint("joint1", "base", "tool"), '<link name="tool"/>'),
    )
    arm = ft.load_arm(str(path), task="planar")
    assert arm.jacobian(np.array([0.3])).shape == (2, 1)
    assert arm.jacobian_derivatives(np.array([0.3])).shape == (1, 2, 1)


def test_read_urdf_returns_the_checked_text_for_pinocchio(tmp_path):
    """read_urdf's xml has no comments or DTD and loads in Pinocchio as the file would."""
    path = write(tmp_path, "arm.urdf", robot("<!-- a comment -->", *chain3()))
    desc = read_urdf(path)
    assert "comment" not in desc.xml and desc.leaves == ("tool",)
    assert pin.buildModelFromXML(desc.xml).nv == 3


@pytest.mark.parametrize(
    "limit, message",
    [
        ('lower="1" upper="-1" effort="1" velocity="1"', "lower limit 1.0 > upper limit -1.0"),
        ('lower="nan" upper="1" effort="1" velocity="1"', 'lower="nan"'),
        ('lower="-inf" upper="1" effort="1" velocity="1"', "finite number"),
        ('lower="-1" upper="abc" effort="1" velocity="1"', 'upper="abc"'),
        ('lower="-1" upper="1" effort="1" velocity="-2"', "must be >= 0"),
    ],
)
def test_bad_joint_limits_are_refused_naming_the_joint(limit, message, tmp_path):
    """<limit> with lower > upper, NaN, infinite or non-numeric bounds, or a negative velocity:
    URDFError naming the file, the joint and the rule."""
    text = robot(*chain3()).replace(LIMIT, f"<limit {limit}/>", 1)
    assert f"<limit {limit}/>" in text
    path = tmp_path / "limits.urdf"
    path.write_text(text)
    with pytest.raises(ft.URDFError, match=re.escape(message)) as info:
        ft.load_arm(str(path))
    assert "joint 'joint1'" in str(info.value) and str(path) in str(info.value)


def test_urdf_bytes_are_checked_like_a_file(tmp_path):
    """read_urdf(name, data) checks the given bytes (DTDs, structure) and never opens ``name``."""
    from fault_tolerance.model.formats.urdf import read_urdf

    desc = read_urdf(tmp_path / "not_there.urdf", robot(*chain3()).encode())
    assert "joint1" in desc.joint_types
    with pytest.raises(ft.URDFError, match="DOCTYPE"):
        read_urdf(tmp_path / "not_there.urdf", billion_laughs().encode())


def long_chain(n: int) -> str:
    """A serial chain of ``n`` revolute joints ending in ``tool`` (alternating z / y axes)."""
    parts = ['<link name="l0"/>']
    for i in range(1, n + 1):
        child = "tool" if i == n else f"l{i}"
        axis = "0 0 1" if i % 2 else "0 1 0"
        parts += [
            joint(f"j{i}", f"l{i - 1}", child, axis=axis, xyz="0 0 0.1"),
            f'<link name="{child}"/>',
        ]
    return robot(*parts)


def test_too_many_active_joints_are_refused_before_pinocchio_allocates(tmp_path):
    """A 1000-joint chain (inside the file limit) as one arm: refused naming the limit (Pinocchio's
    data would need ~60 GB); the same file with a tip near the base loads."""
    from fault_tolerance.model.arm import MAX_ACTIVE_JOINTS

    path = tmp_path / "chain1000.urdf"
    path.write_text(long_chain(1000))
    with pytest.raises(ft.URDFError, match=f"1000 active joints; at most {MAX_ACTIVE_JOINTS}"):
        ft.load_arm(str(path))
    assert ft.load_arm(str(path), tip="l5").n == 5
