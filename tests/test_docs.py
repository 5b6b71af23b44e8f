"""The documentation runs: every code block of README.md and docs/*.md, from a wheel; docstrings.

Every fenced block of README.md and docs/*.md carries a tag of :data:`TAGS`; a block without a
tag, or with a tag not there, fails the test, so no block escapes it:

* ```python blocks run: those of one page, in order, are one script, run in a fresh folder.
* ```bash blocks run command by command, after the page's script and in its folder (lines joined
  at a trailing backslash, ``&&`` chains split). ``fault-tolerance`` is the wheel's console
  script; ``python -m ...`` runs the test's interpreter with the wheel's package, and
  ``python scripts/X.py`` a script of the clean copy the wheel was built from (a clone's
  ``scripts/``, which the wheel does not hold). ``.venv/bin/`` (the README's environment) stands
  for the test's: ``.venv/bin/fault-tolerance`` and ``.venv/bin/python`` as above, other tools
  (``ruff``, ``mypy``) from beside the test's interpreter. Commands run without a shell, so a
  line with shell syntax (``>``, ``|``, ``;``, ``$``) fails the test. A command that starts as a
  key of :data:`SKIP`, or has an option of :data:`NOT_RUN`, is not run, for the reason given
  there; a block that clones a repository needs the network and is not run; any other command
  fails the test.
* ```text blocks show what the tests cannot produce from a wheel (the messages of a cold numba
  cache, a refusal for a description kept only in a clone) or a drawing; they hold no command.
* ```json, ```yaml and ```csv blocks show a file format; each must parse.

Quoted output has one form. A line ``# -> TEXT`` under a command of a bash block, or in a Python
block, quotes what it prints: TEXT must appear in its output (stdout and stderr of a command,
stdout of a page's script; ``(...)`` stands for text left out). ``# -> [exit N]`` under a command
says it exits with status N; otherwise it must exit 0. Output quoted anywhere else would escape
the check, so a bash block has no comment line of its own (trailing comments describe a command),
a Python line that calls ``print`` carries no trailing comment, and a ```text block, checked
against nothing, never shows what a command of the page prints. A command without quoted output is shortened by options
(:data:`SHORTER`: a shorter run, a coarser grid, fewer timed calls); one with quoted output runs
as written.
"""

from __future__ import annotations

import csv
import doctest
import importlib
import io
import json
import os
import re
import shlex
import subprocess
import sys
import tokenize
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]
#: What the test does with a block of each tag.
TAGS = {
    "python": "run: the page's Python blocks are one script",
    "bash": "run, command by command",
    "text": "output the tests cannot produce from a wheel, or a drawing: not run",
    "json": "a file format: parsed",
    "yaml": "a file format: parsed",
    "csv": "a file format: parsed",
}
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
#: The same for ``lock --dynamics``: one planner, not all five (the whole-path plan is the slow one).
SHORTER_DYNAMICS = {"--algorithms": "jvja", "--no-progress": None}
#: Options whose value is made smaller where a command gives them (never added): ``bench
#: --workspace 801`` times an 801² map on one and on two workers, 41² shows the same rows.
SMALLER = {"--workspace": "41"}
#: Options of commands the tests do not run, and why.
NOT_RUN = {
    "--open": "serves a live viewer until Ctrl-C",
    "--scheduler": "needs a Dask cluster of your own",
    "--check": "its exit status is the verdict of timing targets, which depends on the machine's "
    "load (the same benchmark runs without it)",
}
#: Commands that are not run (their start, after ``.venv/bin/``), and why.
SKIP = {
    "python3 -m venv": "makes the environment: the test's wheel install stands for it",
    "pip install": "installs the package or an extra: the test installs the package from a wheel "
    "into an environment that has the extras",
    ". .venv/bin/activate": "changes the user's shell only: the test names its programs",
    "bash scripts/install_browser.sh": "installs Chromium with apt-get (root, the network)",
    "python -m pytest": "runs the test suite, of which this test is a part",
    "jupyter lab": "serves notebooks to a browser (tests/test_notebooks.py executes them)",
    "git clone": "needs the network (and so do the commands of its block, which use the clone)",
    "dask scheduler": "a server of a Dask cluster, which runs until it is stopped",
    "dask worker": "a server of a Dask cluster, which runs until it is stopped",
    "ruff check fault_tolerance": "checks the source tree, which a wheel does not hold "
    "(tests/test_tooling.py runs this command)",
    "mypy fault_tolerance": "checks the source tree, which a wheel does not hold "
    "(tests/test_tooling.py runs this command)",
    "D=$(mktemp -d)": "a timing recipe from an empty compiled cache: compiling every kernel takes "
    "a minute of CPU (docs/performance.md quotes what it measured)",
    "FAULT_TOLERANCE_CACHE_DIR=$D": "the same timing recipe",
}
#: Programs of the test's environment that bash blocks may run (besides fault-tolerance, python).
TOOLS = ("ruff", "mypy")
#: A block that clones a repository needs the network: none of its commands runs.
NETWORK = "git clone "


