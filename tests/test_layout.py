"""The package's module graph: no import circles (also through imports inside functions)."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fault_tolerance"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Modules of the package that ``path`` imports anywhere, except in ``__getattr__`` forwarders.

    A module-level ``__getattr__`` only forwards names that moved to another module (kept for old
    import paths); it is not a dependency of the module's own code.
    """
    tree = ast.parse(path.read_text())
    me = _module_name(path).split(".")
    package = me if path.name == "__init__.py" else me[:-1]
    skip = {
        id(n)
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and f.name == "__getattr__"
        for n in ast.walk(f)
    }
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[: len(package) - node.level + 1]
            target = ".".join(base + ([node.module] if node.module else []))
            names = [target] + [f"{target}.{a.name}" for a in node.names]
            out.update(names)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            mod = node.module if isinstance(node, ast.ImportFrom) else None
            for a in node.names if mod is None else [ast.alias(mod)]:
                if a.name.startswith("fault_tolerance"):
                    out.add(a.name)
    return out


#: The modules that load arms. (The package has two older lazy circles elsewhere, indices <->
#: planner and realtime <-> kernels, outside this test's scope.)
ARM_MODULES = {
    f"fault_tolerance.{m}"
    for m in ("arm", "urdf", "catalog", "chains", "models", "loading", "inspection", "sources")
}


def test_no_import_circle_through_the_arm_modules():
    """No module that loads arms reaches itself through the modules it imports."""
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph = {
        m: {t for t in _imports(p) if t in files and t != m and not m.startswith(t + ".")}
        for m, p in files.items()
    }
    # the package __init__ re-exports; a submodule importing "fault_tolerance" is not a cycle of ours
    for m in graph:
        graph[m].discard("fault_tolerance")
    state: dict[str, int] = {}
    cycles = []

    def visit(m, stack):
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t) :] + [t])
            elif t not in state:
                visit(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    ours = [c for c in cycles if ARM_MODULES & set(c)]
    assert not ours, f"import circles: {ours}"


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
