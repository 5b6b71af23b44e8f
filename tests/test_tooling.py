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
    bad.write_text('"""A module with faults."""\n\nimport os\n\n\ndef f() -> int:\n    return "x"\n')
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
