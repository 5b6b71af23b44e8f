"""The real robot descriptions of ``tests/data/robots`` (see its manifest.json and NOTES.md).

Other test files parametrize over them::

    from real_arms import ARMS, cli_args, load

    @pytest.mark.parametrize("name", ARMS)
    def test_something(name):
        arm = load(name)
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

DATA = Path(__file__).resolve().parent / "data" / "robots"
MANIFEST = json.loads((DATA / "manifest.json").read_text())
#: name -> entry (source, package_dirs, xacro_args, tip, joints, task, lockable, q0, covers, ...)
ARMS: dict[str, dict] = MANIFEST["arms"]


def source(name: str) -> Path:
    """The description file of an arm (URDF or xacro)."""
    return DATA / ARMS[name]["source"]


def package_dirs(name: str) -> list[str]:
    """The package folders of an arm, as absolute paths."""
    return [str(DATA / d) for d in ARMS[name]["package_dirs"]]


def load(name: str, **overrides):
    """``ft.load_arm`` of a manifest arm; the missing-mesh warning (no meshes kept) is silenced."""
    import fault_tolerance as ft

    e = ARMS[name]
    kwargs = dict(
        tip=e["tip"],
        task=e["task"],
        joints=e["joints"],
        package_dirs=package_dirs(name),
        xacro_args=e["xacro_args"] or None,
    )
    kwargs.update(overrides)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*mesh file\\(s\\) not found")
        warnings.filterwarnings("ignore", message=".*is carried by 2 frames")
        return ft.load_arm(source(name), **kwargs)


def path_args(name: str) -> list[str]:
    """Task-path options the arm needs (``path_args`` in the manifest, with ``path_args_why``)."""
    return list(ARMS[name].get("path_args", []))


def cli_args(name: str) -> list[str]:
    """``--urdf FILE --package-dir ... --xacro-arg ... --tip --task [--joints] [--lockable]``."""
    e = ARMS[name]
    args = ["--urdf", str(source(name))]
    for d in package_dirs(name):
        args += ["--package-dir", d]
    for k, v in (e["xacro_args"] or {}).items():
        args += ["--xacro-arg", f"{k}:={v}"]
    args += ["--tip", e["tip"], "--task", e["task"]]
    if e["joints"]:
        args += ["--joints", ",".join(e["joints"])]
    if e["lockable"]:
        args += ["--lockable", ",".join(e["lockable"])]
    return args
