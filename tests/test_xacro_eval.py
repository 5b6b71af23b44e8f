"""Safe xacro expansion gives the same URDF as plain xacro on real descriptions.

Plain xacro (Python's ``eval``, unconfined reads) is run here only on the repository's own,
trusted test data, with ``$(find)`` resolved through the same package folders.
"""

from __future__ import annotations

import contextlib
import io

import pytest
from real_arms import ARMS, package_dirs, source

from fault_tolerance.model.formats import xacro_eval
from fault_tolerance.model.formats.packages import find_package
from fault_tolerance.model.formats.xacro import _XACRO_LOCK, expand_xacro

XACRO_ARMS = [name for name in ARMS if ARMS[name]["source"].endswith(".xacro")]
#: Further argument sets that switch on other branches of the same descriptions.
VARIANTS = [
    ("fr3", {"hand": "false"}),
    ("fr3", {"with_sc": "true", "no_prefix": "true"}),
    ("fr3", {"ros2_control": "true", "use_fake_hardware": "true", "robot_ip": "10.0.0.2"}),
    ("fr3", {"arm_prefix": "left"}),
]


def plain_xacro(path, dirs, args) -> str:
    """The expansion by the unpatched xacro package (only ``$(find)`` points at ``dirs``)."""
    import xacro
    import xacro.substitution_args as subst

    def find(package: str) -> str:
        return str(find_package(package, dirs))

    with _XACRO_LOCK:
        saved = subst._eval_find, subst._eval_dict["find"]
        subst._eval_find = subst._eval_dict["find"] = find
        try:
            with (
                contextlib.redirect_stderr(io.StringIO()),
                contextlib.redirect_stdout(io.StringIO()),
            ):
                return xacro.process_file(str(path.absolute()), mappings=dict(args)).toxml()
        finally:
            subst._eval_find, subst._eval_dict["find"] = saved
            xacro.substitution_args_context["arg"] = {}


CASES = [(name, ARMS[name]["xacro_args"] or {}) for name in XACRO_ARMS] + VARIANTS


@pytest.mark.parametrize("name, args", CASES, ids=[f"{n}-{sorted(a)}" for n, a in CASES])
def test_real_descriptions_expand_to_the_same_urdf_as_plain_xacro(name, args):
    """Every real xacro of the test data (and further argument sets) expands character for
    character as the plain xacro package expands it."""
    dirs = package_dirs(name)
    ours, _ = expand_xacro(source(name), dirs, args)
    assert ours.decode("utf-8") == plain_xacro(source(name), dirs, args)


def test_the_xacro_module_is_restored_after_an_expansion():
    """The patches live only during an expansion: afterwards xacro's functions are its own."""
    import xacro

    before = {n: getattr(xacro, n) for n in ("safe_eval", "eval_text", "parse", "load_yaml")}
    expand_xacro(source("ur5e"), package_dirs("ur5e"))
    assert {n: getattr(xacro, n) for n in before} == before
    assert xacro_eval._SESSION is None
