"""The documentation runs: every code block of README.md and docs/*.md, from a wheel; docstrings.

README.md and docs/*.md: every ```python block (one script per page, blocks in order) and every
command of a ```bash block that starts with ``fault-tolerance`` run in a subprocess, in a fresh
folder, with the package installed from a wheel built once per session (not the source tree, not
an editable install). Lines ``# -> TEXT`` after a command or in a Python block quote what it
prints: TEXT must appear in its output (``(...)`` stands for text left out). A block that
clones a repository needs the network and is not run. Commands without quoted output are
shortened by options (a shorter run, a coarser grid, fewer timed calls).
"""

from __future__ import annotations

import doctest
import importlib
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]
#: Options that shorten a command without quoted output (replacing its own value, or added).
SHORTER = {
    "simulate": {"--duration": "0.1", "--no-progress": None},
    "lock": {"--no-progress": None},
    "reproduce": {"--quick": None, "--cases": "fig2", "--no-progress": None},
    "workspace": {"--grid": "21", "--workers": "0", "--no-progress": None},
    "design": {"--candidates": "4", "--rounds": "1", "--grid": "21", "--workers": "0",
               "--no-progress": None},
    "bench": {"--steps": "3", "--warmup": "1", "--batch-configurations": "0"},
}  # fmt: skip
#: The same for a DH design (``design --vary dh``): one population, no pattern search.
SHORTER_DH = {"--popsize": "4", "--generations": "0", "--rounds": "0", "--workers": "0",
              "--no-progress": None}  # fmt: skip
#: Commands the tests cannot run here, by what they need: a live viewer, a Dask cluster.
NOT_RUN = ("--open", "--scheduler")


def blocks(text: str, lang: str) -> list[str]:
    """The fenced code blocks of ``lang`` in ``text``."""
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def expected(code: str) -> list[str]:
    """The ``# -> TEXT`` lines of ``code``: TEXT, in order."""
    return [m.strip() for m in re.findall(r"^\s*# -> (.*)$", code, flags=re.M)]


def shown(text: str, out: str) -> bool:
    """Whether ``out`` holds ``text``, its ``(...)`` parts standing for anything."""
    at = 0
    for piece in (p.strip() for p in text.split("(...)")):
        at = out.find(piece, at)
        if at < 0:
            return False
        at += len(piece)
    return True


def commands(code: str) -> list[tuple[list[str], list[str]]]:
    """(argv, quoted output) of each ``fault-tolerance`` command of a bash block."""
    found: list[tuple[list[str], list[str]]] = []
    for line in code.replace("\\\n", " ").splitlines():
        if line.lstrip().startswith("# -> ") and found:
            found[-1][1].append(line.strip()[5:].strip())
        elif line.startswith("fault-tolerance "):
            found.append((shlex.split(line, comments=True), []))
    return found


def shorten(argv: list[str]) -> list[str]:
    """``argv`` with the options of :data:`SHORTER` for its command."""
    out = list(argv)
    vary = argv[argv.index("--vary") + 1] if "--vary" in argv[:-1] else ""
    dh = argv[1] == "design" and vary.startswith("dh")
    for opt, value in (SHORTER_DH if dh else SHORTER.get(argv[1], {})).items():
        if opt in out:
            if value is not None:
                out[out.index(opt) + 1] = value
        else:
            out += [opt] if value is None else [opt, value]
    return out


@pytest.fixture(scope="session")
def installed(tmp_path_factory):
    """The package installed from a wheel of this tree into a folder of its own: (site, env)."""
    import shutil

    tmp = tmp_path_factory.mktemp("wheel")
    clean = tmp / "src"  # a clean copy: no virtual environment, build folder or egg-info
    shutil.copytree(ROOT, clean, ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "*.egg-info", "__pycache__", "tests", "notebooks"))  # fmt: skip
    pip = [sys.executable, "-m", "pip", "-q"]
    subprocess.run([*pip, "wheel", "--no-deps", str(clean), "-w", str(tmp)], check=True,
                   capture_output=True)  # fmt: skip
    (wheel,) = tmp.glob("fault_tolerance-*.whl")
    site = tmp / "site"
    subprocess.run([*pip, "install", "--no-deps", "--target", str(site), str(wheel)], check=True,
                   capture_output=True)  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(site), "MPLBACKEND": "Agg", "CI": "true"}
    return site, env


def _run(argv: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=1800)


def test_the_docs_run_from_the_wheel_not_the_tree(installed, tmp_path):
    """The documentation's subprocesses import the wheel's package, and it ships its robots."""
    site, env = installed
    code = ("import fault_tolerance, importlib.resources as r; print(fault_tolerance.__file__); "
            "print(sorted(p.name for p in r.files('fault_tolerance.robots').iterdir()))")  # fmt: skip
    p = _run([sys.executable, "-c", code], tmp_path, env)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(str(site)) and "spatial_4r.urdf" in p.stdout


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_page_code_runs(page, installed, tmp_path):
    """Every Python block and every fault-tolerance command of the page runs (exit 0) and prints
    what the page quotes after ``# ->``."""
    site, env = installed
    text = (ROOT / page).read_text(encoding="utf-8")
    py = blocks(text, "python")
    if py:
        script = "\n".join(py)
        (tmp_path / "page.py").write_text(script)
        p = _run([sys.executable, "page.py"], tmp_path, env)
        assert p.returncode == 0, (page, p.stderr[-3000:])
        for line in expected(script):
            assert shown(line, p.stdout), (page, line, p.stdout[-2000:])
    cli = str(site / "bin" / "fault-tolerance")
    for code in blocks(text, "bash"):
        if "git clone" in code:  # needs the network (docs/robots.md says so)
            continue
        for argv, quoted in commands(code):
            if any(opt in argv for opt in NOT_RUN):
                continue
            argv = argv if quoted else shorten(argv)
            p = _run([cli, *argv[1:]], tmp_path, env)
            assert p.returncode == 0, (page, argv, p.stderr[-3000:])
            for line in quoted:
                assert shown(line, p.stdout + p.stderr), (page, argv, line, p.stderr[-2000:])


def test_every_page_has_runnable_code_and_no_issue_numbers():
    """README and docs pages: code blocks the test above runs, and no issue numbers or history."""
    for page in PAGES:
        text = (ROOT / page).read_text(encoding="utf-8")
        assert not re.search(r"#\d+\b|\bissue\b|\bissues\b", text, flags=re.I), page
        if page != "docs/MATH.md":
            n = len(blocks(text, "python")) + sum(len(commands(b)) for b in blocks(text, "bash"))
            assert n >= 1, page
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 300
    assert readme.count("notebooks") and f"The {_count_word()} notebooks" in readme


def _count_word() -> str:
    n = len(list((ROOT / "notebooks").glob("*.ipynb")))
    return ["no", "one", "two", "three", "four", "five", "six", "seven", "eight"][n]


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
