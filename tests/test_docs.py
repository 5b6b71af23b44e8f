"""The documentation runs: README's Python blocks and the docstring examples."""

from __future__ import annotations

import doctest
import importlib
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    """Every ```python block of README.md runs, in order, in one namespace."""
    blocks = _python_blocks((ROOT / "README.md").read_text())
    assert len(blocks) >= 3
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), ns)  # noqa: S102 - our own documentation
    assert (tmp_path / "out" / "fig2_jvja" / "run.npz").exists()
    np.testing.assert_allclose(ns["panda"].jacobian(ns["q"]) @ ns["qd"], ns["xdot"], atol=1e-10)


@pytest.mark.parametrize(
    "module",
    [
        "arm",
        "loading",
        "indices",
        "planner",
        "planning",
        "realtime",
        "failures",
        "trajectories",
        "simulation",
        "start",
        "task_errors",
    ],
)
def test_docstring_examples(module):
    """The >>> examples in the module's docstrings hold."""
    mod = importlib.import_module(f"fault_tolerance.{module}")
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