class Command(NamedTuple):
    """One command of a bash block: its words, the output it quotes, its exit status, and why it
    is not run (empty when it runs)."""

    words: list[str]
    quoted: list[str]
    status: int = 0
    skip: str = ""


def fenced(text: str) -> list[tuple[int, str, str]]:
    """(line, tag, body) of every fenced block of ``text``; the body without the fence's indent."""
    found: list[tuple[int, str, str]] = []
    start, tag, indent, body = 0, "", 0, []
    for i, line in enumerate(text.splitlines(), 1):
        fence = re.fullmatch(r"( *)```(.*)", line.rstrip())
        if fence and not start:
            start, tag, indent, body = i, fence[2].strip(), len(fence[1]), []
        elif fence and not fence[2]:
            found.append((start, tag, "".join(f"{b[indent:]}\n" for b in body)))
            start = 0
        elif start:
            body.append(line)
    assert not start, f"a block opened at line {start} is not closed"
    return found


def blocks(text: str, tag: str) -> list[str]:
    """The bodies of the fenced blocks of ``text`` tagged ``tag``."""
    return [body for _, t, body in fenced(text) if t == tag]


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


def command(text: str) -> Command:
    """One command of a bash block, run or skipped; ValueError for a command the test does not know
    or shell syntax."""
    text = text.strip().removeprefix(".venv/bin/")
    for start, why in SKIP.items():
        if text.startswith(start):
            return Command([], [], skip=why)
    lexer = shlex.shlex(text, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    words = list(lexer)
    if any(set(w) <= set("();<>|&") or "$" in w or "`" in w for w in words):
        raise ValueError(f"shell syntax (commands run without a shell): {text}")
    words[0] = words[0].removeprefix(".venv/bin/")
    python = words[0] in ("python", "python3") and len(words) > 1
    if not (
        words[0] in ("fault-tolerance", *TOOLS)
        or (python and (words[1] == "-m" or words[1].startswith("scripts/")))
    ):
        raise ValueError(f"a command the docs test does not know (run it, or SKIP it): {text}")
    return Command(words, [], skip=next((w for o, w in NOT_RUN.items() if o in words), ""))


def commands(code: str) -> list[Command]:
    """The commands of a bash block, each with the output quoted under it; ValueError for a line
    the test cannot read (see :func:`command`) or a comment line that quotes nothing."""
    found: list[Command] = []
    for line in code.replace("\\\n", " ").splitlines():
        text = line.strip()
        if text.startswith("# -> ") and found:
            status = re.fullmatch(r"\[exit (\d+)\]", text[5:].strip())
            if status:
                found[-1] = found[-1]._replace(status=int(status[1]))
            else:
                found[-1].quoted.append(text[5:].strip())
        elif text.startswith("#"):
            raise ValueError(f"a comment line (quote output as '# -> TEXT' under a command, say "
                             f"the rest in prose): {text}")  # fmt: skip
        elif text:
            found += [command(part) for part in text.split(" && ")]
    return found


def print_comments(code: str) -> list[str]:
    """The lines of ``code`` that call ``print`` and end in a comment."""
    return [
        tok.line.rstrip()
        for tok in tokenize.generate_tokens(io.StringIO(code).readline)
        if tok.type == tokenize.COMMENT and "print(" in tok.line[: tok.start[1]]
    ]


def shorten(argv: list[str]) -> list[str]:
    """``argv`` with the options of :data:`SHORTER` for its command, and :data:`SMALLER`."""
    out = list(argv)
    vary = argv[argv.index("--vary") + 1] if "--vary" in argv[:-1] else ""
    if argv[1] == "design" and vary.startswith("dh"):
        options = SHORTER_DH
    elif argv[1] == "lock" and "--dynamics" in argv:
        options = SHORTER_DYNAMICS
    else:
        options = SHORTER.get(argv[1], {})
    for opt, value in options.items():
        if opt in out:
            if value is not None:
                out[out.index(opt) + 1] = value
        else:
            out += [opt] if value is None else [opt, value]
    for opt, value in SMALLER.items():
        if opt in out:
            at = out.index(opt) + 1
            given = at < len(out) and not out[at].startswith("-")
            out[at:at + given] = [value]  # fmt: skip
    return out


class Wheel(NamedTuple):
    """The package installed from a wheel: its folder, the environment, the clean copy."""

    site: Path
    env: dict
    clean: Path


@pytest.fixture(scope="session")
def installed(tmp_path_factory) -> Wheel:
    """The package installed from a wheel of a clean copy of this tree, into a folder of its own."""
    import shutil

    tmp = tmp_path_factory.mktemp("wheel")
    clean = tmp / "src"  # a clean copy: no virtual environment, build folder or egg-info
    shutil.copytree(ROOT, clean, ignore=shutil.ignore_patterns(
        ".venv", ".git", ".cache", "build", "*.egg-info", "__pycache__", "tests", "notebooks"))  # fmt: skip
    pip = [sys.executable, "-m", "pip", "-q"]
    subprocess.run([*pip, "wheel", "--no-deps", str(clean), "-w", str(tmp)], check=True,
                   capture_output=True)  # fmt: skip
    (wheel,) = tmp.glob("fault_tolerance-*.whl")
    site = tmp / "site"
    subprocess.run([*pip, "install", "--no-deps", "--target", str(site), str(wheel)], check=True,
                   capture_output=True)  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(site), "MPLBACKEND": "Agg", "CI": "true"}
    return Wheel(site, env, clean)


