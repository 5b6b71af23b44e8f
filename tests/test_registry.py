"""The resolver registry: a resolver registered from outside the package runs everywhere.

``damped_lnva`` (damped least squares, ``q̇ = Jᵀ(JJᵀ + μ²I)⁻¹ẋ``) is defined and registered here,
by this test file alone; no package file knows it. It then runs through ``ft.resolve`` (with and
without bounds), ``ft.Controller``, ``ft.simulate`` (with and without limits), ``ft.batch.resolve``,
the CLI (in-process), a plot and the replay page. A second resolver without a bounded variant shows
the clear error of a bounded use.
"""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput
from fault_tolerance.resolution import registry
from fault_tolerance.resolution.bounded import bounded_nearest
from fault_tolerance.simulation.paths import CirclePath

COLOUR = "#123456"
Q0 = np.array([0.3, 1.2, 1.0])
XD = np.array([0.1, 0.0])


@dataclass(frozen=True)
class DampedOptions:
    """The damping μ >= 0 [m] of the damped least-squares rates."""

    damping: float = 0.01

    def __post_init__(self) -> None:
        if not (np.isfinite(self.damping) and self.damping >= 0):
            raise InvalidInput(f"damping must be finite and >= 0, got {self.damping}")


def damped_lnva(J, xdot, lockable=None, *, damping: float = 0.01, proj=None) -> np.ndarray:
    """Damped least squares ``q̇ = Jᵀ(JJᵀ + μ²I)⁻¹ẋ`` (``lockable`` ignored)."""
    m = J.shape[0]
    return J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(m), xdot)


def closed_form(J, xdot, damping):
    """The same rates the slow way: ``(JᵀJ + μ²I)⁻¹Jᵀẋ`` (the push-through identity)."""
    n = J.shape[1]
    return np.linalg.solve(J.T @ J + damping**2 * np.eye(n), J.T @ xdot)


@pytest.fixture
def damped():
    """``damped_lnva`` registered (with a bounded variant) for one test, then removed."""
    entry = registry.register(
        ft.ResolverEntry(
            "damped_lnva",
            damped_lnva,
            DampedOptions,
            bounded=bounded_nearest(damped_lnva),
            label="damped LNVA",
            colour=COLOUR,
        )
    )
    yield entry
    registry.unregister("damped_lnva")


@pytest.fixture
def unbounded():
    """``plain_damped``: the same rates without a bounded variant, for one test."""
    registry.register(ft.ResolverEntry("plain_damped", damped_lnva, DampedOptions))
    yield
    registry.unregister("plain_damped")


@pytest.fixture(scope="module")
def arm():
    return ft.load_arm("planar_3r")


@pytest.fixture(scope="module")
def path():
    return CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.05)


def test_register_get_names_unregister(damped):
    """A registered resolver is listed and found; an unknown name lists the registered ones."""
    assert "damped_lnva" in registry.names()
    assert registry.get("damped_lnva") is damped
    assert damped.option_names == ("damping",)
    with pytest.raises(InvalidInput, match="damped_lnva"):
        registry.get("nope")
    with pytest.raises(InvalidInput, match="registered already"):
        registry.register(damped)


def test_unregistered_after_the_fixture():
    """The fixture removed it: no test leaks a resolver into the next."""
    assert "damped_lnva" not in registry.names()
    with pytest.raises(InvalidInput, match="not one of"):
        ft.resolve("damped_lnva", np.eye(2, 3), XD)


def test_entries_are_validated():
    """Bad entries are refused: a name that is no identifier, options that are no frozen dataclass."""
    with pytest.raises(InvalidInput, match="lower-case identifier"):
        ft.ResolverEntry("Damped LNVA", damped_lnva, DampedOptions)

    @dataclass
    class Loose:
        damping: float = 0.0

    with pytest.raises(InvalidInput, match="frozen"):
        ft.ResolverEntry("loose", damped_lnva, Loose)
    with pytest.raises(InvalidInput, match="dataclass"):
        ft.ResolverEntry("loose", damped_lnva, dict)


def test_resolve_runs_the_new_resolver(damped, arm):
    """ft.resolve gives the damped rates (checked the slow way); damping 0 is LNVA."""
    J = arm.jacobian(Q0)
    qd = ft.resolve("damped_lnva", J, XD, damping=0.2)
    np.testing.assert_allclose(qd, closed_form(J, XD, 0.2), atol=1e-12)
    assert np.linalg.norm(J @ qd - XD) > 1e-4  # damped: the task is not met exactly
    np.testing.assert_allclose(
        ft.resolve("damped_lnva", J, XD, damping=0.0), ft.lnva(J, XD), atol=1e-12
    )
    np.testing.assert_allclose(
        ft.resolve("damped_lnva", J, XD), closed_form(J, XD, 0.01), atol=1e-12
    )


