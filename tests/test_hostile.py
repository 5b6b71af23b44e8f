"""A hostile corpus: links where writers write, torn saves, tampered chunks, huge sizes, dead
schedulers, names that look like markup, bad numbers (docs/security.md).

Each case asserts exit 2 (or the toolkit's own error), ends in bounded time (every command runs in
a subprocess with a timeout), and checks that nothing was lost or mixed: link targets unchanged,
previous results whole, finished chunks kept.
"""

from __future__ import annotations

import errno
import http.server
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.analysis import sweep
from fault_tolerance.errors import FaultToleranceError, IncompleteResult, OutputError
from fault_tolerance.storage.atomic import output_folder, write_atomic
from fault_tolerance.storage.folder_lock import FolderLock, in_progress, lock_path
from fault_tolerance.storage.result_folder import (
    RECORD,
    staged_folder,
    verify_folder,
)

ROOT = Path(__file__).resolve().parents[1]
#: A small planar-3R workspace map (a few seconds).
WS = ["workspace", "--robot", "planar_3r", "--grid", "21", "--samples", "10"]
WS += ["--theta-samples", "5", "--chunks", "3", "--workers", "0", "--no-progress"]
SECRET = "a file of the user's that no writer may touch\n"


def cli(args: list[str], timeout: float = 240, **kw) -> subprocess.CompletedProcess:
    """``python -m fault_tolerance ARGS`` in a subprocess, within ``timeout`` seconds."""
    return subprocess.run(
        [sys.executable, "-m", "fault_tolerance", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        **kw,
    )


def refused(r: subprocess.CompletedProcess, *words: str) -> None:
    """Exit 2 with one line on stderr that contains each of ``words``."""
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])


@pytest.fixture
def victim(tmp_path) -> Path:
    """A user's file that links will point at; it must never change."""
    p = tmp_path / "victim.txt"
    p.write_text(SECRET)
    return p


@pytest.fixture(scope="module")
def workspace_out(tmp_path_factory) -> Path:
    """A finished small workspace folder (copied by tests that alter it)."""
    out = tmp_path_factory.mktemp("ws") / "out"
    r = cli([*WS, "--out", str(out)])
    assert r.returncode == 0, r.stderr
    return out


