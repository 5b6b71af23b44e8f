"""Hostile xacro files: no code runs, no file outside the package folders is read, all bounded.

Each hostile description is written by the test into ``tmp_path`` and loaded in a subprocess
with a timeout, once through ``fault_tolerance.load_arm`` and once through
``fault-tolerance inspect`` (exit 2, one line on stderr, no traceback).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import fault_tolerance as ft
from fault_tolerance.model.formats import xacro_eval
from fault_tolerance.model.formats.xacro import expand_xacro
from fault_tolerance.model.formats.xacro_eval import FUNCTIONS, evaluate

TIMEOUT = 90  # [s] per subprocess; every refusal below takes a few seconds at most
XMLNS = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'

LOAD = textwrap.dedent(
    """
    import json, sys
    import fault_tolerance as ft
    path, dirs = sys.argv[1], json.loads(sys.argv[2])
    try:
        ft.load_arm(path, package_dirs=dirs or None, task="position")
    except Exception as err:
        print(json.dumps([type(err).__name__, isinstance(err, ft.UnsafeDescription), str(err)]))
    else:
        print(json.dumps(["loaded", False, ""]))
    """
)


def description(tmp_path: Path, body: str, name: str = "evil.urdf.xacro") -> Path:
    """A xacro file in ``tmp_path/pkg`` with ``body`` before a two-link arm."""
    folder = tmp_path / "pkg"
    folder.mkdir(exist_ok=True)
    path = folder / name
    path.write_text(
        f'<?xml version="1.0"?>\n<robot name="evil" {XMLNS}>\n{body}\n'
        '<link name="base"/><link name="tool"/>\n'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="tool"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n'
        "</robot>\n"
    )
    return path


def assert_refused(path: Path, match: str, package_dirs=()) -> None:
    """load_arm raises UnsafeDescription (message matching ``match``) and the CLI exits 2."""
    dirs = [str(d) for d in package_dirs]
    start = time.monotonic()
    p = subprocess.run(
        [sys.executable, "-c", LOAD, str(path), json.dumps(dirs)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        cwd=path.parent,
    )
    assert p.returncode == 0, p.stderr
    kind, unsafe, message = json.loads(p.stdout.strip().splitlines()[-1])
    assert unsafe, (kind, message)
    assert __import__("re").search(match, message), message
    cli = [sys.executable, "-m", "fault_tolerance", "inspect", str(path)]
    for d in dirs:
        cli += ["--package-dir", d]
    q = subprocess.run(cli, capture_output=True, text=True, timeout=TIMEOUT, cwd=path.parent)
    assert q.returncode == 2, (q.stdout, q.stderr)
    assert q.stderr.count("\n") == 1 and "Traceback" not in q.stderr, q.stderr
    assert time.monotonic() - start < 2 * TIMEOUT


# -- code execution -------------------------------------------------------------------------------


def marker_body(marker: Path, expr: str) -> str:
    return f'<xacro:property name="x" value="${{{expr}}}"/><link name="l${{x}}"/>'.replace(
        "MARKER", str(marker)
    )


CODE = {
    "comprehension reaching __subclasses__": (
        "[c for c in ().__class__.__base__.__subclasses__() if c.__name__ == 'Popen'][0]"
        "(['touch', 'MARKER'])",
        r"comprehensions are not allowed",
    ),
    "comprehension without dunders": ("[x for x in 'ab']", r"comprehensions are not allowed"),
    "__import__": ("__import__('os').system('touch MARKER')", r"'__import__' is not allowed"),
    "lambda": ("(lambda: 1)()", r"lambdas are not allowed"),
    "attribute of a tuple": ("().__class__", r"'.__class__' is not allowed"),
    "str method outside the list": ("'a'.format(1)", r"'.format' of a str is not allowed"),
    "python namespace": ("python.sorted('ba')", r"'python' \(NameSpace\) is not among"),
    "builtin outside the list": ("list('ab')", r"'list' \(type\) is not among"),
    "walrus": ("(y := 1)", r"assignments \(:=\) are not allowed"),
    "f-string": ("f'x'", r"f-strings are not allowed"),
}


@pytest.mark.parametrize("case", sorted(CODE))
def test_code_execution_is_refused(tmp_path, case):
    """Expressions outside the whitelist are refused with the file, line and expression; nothing runs."""
    expr, match = CODE[case]
    marker = tmp_path / "MARKER_CREATED"
    path = description(tmp_path, marker_body(marker, expr))
    assert_refused(path, rf"evil\.urdf\.xacro:3: \$\{{.*\}}: .*{match}")
    assert not marker.exists()


def test_eval_substitution_is_refused(tmp_path):
    """``$(eval ...)`` goes through the same evaluator (xacro gave it Python's builtins)."""
    path = description(tmp_path, "<link name=\"$(eval [x for x in 'ab'])\"/>")
    assert_refused(path, r"\$\{\$\(eval \[x for x in 'ab'\]\)\}: comprehensions are not allowed")


# -- file reads -------------------------------------------------------------------------------------


def yaml_body(file: str) -> str:
    return (
        f'<xacro:property name="c" value="${{xacro.load_yaml(\'{file}\')}}"/><link name="${{c}}"/>'
    )


def test_load_yaml_of_etc_passwd_is_refused(tmp_path):
    """``xacro.load_yaml('/etc/passwd')`` reads nothing outside the package folders."""
    path = description(tmp_path, yaml_body("/etc/passwd"))
    assert_refused(path, r"xacro\.load_yaml of /etc/passwd lies outside the folders xacro may read")


def test_load_yaml_outside_the_package_dirs_is_refused(tmp_path):
    """A YAML file next to, but outside, the description's folder and package folders is refused."""
    secret = tmp_path / "secret.yaml"
    secret.write_text("token: hunter2\n")
    path = description(tmp_path, yaml_body("../secret.yaml"))
    assert_refused(path, r"secret\.yaml lies outside", package_dirs=[tmp_path / "other"])


def test_include_of_a_fifo_does_not_block(tmp_path):
    """A FIFO inside the package folder is refused at once (never opened for a blocking read)."""
    fifo = tmp_path / "pkg" / "pipe.xacro"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    path = description(tmp_path, '<xacro:include filename="pipe.xacro"/>')
    assert_refused(path, r"evil\.urdf\.xacro:3: xacro file .*pipe\.xacro is a FIFO")


def test_include_of_dev_zero_is_refused(tmp_path):
    """``/dev/zero`` is outside the folders and a device: refused, not read until memory is gone."""
    path = description(tmp_path, '<xacro:include filename="/dev/zero"/>')
    assert_refused(path, r"/dev/zero lies outside")


def test_dev_zero_inside_a_package_folder_is_refused():
    """A device is refused even when its folder is a package folder (not a regular file)."""
    with pytest.raises(ft.UnsafeDescription, match=r"/dev/zero is a character device"):
        xacro_eval.read_confined("/dev/zero", ["/dev"])


def test_include_of_a_symlink_pointing_outside_is_refused(tmp_path):
    """A symlink inside the package folder to a file outside it is refused (real paths count)."""
    outside = tmp_path / "outside.xacro"
    outside.write_text(f'<robot {XMLNS}><link name="stolen"/></robot>')
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "link.xacro").symlink_to(outside)
    path = description(tmp_path, '<xacro:include filename="link.xacro"/>')
    assert_refused(path, r"link\.xacro \(-> .*outside\.xacro\) lies outside")