def test_resolve_with_bounds_uses_the_bounded_variant(damped, arm):
    """Inside a wide box the bounded rates are the unbounded ones; a tight box is honoured."""
    J = arm.jacobian(Q0)
    wide = (np.full(3, -10.0), np.full(3, 10.0))
    np.testing.assert_allclose(
        ft.resolve("damped_lnva", J, XD, bounds=wide, damping=0.05),
        ft.resolve("damped_lnva", J, XD, damping=0.05),
        atol=1e-12,
    )
    free = ft.resolve("damped_lnva", J, XD, damping=0.05)
    cap = 0.5 * np.abs(free).max()
    out = ft.resolve_bounded("damped_lnva", J, XD, bounds=(-cap, cap), damping=0.05)
    assert np.all(np.abs(out.qd) <= cap + 1e-9)
    assert out.active.any()
    np.testing.assert_allclose(J @ out.qd, out.scale * XD, atol=1e-9)


def test_unknown_options_raise_naming_the_allowed_ones(damped, arm):
    """An option a resolver does not take raises InvalidInput naming its options; bad values too."""
    J = arm.jacobian(Q0)
    with pytest.raises(InvalidInput, match=r"unknown option\(s\) \['gain'\].*\['damping'\]"):
        ft.resolve("damped_lnva", J, XD, gain=0.1)
    with pytest.raises(InvalidInput, match="damping must be finite"):
        ft.resolve("damped_lnva", J, XD, damping=-1.0)
    with pytest.raises(InvalidInput, match=r"\['weights', 'response'\]"):
        ft.resolve("jvja", J, XD, damping=0.1)
    with pytest.raises(InvalidInput, match="lnva.*unknown option"):
        ft.resolve("lnva", J, XD, response="least_norm")  # lnva has no options
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.resolve("damped_lnva", J, XD, bounds=(-np.ones(3), np.ones(3)), gain=1.0)


def test_controller_steps_the_new_resolver(damped, arm):
    """Controller(method=...) without a compiled kernel runs the reference rates, with options."""
    ctrl = ft.Controller(arm, "all", method="damped_lnva", options={"damping": 0.2}, limits=False)
    J = arm.jacobian(Q0)
    np.testing.assert_allclose(ctrl.step(Q0, XD), closed_form(J, XD, 0.2), atol=1e-12)
    out = np.empty(3)
    assert ctrl.step(Q0, XD, out) is out
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.Controller(arm, method="damped_lnva", options={"gain": 1.0}, limits=False)
    with pytest.raises(InvalidInput, match="shape"):
        ctrl.step(Q0[:2], XD)


def test_controller_with_limits_stays_in_the_box(damped, arm):
    """Under limits the Controller's generic step is the bounded variant in the rate box (L1)."""
    ctrl = ft.Controller(arm, "all", method="damped_lnva", options={"damping": 0.05})
    J = arm.jacobian(Q0)
    box = arm.rate_bounds(Q0, ctrl.horizon)
    big = 50.0 * XD  # fast enough to meet a velocity bound
    qd = ctrl.step(Q0, big)
    ref = ft.resolve("damped_lnva", J, big, bounds=box, damping=0.05)
    np.testing.assert_allclose(qd, ref, atol=1e-12)
    assert np.all(qd >= box[0] - 1e-9) and np.all(qd <= box[1] + 1e-9)
    assert ctrl.bounded_steps == 1 and ctrl.last_active.any()


def test_simulate_with_and_without_limits(damped, arm, path):
    """simulate runs it (the reference sample), records its options, and the first rates match."""
    for limits in (False, True):
        run = ft.simulate(
            arm, path, "damped_lnva", q0=Q0, duration=0.2, limits=limits,
            options={"damping": 0.05},
        )  # fmt: skip
        assert run.meta["algorithm"] == "damped_lnva"
        assert run.meta["options"] == {"damping": 0.05}
        J = arm.jacobian(run.q[0])
        xd = path.xdot(0.0)
        box = arm.rate_bounds(run.q[0], 0.05) if limits else None
        np.testing.assert_allclose(
            run.qd[0], ft.resolve("damped_lnva", J, xd, bounds=box, damping=0.05), atol=1e-10
        )
        assert np.all(np.isfinite(run.jvj))
    with pytest.raises(InvalidInput, match="does not cover"):
        ft.simulate(arm, path, "damped_lnva", q0=Q0, duration=0.1, engine="fast")
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.simulate(arm, path, "damped_lnva", q0=Q0, duration=0.1, options={"gain": 1.0})
    with pytest.raises(InvalidInput, match="plan_options"):
        ft.simulate(arm, path, "global", duration=0.1, options={"damping": 0.1})


