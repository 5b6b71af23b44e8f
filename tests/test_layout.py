"""The package's layout on disk: the shipped robots are found in every way the package is installed.

The layers, circles and sizes are tests/test_architecture.py's.
"""

from __future__ import annotations

from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fault_tolerance"


# -- shipped robots in every layout -----------------------------------------------------------

ROOT = PKG.parent
#: Run in a child interpreter: drop the editable install's import hook (a user's clone after a
#: plain ``pip install .`` has none; here it would map ``fault_tolerance.robots`` to the
#: worktree and hide the problem), put ``SITE`` after the working folder, load a shipped arm.
CHILD = (
    "import sys\n"
    "sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in str(getattr(f, '__module__', ''))]\n"
    "sys.path.insert(1, {site!r})\n"
    "import fault_tolerance as ft\n"
    "arm = ft.load_arm('planar_3r')\n"
    "print(ft.__file__, arm.n)\n"
)


def _copy_package(dest: Path) -> None:
    import shutil

    shutil.copytree(PKG, dest, ignore=shutil.ignore_patterns("__pycache__"))


def _child(cwd: Path, site: Path):
    import subprocess
    import sys

    return subprocess.run(
        [sys.executable, "-c", CHILD.format(site=str(site))],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_clone_root_shadowing_the_installed_package_finds_the_robots(tmp_path):
    """From the root of a clone after ``pip install .`` (non-editable), ``import fault_tolerance``
    is the clone's folder, which has no ``robots`` subpackage; the shipped arms still load from
    the clone's ``robots/``."""
    import shutil

    clone, site = tmp_path / "clone", tmp_path / "site"
    _copy_package(clone / "fault_tolerance")
    shutil.copytree(ROOT / "robots", clone / "robots")
    _copy_package(site / "fault_tolerance")  # the installed copy: the wheel's layout
    shutil.copytree(ROOT / "robots", site / "fault_tolerance" / "robots")
    p = _child(clone, site)
    assert p.returncode == 0, p.stderr
    where, n = p.stdout.split()
    assert Path(where).parent == clone / "fault_tolerance" and n == "3"  # the clone shadowed it


def test_installed_layout_finds_the_robots_as_package_data(tmp_path):
    """Installed (the wheel's layout, ``fault_tolerance/robots/`` as package data), imported
    from anywhere else, the shipped arms load."""
    import shutil

    site = tmp_path / "site"
    _copy_package(site / "fault_tolerance")
    shutil.copytree(ROOT / "robots", site / "fault_tolerance" / "robots")
    (tmp_path / "elsewhere").mkdir()
    p = _child(tmp_path / "elsewhere", site)
    assert p.returncode == 0, p.stderr
    where, n = p.stdout.split()
    assert Path(where).parent == site / "fault_tolerance" and n == "3"


def test_the_wheel_maps_robots_into_the_package():
    """pyproject puts ``robots/`` into the wheel as ``fault_tolerance.robots`` with its files."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "fault_tolerance.robots" in cfg["packages"]
    assert cfg["package-dir"]["fault_tolerance.robots"] == "robots"
    assert {"*.urdf", "*.json"} <= set(cfg["package-data"]["fault_tolerance.robots"])
