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

from fault_tolerance.errors import FaultToleranceError
from fault_tolerance.model.arm import Arm
from fault_tolerance.storage.atomic import write_atomic
from fault_tolerance.viz.charts import chart_data, plots_html, run_strokes
from fault_tolerance.viz.collect import collect_runs
from fault_tolerance.viz.geometry import LOCK_COLOR, PATH_COLOR, TRACE_COLOR
from fault_tolerance.viz.scene import _build_scene, _require_meshcat, _Scene
from fault_tolerance.viz.template import PAGE as _PAGE


def _viewer_js() -> str:
    meshcat = _require_meshcat()
    path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    text = path.read_text(encoding="utf-8")
    if "</script" in text.lower():  # pragma: no cover - would end the inline script early
        raise FaultToleranceError(f"{path} contains '</script'; it cannot be inlined")
    return text


#: What :func:`script_json` escapes: the characters that could end or reopen markup inside an
#: inline ``<script>`` (``</script``, ``<!--``, ``]]>``), and the line separators JavaScript
#: once treated as line ends.
_SCRIPT_ESCAPES = {
    "<": "\\u003c",
    ">": "\\u003e",
    "&": "\\u0026",
    "\u2028": "\\u2028",
    "\u2029": "\\u2029",
}


def script_json(obj, **kwargs) -> str:
    r"""``obj`` as JSON that is inert inside an HTML ``<script>`` (names are data, never markup).

    ``<``, ``>``, ``&``, U+2028 and U+2029 become ``\u003c``-style escapes, which JSON and
    JavaScript read back as the same characters: a joint named ``<!--<script>`` stays a name.
    """
    text = json.dumps(obj, **kwargs)
    for ch, esc in _SCRIPT_ESCAPES.items():
        text = text.replace(ch, esc)
    return text


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
    from fault_tolerance.simulation.diagnostics import check_run
    from fault_tolerance.simulation.run import Run

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
    package_dirs=(),
) -> _Page:
    """Scenes and plots of ``run`` (one run, or the runs of a folder / list / dict)."""
    items = collect_runs(run)
    scenes, charts, warnings = [], [], []
    for _, item in items:
        scenes.append(
            _build_scene(
                item, arm, speed=speed, fps=fps, meshes=meshes, dt=dt, package_dirs=package_dirs
            )
        )
    strokes = run_strokes([scene.info.get("algorithm") for scene in scenes])
    for (label, item), scene, (color, dash) in zip(items, scenes, strokes, strict=True):
        data = item if hasattr(item, "jvj") else (scene.motion.t, scene.motion.q)
        chart = chart_data(data, label, color, scene.arm.velocity_limit, scene.arm.joint_names)
        chart.dash, chart.method = dash, str(scene.info.get("algorithm") or "")
        charts.append(chart)
        warnings.append(_warnings_of(item, scene.arm))
    plots = _comparison_html(items) + plots_html(charts, warnings)
    return _Page(scenes, [c.label for c in charts], plots)


def _comparison_html(items) -> str:
    """With two runs or more: which start each used and the λ winners (:mod:`.compare`), as HTML.

    Empty for one run or for bare joint positions (no λ to compare).
    """
    from fault_tolerance.simulation.compare import compare_runs
    from fault_tolerance.simulation.run import Run

    runs = {label: item for label, item in items if isinstance(item, Run)}
    if len(runs) < 2:
        return ""
    lines = compare_runs(runs).lines()
    body = "".join(f"<li>{html_lib.escape(line.strip())}</li>" for line in lines)
    return f'<ul id="ft-comparison" class="ft-comparison">{body}</ul>'


#: Scene commands a page keeps when it switches the run shown (the camera stays where it is).
_STAGE_PATHS = (b"/Cameras", b"/Background", b"/Axes")


def _encode(commands) -> list[str]:
    return [base64.b64encode(data).decode("ascii") for _, _, data in commands]


def _page_html(page: _Page, *, live: bool = False) -> str:
    """The page's HTML; ``live``: scene 0 comes from the meshcat server's websocket."""
    from fault_tolerance.version import __version__

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
        return script_json(obj, separators=(",\n", ":"))

    return _PAGE.format(
        version=__version__,
        title=html_lib.escape(title),
        heading=html_lib.escape(heading),
        legend=legend,
        plots=page.plots,
        viewer_script=viewer_script,
        info=script_json(first.info),
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
        run: A :class:`~fault_tolerance.simulation.run.Run`, a folder it was saved to (or a folder of
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
