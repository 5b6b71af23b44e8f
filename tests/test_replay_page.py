"""The replay page's plots (#ft-plots): λ, K and joint rates beside the 3D view, synced both ways.

The SVG checks run without a browser; the ``browser`` tests drive Debian's /usr/bin/chromium with
Playwright (as tests/test_viz.py does): the cursor follows the animation, a click on a plot moves
the arm, several runs of one command share a page.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest
from headless import launched

import fault_tolerance as ft
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.simulate import simulate

viz = pytest.importorskip("fault_tolerance.viz")
from fault_tolerance.figures import scales  # noqa: E402
from fault_tolerance.viz import charts  # noqa: E402
from fault_tolerance.viz.page import embed, export_html  # noqa: E402
from fault_tolerance.viz.server import serve  # noqa: E402

VIEWPORT = {"width": 1200, "height": 700}


@pytest.fixture(scope="module")
def planar_runs():
    """Planar 3R, 0.6 s of the Fig. 2 circle: LNVA and JVJA, and a JVJA run where joint2 locks."""
    arm = ft.load_arm("planar_3r")
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.6)
    runs = {a: simulate(arm, path, a, q0=q0) for a in ("lnva", "jvja")}
    lock = simulate(
        arm, path, "jvja", q0=q0, lock_joint="joint2", lock_time=0.3, feedback_gain=10.0
    )
    return arm, runs, lock


@pytest.fixture(scope="module")
def folder(planar_runs, tmp_path_factory) -> Path:
    """A folder of run folders, as `simulate --out` writes it."""
    _, runs, _ = planar_runs
    out = tmp_path_factory.mktemp("sim")
    for alg, run in runs.items():
        run.save(out / alg)
    return out


@pytest.fixture(scope="module")
def lock_html(planar_runs, tmp_path_factory) -> Path:
    arm, _, lock = planar_runs
    return export_html(lock, tmp_path_factory.mktemp("lock") / "lock.html", arm)


@pytest.fixture(scope="module")
def folder_html(folder, tmp_path_factory) -> Path:
    return export_html(folder, tmp_path_factory.mktemp("multi") / "fig2.html")


def plots_of(html: str) -> str:
    start = html.index('<div id="ft-plots">')
    return html[start : html.index("</div>\n<script", start)]


# -- the SVG, without a browser ---------------------------------------------------------------


def test_page_has_three_svg_panels_with_lock_marks(lock_html):
    """#ft-plots holds λ, K and rate panels as SVG; each marks the lock and has a cursor."""
    plots = plots_of(lock_html.read_text())
    kinds = re.findall(r'<svg class="ft-plot" data-kind="(\w+)"', plots)
    assert kinds == ["jump", "rcn", "rates"]
    assert plots.count('class="ft-cursor"') == 3
    assert plots.count('class="ft-lock"') == 3 and "joint2 locks" in plots
    assert "http://" not in plots.replace('xmlns="http://www.w3.org/2000/svg"', "")


def test_rates_panel_draws_the_velocity_limits(planar_runs):
    """The rate panel has one curve per joint and the ±limit lines at the URDF's 3 rad/s."""
    arm, runs, _ = planar_runs
    data = charts.chart_data(runs["jvja"], "jvja", "#d62728", arm.velocity_limit, arm.joint_names)
    svg = charts.rates_panel([data])
    assert sorted(set(re.findall(r'<polyline[^>]*data-joint="(\w+)"', svg))) == arm.joint_names
    limits = [float(y) for y in re.findall(r'class="ft-limit"[^>]*y1="([-\d.]+)"', svg)]
    assert len(limits) == 2  # the three joints share 3 rad/s: one pair of lines
    ax_rows = re.search(r'data-t0="([\d.e-]+)" data-t1="([\d.e-]+)"', svg)
    assert float(ax_rows.group(1)) == 0.0 and float(ax_rows.group(2)) == pytest.approx(0.6)


def test_jump_panel_draws_the_parts_of_each_scenario(planar_runs):
    """Panel (a) has λ and one dashed part per lockable joint, named after it."""
    arm, runs, _ = planar_runs
    data = charts.chart_data(runs["jvja"], "jvja", "#d62728", arm.velocity_limit, arm.joint_names)
    svg = charts.jump_panel([data])
    assert sorted(re.findall(r'data-part="(\w+)"', svg)) == ["joint1", "joint2", "joint3"]
    assert svg.count('class="ft-run"') == 1


def test_k_uses_a_log_axis_only_when_it_spans_decades(planar_runs):
    """K on a log axis when max/min > 10**2 (ticks at decades), else linear."""
    arm, runs, _ = planar_runs
    data = charts.chart_data(runs["jvja"], "jvja", "#d62728", arm.velocity_limit, arm.joint_names)
    assert 'data-scale="linear"' in charts.rcn_panel([data])
    spiky = charts.ChartRun(**{**data.__dict__, "K": np.geomspace(3.0, 3e5, len(data.t))})
    svg = charts.rcn_panel([spiky])
    assert 'data-scale="log"' in svg and "log axis" in svg
    ticks = re.findall(r'class="ft-tick">([^<]+)</text>', svg)
    assert {"1", "10", "100", "1000", "1e4", "1e5", "1e6"} <= set(ticks)
    assert scales.use_log(np.array([1.0, 99.0])) is False
    assert scales.use_log(np.array([1.0, 101.0])) is True


