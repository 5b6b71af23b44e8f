"""The house: layered subpackages, imports pointing down only, no circles, no forwarders.

Every import counts, at module level or inside a function (a lazy import is an edge like any
other). docs/architecture.md draws the same layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fault_tolerance"

#: The layers, bottom first: a module may import only from its own layer or the ones below.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "fast_cache", "version"),
    ("storage",),
    ("numerics",),
    ("model",),
    ("resolution",),
    ("control",),
    ("simulation",),
    ("planning",),
    ("analysis",),
    ("figures",),
    ("viz",),
    ("paper", "bench"),
    ("cli", "__main__"),
)
#: At most this many modules (``.py`` files) at the package's top level, ``__init__`` included.
MAX_TOP_LEVEL = 12
#: Longest function [lines, ``def`` to its last line, docstring included] (STYLE.md).
FUNCTION_LINES = 80


def module_name(path: Path, root: Path = PKG) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(path: Path, root: Path = PKG) -> set[str]:
    """Every ``fault_tolerance`` module ``path`` imports, wherever the import stands."""
    me = module_name(path, root).split(".")
    package = me if path.name == "__init__.py" else me[:-1]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("fault_tolerance"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "fault_tolerance":
                continue
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
    return out


def graph(root: Path = PKG) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a package stands for its ``__init__``)."""
    files = {module_name(p, root): p for p in root.rglob("*.py")}
    return {m: {t for t in imports(p, root) if t in files and t != m} for m, p in files.items()}


def layer_of(module: str) -> int:
    """Index in :data:`LAYERS` of a module, by its first name below the package; -1: the façade."""
    parts = module.split(".")
    if len(parts) == 1:
        return len(LAYERS)  # fault_tolerance/__init__.py: the façade sits on top
    for i, names in enumerate(LAYERS):
        if parts[1] in names:
            return i
    raise AssertionError(f"{module} is in no layer of LAYERS: add its folder there")


def upward_edges(g: dict[str, set[str]]) -> list[tuple[str, str]]:
    return sorted((a, b) for a, bs in g.items() for b in bs if layer_of(b) > layer_of(a))


def cycles(g: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_the_import_graph_is_read():
    """The graph sees module-level and in-function imports."""
    g = graph()
    assert "fault_tolerance.control.controller" in g["fault_tolerance.bench.cases"]
    assert "fault_tolerance.model.arm" in g["fault_tolerance.planning.default_start"]


def test_the_checks_can_fail(tmp_path):
    """A lazy upward import and a lazy circle are found: the checks below can fail."""
    pkg = tmp_path / "fault_tolerance"
    (pkg / "model").mkdir(parents=True)
    (pkg / "cli").mkdir()
    for d in (pkg, pkg / "model", pkg / "cli"):
        (d / "__init__.py").write_text("")
    (pkg / "model" / "arm.py").write_text("def f():\n    from fault_tolerance.cli import run\n")
    (pkg / "cli" / "run.py").write_text("from ..model.arm import f\n")
    g = graph(pkg)
    assert ("fault_tolerance.model.arm", "fault_tolerance.cli.run") in upward_edges(g)
    assert [sorted(c) for c in cycles(g)] == [
        ["fault_tolerance.cli.run", "fault_tolerance.model.arm"]
    ]


def test_imports_point_down_only():
    """No module imports from a layer above its own, lazily or not."""
    assert upward_edges(graph()) == []


def test_no_import_circles():
    """No module reaches itself through its imports, at module level or inside functions."""
    assert [sorted(c) for c in cycles(graph())] == []


def test_no_forwarders_and_no_reexports():
    """No module-level ``__getattr__``; no ``__all__`` below the façade lists a name it imports;
    (ruff's F401, run by tests/test_tooling.py, finds an import nobody uses: a re-export)."""
    for path in PKG.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        rel = path.relative_to(PKG).as_posix()
        assert not any(
            isinstance(n, ast.FunctionDef) and n.name == "__getattr__" for n in tree.body
        ), f"{rel}: a module __getattr__ forwards names; import them where they are defined"
        if rel == "__init__.py":
            continue
        defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
        for n in tree.body:
            if isinstance(n, (ast.Assign, ast.AnnAssign)):
                for t in n.targets if isinstance(n, ast.Assign) else [n.target]:
                    defined.update(x.id for x in ast.walk(t) if isinstance(x, ast.Name))
        for n in tree.body:
            if isinstance(n, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets
            ):
                listed = {e.value for e in n.value.elts}  # type: ignore[attr-defined]
                assert listed <= defined, f"{rel}: __all__ re-exports {sorted(listed - defined)}"


def test_the_top_level_is_small():
    """At most MAX_TOP_LEVEL modules at the top: the folders show the layers."""
    top = [p for p in PKG.iterdir() if p.suffix == ".py"]
    assert len(top) <= MAX_TOP_LEVEL, sorted(p.name for p in top)


def test_every_folder_is_a_layer():
    """Every subpackage has its place in LAYERS (a new folder must be placed, not guessed)."""
    for p in PKG.iterdir():
        if (p / "__init__.py").exists() or (p.suffix == ".py" and p.name != "__init__.py"):
            layer_of(f"fault_tolerance.{p.stem}")


def _functions(tree: ast.AST, prefix: str = ""):
    """``(qualified name, lines)`` of every function and method, nested ones included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node.end_lineno - node.lineno + 1  # type: ignore[operator]
            yield from _functions(node, prefix + node.name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


def test_the_size_check_sees_long_functions():
    """The measure itself: a method of 81 lines is found, one of 80 is not."""
    body = "\n".join(["        x = 1"] * 79)
    src = f"class A:\n    def long(self):\n{body}\n        return x\n    def ok(self):\n        return 1\n"
    assert [(n, k) for n, k in _functions(ast.parse(src)) if k > FUNCTION_LINES] == [("A.long", 81)]
    src = src.replace("        x = 1\n", "", 1)
    assert [n for n, k in _functions(ast.parse(src)) if k > FUNCTION_LINES] == []


def test_no_function_over_80_lines():
    """STYLE.md: no function you must scroll (modules are cut by concept, not by a line count)."""
    over = {
        f"{p.relative_to(PKG).as_posix()}:{name}": n
        for p in sorted(PKG.rglob("*.py"))
        for name, n in _functions(ast.parse(p.read_text(encoding="utf-8")))
        if n > FUNCTION_LINES
    }
    assert not over, over


def test_no_issue_numbers_outside_the_changelog():
    """Issue numbers and development history belong to CHANGELOG.md: none in the package,
    tests, scripts, notebooks or pyproject (this file's own pattern excepted)."""
    import re

    root = PKG.parent
    pattern = re.compile(r"\(#\d+\)|\bissue \d+|#1[0-9]\b|#2[0-9]\b", re.I)
    paths = [
        p
        for d in ("fault_tolerance", "tests", "scripts", "notebooks")
        for p in (root / d).rglob("*")
    ]
    found = [
        f"{p.relative_to(root)}:{i}"
        for p in paths + [root / "pyproject.toml"]
        if p.is_file()
        and p.suffix in (".py", ".ipynb", ".toml", ".md")
        and p.name != "test_architecture.py"
        for i, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not found, found