def test_include_glob_outside_is_refused(tmp_path):
    """An include pattern is refused when its folder lies outside the package folders."""
    path = description(tmp_path, '<xacro:include filename="/etc/*.conf"/>')
    assert_refused(path, r"include pattern /etc/\*\.conf lies outside")


def test_symlink_inside_the_folders_is_followed(tmp_path):
    """A symlink that stays inside the package folder is read as usual."""
    (tmp_path / "pkg" / "inc").mkdir(parents=True)
    (tmp_path / "pkg" / "inc" / "real.xacro").write_text(
        f'<robot {XMLNS}><link name="extra"/></robot>'
    )
    (tmp_path / "pkg" / "alias.xacro").symlink_to(tmp_path / "pkg" / "inc" / "real.xacro")
    path = description(tmp_path, '<xacro:include filename="alias.xacro"/>')
    assert b'<link name="extra"/>' in expand_xacro(path)[0]


# -- unbounded expansions ---------------------------------------------------------------------------


def macro_bomb(levels: int = 30) -> str:
    """Macros m0..m{levels}, each calling the one below twice: 2**levels links."""
    macros = ['<xacro:macro name="m0" params="p"><link name="l${p}"/></xacro:macro>']
    for i in range(1, levels + 1):
        macros.append(
            f'<xacro:macro name="m{i}" params="p"><xacro:m{i - 1} p="${{p}}a"/>'
            f'<xacro:m{i - 1} p="${{p}}b"/></xacro:macro>'
        )
    return "\n".join(macros) + f'\n<xacro:m{levels} p="x"/>'


