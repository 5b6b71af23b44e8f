"""The HTML of a replay page, as a ``str.format`` template (braces of CSS and JS doubled).

Fields: ``version``, ``title``, ``heading``, ``legend`` (rows of the 3D view's legend), ``plots``
(the content of ``#ft-plots``), ``viewer_script`` (meshcat's viewer, inlined or from the live
server), ``info`` (``window.ftReplay``), ``runs`` (one info per run), ``commands`` (base64 meshcat
commands of the first run), ``more`` (per run: the commands that switch the 3D view to it) and
``live`` (``true``: the first run comes over the live server's websocket).

The script keeps the plots' cursor at the animation's time (every frame), seeks the animation
where a plot is clicked (``ftReplay.seekTime(t)``), and switches the run shown
(``ftReplay.select(k)``, the ``#ft-run`` selector) keeping the time and the camera.
"""

PAGE = """<!DOCTYPE html>
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
