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
from pathlib import Path

from ..arm import Arm
from ..errors import FaultToleranceError
from ..simulation import write_atomic
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
  body {{ margin: 0; overflow: hidden;
          font-family: system-ui, -apple-system, "Segoe UI", sans-serif; }}
  #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
  #ft-legend {{ position: absolute; left: 12px; bottom: 12px; padding: 8px 12px; border-radius: 6px;
               background: rgba(255, 255, 255, 0.86); color: #1d1f24;
               font-size: 13px; line-height: 1.6;
               box-shadow: 0 1px 4px rgba(0, 0, 0, 0.18); pointer-events: none; }}
  #ft-legend b {{ font-weight: 600; }}
  .ft-swatch {{ display: inline-block; width: 22px; height: 5px; border-radius: 2px;
                vertical-align: middle; margin-right: 7px; }}
  .ft-dot {{ display: inline-block; width: 10px; height: 10px; border-radius: 5px;
             vertical-align: middle; margin: 0 13px 0 6px; }}
  #ft-clock {{ font-variant-numeric: tabular-nums; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="ft-legend">
  <div><b>{heading}</b></div>
  {legend}
  <div id="ft-clock">t = 0.00 s</div>
</div>
<script>
{viewer_js}
</script>
<script>
window.ftReplay = {info};
(function () {{
  var info = window.ftReplay;
  info.ready = false;
  info.errors = [];
  var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
  window.viewer = viewer;
  var commands = {commands};
  for (var i = 0; i < commands.length; i++) {{
    try {{
      var raw = atob(commands[i]);
      var bytes = new Uint8Array(raw.length);
      for (var j = 0; j < raw.length; j++) bytes[j] = raw.charCodeAt(j);
      viewer.handle_command_bytearray(bytes);
    }} catch (err) {{
      info.errors.push(String(err));
    }}
  }}
  // Show the animation controls (play, pause, time) and fold the long scene tree.
  try {{
    var folders = viewer.gui.__folders;
    if (folders["Scene"]) folders["Scene"].close();
    if (folders["Save / Load / Capture"]) folders["Save / Load / Capture"].close();
    viewer.gui.open();
  }} catch (err) {{
    info.errors.push(String(err));
  }}
  var clock = document.getElementById("ft-clock");
  function tick() {{
    var tau = viewer.animator ? viewer.animator.time : 0;
    var t = info.run_start + tau * info.speed;
    var text = "t = " + t.toFixed(2) + " s";
    if (info.speed !== 1) text += "  (replay \u00d7" + info.speed + ")";
    if (info.lock && t >= info.lock.time) text += "  \u2014 " + info.lock.joint + " locked";
    if (clock.textContent !== text) clock.textContent = text;
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


def _static_html(scene: _Scene) -> str:
    from .. import __version__

    title, heading, legend = _legend(scene.info)
    payload = [base64.b64encode(data).decode("ascii") for _, _, data in scene.commands]
    # "</" cannot occur in base64 or in this JSON of plain names and numbers, but escape anyway.
    info_json = json.dumps(scene.info).replace("</", "<\\/")
    return _PAGE.format(
        version=__version__,
        title=html_lib.escape(title),
        heading=html_lib.escape(heading),
        legend=legend,
        viewer_js=_viewer_js(),
        info=info_json,
        commands=json.dumps(payload, separators=(",", "\n")),
    )


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

    Args:
        run: A :class:`~fault_tolerance.simulation.Run`, a folder it was saved to, joint
            positions of shape (K, n) (with ``dt``) or a pair ``(t, q)``.
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
        >>> export_html("out/run", "replay.html")  # doctest: +SKIP
    """
    scene = _build_scene(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
    return write_atomic(path, _static_html(scene))


def embed(run, arm: Arm | None = None, height: int = 400, *, speed: float = 1.0, fps: float = 25.0):
    """The replay for a Jupyter notebook: an iframe whose ``srcdoc`` is the self-contained page.

    The page lives in the notebook's output, so it survives saving the notebook and plays without
    a server. ``fps`` defaults to 25 to keep the notebook small (about 1.3 MB for a shipped arm).
    """
    scene = _build_scene(run, arm, speed=speed, fps=fps)
    page = _static_html(scene)
    srcdoc = page.replace("&", "&amp;").replace('"', "&quot;")
    markup = (
        f'<div style="height: {int(height)}px; width: 100%; overflow: hidden; resize: both">'
        f'<iframe srcdoc="{srcdoc}" style="width: 100%; height: 100%; border: none" '
        f'title="{html_lib.escape(_legend(scene.info)[0])}"></iframe></div>'
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
