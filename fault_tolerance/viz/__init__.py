"""Replay of runs in the browser with meshcat: live, or as one self-contained HTML file.

A run is replayed as a meshcat **animation** (the viewer's *Animations* controls play, pause and
scrub it), recorded frame by frame from the run's joint positions with Pinocchio's
``MeshcatVisualizer``: real time by default, ``speed`` times faster otherwise, ``fps`` frames per
second of replay (a 1 kHz run is decimated; meshcat interpolates between frames). The scene adds

* the desired path (dark line) and the tool's actual trace (teal line), as thin tubes so they keep
  their width on every screen;
* a small dark ball that moves along the desired path, so the path error after a lock shows;
* for a lock run, the link driven by the locked joint turns magenta from the lock time on, and a
  magenta ball marks the lock moment on the path.

Two outputs:

* :func:`export_html` writes one HTML file that plays offline: meshcat's viewer (three.js
  included) and the scene's commands are inlined; nothing is fetched from a network or a server.
* :func:`serve` starts meshcat's server in a child process, bound to ``127.0.0.1`` only (meshcat's
  own server listens on every interface for its web port; ours does not), sends it the scene and
  returns the URL and a handle whose ``close()`` stops the server.

meshcat is imported lazily, so neither ``import fault_tolerance`` nor ``import fault_tolerance.viz``
imports it.

In the page, ``window.viewer`` is meshcat's viewer; ``viewer.animator`` holds the animation
(``play()``, ``pause()``, ``seek(t)``, ``time_scrubber``, ``duration``, with ``t`` in replay
seconds). The exported page also sets ``window.ftReplay`` (robot, speed, lock time, ready flag).

The package: ``motion.py`` loads and checks what is replayed; ``geometry.py`` holds the colours,
tubes, stand-in links and camera; ``scene.py`` records the scene as meshcat commands; ``page.py``
writes the static page; ``server.py`` runs the live server. This module holds :func:`replay` and
the CLI's ``replay`` command.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any, NamedTuple

from fault_tolerance.errors import FaultToleranceError, InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.storage.atomic import write_atomic
from fault_tolerance.viz.collect import describe_runs, run_folders
from fault_tolerance.viz.page import _build_page, _page_html
from fault_tolerance.viz.server import ReplayServer, _serve_page


class Replay(NamedTuple):
    """What :func:`replay` made: the HTML file written and/or the live URL and its server."""

    html: Path | None
    url: str | None
    server: ReplayServer | None


def replay(
    run,
    arm: Arm | None = None,
    *,
    speed: float = 1.0,
    fps: float = 50.0,
    open: bool = False,  # noqa: A002 - the CLI's flag
    html: str | Path | None = None,
    port: int | None = None,
    meshes: str = "compact",
    dt: float | None = None,
    package_dirs: Sequence[str | Path] = (),
) -> Replay:
    """Replay ``run`` in the browser: a self-contained HTML file, a live viewer, or both.

    Args:
        run: A Run, the folder it was saved to, a folder of run folders (one command's runs,
            shown together), a list or dict of runs, an array q (K, n) with ``dt``, or ``(t, q)``.
        arm: The arm (default: rebuilt from each run's carried URDF text, meshes only from
            ``package_dirs`` and installed robot data; :mod:`~fault_tolerance.model.arm_record`).
        speed: Replay speed factor (1: real time).
        fps: Animation frames per replay second.
        open: Start a live meshcat server on 127.0.0.1 (stop it with ``result.server.close()``).
        html: Write the replay to this HTML file.
        port: Web port of the live server (default: the first free one from 7000).
        meshes: ``"compact"`` or ``"original"`` (see :func:`export_html`).
        dt: Time step [s] when ``run`` is an array of joint positions.
        package_dirs: Folders where ``package://`` meshes of the run's arm may be read.
    """
    if not open and html is None:
        raise InvalidInput("choose where to replay: open=True (live viewer) and/or html=FILE")
    page = _build_page(
        run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt, package_dirs=package_dirs
    )
    path = write_atomic(html, _page_html(page)) if html is not None else None
    server = _serve_page(page, port) if open else None
    return Replay(path, server.url if server else None, server)


def _wait_for_interrupt() -> None:  # pragma: no cover - blocks
    while True:
        time.sleep(3600)


def replay_main(
    run_dir: str | Path,
    open: bool = False,  # noqa: A002 - the CLI's flag
    html: str | None = None,
    speed: float = 1.0,
    *,
    fps: float = 50.0,
    port: int | None = None,
    package_dirs: Sequence[str | Path] = (),
    wait: Callable[[], Any] | None = None,
    stdout: IO[str] | None = None,
    stderr: IO[str] | None = None,
) -> int:
    """``fault-tolerance replay RUN [--open | --html FILE] [--speed S]``; returns the exit code.

    ``RUN`` is a run folder, or a folder of run folders (e.g. ``simulate --out``'s): those are
    shown together in one page (λ and K overlaid, a selector for the arm shown); without
    ``--open`` or ``--html`` such a folder's runs are listed. With ``open`` it prints the URL and
    calls ``wait()`` (default: sleep until Ctrl-C), then stops the server. Exit codes: 0 done,
    2 bad input (one line on stderr), 130 stopped by Ctrl-C (the server is stopped first),
    1 anything else.
    """
    out = stdout or sys.stdout
    err = stderr or sys.stderr
    if not open and not html:
        try:
            folders = run_folders(run_dir)
        except FaultToleranceError:
            folders = []
        if len(folders) > 1:
            print(f"{run_dir} holds {len(folders)} runs:", file=out)
            for line in describe_runs(run_dir):
                print(f"  {line}", file=out)
            print(
                f"replay them together with --html FILE or --open, or one of them, e.g. "
                f"fault-tolerance replay {folders[0]} --html replay.html",
                file=out,
            )
            return 0
        print("replay: choose --open (live viewer) or --html FILE (self-contained page)", file=err)
        return 2
    try:
        result = replay(
            run_dir,
            speed=speed,
            fps=fps,
            open=open,
            html=html,
            port=port,
            package_dirs=package_dirs,
        )
    except FaultToleranceError as e:
        print(f"replay: {e}", file=err)
        return 2
    except ImportError as e:
        print(f"replay: {e}", file=err)
        return 1
    if result.html is not None:
        print(
            f"wrote {result.html} ({result.html.stat().st_size / 1e6:.1f} MB); "
            "open it in a browser",
            file=out,
        )
    if result.server is None:
        return 0
    print(
        f"meshcat replay at {result.url} (listening on 127.0.0.1 only); Ctrl-C stops it", file=out
    )
    out.flush()
    try:
        (wait or _wait_for_interrupt)()
    except KeyboardInterrupt:
        print("replay: interrupted; the server is stopped", file=err)
        return 130
    finally:
        result.server.close()
    return 0


__all__ = [
    "Replay",
    "replay",
    "replay_main",
]