def test_decimation_keeps_every_peak():
    """A 20 000-sample curve is cut to at most ~2 per bucket per curve, its extremes kept."""
    t = np.linspace(0, 1, 20_000)
    y = np.sin(40 * t)
    y[12_345] = 9.0
    idx = charts._keep(t, [y], [])
    assert len(idx) <= 2 * charts.BUCKETS + 2
    assert 12_345 in idx and y[idx].min() == pytest.approx(y.min())


def test_several_runs_share_one_page(folder_html):
    """A folder of run folders: one selector, λ and K overlaid per run, both scenes inlined."""
    html = folder_html.read_text()
    plots = plots_of(html)
    assert re.findall(r'<option value="(\d)">(\w+)</option>', plots) == [
        ("0", "jvja"),
        ("1", "lnva"),
    ]
    jump = plots[plots.index('data-kind="jump"') : plots.index('data-kind="rcn"')]
    assert sorted(re.findall(r'class="ft-run" data-run="(\d)"', jump)) == ["0", "1"]
    assert len(re.findall(r'class="ft-run-only" data-run="(\d)"', plots)) == 4  # parts, rates
    assert "#1f77b4" in jump and "#d62728" in jump  # LNVA blue, JVJA red as in the figures


def test_runs_of_different_arms_are_refused(planar_runs, tmp_path):
    """Runs of two arms in one folder give a clear error naming both joint lists."""
    _, runs, _ = planar_runs
    runs["jvja"].save(tmp_path / "a")
    arm4 = ft.load_arm("spatial_4r")
    q0 = np.array([0.3, 0.6, 0.4, 1.2])
    simulate(arm4, CirclePath(arm4.fk(q0), 0.05, 2 * np.pi, 0.05), "lnva", q0=q0).save(
        tmp_path / "b"
    )
    with pytest.raises(ft.FaultToleranceError, match="different arms"):
        export_html(tmp_path, tmp_path / "x.html")


def test_replay_lists_the_runs_of_a_folder(folder):
    """`replay DIR` without --html/--open lists a folder's runs (exit 0) and says how to open them."""
    out, err = io.StringIO(), io.StringIO()
    assert viz.replay_main(folder, stdout=out, stderr=err) == 0
    text = out.getvalue()
    assert "holds 2 runs" in text and "jvja" in text and "lnva" in text and "--html" in text
    assert err.getvalue() == ""


def test_page_lists_the_runs_warnings(planar_runs, tmp_path):
    """A run with rates over the velocity limit shows its warning under the plots."""
    arm = ft.load_arm("planar_3r")
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 40 * np.pi, 0.05)
    fast = simulate(arm, path, "lnva", q0=q0, limits=False)  # the paper's: no joint limits
    html = export_html(fast, tmp_path / "fast.html", arm).read_text()
    assert re.search(r'class="ft-warning"[^>]*>\d+ of \d+ samples over the velocity limit', html)


# -- in a real browser ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def chromium():
    """Headless Debian chromium driven by Playwright (never a downloaded browser)."""
    with launched() as browser:
        yield browser


def open_page(browser, url: str):
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function(
        "() => window.ftReplay && ftReplay.ready && viewer.animator.duration > 0",
        timeout=30_000,
    )
    return page, errors


def frames(page, count: int = 2) -> None:
    page.evaluate(
        "n => new Promise(r => { const f = k => k ? requestAnimationFrame(() => f(k - 1)) : r();"
        " f(n); })",
        count,
    )


CURSORS = """() => Array.from(document.querySelectorAll('#ft-plots svg.ft-plot')).map(s => {
    const d = s.dataset, x = +s.querySelector('.ft-cursor').getAttribute('x1');
    return (+d.t0) + (x - d.x0) / (d.x1 - d.x0) * (d.t1 - d.t0);   // the time the cursor shows
})"""

ARM = """() => { const out = [];   // world positions of the arm's links
    viewer.scene.updateMatrixWorld(true);
    viewer.scene.traverse(o => {
        if (!o.isMesh) return;
        let p = o, inRobot = false;
        while (p) { if (p.name === 'robot') inRobot = true; p = p.parent; }
        if (inRobot) { const e = o.matrixWorld.elements; out.push(e[12], e[13], e[14]); }
    });
    return out; }"""


def pause_at(page, tau: float) -> None:
    page.evaluate(
        "tau => { const a = viewer.animator; a.pause(); a.time_scrubber.setValue(tau); }", tau
    )
    frames(page)


