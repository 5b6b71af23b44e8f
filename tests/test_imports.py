"""No import circles inside the package: every import, at module level or inside a function."""

from __future__ import annotations

import ast
from pathlib import Path

import fault_tolerance

PKG = Path(fault_tolerance.__file__).resolve().parent

def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """The package's modules that ``path`` imports (relative or absolute), wherever in the file.

    Except in a module-level ``__getattr__``: it forwards names that moved (old import paths).
    """
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    skip = {
        id(n)
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and f.name == "__getattr__"
        for n in ast.walk(f)
    }
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("fault_tolerance"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if not mod.startswith("fault_tolerance"):
                continue
            if node.module or not node.level:  # `from . import kernels` needs kernels only
                out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)  # `from . import kernels`
    return out


def _graph() -> dict[str, set[str]]:
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph = {}
    for name, path in files.items():
        # an import of a package's submodule is an edge to it; a package itself is its __init__
        graph[name] = {m for m in _imports(path) if m in files and m != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_the_import_graph_is_read():
    g = _graph()
    assert "fault_tolerance.realtime" in g["fault_tolerance.bench.cases"]
    assert "fault_tolerance.kernels" in g["fault_tolerance.realtime"]


def test_the_circle_finder_finds_lazy_circles():
    """A circle closed by an import inside a function counts: the check can fail."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert [sorted(c) for c in _cycles(graph)] == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circles():
    """No module reaches itself through its imports, at module level or inside functions.

    Gone: indices/planner, kernels/realtime, arm/urdf (#11) and the whole-path circle
    simulation -> wholepath.run -> wholepath.plan -> posture -> simulation (#11 item 5: the
    planning loop moved to ``planning``, and simulate hands its loop to ``wholepath.run``).
    """
    assert [sorted(c) for c in _cycles(_graph())] == []


def test_a_lazy_import_is_an_edge(tmp_path):
    """An import inside a function body is read as an edge of the graph (a lazy circle counts)."""
    mod = tmp_path / "fault_tolerance" / "lazy.py"
    mod.parent.mkdir()
    mod.write_text("def f():\n    from .simulation import simulate\n    return simulate\n")
    global PKG
    saved, PKG = PKG, mod.parent
    try:
        assert "fault_tolerance.simulation" in _imports(mod)
    finally:
        PKG = saved
