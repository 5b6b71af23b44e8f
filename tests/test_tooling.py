"""The tools hold: ruff and mypy pass on the package with the project's own configuration.

Both run in subprocesses from the virtual environment's ``bin`` next to :data:`sys.executable`
(the ``test`` extra installs them), from the repository root so that ``pyproject.toml`` is read.
Each check prints the tool's output when it fails. A small file with a known fault shows that the
same command does report faults (a check that could not fail would prove nothing).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _tool(name: str) -> str:
    """Path of a console script of this environment, or a failure saying how to install it."""
    path = BIN / name
    if not path.exists():
        pytest.fail(f"{name} is not installed next to {sys.executable}: pip install -e '.[test]'")
    return str(path)


def _run(*cmd: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
    )


def _report(proc: subprocess.CompletedProcess) -> str:
    return f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"


def test_ruff_passes():
    """``ruff check fault_tolerance tests scripts`` exits 0."""
    proc = _run(_tool("ruff"), "check", "fault_tolerance", "tests", "scripts")
    assert proc.returncode == 0, _report(proc)


def test_mypy_passes():
    """``mypy fault_tolerance`` (``[tool.mypy]`` of pyproject.toml) exits 0 with no error."""
    proc = _run(_tool("mypy"), "fault_tolerance")
    assert proc.returncode == 0, _report(proc)
    assert "Success: no issues found" in proc.stdout, _report(proc)


def test_the_checks_can_fail(tmp_path):
    """The same commands report a fault: an unused import (ruff), a wrong return type (mypy)."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        '"""A module with faults."""\n\nimport os\n\n\ndef f() -> int:\n    return "x"\n'
    )
    ruff = _run(_tool("ruff"), "check", "--no-cache", str(bad))
    assert ruff.returncode != 0 and "F401" in ruff.stdout, _report(ruff)
    mypy = _run(_tool("mypy"), str(bad))
    assert mypy.returncode != 0 and "[return-value]" in mypy.stdout, _report(mypy)


def test_mypy_configuration_is_not_weakened():
    """No blanket escape hatches: no ``ignore_errors``, no codes disabled, ignores name a code."""
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    assert config.get("ignore_missing_imports") is True
    assert "ignore_errors" not in config and "disable_error_code" not in config, config
    for override in config.get("overrides", []):
        assert "ignore_errors" not in override and "disable_error_code" not in override, override
    bare = [
        f"{path.relative_to(ROOT)}:{i}"
        for path in sorted((ROOT / "fault_tolerance").rglob("*.py"))
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if re.search(r"#\s*type:\s*ignore(?!\[)", line)
    ]
    assert not bare, f"# type: ignore without an error code: {bare}"


# -- guards the type checker asked for: what used to escape as AttributeError / TypeError ---------
def test_require_planar_chain_names_an_arm_that_is_not_planar():
    """A planar 3R has its chain; a spatial arm is refused with InvalidInput naming its task."""
    import fault_tolerance as ft
    from fault_tolerance.model.planar import require_planar_chain

    chain = require_planar_chain(ft.load_arm("planar_3r"))
    assert len(chain.lengths) == 3 and np.all(chain.lengths > 0)
    with pytest.raises(ft.InvalidInput, match="is not a planar chain"):
        require_planar_chain(ft.load_arm("panda", task="position"))


def test_rollout_track_needs_its_reference():
    """``rollout(mode="track")`` without ``q_ref`` raises InvalidInput; with it, it runs."""
    import fault_tolerance as ft
    from fault_tolerance.planning.wholepath.problem import build_problem, rollout
    from fault_tolerance.simulation.paths import CirclePath

    arm = ft.load_arm("planar_3r")
    q0 = np.array([0.3, 1.2, 1.0])
    path = CirclePath(arm.fk(q0), 0.1, 2 * np.pi, 0.02)
    prob = build_problem(arm, path, dt=1e-3, steps=10, lockable=[1, 2])
    with pytest.raises(ft.InvalidInput, match="'track' needs q_ref"):
        rollout(prob, q0, "track")
    plain = rollout(prob, q0, "jvja")
    tracked = rollout(prob, q0, "track", q_ref=plain.q)
    np.testing.assert_allclose(tracked.q, plain.q, atol=1e-9)