@pytest.mark.browser
def test_cursor_follows_the_animation(chromium, lock_html):
    """Seeking and playing the animation move the cursor of every plot to the animation's time."""
    page, errors = open_page(chromium, lock_html.as_uri())
    for tau in (0.1, 0.45):
        pause_at(page, tau)
        assert page.evaluate(CURSORS) == pytest.approx([tau] * 3, abs=2e-3)
    page.evaluate("() => { viewer.animator.time_scrubber.setValue(0); viewer.animator.play(); }")
    page.wait_for_function("() => viewer.animator.time > 0.05", timeout=30_000)
    page.evaluate("() => viewer.animator.pause()")
    frames(page)
    tau = page.evaluate("() => viewer.animator.time")
    assert 0.05 < tau <= 0.6 + 1e-6  # played (on a busy machine possibly to the end)
    assert page.evaluate(CURSORS) == pytest.approx([tau] * 3, abs=2e-3)
    assert errors == [] and page.evaluate("() => ftReplay.errors") == []
    page.close()


def click_at_time(page, kind: str, t: float) -> None:
    """A mouse click on the plot ``kind`` at the x of time ``t``."""
    box = page.evaluate(
        """kind => { const s = document.querySelector(`svg.ft-plot[data-kind="${kind}"]`);
            s.scrollIntoView(); const b = s.getBoundingClientRect(), d = s.dataset;
            return {left: b.left, top: b.top, width: b.width, height: b.height,
                    vb: s.viewBox.baseVal.width, t0: +d.t0, t1: +d.t1, x0: +d.x0, x1: +d.x1}; }""",
        kind,
    )
    x = box["x0"] + (t - box["t0"]) / (box["t1"] - box["t0"]) * (box["x1"] - box["x0"])
    page.mouse.click(box["left"] + x / box["vb"] * box["width"], box["top"] + box["height"] / 2)
    frames(page)


@pytest.mark.browser
def test_click_on_a_plot_moves_the_arm(chromium, lock_html):
    """A click on each plot seeks the animation there: the arm takes the pose of that time."""
    page, errors = open_page(chromium, lock_html.as_uri())
    pause_at(page, 0.0)
    start = np.array(page.evaluate(ARM))
    for kind, t in (("rates", 0.5), ("jump", 0.2), ("rcn", 0.4)):
        click_at_time(page, kind, t)
        tau = page.evaluate("() => viewer.animator.time")
        assert tau == pytest.approx(t, abs=3e-3), kind
        assert page.evaluate(CURSORS) == pytest.approx([tau] * 3, abs=2e-3)
        clicked = np.array(page.evaluate(ARM))
        assert np.max(np.abs(clicked - start)) > 1e-3, "the arm moved"
        pause_at(page, tau)  # the same time set through meshcat's own slider
        np.testing.assert_allclose(page.evaluate(ARM), clicked, atol=1e-6)
    assert errors == []
    page.close()


@pytest.mark.browser
def test_several_runs_switch_the_arm_shown(chromium, folder_html):
    """The selector shows another run's arm at the same time; its rates replace the first's."""
    page, errors = open_page(chromium, folder_html.as_uri())
    pause_at(page, 0.5)
    first = np.array(page.evaluate(ARM))
    assert page.evaluate("() => ftReplay.algorithm") == "jvja"
    page.select_option("#ft-run", "1")
    page.wait_for_function("() => ftReplay.selected === 1")
    frames(page)
    assert page.evaluate("() => [ftReplay.algorithm, viewer.animator.time]") == [
        "lnva",
        pytest.approx(0.5, abs=1e-6),
    ]
    other = np.array(page.evaluate(ARM))
    assert other.shape == first.shape and np.max(np.abs(other - first)) > 1e-4
    shown = page.evaluate(
        """() => Array.from(document.querySelectorAll('.ft-run-only')).map(g =>
            [+g.dataset.run, getComputedStyle(g).display !== 'none'])"""
    )
    assert all(visible == (run == 1) for run, visible in shown), shown
    assert "LNVA" in page.inner_text("#ft-heading")
    assert errors == [] and page.evaluate("() => ftReplay.errors") == []
    page.close()


@pytest.mark.browser
def test_live_viewer_and_notebook_embed_have_the_plots(chromium, planar_runs):
    """The live page on 127.0.0.1 and the notebook iframe show the plots, synced to the animation."""
    arm, _, lock = planar_runs
    url, server = serve(lock, arm, fps=25)
    try:
        page, errors = open_page(chromium, url)
        page.wait_for_function("() => viewer.animator.duration > 0.5")
        pause_at(page, 0.25)
        assert page.evaluate(CURSORS) == pytest.approx([0.25] * 3, abs=2e-3)
        click_at_time(page, "rates", 0.5)
        assert page.evaluate("() => viewer.animator.time") == pytest.approx(0.5, abs=3e-3)
        assert errors == []
        page.close()
    finally:
        server.close()
    markup = embed(lock, arm, height=500)._repr_html_()
    page = chromium.new_page(viewport=VIEWPORT)
    page.set_content(f"<!DOCTYPE html><html><body>{markup}</body></html>")
    frame = page.frames[1]
    frame.wait_for_function("() => window.ftReplay && ftReplay.ready && viewer.animator.duration")
    frame.evaluate(
        "() => { viewer.animator.pause(); viewer.animator.time_scrubber.setValue(0.4); }"
    )
    frame.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    assert frame.evaluate(CURSORS) == pytest.approx([0.4] * 3, abs=2e-3)
    page.close()
