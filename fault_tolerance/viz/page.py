"""The self-contained HTML page of a replay: meshcat's viewer and the scene inlined, a legend.

:func:`export_html` writes it to a file that plays offline (nothing is fetched from a network or a
server); :func:`embed` puts it in a Jupyter notebook's output as an iframe's ``srcdoc``;
:func:`scene_commands` decodes the commands a page carries. In the page, ``window.viewer`` is
meshcat's viewer and ``window.ftReplay`` what was replayed (robot, speed, lock time, ready flag).
"""

from __future__ import annotations

import base64
import html as html_lib
import json
from dataclasses import dataclass
from pathlib import Path

from ..arm import Arm
from ..errors import FaultToleranceError
from ..simulation import write_atomic
from .charts import chart_data, plots_html, run_color
from .collect import collect_runs
from .geometry import LOCK_COLOR, PATH_COLOR, TRACE_COLOR
from .scene import _build_scene, _require_meshcat, _Scene


def _viewer_js() -> str:
    meshcat = _require_meshcat()
    path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    text = path.read_text(encoding="utf-8")
    if "</script" in text.lower():  # pragma: no cover - would end the inline script early
        raise FaultToleranceError(f"{path} contains '</script'; it cannot be inlined")
    return text


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="fault_tolerance {version} with meshcat">
<title>{title}</title>
<style>
  body {{ margin: 0; overflow: hidden; display: flex; height: 100vh;
          font-family: system-ui, -apple-system, "Segoe UI", sans-serif; }}
  #ft-view {{ position: relative; flex: 1 1 auto; min-width: 0; height: 100vh; }}
  #meshcat-pane {{ width: 100%; height: 100vh; overflow: hidden; }}
  #ft-legend {{ position: absolute; left: 12px; bottom: 12px; padding: 8px 12px; border-radius: 6px;
               background: rgba(255, 255, 255, 0.86); color: #1d1f24;
               font-size: 13px; line-height: 1.6;
               box-shadow: 0 1px 4px rgba(0, 0, 0, 0.18); pointer-events: none; }}
  #ft-legend b {{ font-weight: 600; }}
  .ft-swatch {{ display: inline-block; width: 22px; height: 5px; border-radius: 2px;
                vertical-align: middle; margin-right: 7px; }}
  .ft-swatch.ft-thin {{ width: 14px; height: 3px; margin-right: 4px; }}
  .ft-dot {{ display: inline-block; width: 10px; height: 10px; border-radius: 5px;
             vertical-align: middle; margin: 0 13px 0 6px; }}
  #ft-clock {{ font-variant-numeric: tabular-nums; }}
  #ft-plots {{ flex: 0 0 40%; max-width: 560px; height: 100vh; overflow-y: auto;
               box-sizing: border-box; padding: 6px 8px 8px; background: #f4f5f7;
               border-left: 1px solid #d5d8de; color: #1d1f24; font-size: 12px; }}
  #ft-plots svg {{ display: block; width: 100%; height: auto; margin-top: 4px;
                   cursor: crosshair; font-size: 11px; }}
  #ft-plots .ft-tick {{ fill: #50545e; font-size: 10px; }}
  #ft-plots .ft-title {{ fill: #1d1f24; font-size: 12px; font-weight: 600; }}
  #ft-plots .ft-unit {{ fill: #50545e; font-size: 10px; }}
  #ft-plots .ft-lock-label {{ font-size: 10px; }}
  .ft-keys {{ line-height: 1.7; }}
  .ft-key {{ margin-right: 10px; white-space: nowrap; }}
  .ft-select select {{ font: inherit; margin: 0 0 4px 4px; }}
  .ft-warnings {{ margin: 6px 0 0; padding-left: 18px; color: #a3151a; }}
  @media (max-width: 720px) {{
    body {{ flex-direction: column; overflow: auto; height: auto; }}
    #ft-view, #meshcat-pane {{ height: 60vh; }}
    #ft-plots {{ flex: none; max-width: none; height: auto; border-left: none; }}
  }}
</style>
</head>
<body>
<div id="ft-view">
<div id="meshcat-pane"></div>
<div id="ft-legend">
  <div><b id="ft-heading">{heading}</b></div>
  {legend}
  <div id="ft-clock">t = 0.00 s</div>
</div>
</div>
<div id="ft-plots">
{plots}
</div>
{viewer_script}
<script>
window.ftReplay = {info};
(function () {{
  var info = window.ftReplay;
  var runs = {runs};
  info.ready = false;
  info.errors = [];
  info.runs = runs;
  info.selected = 0;
  var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
  window.viewer = viewer;
  var commands = {commands};
  var more = {more};
  function apply(list) {{
    for (var i = 0; i < list.length; i++) {{
      try {{
        var item = typeof list[i] === "number" ? commands[list[i]] : list[i];
        var raw = atob(item);
        var bytes = new Uint8Array(raw.length);
        for (var j = 0; j < raw.length; j++) bytes[j] = raw.charCodeAt(j);
        viewer.handle_command_bytearray(bytes);
      }} catch (err) {{
        info.errors.push(String(err));
      }}
    }}
  }}
  if ({live}) {{
    try {{ viewer.connect(); }} catch (err) {{ info.errors.push(String(err)); }}
  }} else {{
    apply(commands);
  }}
  // Show the animation controls (play, pause, time) and fold the long scene tree.
  function tidy() {{
    try {{
      var folders = viewer.gui.__folders;
      if (folders["Scene"]) folders["Scene"].close();
      if (folders["Save / Load / Capture"]) folders["Save / Load / Capture"].close();
      viewer.gui.open();
    }} catch (err) {{
      info.errors.push(String(err));
    }}
  }}
  tidy();
  var plots = document.getElementById("ft-plots");
  var svgs = Array.prototype.slice.call(plots.querySelectorAll("svg.ft-plot"));
  function runInfo() {{ return runs[info.selected]; }}
  // run time t [s] <-> replay time tau [s] of the run shown
  function tauOf(t) {{
    var r = runInfo();
    return Math.max(0, Math.min(r.duration, (t - r.run_start) / r.speed));
  }}
  function timeOf(tau) {{ var r = runInfo(); return r.run_start + tau * r.speed; }}
  function xOf(svg, t) {{
    var d = svg.dataset, t0 = +d.t0, t1 = +d.t1, x0 = +d.x0, x1 = +d.x1;
    var u = Math.max(0, Math.min(1, (t - t0) / (t1 - t0)));
    return x0 + u * (x1 - x0);
  }}
  function seekTime(t) {{
    var a = viewer.animator;
    if (!a || !a.time_scrubber) return;
    a.time_scrubber.setValue(tauOf(t));  // sets a.time and seeks every action
    drawCursor(timeOf(a.time));
  }}
  info.seekTime = seekTime;
  function drawCursor(t) {{
    for (var i = 0; i < svgs.length; i++) {{
      var line = svgs[i].querySelector(".ft-cursor");
      var x = xOf(svgs[i], t).toFixed(2);
      if (line.getAttribute("x1") !== x) {{
        line.setAttribute("x1", x);
        line.setAttribute("x2", x);
      }}
    }}
    info.cursorTime = t;
  }}
  svgs.forEach(function (svg) {{
    svg.addEventListener("click", function (ev) {{
      var box = svg.getBoundingClientRect(), vb = svg.viewBox.baseVal;
      var x = vb.x + (ev.clientX - box.left) / box.width * vb.width;
      var d = svg.dataset, t0 = +d.t0, t1 = +d.t1, x0 = +d.x0, x1 = +d.x1;
      seekTime(t0 + (x - x0) / (x1 - x0) * (t1 - t0));
    }});
  }});
  function showRun(k) {{
    plots.querySelectorAll(".ft-run-only").forEach(function (g) {{
      g.style.display = (+g.dataset.run === k) ? "" : "none";
    }});
    plots.querySelectorAll(".ft-run").forEach(function (g) {{
      g.style.opacity = (+g.dataset.run === k || runs.length === 1) ? "1" : "0.45";
    }});
    plots.querySelectorAll(".ft-warning").forEach(function (li) {{
      li.style.display = (+li.dataset.run === k) ? "" : "none";
    }});
  }}
  function select(k) {{
    if (k === info.selected || k < 0 || k >= runs.length) return;
    var a = viewer.animator, tau = a ? a.time : 0, playing = a ? a.playing : false;
    viewer.handle_command({{type: "delete", path: "/meshcat"}});
    apply(more[k]);
    info.selected = k;
    var r = runs[k];
    for (var key in r) if (key !== "ready" && key !== "errors") info[key] = r[key];
    document.getElementById("ft-heading").textContent = r.heading;
    tidy();
    seekTime(timeOf(tau));
    if (!playing) viewer.animator.pause();
    showRun(k);
  }}
  info.select = select;
  var chooser = document.getElementById("ft-run");
  if (chooser) chooser.addEventListener("change", function () {{ select(+chooser.value); }});
  showRun(0);
  var clock = document.getElementById("ft-clock");
  function tick() {{
    var tau = viewer.animator ? viewer.animator.time : 0;
    var t = timeOf(tau);
    var text = "t = " + t.toFixed(2) + " s";
    if (info.speed !== 1) text += "  (replay \u00d7" + info.speed + ")";
    if (info.lock && t >= info.lock.time) text += "  \u2014 " + info.lock.joint + " locked";
    if (clock.textContent !== text) clock.textContent = text;
    drawCursor(t);
    requestAnimationFrame(tick);
  }}
  requestAnimationFrame(tick);
  info.ready = true;
}})();
</script>
</body>
</html>
"""


def _legend(info: dict) -> tuple[str, str, str]:
    """Title, heading and legend rows of the page."""
    esc = html_lib.escape
    robot = str(info.get("robot") or "arm")
    parts = [robot] + ([str(info["algorithm"]).upper()] if info.get("algorithm") else [])
    lock = info.get("lock")
    if lock:
        parts.append(f"{lock['joint']} locks at {lock['time']:.2f} s")
    heading = " \u00b7 ".join(parts)

    def css(rgb):
        return "rgb({},{},{})".format(*(int(round(255 * c)) for c in rgb))

    rows = []
    if info.get("has_desired_path"):
        rows.append(
            f'<div><span class="ft-swatch" style="background:{css(PATH_COLOR)}"></span>'
            f"desired path; the dark ball is where the tool should be</div>"
        )
    rows.append(
        f'<div><span class="ft-swatch" style="background:{css(TRACE_COLOR)}"></span>'
        f"the tool's actual trace</div>"
    )
    if lock:
        rows.append(
            f'<div><span class="ft-swatch" style="background:{css(LOCK_COLOR)}"></span>'
            f"{esc(lock['joint'])} locked from {lock['time']:.2f} s; the ball marks the lock</div>"
        )
    return f"fault_tolerance replay: {heading}", heading, "\n  ".join(rows)


@dataclass
class _Page:
    """What one replay page shows: a scene per run (the first shown first) and the plots."""

    scenes: list[_Scene]
    labels: list[str]
    plots: str


def _warnings_of(run, arm: Arm | None) -> list[str]:
    """The diagnostics' warnings of a run (none for bare joint positions)."""
    from ..diagnostics import check_run
    from ..simulation import Run

    if not isinstance(run, Run):
        return []
    return [w.message for w in check_run(run, arm)]


def _build_page(
    run,
    arm: Arm | None,
    *,
    speed: float,
    fps: float,
    meshes: str = "compact",
    dt: float | None = None,
) -> _Page:
    """Scenes and plots of ``run`` (one run, or the runs of a folder / list / dict)."""
    items = collect_runs(run)
    scenes, charts, warnings, taken = [], [], [], set()
    for i, (label, item) in enumerate(items):
        scene = _build_scene(item, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
        scenes.append(scene)
        color = run_color(scene.info.get("algorithm"), i, taken)
        taken.add(color)
        data = item if hasattr(item, "jvj") else (scene.motion.t, scene.motion.q)
        charts.append(
            chart_data(data, label, color, scene.arm.velocity_limit, scene.arm.joint_names)
        )
        warnings.append(_warnings_of(item, scene.arm))
    return _Page(scenes, [c.label for c in charts], plots_html(charts, warnings))


#: Scene commands a page keeps when it switches the run shown (the camera stays where it is).
_STAGE_PATHS = (b"/Cameras", b"/Background", b"/Axes")


def _encode(commands) -> list[str]:
    return [base64.b64encode(data).decode("ascii") for _, _, data in commands]


def _page_html(page: _Page, *, live: bool = False) -> str:
    """The page's HTML; ``live``: scene 0 comes from the meshcat server's websocket."""
    from .. import __version__

    first = page.scenes[0]
    title, heading, legend = _legend(first.info)
    runs = []
    for scene, label in zip(page.scenes, page.labels, strict=True):
        info = dict(scene.info, label=label, heading=_legend(scene.info)[1])
        runs.append(info)
    more: list = []
    if len(page.scenes) > 1:
        more.append([i for i, c in enumerate(first.commands) if not c[1].startswith(_STAGE_PATHS)])
        for scene in page.scenes[1:]:
            more.append(_encode(c for c in scene.commands if not c[1].startswith(_STAGE_PATHS)))
    if live:
        viewer_script = '<script src="main.min.js"></script>'
    else:
        viewer_script = f"<script>\n{_viewer_js()}\n</script>"

    def js(obj) -> str:
        # "</" cannot occur in base64 or in this JSON of plain names and numbers; escape anyway
        return json.dumps(obj, separators=(",\n", ":")).replace("</", "<\\/")

    return _PAGE.format(
        version=__version__,
        title=html_lib.escape(title),
        heading=html_lib.escape(heading),
        legend=legend,
        plots=page.plots,
        viewer_script=viewer_script,
        info=json.dumps(first.info).replace("</", "<\\/"),
        runs=js(runs),
        commands=js([] if live and len(page.scenes) == 1 else _encode(first.commands)),
        more=js(more),
        live="true" if live else "false",
    )


def _static_html(scene: _Scene) -> str:
    """The page of one recorded scene, without plots (kept for callers of the scene API)."""
    return _page_html(_Page([scene], [str(scene.info.get("algorithm") or "run")], ""))


def scene_commands(html: str) -> list[dict]:
    """The meshcat commands embedded in an exported replay page, decoded (for checks and tests)."""
    import umsgpack

    start = html.index("var commands = ") + len("var commands = ")
    end = html.index(";\n", start)
    return [umsgpack.unpackb(base64.b64decode(s)) for s in json.loads(html[start:end])]


def export_html(
    run,
    path: str | Path,
    arm: Arm | None = None,
    speed: float = 1.0,
    fps: float = 50.0,
    *,
    meshes: str = "compact",
    dt: float | None = None,
) -> Path:
    """Write the replay of ``run`` as one self-contained HTML file that plays offline.

    Beside the 3D view, the element ``#ft-plots`` shows λ(t) with its parts, K(t) and the joint
    rates against their velocity limits (SVG), with a cursor at the animation's time; a click on
    a plot seeks the animation there. Several runs (a folder of run folders, a list or a dict of
    runs) share one page: their λ and K are overlaid and a selector switches the arm shown.

    Args:
        run: A :class:`~fault_tolerance.simulation.Run`, a folder it was saved to (or a folder of
            such folders, e.g. ``simulate --out``'s), a list or dict of runs, joint positions of
            shape (K, n) (with ``dt``) or a pair ``(t, q)``.
        path: The HTML file to write (atomically: a reader never sees half a file).
        arm: The arm (default: rebuilt from the run's metadata).
        speed: Replay speed factor (1: real time, 0.5: half speed).
        fps: Animation frames per replay second (the run's samples are interpolated).
        meshes: ``"compact"`` draws mesh files from the triangles Pinocchio loaded (binary,
            single colour, about a quarter of the size); ``"original"`` embeds the mesh files.
        dt: Time step [s] when ``run`` is an array of joint positions.

    Returns:
        The path written.

    Example:
        >>> export_html("out/fig2", "replay.html")  # doctest: +SKIP
    """
    page = _build_page(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
    return write_atomic(path, _page_html(page))


def embed(run, arm: Arm | None = None, height: int = 400, *, speed: float = 1.0, fps: float = 25.0):
    """The replay for a Jupyter notebook: an iframe whose ``srcdoc`` is the self-contained page.

    The page lives in the notebook's output, so it survives saving the notebook and plays without
    a server; its plots sit beside the 3D view as in :func:`export_html`. ``fps`` defaults to 25
    to keep the notebook small (about 1.3 MB for a shipped arm).
    """
    built = _build_page(run, arm, speed=speed, fps=fps)
    page = _page_html(built)
    srcdoc = page.replace("&", "&amp;").replace('"', "&quot;")
    markup = (
        f'<div style="height: {int(height)}px; width: 100%; overflow: hidden; resize: both">'
        f'<iframe srcdoc="{srcdoc}" style="width: 100%; height: 100%; border: none" '
        f'title="{html_lib.escape(_legend(built.scenes[0].info)[0])}"></iframe></div>'
    )
    try:
        from IPython.display import HTML
    except ImportError:  # pragma: no cover - IPython comes with meshcat
        return _HTMLEmbed(markup)
    return HTML(markup)


class _HTMLEmbed:
    """Minimal rich-display object when IPython is not installed."""

    def __init__(self, markup: str) -> None:
        self.data = markup

    def _repr_html_(self) -> str:
        return self.data