def test_a_resolver_without_bounded_variant_says_so(unbounded, arm, path):
    """Without a bounded variant, every bounded use raises a clear error; unbounded use works."""
    J = arm.jacobian(Q0)
    with pytest.raises(InvalidInput, match="no bounded variant"):
        ft.resolve("plain_damped", J, XD, bounds=arm.rate_bounds(Q0))
    with pytest.raises(InvalidInput, match="no bounded variant.*limits=False"):
        ft.simulate(arm, path, "plain_damped", q0=Q0, duration=0.1)
    with pytest.raises(InvalidInput, match="no bounded variant"):
        ft.Controller(arm, method="plain_damped")
    run = ft.simulate(arm, path, "plain_damped", q0=Q0, duration=0.1, limits=False)
    assert run.meta["algorithm"] == "plain_damped"
    qd = ft.Controller(arm, method="plain_damped", limits=False).step(Q0, XD)
    np.testing.assert_allclose(qd, closed_form(J, XD, 0.01), atol=1e-12)


def test_batch_resolve_runs_it_row_by_row(damped, arm):
    """ft.batch.resolve of the new resolver equals ft.resolve on every row."""
    rng = np.random.default_rng(3)
    Q = Q0 + 0.2 * rng.standard_normal((5, 3))
    Js = ft.batch.jacobians(arm, Q)
    xd = rng.standard_normal((5, 2))
    qd = ft.batch.resolve("damped_lnva", Js, xd, options={"damping": 0.1})
    for b in range(5):
        np.testing.assert_allclose(qd[b], closed_form(Js[b], xd[b], 0.1), atol=1e-12)
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.batch.resolve("damped_lnva", Js, xd, options={"gain": 0.1})


