"""meshcat replay: the self-contained HTML export, the live server on 127.0.0.1, a real browser.

The browser tests (``-m browser``) drive Debian's ``/usr/bin/chromium`` through Playwright's
Python API (no browser download; ``scripts/install_browser.sh`` installs chromium). They are
skipped, with the reason, only where chromium or playwright is missing.

``FT_REPLAY_PNG=docs/replay.png pytest -m browser tests/test_viz.py`` also saves the README's
screenshot of the exported page.
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from headless import launched

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.run import Run
from fault_tolerance.simulation.simulate import simulate

viz = pytest.importorskip("fault_tolerance.viz")
from fault_tolerance.viz.geometry import LOCK_COLOR, TRACE_COLOR  # noqa: E402
from fault_tolerance.viz.page import embed, export_html, scene_commands  # noqa: E402
from fault_tolerance.viz.server import serve  # noqa: E402

VIEWPORT = {"width": 1000, "height": 650}
LOCK_TIME = 0.5
#: Largest HTML of a shipped arm for a 1 s run at 50 fps [bytes] (measured: about 1.2 MB).
SHIPPED_HTML_LIMIT = 3_000_000
#: Largest HTML of the Panda (compact meshes) for a 1 s run [bytes] (measured: about 4.8 MB).
PANDA_HTML_LIMIT = 7_000_000


# -- runs -----------------------------------------------------------------------------------


def lock_run(robot: str) -> tuple[ft.Arm, Run]:
    """A 1 s circle with a lock at 0.5 s, for a shipped arm or the Panda."""
    arm = ft.load_arm(robot)
    if robot in ("planar_3r", "powercube_3r"):
        x0 = [0.35, 0.0] if robot == "planar_3r" else [0.4, 0.1]
        q0 = initial_posture(arm, x0).q
        path = CirclePath(x0, 0.1 if robot == "planar_3r" else 0.08, 2 * np.pi, 1.0)
        options = {"lock_joint": "joint2" if robot == "planar_3r" else "joint3"}
    elif robot == "spatial_4r":
        q0 = np.array([0.3, 0.6, 0.4, 1.2])
        path = CirclePath(arm.fk(q0), 0.08, 2 * np.pi, 1.0)
        options = {"lock_joint": "joint2"}
    elif robot == "panda":
        # the reference configuration of example-robot-data; joint 1 keeps the pose task when locked
        q0 = np.array([0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398])
        path = CirclePath(arm.fk(q0), 0.05, 2 * np.pi, 1.0, rows=(1, 2))
        options = {"lock_joint": "panda_joint1", "lockable": [0, 2]}
    else:  # pragma: no cover
        raise ValueError(robot)
    run = simulate(arm, path, "jvja", q0=q0, lock_time=LOCK_TIME, feedback_gain=10.0, **options)
    return arm, run


@pytest.fixture(scope="module")
def planar():
    """The example: planar 3R, circle, joint2 locks at 0.5 s."""
    return lock_run("planar_3r")


@pytest.fixture(scope="module")
def planar_html(planar, tmp_path_factory) -> Path:
    arm, run = planar
    return export_html(run, tmp_path_factory.mktemp("html") / "planar.html", arm)


# -- the package stays light ----------------------------------------------------------------


def test_import_does_not_import_meshcat():
    """Importing fault_tolerance (and its viz module) imports neither meshcat nor matplotlib."""
    code = (
        "import sys, fault_tolerance, fault_tolerance.viz; "
        "print(sorted(m for m in ('meshcat', 'matplotlib', 'zmq', 'tornado') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_missing_meshcat_says_what_to_install(monkeypatch, planar, tmp_path):
    """Without meshcat the replay raises an ImportError naming the package to install."""
    monkeypatch.setitem(sys.modules, "meshcat", None)
    arm, run = planar
    with pytest.raises(ImportError, match=r"pip install 'meshcat"):
        export_html(run, tmp_path / "r.html", arm)


# -- the HTML export ------------------------------------------------------------------------


def animation_of(html: str) -> dict:
    """The set_animation command embedded in a page."""
    commands = scene_commands(html)
    anims = [c for c in commands if c["type"] == "set_animation"]
    assert len(anims) == 1, "one animation, sent once"
    assert commands[-1]["type"] == "set_animation", "sent after the objects it animates"
    return anims[0]


def track_times(track: dict) -> np.ndarray:
    times = track["times"]
    if hasattr(times, "data"):  # Float32Array extension
        return np.frombuffer(times.data, dtype=np.float32)
    return np.asarray(times, dtype=float)


@pytest.mark.parametrize("robot", ["planar_3r", "spatial_4r", "powercube_3r"])
def test_html_is_self_contained_and_animated(robot, tmp_path):
    """The page inlines the viewer and an animation of every link over the run, and is small."""
    arm, run = lock_run(robot)
    path = export_html(run, tmp_path / "replay.html", arm)
    html = path.read_text(encoding="utf-8")
    size = path.stat().st_size
    assert size < SHIPPED_HTML_LIMIT, f"{robot}: {size} bytes"
    # no script, stylesheet or image fetched from anywhere
    assert not re.search(r"<script[^>]*\bsrc\s*=", html, re.I)
    assert not re.search(r"<link\b", html, re.I)
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", html, re.I)
    assert not re.search(r"""(fetch|import)\s*\(\s*["'`]https?://""", html)
    assert "MeshCat.Viewer" in html and "THREE" in html, "meshcat's viewer (three.js) is inlined"
    anim = animation_of(html)
    assert anim["options"]["play"] is True
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    for g in arm.visual_model.geometryObjects:
        clip = clips[f"/meshcat/robot/visuals/{g.name}"]
        names = {t["name"] for t in clip["tracks"]}
        assert {".position", ".quaternion"} <= names
        times = track_times(next(t for t in clip["tracks"] if t["name"] == ".position"))
        np.testing.assert_allclose(times[-1], run.t[-1], atol=1e-6)
        assert 40 <= len(times) <= 60, "decimated to 50 fps, not 1000 Hz"
    # the locked joint's link switches to its lock-coloured copy at the lock time
    jid = arm.model.getJointId(run.meta["lock"]["joint"])
    locked = [g.name for g in arm.visual_model.geometryObjects if g.parentJoint == jid]
    assert locked
    for name in locked:
        vis = next(
            t for t in clips[f"/meshcat/robot/visuals/{name}"]["tracks"] if t["name"] == ".visible"
        )
        assert list(vis["values"]) == [True, False]
        np.testing.assert_allclose(vis["times"], [0.0, LOCK_TIME], atol=1e-9)
        copy = next(
            t for t in clips[f"/meshcat/locked/visuals/{name}"]["tracks"] if t["name"] == ".visible"
        )
        assert list(copy["values"]) == [False, True]
    info = json.loads(re.search(r"window\.ftReplay = (\{.*?\});\n", html).group(1))
    assert info["lock"]["joint"] == run.meta["lock"]["joint"]
    assert info["has_desired_path"] and info["meshes"] >= len(arm.visual_model.geometryObjects) + 4


def test_html_of_the_panda_with_meshes(tmp_path):
    """The Panda's meshes replay too, compact by default (a few MB for a 1 s run)."""
    arm, run = lock_run("panda")
    path = export_html(run, tmp_path / "panda.html", arm)
    assert path.stat().st_size < PANDA_HTML_LIMIT, path.stat().st_size
    html = path.read_text(encoding="utf-8")
    clips = {a["path"] for a in animation_of(html)["animations"]}
    assert {f"/meshcat/robot/visuals/{g.name}" for g in arm.visual_model.geometryObjects} <= clips
    assert "/meshcat/locked/visuals/panda_link1_0" in clips


def test_speed_and_frame_rate(planar, tmp_path):
    """speed=2 halves the replay's length; fps sets the number of frames."""
    arm, run = planar
    html = export_html(run, tmp_path / "fast.html", arm, speed=2.0, fps=30.0).read_text()
    clip = next(
        a["clip"] for a in animation_of(html)["animations"] if a["path"].endswith("link1_0")
    )
    times = track_times(clip["tracks"][0])
    np.testing.assert_allclose(times[-1], 0.5, atol=1e-6)
    assert len(times) == 16  # 0, 1/30, ..., 0.5
    with pytest.raises(InvalidInput, match="speed"):
        export_html(run, tmp_path / "bad.html", arm, speed=0.0)


def test_export_from_a_saved_run_and_from_arrays(planar, tmp_path):
    """A saved run folder rebuilds its arm from its metadata; arrays of q need the arm and dt."""
    arm, run = planar
    run.save(tmp_path / "run")
    assert export_html(tmp_path / "run", tmp_path / "saved.html").stat().st_size > 0
    q = run.q[::10]
    assert export_html(q, tmp_path / "q.html", arm, dt=0.01).stat().st_size > 0
    with pytest.raises(InvalidInput, match="arm"):
        export_html(q, tmp_path / "q.html", dt=0.01)
    with pytest.raises(InvalidInput, match="shape"):
        export_html(q[:, :2], tmp_path / "q.html", arm, dt=0.01)


def test_export_is_atomic(planar, tmp_path, monkeypatch):
    """A failed write leaves the previous file intact and no temporary file behind."""
    arm, run = planar
    target = tmp_path / "replay.html"
    target.write_text("previous replay")

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr("fault_tolerance.storage.atomic.os.replace", fail)
    with pytest.raises(OSError, match="disk full"):
        export_html(run, target, arm)
    assert target.read_text() == "previous replay"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["replay.html"]


def test_embed_for_notebooks(planar):
    """embed() gives notebook HTML: the whole page in an iframe srcdoc, of modest size."""
    arm, run = planar
    markup = embed(run, arm, height=320)._repr_html_()
    assert markup.count("<iframe") == 1 and "srcdoc=" in markup and "320px" in markup
    assert "http://" not in markup.split("srcdoc=")[0]
    assert len(markup) < 2_000_000


# -- the live server ------------------------------------------------------------------------


def listening_sockets(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every TCP socket the process listens on, from /proc."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = []
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        if not Path(table).exists():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            cols = line.split()
            if cols[3] != "0A" or cols[9] not in inodes:  # 0A: LISTEN
                continue
            addr, port = cols[1].split(":")
            if width == 8:
                ip = ".".join(str(int(addr[i : i + 2], 16)) for i in (6, 4, 2, 0))
            else:
                ip = "::" if int(addr, 16) == 0 else f"ipv6:{addr}"
            found.append((ip, int(port, 16)))
    return found


@pytest.fixture(scope="module")
def live(planar):
    """A live replay of the planar run; stopped at the end of the module."""
    arm, run = planar
    url, server = serve(run, arm)
    yield url, server
    server.close()


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc to list sockets")
def test_live_server_listens_on_localhost_only(live):
    """Every socket of the live server (web and ZMQ) is bound to 127.0.0.1, none to 0.0.0.0."""
    url, server = live
    assert url.startswith("http://127.0.0.1:") and url.endswith("/static/")
    sockets = listening_sockets(server.process.pid)
    assert len(sockets) >= 2, sockets  # the web port and the ZMQ port
    assert {ip for ip, _ in sockets} == {"127.0.0.1"}, sockets
    assert int(url.split(":")[2].split("/")[0]) in {port for _, port in sockets}
    if shutil.which("ss"):  # the same seen by ss -ltnp
        out = subprocess.run(["ss", "-ltnp"], capture_output=True, text=True).stdout
        ours = [line for line in out.splitlines() if f"pid={server.process.pid}," in line]
        assert ours and all(" 127.0.0.1:" in line for line in ours), out


def test_server_close_stops_it(planar):
    """close() ends the server process; a second close() is harmless."""
    arm, run = planar
    url, server = serve(run, arm, fps=10)
    assert server.running
    server.close()
    assert not server.running
    server.close()


def test_busy_port_is_reported(planar):
    """A web port already taken gives an error naming the port, and no server is left running."""
    import socket

    arm, run = planar
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ft.FaultToleranceError, match=f"port {port}"):
            serve(run, arm, fps=10, port=port)


def test_replay_main(planar, tmp_path):
    """The CLI body: --html writes the page; --open prints a 127.0.0.1 URL, stops after wait()."""
    arm, run = planar
    run.save(tmp_path / "run")
    out, err = io.StringIO(), io.StringIO()
    assert (
        viz.replay_main(tmp_path / "run", html=str(tmp_path / "r.html"), stdout=out, stderr=err)
        == 0
    )
    assert (tmp_path / "r.html").stat().st_size > 100_000 and "r.html" in out.getvalue()
    seen = {}

    def wait():
        seen["url"] = re.search(r"http://\S+", out.getvalue()).group(0)

    out = io.StringIO()
    assert (
        viz.replay_main(tmp_path / "run", open=True, speed=0.5, wait=wait, stdout=out, stderr=err)
        == 0
    )
    assert seen["url"].startswith("http://127.0.0.1:")
    for args in ({"open": False, "html": None}, {"html": str(tmp_path / "x.html"), "speed": -1.0}):
        err = io.StringIO()
        assert viz.replay_main(tmp_path / "run", stdout=out, stderr=err, **args) == 2
        assert err.getvalue().count("\n") == 1
    err = io.StringIO()
    assert (
        viz.replay_main(tmp_path / "missing", html=str(tmp_path / "x.html"), stdout=out, stderr=err)
        == 2
    )
    assert "missing" in err.getvalue()


# -- in a real browser ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def chromium():
    """Headless Debian chromium driven by Playwright (never a downloaded browser)."""
    with launched() as browser:
        yield browser


COUNT_MESHES = (
    """() => { let n = 0; viewer.scene.traverse(o => { if (o.isMesh) n += 1; }); return n; }"""
)


def open_replay(browser, url: str, meshes: int):
    """A page with the replay loaded: viewer up, animation set, every mesh in the scene."""
    page = browser.new_page(viewport=VIEWPORT)
    requests: list[str] = []
    errors: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function(
        f"""() => window.viewer && viewer.animator && viewer.animator.duration > 0
               && ({COUNT_MESHES})() >= {meshes}""",
        timeout=30_000,
    )
    return page, requests, errors


def seek(page, t: float, overlays: bool = False) -> bytes:
    """Pause, move the viewer's time slider to ``t`` (replay seconds), render, screenshot."""
    page.evaluate(
        """([t, overlays]) => {
            const a = viewer.animator;
            a.pause();
            a.time_scrubber.setValue(t);   // the GUI control: sets a.time and seeks the mixer
            for (const id of ["ft-legend", "ft-plots"]) {   // colours of the 3D view only
                const el = document.getElementById(id);
                if (el) el.style.visibility = overlays ? "visible" : "hidden";
            }
            viewer.gui.domElement.style.visibility = overlays ? "visible" : "hidden";
        }""",
        [t, overlays],
    )
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    assert abs(page.evaluate("() => viewer.animator.actions[0].time") - t) < 1e-6
    return page.screenshot()


def colour_counts(png: bytes, colours: dict[str, tuple]) -> dict[str, int]:
    """Pixels of each named colour: same hue (±12°), saturated, not dark (shading-proof)."""
    from PIL import Image

    hsv = np.asarray(Image.open(io.BytesIO(png)).convert("RGB").convert("HSV")).astype(float)
    h, s, v = hsv[..., 0] * 360 / 255, hsv[..., 1] / 255, hsv[..., 2] / 255
    import colorsys

    counts = {}
    for name, rgb in colours.items():
        hue = colorsys.rgb_to_hsv(*rgb)[0] * 360
        dh = np.abs((h - hue + 180) % 360 - 180)
        counts[name] = int(np.count_nonzero((dh < 12) & (s > 0.45) & (v > 0.2)))
    return counts


FRAMED = """() => {
    // every visible mesh (links, paths, markers) projects inside the view
    const cam = viewer.camera, out = [];
    cam.updateMatrixWorld(true);
    viewer.scene.updateMatrixWorld(true);
    viewer.scene.traverseVisible(o => {
        if (!o.isMesh) return;
        o.geometry.computeBoundingBox();
        const b = o.geometry.boundingBox;
        const V = cam.position.constructor;
        for (const x of [b.min.x, b.max.x])
          for (const y of [b.min.y, b.max.y])
            for (const z of [b.min.z, b.max.z]) {
              const p = new V(x, y, z).applyMatrix4(o.matrixWorld).project(cam);
              if (Math.abs(p.x) > 1 || Math.abs(p.y) > 1 || p.z > 1) out.push([o.parent.name]);
            }
    });
    return out;
}"""


def check_replay_frames(page, info: dict) -> dict:
    """Whole arm and path framed at the start; link colours on screen; two times differ; the
    locked joint's link changes colour at the lock."""
    seek(page, 0.0)
    assert page.evaluate(FRAMED) == []
    colours = {
        "link1": (0.85, 0.2, 0.2),
        "link2": (0.2, 0.7, 0.3),
        "link3": (0.2, 0.4, 0.9),
        "lock": LOCK_COLOR,
        "trace": TRACE_COLOR,
    }
    lock_tau = info["lock"]["replay_time"]
    before, after = seek(page, 0.8 * lock_tau), seek(page, min(lock_tau + 0.3, info["duration"]))
    cb, ca = colour_counts(before, colours), colour_counts(after, colours)
    for link in ("link1", "link2", "link3"):
        assert cb[link] > 300, (link, cb)
    assert cb["trace"] > 100, cb
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(before)).convert("RGB"), dtype=float)
    b = np.asarray(Image.open(io.BytesIO(after)).convert("RGB"), dtype=float)
    assert np.mean(np.any(np.abs(a - b) > 30, axis=-1)) > 0.005, (
        "the arm moved between the two times"
    )
    # joint2 locks: its (green) link turns magenta; the lock ball was the only magenta before
    assert ca["link2"] < 0.1 * cb["link2"], (cb, ca)
    assert ca["lock"] > cb["lock"] + 0.5 * cb["link2"], (cb, ca)
    assert ca["link1"] > 300 and ca["link3"] > 300, ca
    return {"before": cb, "after": ca}