def _run(argv: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=1800)


def test_the_docs_run_from_the_wheel_not_the_tree(installed, tmp_path):
    """The documentation's subprocesses import the wheel's package, and it ships its robots."""
    code = ("import fault_tolerance, importlib.resources as r; print(fault_tolerance.__file__); "
            "print(sorted(p.name for p in r.files('fault_tolerance.robots').iterdir()))")  # fmt: skip
    p = _run([sys.executable, "-c", code], tmp_path, installed.env)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(str(installed.site)) and "spatial_4r.urdf" in p.stdout


def _argv(cmd: Command, wheel: Wheel) -> list[str]:
    """What runs for ``cmd``: the wheel's CLI, the test's interpreter, or a tool beside it."""
    words = cmd.words
    if words[0] == "fault-tolerance":
        as_written = cmd.quoted or cmd.status
        argv = words if as_written else shorten(words)
        return [str(wheel.site / "bin" / "fault-tolerance"), *argv[1:]]
    if words[0] in ("python", "python3"):
        script = [] if words[1] == "-m" else [str(wheel.clean / words[1])]
        return [sys.executable, *(script or words[1:2]), *words[2:]]
    return [str(Path(sys.executable).parent / words[0]), *words[1:]]


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_page_code_runs(page, installed, tmp_path):
    """The page's Python script and every command of its bash blocks run, exit as the page says
    (0 unless ``# -> [exit N]``) and print what the page quotes after ``# ->``."""
    text = (ROOT / page).read_text(encoding="utf-8")
    py = blocks(text, "python")
    if py:
        script = "\n".join(py)
        (tmp_path / "page.py").write_text(script)
        p = _run([sys.executable, "page.py"], tmp_path, installed.env)
        assert p.returncode == 0, (page, p.stderr[-3000:])
        for line in expected(script):
            assert shown(line, p.stdout), (page, line, p.stdout[-2000:])
    for code in blocks(text, "bash"):
        for cmd in [] if NETWORK in code else commands(code):
            if cmd.skip:
                continue
            argv = _argv(cmd, installed)
            p = _run(argv, tmp_path, installed.env)
            assert p.returncode == cmd.status, (page, argv, p.stdout[-2000:], p.stderr[-3000:])
            for line in cmd.quoted:
                assert shown(line, p.stdout + p.stderr), (page, argv, line, p.stderr[-2000:])