def block_bomb(levels: int = 8) -> str:
    """A block inserted ten times per level, one macro call per level: 10**levels links."""
    insert = '<xacro:insert_block name="x"/>'
    macros = [f'<xacro:macro name="b0" params="**x">{insert}</xacro:macro>']
    for i in range(1, levels + 1):
        macros.append(
            f'<xacro:macro name="b{i}" params="**x"><xacro:b{i - 1}><w>{insert * 10}</w>'
            f"</xacro:b{i - 1}></xacro:macro>"
        )
    return "\n".join(macros) + f'\n<xacro:b{levels}><w><link name="z"/></w></xacro:b{levels}>'


BOUNDS = {
    "macro bomb": (macro_bomb(), r"more than 10000 macro calls \(MAX_MACRO_CALLS\)"),
    "block bomb": (block_bomb(), r"\(MAX_ELEMENTS\)|\(MAX_DOM_WORK\)"),
    "recursion": (
        '<xacro:macro name="r" params="n"><xacro:r n="${n+1}"/></xacro:macro><xacro:r n="0"/>',
        r"nested more than 100 deep \(MAX_MACRO_DEPTH\)",
    ),
    "power tower": (
        '<link name="${9**9**9}"/>',
        r"evil\.urdf\.xacro:3: \$\{9\*\*9\*\*9\}: the power 9 \*\* 387420489 would have",
    ),
    "string bomb": ("<link name=\"${'a'*10**9}\"/>", r"repeating a str 1000000000 times"),
    "string doubling": (
        '<xacro:property name="s0" value="aaaaaaaaaaaaaaaa"/>\n'
        + "\n".join(
            f'<xacro:property name="s{i}" value="${{s{i - 1} + s{i - 1}}}"/>' for i in range(1, 40)
        )
        + '\n<link name="${s39}"/>',
        r"the sum would be larger than 1000000 characters",
    ),
    "format width": ("<link name=\"${'%999999999d' % 1}\"/>", r"width or precision"),
    "self include": (
        '<xacro:include filename="evil.urdf.xacro"/>',
        r"includes are nested more than 50 deep",
    ),
    "yaml alias bomb": (
        '<xacro:property name="c" value="${xacro.load_yaml(\'bomb.yaml\')}"/>'
        '<link name="${str(c)}"/>',
        r"bomb\.yaml expands to more than 1000000 characters",
    ),
}