def test_cli_simulate_and_lock_run_it(damped, tmp_path, capsys):
    """The CLI lists it, runs it with --option, writes its run, plot and replay page."""
    from fault_tolerance.cli import main

    out = tmp_path / "out"
    argv = ["simulate", "--robot", "planar_3r", "--q0", "0.3,1.2,1.0", "--duration", "0.2",
            "--algorithms", "damped_lnva,jvja", "--option", "damping=0.05", "--no-progress",
            "--out", str(out), "--html"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((out / "damped_lnva" / "summary.json").read_text())
    assert summary  # the run is whole
    page = (out / "damped_lnva" / "replay.html").read_text(encoding="utf-8")
    assert COLOUR in page and "DAMPED_LNVA" in page
    assert (out / "comparison.png").exists()
    capsys.readouterr()
    assert main(["simulate", "--robot", "planar_3r", "--algorithms", "jvja",
                 "--option", "damping=0.05"]) == 2  # fmt: skip
    assert "not an option of ['jvja']" in capsys.readouterr().err
    lock = ["lock", "--robot", "planar_3r", "--q0", "0.3,1.2,1.0", "--duration", "0.2",
            "--joint", "joint2", "--at", "0.1", "--algorithm", "damped_lnva",
            "--option", "damping=0.05", "--no-progress"]  # fmt: skip
    assert main(lock) == 0
    assert "joint2 locks at t = 0.100 s" in capsys.readouterr().out


def test_cli_help_lists_registered_algorithms(damped, capsys):
    """--algorithms' help and lock's --algorithm choices come from the registry (and 'global')."""
    from fault_tolerance.cli import main

    with pytest.raises(SystemExit):
        main(["lock", "--help"])
    text = capsys.readouterr().out
    assert "damped_lnva" in text and "global" in text
    assert main(["simulate", "--robot", "planar_3r", "--algorithms", "nope"]) == 2
    err = capsys.readouterr().err
    assert "damped_lnva" in err and "global" in err


def test_plot_uses_the_registered_colour_and_label(damped, arm, path):
    """figures.runs.plot_comparison draws it in its registered colour with its label."""
    from matplotlib.colors import to_hex

    from fault_tolerance.figures import runs as plots

    run = ft.simulate(arm, path, "damped_lnva", q0=Q0, duration=0.1, limits=False)
    fig = plots.plot_comparison({"damped_lnva": run}, "t")
    line = fig.axes[0].get_lines()[0]
    assert to_hex(line.get_color()) == COLOUR
    assert line.get_label() == "damped LNVA"
    assert plots.style("jvja") == {"color": "#d62728", "label": "JVJA (minimum jump)"}


def test_replay_page_uses_the_registered_colour(damped, arm, path, tmp_path):
    """The replay page colours the run's curves with the resolver's registered colour."""
    from fault_tolerance.viz.page import export_html

    run = ft.simulate(arm, path, "damped_lnva", q0=Q0, duration=0.1, limits=False)
    page = export_html(run, tmp_path / "replay.html", arm).read_text(encoding="utf-8")
    assert COLOUR in page
    assert 'id="ft-plots"' in page


#: Package folders and files allowed to spell several built-in names together, with the reason:
#: they are about those very algorithms, not lists of "the algorithms there are".
NAME_LISTS_ALLOWED = {
    "paper/": "the paper compares exactly LNVA, JVJA and MDA (its cases, report, sensitivity)",
    "planning/wholepath/": "the global planner's warm starts are LNVA and JVJA rollouts (W1-W5)",
    "bench/cases.py": "the benchmark's rows time the built-ins' compiled Controller steps",
}
BUILTIN_NAMES = {"lnva", "jvja", "mda", "jvja_inertia"}


def _name_lists(tree: ast.AST):
    """Literal tuples, lists, sets and dict keys holding two or more built-in resolver names."""
    skip = {  # the façade's __all__ names functions (ft.lnva, ...), not resolvers
        id(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)
    }
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            items = node.elts
        elif isinstance(node, ast.Dict):
            items = [k for k in node.keys if k is not None]
        else:
            continue
        found = {i.value for i in items if isinstance(i, ast.Constant) and i.value in BUILTIN_NAMES}
        if len(found) >= 2:
            yield node.lineno, sorted(found)


def test_the_lint_finds_a_name_list():
    """The check below can fail: it sees a tuple and a dict keyed by resolver names."""
    src = 'A = ("lnva", "jvja")\nB = {"mda": 1, "jvja": 2}\nC = ("lnva", "x")\n'
    assert [n for n, _ in _name_lists(ast.parse(src))] == [1, 2]
    assert list(_name_lists(ast.parse('__all__ = ["lnva", "jvja"]\n'))) == []


def test_no_resolver_name_list_outside_the_registry():
    """No package module hard-codes a list of resolver names: they come from the registry."""
    pkg = Path(ft.__file__).resolve().parent
    found = {}
    for p in sorted(pkg.rglob("*.py")):
        rel = p.relative_to(pkg).as_posix()
        if any(rel.startswith(allowed) for allowed in NAME_LISTS_ALLOWED):
            continue
        hits = list(_name_lists(ast.parse(p.read_text(encoding="utf-8"))))
        if hits:
            found[rel] = hits
    assert not found, found


def test_the_architecture_page_example_runs(tmp_path, monkeypatch, capsys):
    """docs/architecture.md, 'Adding a resolver': its Python block runs and leaves no resolver."""
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text("utf-8")
    section = text.split("## Adding a resolver", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "docs/architecture.md", "exec"), {})  # noqa: S102 - our own docs
    out = capsys.readouterr().out
    assert out.startswith("True\nTrue\nresolver 'damped_lnva': unknown option(s) ['gain']")
    assert "damped_lnva" in out.split("algorithm", 1)[1]  # the CLI's table has its row
    assert "damped_lnva" not in registry.names()


def test_options_the_caller_owns_are_refused(arm, path):
    """Weights (and a run's response) belong to simulate / Controller: options= may not set them."""
    with pytest.raises(InvalidInput, match=r"simulate\(weights=...\)"):
        ft.simulate(arm, path, "jvja", q0=Q0, duration=0.1, options={"weights": [1, 2, 3]})
    with pytest.raises(InvalidInput, match=r"simulate\(response=...\)"):
        ft.simulate(arm, path, "jvja", q0=Q0, duration=0.1, options={"response": "continuation"})
    with pytest.raises(InvalidInput, match=r"Controller\(weights=...\)"):
        ft.Controller(arm, method="jvja", options={"weights": [1, 2, 3]}, limits=False)


def test_builtin_options_through_the_controller(arm):
    """A built-in given options of its own steps by its reference rates, with those options."""
    ctrl = ft.Controller(arm, "all", method="mda", options={"gain": 0.5}, limits=False)
    J = arm.jacobian(Q0)
    np.testing.assert_allclose(
        ctrl.step(Q0, XD), ft.resolve("mda", J, XD, "all", arm=arm, q=Q0, gain=0.5), atol=1e-12
    )
    compiled = ft.Controller(arm, "all", method="mda", gain=0.5, limits=False)
    np.testing.assert_allclose(ctrl.step(Q0, XD), compiled.step(Q0, XD), atol=1e-9)
