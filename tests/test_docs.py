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


def _modules_with_examples() -> list[str]:
    """Every module of the package whose docstrings hold a ``>>>`` example (none is left out)."""
    root = Path(__file__).resolve().parents[1] / "fault_tolerance"
    found = []
    for path in sorted(root.rglob("*.py")):
        if ">>> " in path.read_text(encoding="utf-8"):
            rel = path.relative_to(root).with_suffix("")
            found.append(".".join(p for p in rel.parts if p != "__init__"))
    return found


@pytest.mark.parametrize("module", _modules_with_examples())
def test_docstring_examples(module):
    """The >>> examples in the module's docstrings hold."""
    mod = importlib.import_module(f"fault_tolerance.{module}" if module else "fault_tolerance")
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