@pytest.mark.browser
def test_exported_html_plays_offline_in_chromium(chromium, planar_html):
    """The exported file loads from disk with no network, and its animation seeks frame by frame."""
    page, requests, errors = open_replay(chromium, planar_html.as_uri(), meshes=0)
    info = page.evaluate("() => window.ftReplay")
    assert info["ready"] and info["errors"] == [], info.get("errors")
    page.wait_for_function(f"() => ({COUNT_MESHES})() >= {info['meshes']}")
    check_replay_frames(page, info)
    assert page.evaluate("() => viewer.animator.time_scrubber.__max") == pytest.approx(
        info["duration"], abs=1e-3
    )
    clock = page.evaluate(
        "() => new Promise(r => requestAnimationFrame("
        "() => r(document.getElementById('ft-clock').textContent)))"
    )
    assert "locked" in clock, clock
    assert all(u.startswith(("file:", "data:", "blob:", "about:")) for u in requests), requests
    assert errors == []
    shot = os.environ.get("FT_REPLAY_PNG")
    if shot:  # the README's picture: just after the lock, legend and controls shown
        Path(shot).write_bytes(seek(page, LOCK_TIME + 0.3, overlays=True))
    page.close()


@pytest.mark.browser
def test_live_replay_in_chromium(chromium, live):
    """The live viewer on 127.0.0.1 receives the scene and animation and seeks like the file."""
    url, server = live
    page, requests, errors = open_replay(chromium, url, meshes=server.info["meshes"])
    check_replay_frames(page, server.info)
    assert all(
        u.startswith(("http://127.0.0.1:", "ws://127.0.0.1:", "data:", "blob:")) for u in requests
    ), requests
    assert errors == []
    page.close()


@pytest.mark.browser
def test_notebook_embed_plays_in_chromium(chromium, planar):
    """The notebook embed (iframe srcdoc) runs the same replay inside a host page."""
    arm, run = planar
    markup = embed(run, arm, height=500)._repr_html_()
    page = chromium.new_page(viewport=VIEWPORT)
    page.set_content(f"<!DOCTYPE html><html><body>{markup}</body></html>")
    frame = page.frames[1]
    frame.wait_for_function(
        "() => window.ftReplay && window.ftReplay.ready && viewer.animator.duration > 0"
    )
    assert frame.evaluate("() => window.ftReplay.errors") == []
    page.close()