def _check_block(tag: str, body: str) -> None:
    """Fail unless ``body`` reads as a block of ``tag`` should (see the module docstring)."""
    assert tag in TAGS, f"a block tagged {tag!r}: tag it as one of {sorted(TAGS)}"
    if tag == "python":
        compile(body, "block", "exec")
        hidden = print_comments(body)
        assert not hidden, f"print() lines with a comment (quote output on '# -> ' lines): {hidden}"
    elif tag == "bash":
        commands(body)  # raises on a line the test cannot run or skip
    elif tag == "text":
        command_line = re.search(r"^(\$ |fault-tolerance [a-z]+\b(?!:)|python3? ).*", body, re.M)
        assert not command_line, f"a command in a text block: {command_line[0]}"
    elif tag == "json":
        json.loads(body)
    elif tag == "yaml":
        import yaml

        assert yaml.safe_load(body), body
    elif tag == "csv":
        rows = list(csv.reader(io.StringIO(body)))
        assert len(rows) > 1 and all(len(r) == len(rows[0]) for r in rows), body


@pytest.mark.parametrize("page", PAGES)
def test_every_block_is_known(page):
    """Every fenced block of the page has a tag of TAGS and reads as that tag says: Python that
    compiles, commands the test runs or skips for a stated reason, text without commands, files
    that parse."""
    problems = []
    for line, tag, body in fenced((ROOT / page).read_text(encoding="utf-8")):
        try:
            _check_block(tag, body)
        except (AssertionError, ValueError, SyntaxError) as err:
            problems.append(f"{page}:{line}: {str(err).split(chr(10) + 'assert')[0]}")
    assert not problems, "\n".join(problems)


def test_the_block_checks_can_fail():
    """Untagged and unknown blocks, unknown commands, shell syntax, comment lines and quoted output
    in a comment are refused; a known skip and a quoted exit status are read."""
    page = "```\nfault-tolerance robots\n```\n```sh\nls\n```\n"
    assert [t for _, t, _ in fenced(page)] == ["", "sh"]
    for tag, body in [("", "x\n"), ("sh", "ls\n"), ("bash", "ls -l\n"),
                      ("bash", "fault-tolerance robots > r.txt\n"), ("bash", "# 1.0\n"),
                      ("python", "print(1)  # 1\n"), ("text", "$ fault-tolerance robots\n"),
                      ("text", "fault-tolerance robots\n"),
                      ("json", "{'a': 1}\n"), ("csv", "a,b\n1\n")]:  # fmt: skip
        with pytest.raises((AssertionError, ValueError)):
            _check_block(tag, body)
    (cmd,) = commands(".venv/bin/fault-tolerance inspect x.urdf\n# -> [exit 2]\n# -> error\n")
    assert (cmd.words[:2], cmd.quoted, cmd.status, cmd.skip) == (
        ["fault-tolerance", "inspect"], ["error"], 2, "")  # fmt: skip
    assert [c.skip != "" for c in commands("python3 -m venv .venv && python -m x.y\n")] == [
        True, False]  # fmt: skip


def test_every_skip_is_used():
    """Each entry of SKIP and NOT_RUN matches a command of the pages: the lists hold no stale
    entry."""
    code = "".join(b for page in PAGES for b in blocks((ROOT / page).read_text("utf-8"), "bash"))
    code += code.replace(".venv/bin/", "")  # as commands are matched
    assert [k for k in [*SKIP, *NOT_RUN] if k not in code] == []


def test_every_page_has_runnable_code_and_no_issue_numbers():
    """README and docs pages: code blocks the test above runs, and no issue numbers or history."""
    for page in PAGES:
        text = (ROOT / page).read_text(encoding="utf-8")
        assert not re.search(r"#\d+\b|\bissue\b|\bissues\b", text, flags=re.I), page
        if page != "docs/MATH.md":
            run = [c for b in blocks(text, "bash") for c in commands(b) if not c.skip]
            assert len(blocks(text, "python")) + len(run) >= 1, page
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