def copy_tree(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def chunk_dir(out: Path) -> Path:
    (c,) = sorted(out.glob("chunks-*"))
    return c


# -- (a) writers never follow links --------------------------------------------------------------


@pytest.mark.parametrize("command", ["workspace", "design", "simulate"])
def test_a_lock_file_that_is_a_link_is_refused_and_its_target_kept(tmp_path, victim, command):
    """The lock beside --out is a symlink: every writer exits 2 naming it; the target is intact."""
    out = tmp_path / "out"
    os.symlink(victim, lock_path(out))
    args = {
        "workspace": WS,
        "design": ["design", "--robot", "planar_3r", "--candidates", "2", "--rounds", "0"],
        "simulate": ["simulate", "--robot", "planar_3r", "--duration", "0.01", "--no-progress"],
    }[command]
    refused(cli([*args, "--out", str(out)]), str(lock_path(out)), "symbolic link")
    assert victim.read_text() == SECRET
    assert not out.exists()


def test_a_lock_file_that_is_a_fifo_is_refused_without_hanging(tmp_path):
    """A FIFO where the lock goes: FolderLock refuses at once (no open that waits for a writer)."""
    out = tmp_path / "out"
    os.mkfifo(lock_path(out))
    with pytest.raises(OutputError, match="FIFO"):
        FolderLock(out).acquire()


def test_workspace_files_that_are_links_are_refused(tmp_path, workspace_out, victim):
    """workspace.json of an earlier result replaced by a link: the rerun exits 2 naming it."""
    out = copy_tree(workspace_out, tmp_path / "out")
    (out / "workspace.json").unlink()
    os.symlink(victim, out / "workspace.json")
    refused(cli([*WS, "--out", str(out)]), "workspace.json", "symbolic link")
    assert victim.read_text() == SECRET


def test_a_spec_json_that_is_a_link_is_refused(tmp_path, workspace_out, victim):
    """chunks-<hash>/spec.json replaced by a link: exit 2 naming it, the target intact, the
    finished chunks still there."""
    out = copy_tree(workspace_out, tmp_path / "out")
    cdir = chunk_dir(out)
    (cdir / "spec.json").unlink()
    os.symlink(victim, cdir / "spec.json")
    refused(cli([*WS, "--out", str(out)]), "spec.json", "symbolic link")
    assert victim.read_text() == SECRET
    assert len(list(cdir.glob("chunk-*.npz"))) == 3


def test_a_chunk_folder_that_is_a_link_is_refused(tmp_path, workspace_out):
    """chunks-<hash>/ itself a link to a folder elsewhere: exit 2; nothing written there."""
    out = copy_tree(workspace_out, tmp_path / "out")
    cdir = chunk_dir(out)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    import shutil

    shutil.rmtree(cdir)
    os.symlink(elsewhere, cdir)
    refused(cli([*WS, "--out", str(out)]), cdir.name, "symbolic link")
    assert list(elsewhere.iterdir()) == []


def test_library_writers_refuse_links(tmp_path, victim):
    """write_atomic, output_folder, staged_folder, in_progress: a link where they write raises
    OutputError naming it, and the link's target is unchanged."""
    link = tmp_path / "link"
    os.symlink(victim, link)
    with pytest.raises(OutputError, match="symbolic link"):
        write_atomic(link, "new")
    dlink = tmp_path / "dlink"
    os.symlink(tmp_path, dlink)
    for call in (
        lambda: output_folder(dlink),
        lambda: staged_folder(dlink).__enter__(),
        lambda: in_progress(dlink).__enter__(),
    ):
        with pytest.raises(OutputError, match=str(dlink)):
            call()
    folder = tmp_path / "marked"
    folder.mkdir()
    os.symlink(victim, folder / "in_progress.json")
    with pytest.raises(OutputError, match="in_progress.json"), in_progress(folder):
        pass
    assert victim.read_text() == SECRET


def test_verify_folder_does_not_follow_links_nor_wait_on_fifos(tmp_path, victim):
    """A saved folder whose file became a link or a FIFO: verify_folder refuses at once."""
    folder = tmp_path / "r"
    with staged_folder(folder) as tmp:
        (tmp / "a.txt").write_text(SECRET)
        (tmp / "b.txt").write_text("b")
    (folder / "a.txt").unlink()
    os.symlink(victim, folder / "a.txt")
    with pytest.raises(IncompleteResult, match="a.txt"):
        verify_folder(folder)
    (folder / "b.txt").unlink()
    os.mkfifo(folder / "b.txt")
    with pytest.raises(IncompleteResult, match="b.txt"):
        verify_folder(folder, files=["b.txt"])


# -- (b) workspace and design results whole or absent ------------------------------------------

SAVE_TWICE = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import fault_tolerance as ft
    from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace

    out, ready = Path(sys.argv[1]), Path(sys.argv[2])
    arm = ft.load_arm("planar_3r")
    opts = dict(grid=21, samples=10, theta_samples=5, chunks=3)
    failure_tolerant_workspace(arm, **opts).save(out)
    ws = failure_tolerant_workspace(arm, "-1:1,-2:2,-2:2", **opts)

    def draw(w, path):  # the caller's figure: the parent kills us while it runs
        path.write_bytes(b"half a figure")
        ready.write_text("drawing")
        time.sleep(60)

    ws.save(out, draw=draw)
    """
)


def test_kill_9_while_a_workspace_saves_leaves_the_previous_result(tmp_path):
    """A process killed (-9) in the middle of Workspace.save: the folder holds the previous
    complete result (it verifies, its JSON and npz belong together), never a mix; the next save
    sweeps the staging leftover."""
    out, ready = tmp_path / "ws", tmp_path / "ready"
    script = tmp_path / "save_twice.py"
    script.write_text(SAVE_TWICE)
    proc = subprocess.Popen([sys.executable, str(script), str(out), str(ready)], cwd=ROOT)
    deadline = time.monotonic() + 240
    while not ready.exists():
        assert proc.poll() is None, "the script ended before drawing"
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    record = verify_folder(out)
    assert sorted(record["files"]) == ["workspace.json", "workspace.npz"]
    summary = json.loads((out / "workspace.json").read_text())
    assert summary["limits"] == [list(map(float, lim)) for lim in summary["spec"]["limits"]]
    full = ft.load_arm("planar_3r")
    assert np.allclose(summary["limits"], np.stack([full.lower, full.upper], 1))  # the first
    with np.load(out / "workspace.npz") as z:
        assert z["pre"].sum() * summary["cell"] == pytest.approx(summary["area_pre"])
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".ws.tmp-")]
    assert len(leftovers) == 1  # the killed writer's stage, beside and never inside


def test_a_full_disk_while_a_workspace_saves_leaves_the_previous_result(tmp_path, monkeypatch):
    """ENOSPC while the new workspace.json is written: OutputError (exit 2 on the command line),
    the previous result whole and unchanged, no staging folder left."""
    from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace

    arm = ft.load_arm("planar_3r")
    opts = dict(grid=21, samples=10, theta_samples=5, chunks=3)
    out = tmp_path / "ws"
    failure_tolerant_workspace(arm, **opts).save(out)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    new = failure_tolerant_workspace(arm, "-1:1,-2:2,-2:2", **opts)
    real = Path.write_text

    def full(self, *a, **k):
        if self.name == "workspace.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(OutputError, match="no space left"):
        new.save(out)
    monkeypatch.undo()
    verify_folder(out)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["ws"]


def test_a_design_save_is_whole_and_keeps_the_chunks(tmp_path):
    """Design.save stages: the folder verifies, lists design.json, and keeps chunks-*/ aside."""
    from fault_tolerance.analysis.design.search import Design

    out = tmp_path / "d"
    (out / "chunks-0123456789abcdef").mkdir(parents=True)
    (out / "chunks-0123456789abcdef" / "chunk-00000.npz").write_bytes(b"x")
    Design({"objective": "ftw-area"}, {}).save(out)
    assert sorted(verify_folder(out)["files"]) == ["design.json"]
    assert (out / "chunks-0123456789abcdef" / "chunk-00000.npz").read_bytes() == b"x"


# -- (c) chunks are verified, never trusted -----------------------------------------------------


def toy(spec: dict, k: int) -> dict:
    """A sweep's compute: a few deterministic arrays per chunk."""
    rng = np.random.default_rng([spec["seed"], k])
    return {"x": rng.normal(size=50), "m": rng.normal(size=50) > 0}


def test_tampered_damaged_oversized_fifo_and_linked_chunks_are_recomputed(tmp_path, capfd, victim):
    """Each bad chunk is recomputed with one stderr line naming it; the results equal a clean
    run's; a link's target and a FIFO are not read."""
    spec = {"seed": 3}
    clean = sweep.run(toy, spec, 6)
    sweep.run(toy, spec, 6, folder=tmp_path, chunk_bytes=10_000)
    cdir = sweep.chunk_folder(tmp_path, spec)
    p = [cdir / f"chunk-{k:05d}.npz" for k in range(6)]
    z = dict(np.load(p[0]))
    z["x"] = z["x"] + 1.0  # tampered: a valid npz, the old checksum
    np.savez(p[0], **z)
    p[1].write_bytes(p[1].read_bytes()[:100])  # damaged
    np.savez_compressed(p[2], x=np.zeros(1 << 22))  # 32 MiB when decompressed: over the bound
    p[3].unlink()
    os.mkfifo(p[3])  # a FIFO would hang a plain np.load
    p[4].unlink()
    os.symlink(victim, p[4])
    np.savez(p[5], **toy({"seed": 4}, 5))  # a chunk of another spec, without our tags
    capfd.readouterr()
    again = sweep.run(toy, spec, 6, folder=tmp_path, chunk_bytes=10_000)
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 6, err
    for k, word in enumerate(["checksum", "cannot be read", "more than", "regular", "regular"]):
        assert p[k].name in err[k] and word in err[k], err[k]
    assert "spec hash" in err[5]
    for a, b in zip(clean, again, strict=True):
        np.testing.assert_array_equal(a["x"], b["x"])
        np.testing.assert_array_equal(a["m"], b["m"])
    assert victim.read_text() == SECRET
    assert all(f.is_file() and not f.is_symlink() for f in p)  # rewritten whole
    capfd.readouterr()
    sweep.run(toy, spec, 6, folder=tmp_path, chunk_bytes=10_000)
    assert capfd.readouterr().err == ""  # now trusted: all verify


def test_a_chunk_may_not_be_moved_to_another_index(tmp_path, capfd):
    """A valid chunk copied over another index is refused (its index is part of it)."""
    spec = {"seed": 1}
    sweep.run(toy, spec, 2, folder=tmp_path)
    cdir = sweep.chunk_folder(tmp_path, spec)
    (cdir / "chunk-00001.npz").write_bytes((cdir / "chunk-00000.npz").read_bytes())
    capfd.readouterr()
    out = sweep.run(toy, spec, 2, folder=tmp_path)
    assert "another spec or chunk" in capfd.readouterr().err
    np.testing.assert_array_equal(out[1]["x"], toy(spec, 1)["x"])


def test_a_tampered_workspace_chunk_does_not_change_the_area(tmp_path, workspace_out):
    """The case: a tampered chunk once changed area_ftw; now the rerun recomputes it
    (stderr says so) and the area is the clean one."""
    out = copy_tree(workspace_out, tmp_path / "out")
    clean = json.loads((out / "workspace.json").read_text())
    p = chunk_dir(out) / "chunk-00001.npz"
    z = dict(np.load(p))
    z["locks"] = np.ones_like(z["locks"])
    np.savez(p, **z)
    r = cli([*WS, "--out", str(out)])
    assert r.returncode == 0, r.stderr
    assert "chunk-00001.npz does not match its checksum" in r.stderr
    again = json.loads((out / "workspace.json").read_text())
    assert again["area_ftw"] == clean["area_ftw"] and again["area_pre"] == clean["area_pre"]
    verify_folder(out)


# -- (d) every size checked before work starts --------------------------------------------------


@pytest.mark.parametrize(
    "args, words",
    [
        (["workspace", "--robot", "planar_3r", "--grid", "100000"], ["--grid", "at most"]),
        (["workspace", "--robot", "planar_3r", "--chunks", "1000000000"], ["--chunks", "100,000"]),
        (["workspace", "--robot", "planar_3r", "--samples", "1000000000000"], ["--samples"]),
        (["workspace", "--robot", "planar_3r", "--theta-samples", "1000000000"], ["--theta"]),
        (["workspace", "--robot", "spatial_4r", "--grid", "100000"], ["--grid", "at most"]),
        (["design", "--robot", "planar_3r", "--candidates", "1000000000000"], ["--candidates"]),
        (["design", "--robot", "planar_3r", "--rounds", "1000000000"], ["--rounds", "60"]),
        (["design", "--robot", "planar_3r", "--grid", "100000"], ["--grid", "at most"]),
    ],
)
def test_huge_sizes_are_refused_up_front(tmp_path, args, words):
    """Sizes past the limits exit 2 at once with the limit, and create nothing."""
    out = tmp_path / "new" / "out"
    t0 = time.monotonic()
    refused(cli([*args, "--workers", "0", "--no-progress", "--out", str(out)], timeout=120), *words)
    assert time.monotonic() - t0 < 120
    assert not (tmp_path / "new").exists()


def test_out_that_is_a_file_or_under_a_file_is_refused(tmp_path):
    """--out naming an existing file, or a path under a file: exit 2; the file is unchanged."""
    f = tmp_path / "file"
    f.write_text(SECRET)
    refused(cli([*WS, "--out", str(f)]), str(f), "not a folder")
    refused(cli([*WS, "--out", str(f / "sub")]), "under", "not a folder")
    assert f.read_text() == SECRET


@pytest.mark.parametrize(
    "address", ["localhost", "tcp://127.0.0.1:99999", "tcp://a b:1", "http://x:1"]
)
def test_a_malformed_scheduler_address_is_refused(tmp_path, address):
    """A malformed --scheduler exits 2 naming the allowed form; no --out is left behind."""
    out = tmp_path / "out"
    refused(
        cli([*WS[:-3], "--no-progress", "--scheduler", address, "--out", str(out)]),
        "tcp://HOST:PORT",
    )
    assert not out.exists()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_a_plain_http_server_is_not_a_scheduler(tmp_path):
    """--scheduler pointed at an HTTP server on 127.0.0.1: exit 2 with one line in bounded time,
    and no folder left (neither --out nor a stray chunks-<hash>/)."""
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    out = tmp_path / "out"
    try:
        t0 = time.monotonic()
        r = cli(
            [
                *WS[:-3],
                "--no-progress",
                "--scheduler",
                f"tcp://127.0.0.1:{server.server_port}",
                "--out",
                str(out),
            ]
        )
        refused(r, "cannot reach a Dask scheduler")
        assert time.monotonic() - t0 < 120
    finally:
        server.shutdown()
    assert not out.exists()


def start_scheduler(port: int) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--dashboard-address",
            "127.0.0.1:0",
            "--no-show",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def wait_port(port: int, proc: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the scheduler ended"
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    pytest.fail("the scheduler did not start")


@pytest.mark.slow
def test_a_scheduler_without_workers_and_one_that_dies(tmp_path):
    """A scheduler with no worker: exit 2 after the stated wait. A scheduler killed mid-run:
    exit 2 with one line in bounded time, the chunks that finished kept on disk."""
    port = free_port()
    sched = start_scheduler(port)
    try:
        wait_port(port, sched)
        out = tmp_path / "out"
        addr = f"tcp://127.0.0.1:{port}"
        r = cli([*WS[:-3], "--no-progress", "--scheduler", addr, "--out", str(out)], timeout=120)
        refused(r, "no worker after 10 s")
        assert not out.exists()
        worker = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_worker",
                addr,
                "--nthreads",
                "1",
                "--no-nanny",
                "--host",
                "127.0.0.1",
                "--no-dashboard",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            cwd=ROOT,
        )
        args = [
            "workspace",
            "--robot",
            "planar_3r",
            "--grid",
            "81",
            "--samples",
            "60",
            "--chunks",
            "40",
            "--no-progress",
            "--scheduler",
            addr,
            "--out",
            str(out),
        ]
        proc = subprocess.Popen(
            [sys.executable, "-m", "fault_tolerance", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        deadline = time.monotonic() + 240
        while not list(out.glob("chunks-*/chunk-*.npz")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk finished"
            time.sleep(0.1)
        sched.kill()
        t0 = time.monotonic()
        _, err = proc.communicate(timeout=120)
        assert time.monotonic() - t0 < 120
        assert proc.returncode == 2, err
        assert len(err.strip().splitlines()) == 1 and "lost the Dask scheduler" in err, err
        kept = list(out.glob("chunks-*/chunk-*.npz"))
        assert kept and len(kept) < 40
        worker.kill()
    finally:
        sched.kill()


# -- (e) names are data ----------------------------------------------------------------------

EVIL_SCRIPT, EVIL_MATH = "<!--<script>", r"$\frac{a$"


@pytest.fixture(scope="module")
def evil_run(tmp_path_factory) -> Path:
    """simulate --html on a planar 3R whose joints are named <!--<script> and $\\frac{a$."""
    import html

    d = tmp_path_factory.mktemp("evil")
    urdf = (ROOT / "robots" / "planar_3r.urdf").read_text()
    urdf = urdf.replace('name="joint2"', f'name="{html.escape(EVIL_SCRIPT)}"')
    urdf = urdf.replace('joint name="joint3"', f'joint name="{html.escape(EVIL_MATH)}"')
    (d / "evil.urdf").write_text(urdf)
    out = d / "out"
    r = cli(
        [
            "simulate",
            "--urdf",
            str(d / "evil.urdf"),
            "--task",
            "planar",
            "--algorithms",
            "jvja",
            "--duration",
            "0.3",
            "--q0",
            "0.3,1.2,1.0",
            "--html",
            "--no-progress",
            "--out",
            str(out),
        ]
    )
    assert r.returncode == 0, r.stderr
    return out


def test_names_that_look_like_markup_or_mathtext_save_plots_and_a_page(evil_run):
    """The plots and the page are written; the page's scripts hold the names only as escaped
    JSON (no raw <!-- nor a second <script> opener), and the JSON reads back the exact names."""
    import re

    for f in ("comparison.png", "jvja/run.png", "jvja/run.svg", "jvja/replay.html"):
        assert (evil_run / f).stat().st_size > 1000, f
    page = (evil_run / "jvja" / "replay.html").read_text(encoding="utf-8")
    assert "<!--" not in page
    scripts = re.findall(r"<script[^>]*>(.*?)</script>", page, flags=re.S)
    assert not any("<script" in s.lower() for s in scripts)
    found = re.findall(r'"joints":\s*(\[[^\]]*\])', page)
    assert found and EVIL_SCRIPT in json.loads(found[0]) and EVIL_MATH in json.loads(found[0])


def test_script_json_escapes_what_could_end_a_script():
    """script_json: <, >, &, U+2028/9 escaped; the text parses back to the same object."""
    from fault_tolerance.viz.page import script_json

    obj = {"name": "</script><!--<script>&\u2028\u2029"}
    text = script_json(obj)
    assert not set("<>&\u2028\u2029") & set(text)
    assert json.loads(text) == obj


def test_plain_text_in_figures_draws_dollar_names():
    """figures.text.plain: a name with unbalanced $ draws (no mathtext error) as written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fault_tolerance.figures.text import plain

    fig, ax = plt.subplots()
    ax.set_title(plain(EVIL_MATH))
    fig.canvas.draw()
    assert ax.title.get_text() == r"\$\frac{a\$"
    plt.close(fig)


@pytest.mark.browser
def test_the_page_of_evil_names_renders_and_runs_no_injected_script(evil_run):
    """In headless Chromium the replay of the evil-named arm renders its 3D view and plots, and
    no script but the page's own runs (no page error, no marker set by an injected script)."""
    from headless import launched

    with launched() as browser:
        page = browser.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((evil_run / "jvja" / "replay.html").as_uri())
        page.wait_for_function(
            "() => window.viewer && viewer.animator && viewer.animator.duration > 0",
            timeout=30_000,
        )
        meshes = page.evaluate(
            "() => { let n = 0; viewer.scene.traverse(o => { if (o.isMesh) n += 1; }); return n; }"
        )
        assert meshes >= 3
        assert page.evaluate("() => document.querySelectorAll('svg').length") >= 1
        assert errors == []


# -- (f) bad numbers anywhere in the Python API --------------------------------------------------


def _bad_calls():
    arm = ft.load_arm("planar_3r")
    q = np.array([0.3, 1.2, 1.0])
    J = arm.jacobian(q)
    xd = np.array([0.1, 0.0])
    qd = ft.resolve("jvja", J, xd)
    nan, inf = np.nan, np.inf
    Jn, Ji = J.copy(), J.copy()
    Jn[0, 1], Ji[1, 2] = nan, inf
    Js = ft.batch.jacobians(arm, np.stack([q, q]))
    X = np.stack([xd, xd])
    Jsn, Xn = Js.copy(), X.copy()
    Jsn[1, 0, 0], Xn[0, 1] = nan, inf
    circle = ft.CirclePath(np.array([1.0, 0.5]), 0.1, 6.28, 0.05)
    lo, hi, v = arm.lower, arm.upper, arm.velocity_limit
    return [
        ("J", lambda: ft.rcn(Jn)),
        ("J", lambda: ft.rcn(Ji)),
        ("J", lambda: ft.rcn(J[0])),
        ("lockable", lambda: ft.rcn(J, [])),
        ("lockable", lambda: ft.rcn(J, [1, 1])),
        ("J", lambda: ft.square_sum_rcn(Jn)),
        ("J", lambda: ft.fault_tolerance_measure(Jn)),
        ("J", lambda: ft.resolve("jvja", Jn, xd)),
        ("xdot", lambda: ft.resolve("jvja", J, [nan, 0])),
        ("xdot", lambda: ft.resolve("lnva", J, [0.1, 0, 0])),
        ("lockable", lambda: ft.resolve("jvja", J, xd, [])),
        ("lockable", lambda: ft.resolve("jvja", J, xd, [2, 2])),
        ("weights", lambda: ft.resolve("jvja", J, xd, [1, 2], weights=[1, nan])),
        ("weights", lambda: ft.resolve("jvja", J, xd, [1, 2], weights=[1])),
        ("bounds", lambda: ft.resolve("jvja", J, xd, bounds=(np.full(3, nan), np.ones(3)))),
        ("J", lambda: ft.jvj(Jn, xd, qd)),
        ("qd", lambda: ft.jvj(J, xd, [nan, 0, 0])),
        ("qd", lambda: ft.jvj(J, xd, [0, 0])),
        ("xdot", lambda: ft.jvj(J, [inf, 0], qd)),
        ("Js", lambda: ft.batch.resolve("jvja", Jsn, X)),
        ("xdots", lambda: ft.batch.resolve("jvja", Js, Xn)),
        ("Js", lambda: ft.batch.rcn(Jsn)),
        ("Js", lambda: ft.batch.square_sum_rcn(Jsn)),
        ("Js", lambda: ft.batch.mean_jump(Jsn, [1, 2])),
        ("Q", lambda: ft.batch.jacobians(arm, np.array([[nan, 0, 0]]))),
        ("q", lambda: arm.jacobian([nan, 0, 0])),
        ("q", lambda: arm.jacobian([0, 0])),
        ("q", lambda: arm.fk([inf, 0, 0])),
        ("q", lambda: arm.fk([0, 0, 0, 0])),
        ("x0", lambda: ft.CirclePath(np.array([nan, 0.0]), 0.1, 6.28, 1.0)),
        ("radius", lambda: ft.CirclePath(np.array([1.0, 0.0]), nan, 6.28, 1.0)),
        ("omega", lambda: ft.CirclePath(np.array([1.0, 0.0]), 0.1, inf, 1.0)),
        ("duration", lambda: ft.CirclePath(np.array([1.0, 0.0]), 0.1, 6.28, -1.0)),
        ("q", lambda: ft.rate_box([nan, 0, 0], lo, hi, v)),
        ("lower", lambda: ft.rate_box(q, [nan, 0, 0], hi, v)),
        ("velocity", lambda: ft.rate_box(q, lo, hi, [1.0, 1.0])),
        ("lockable", lambda: ft.scenarios([], 3)),
        ("lockable", lambda: ft.scenarios([0, 0], 3)),
        ("weights", lambda: ft.scenarios([0, 1], 3, weights=[1, nan])),
        ("weights", lambda: ft.Controller(arm, [1, 2], weights=[nan, 1])),
        ("lockable", lambda: ft.Controller(arm, [])),
        ("q0", lambda: ft.simulate(arm, circle, q0=np.array([nan, 0, 0]))),
        ("q0", lambda: ft.simulate(arm, circle, q0=np.array([0.0, 0]))),
        ("dt", lambda: ft.simulate(arm, circle, q0=q, dt=nan)),
    ]


BAD = _bad_calls()


@pytest.mark.parametrize("name, call", BAD, ids=[f"{i}-{n}" for i, (n, _) in enumerate(BAD)])
def test_bad_numbers_raise_the_toolkits_error_naming_the_argument(name, call):
    """NaN, inf, wrong shapes, empty or duplicated lockable sets: a FaultToleranceError whose
    message names the argument (never a NumPy error, never a finite-looking answer)."""
    with pytest.raises(FaultToleranceError) as info:
        call()
    assert name in str(info.value), str(info.value)


def test_the_security_page_examples_run(tmp_path, monkeypatch):
    """Every ```python block of docs/security.md runs, in order, in one namespace."""
    import re

    text = (ROOT / "docs" / "security.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    for block in blocks:
        exec(compile(block, "docs/security.md", "exec"), ns)  # noqa: S102 - our own documentation
    assert (tmp_path / "out" / "ws_doc" / RECORD).is_file()