@pytest.mark.parametrize("case", sorted(BOUNDS))
def test_unbounded_expansion_is_refused(tmp_path, case):
    """Exponential macros, huge powers and strings, recursion: a clear refusal in bounded time."""
    body, match = BOUNDS[case]
    (tmp_path / "pkg").mkdir()
    lines = ['a: &a ["xxxxxxxxxx", "xxxxxxxxxx", "xxxxxxxxxx", "xxxxxxxxxx"]']
    lines += [
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}]"
        for p, c in zip("abcdefgh", "bcdefghi", strict=True)
    ]
    (tmp_path / "pkg" / "bomb.yaml").write_text("\n".join(lines) + "\n")
    path = description(tmp_path, body)
    assert_refused(path, match)


def test_deadline_stops_a_slow_expansion(tmp_path):
    """The wall-time deadline, checked in the evaluator and in every element, stops an expansion."""
    import xacro

    path = description(tmp_path, macro_bomb(12))
    with pytest.raises(ft.UnsafeDescription, match=r"longer than 0\.2 s \(DEADLINE_SECONDS\)"):
        with xacro_eval.confined(xacro, path, [path.parent], seconds=0.2):
            time.sleep(0.3)
            xacro.process_file(str(path))


# -- what stays allowed -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "expr, value",
    [
        ("radians(90)", math.pi / 2),
        ("pi/2", math.pi / 2),
        ("math.pi / 4", math.pi / 4),
        ("sin(pi/2) + cos(0)", 2.0),
        ("atan2(1, 1) * 4", math.pi),
        ("sqrt(16) ** 2 // 3 % 4", 1.0),
        ("-x if x > 0 and not flag else x", -2.0),
        ("'a' if 'y' in axis else 'b'", "a"),
        ("cfg['shoulder']['x'] * 2", 0.5),
        ("cfg.shoulder.x", 0.25),
        ("xyz.split(' ')[2]", "3"),
        ("[1, 2][0] + len('abc') + max(1, 2) + int('4') + float('0.5')", 10.5),
        ("round(2 ** 0.5, 3)", 1.414),
        ("'%s_link' % name", "arm_link"),
        ("2 ** 100", 2**100),
        ("str(1.5) + '!'", "1.5!"),
        ("1 < x < 3 == 3", True),
    ],
)
def test_whitelisted_expressions_evaluate_as_python(expr, value):
    """Arithmetic, math functions, conditionals and YAML dict access give Python's values."""
    import xacro

    symbols = xacro.Table(xacro._global_symbols)
    symbols["x"] = 2.0
    symbols._setitem("flag", False, unevaluated=False)
    symbols["axis"] = "x y"
    symbols["xyz"] = "1 2 3"
    symbols["name"] = "arm"
    symbols._setitem("cfg", xacro.YamlListWrapper.wrap({"shoulder": {"x": 0.25}}), False)
    assert evaluate(expr, symbols) == value


def test_evaluate_without_xacro_tables():
    """``evaluate`` also works over a plain dict with :data:`FUNCTIONS` (as ``$(eval)`` does)."""
    assert evaluate("degrees(a) if a else 0", {"a": math.pi}, functions=FUNCTIONS) == 180.0
    with pytest.raises(ft.UnsafeDescription, match=r"\$\{\(\)\.__class__\}"):
        evaluate("().__class__", {})


def test_yaml_dict_access_and_units_in_a_description(tmp_path):
    """load_yaml inside the package folder, dict and dotted access and xacro's unit tags work."""
    folder = tmp_path / "pkg"
    folder.mkdir()
    (folder / "cfg.yaml").write_text("shoulder:\n  x: !degrees 180\n  name: tool\n")
    body = (
        '<xacro:property name="cfg" value="${xacro.load_yaml(\'cfg.yaml\')}"/>'
        "<link name=\"${cfg['shoulder']['name']}_${cfg.shoulder.x == pi}\"/>"
    )
    path = description(tmp_path, body)
    assert b'<link name="tool_True"/>' in expand_xacro(path)[0]
