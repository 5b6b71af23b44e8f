"""The live replay: meshcat's server in a child process, listening on 127.0.0.1 only.

meshcat's own server listens on every interface for its web port; :func:`_serve_local` (the body
of the child process) binds it, and its ZMQ port, to :data:`LOCALHOST`. It also answers only
requests addressed to the loopback by name (``Host`` of 127.0.0.1, ``localhost`` or ``[::1]``,
:func:`loopback_host`) and websockets opened from a loopback page (``Origin``,
:func:`loopback_origin`): a web page elsewhere cannot reach the viewer by *DNS rebinding* (its
own name resolving to 127.0.0.1), which a bind address alone does not stop. Anything else gets
HTTP 403. :class:`ReplayServer` starts that process, sends it a recorded scene over ZMQ and stops
it; :func:`serve` does all three for a run.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from fault_tolerance.errors import FaultToleranceError, InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.viz.page import _build_page, _Page, _page_html
from fault_tolerance.viz.scene import _require_meshcat, _Scene

#: The only interface the live server listens on.
LOCALHOST = "127.0.0.1"
#: Host names a request to the live server may carry (``Host`` and websocket ``Origin``).
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")


def loopback_host(host: str | None) -> bool:
    """Whether an HTTP ``Host`` header names the loopback (``127.0.0.1[:port]``, ``localhost``, ``[::1]``).

    Example:
        >>> loopback_host("127.0.0.1:7000"), loopback_host("evil.example:7000")
        (True, False)
    """
    if not host:
        return False
    name = host.strip().lower()
    if name.startswith("["):  # [::1]:port
        name = name[1 : name.find("]")] if "]" in name else ""
    elif name.count(":") == 1:
        name, _, port = name.partition(":")
        if not port.isdigit():
            return False
    return name in LOOPBACK_NAMES


def loopback_origin(origin: str | None) -> bool:
    """Whether a websocket ``Origin`` is a page served from the loopback (``http://127.0.0.1:PORT``).

    A missing ``Origin`` (a non-browser client on this machine) is accepted; ``null`` (a local file
    or sandboxed frame) and any other host are refused.
    """
    if origin is None:
        return True
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(origin.strip())
        hostname, _ = parts.hostname, parts.port  # .port raises on a malformed port
    except ValueError:
        return False
    return parts.scheme in ("http", "https") and hostname in LOOPBACK_NAMES


def _serve_local(  # pragma: no cover - runs in the child process
    port: int | None = None, page: str | None = None
) -> None:
    """Run meshcat's server with every socket on 127.0.0.1 (the body of the server process).

    meshcat's ``ZMQWebSocketBridge`` binds ZMQ to its ``host`` but starts its web server with
    ``app.listen(port)``, which listens on every interface; here ``listen`` gets the address.
    With ``page`` (a file), ``/static/`` serves that page (the replay with its plots, connected to
    the websocket) instead of meshcat's bare viewer; the viewer's other files are served as before.
    """
    import tornado.ioloop
    import tornado.web
    from meshcat.servers import zmqserver

    def refuse_foreign(handler) -> None:
        if not loopback_host(handler.request.headers.get("Host")):
            raise tornado.web.HTTPError(403, "Host must be 127.0.0.1 or localhost")
        if not loopback_origin(handler.request.headers.get("Origin")):
            raise tornado.web.HTTPError(403, "cross-origin requests are refused")

    class LocalStatic(zmqserver.StaticFileHandlerNoCache):
        def prepare(self):
            refuse_foreign(self)

    class PageHandler(tornado.web.RequestHandler):
        def prepare(self):
            refuse_foreign(self)

        def get(self):
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.write(Path(page).read_bytes())

    class LocalSocket(zmqserver.WebSocketHandler):
        def prepare(self):
            refuse_foreign(self)

        def check_origin(self, origin):
            return loopback_origin(origin)

    class LocalBridge(zmqserver.ZMQWebSocketBridge):
        def make_app(self):
            pages = [] if page is None else [(r"/static/(?:index\.html)?", PageHandler)]
            app = tornado.web.Application(
                pages
                + [
                    (
                        r"/static/(.*)",
                        LocalStatic,
                        {"path": zmqserver.VIEWER_ROOT, "default_filename": zmqserver.VIEWER_HTML},
                    ),
                    (r"/", LocalSocket, {"bridge": self}),
                ]
            )
            listen = app.listen

            def listen_local(port, address=None, **kwargs):
                return listen(port, address=LOCALHOST, **kwargs)

            app.listen = listen_local
            return app

    bridge = LocalBridge(host=LOCALHOST, port=port)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    parent = os.getppid()

    def orphaned():
        if os.getppid() != parent:  # the replaying process died: do not linger
            bridge.ioloop.stop()

    tornado.ioloop.PeriodicCallback(orphaned, 1000).start()
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


class ReplayServer:
    """A meshcat server in a child process, bound to 127.0.0.1; ``close()`` stops it.

    Attributes:
        url: The viewer's URL (``http://127.0.0.1:PORT/static/``).
        zmq_url: Where scene commands are sent.
        process: The server process.
    """

    def __init__(
        self, process: subprocess.Popen, url: str, zmq_url: str, log: IO, page: Path | None = None
    ) -> None:
        self.process = process
        self._page = page
        self.url = url
        self.zmq_url = zmq_url
        self._log = log
        self._socket: Any = None  # a zmq REQ socket once connected (zmq is imported lazily)
        self.info: dict = {}  # what was served (see export's window.ftReplay)
        atexit.register(self.close)

    @classmethod
    def start(
        cls, port: int | None = None, timeout: float = 30.0, page: str | None = None
    ) -> ReplayServer:
        """Start the server process and wait until it says where it listens.

        ``page``: HTML served at ``/static/`` instead of meshcat's bare viewer (the replay page
        with its plots, see :func:`serve`).
        """
        _require_meshcat()
        if port is not None and not (isinstance(port, int) and 0 < port < 65536):
            raise InvalidInput(f"port must be an integer in 1..65535, got {port!r}")
        page_file = None
        if page is not None:
            fd, name = tempfile.mkstemp(prefix="ft-replay-", suffix=".html")
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(page)
            page_file = Path(name)
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])  # the folder holding fault_tolerance/
        env["PYTHONPATH"] = os.pathsep.join(
            [root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])
        )
        where = None if page_file is None else str(page_file)
        code = (
            "from fault_tolerance.viz.server import _serve_local; "
            f"_serve_local({port!r}, {where!r})"
        )
        log = tempfile.TemporaryFile()
        proc = subprocess.Popen(
            [sys.executable, "-u", "-c", code],
            stdout=subprocess.PIPE,
            stderr=log,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        lines: queue.Queue = queue.Queue()

        def read():
            for raw in proc.stdout:
                lines.put(raw.decode("utf-8", "replace").strip())
            lines.put(None)

        threading.Thread(target=read, daemon=True).start()
        found: dict[str, str] = {}
        deadline = time.monotonic() + timeout
        while len(found) < 2:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                line = None
            if line is None:
                proc.kill()
                proc.wait()
                log.seek(0)
                detail = log.read().decode("utf-8", "replace").strip().splitlines()[-1:] or [
                    "no output"
                ]
                log.close()
                if page_file is not None:
                    page_file.unlink(missing_ok=True)
                where = f"port {port}" if port else "a free port"
                raise FaultToleranceError(
                    f"the meshcat server did not start on {where}: {detail[0]}"
                )
            key, _, value = line.partition("=")
            if key in ("zmq_url", "web_url"):
                found[key] = value
        return cls(proc, found["web_url"], found["zmq_url"], log, page_file)

    def send(self, commands: Sequence[tuple[bytes, bytes, bytes]], timeout: float = 30.0) -> None:
        """Send recorded scene commands (type, path, msgpack) to the server."""
        import zmq

        if self._socket is None:
            sock: Any = zmq.Context.instance().socket(zmq.REQ)
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RCVTIMEO, int(timeout * 1000))
            sock.setsockopt(zmq.SNDTIMEO, int(timeout * 1000))
            sock.connect(self.zmq_url)
            self._socket = sock
        for frames in commands:
            self._socket.send_multipart(list(frames))
            reply = self._socket.recv()
            if reply != b"ok":
                raise FaultToleranceError(f"the meshcat server refused a command: {reply[:200]!r}")

    @property
    def running(self) -> bool:
        """Whether the server process is alive."""
        return self.process.poll() is None

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()
        if not self._log.closed:
            self._log.close()
        if self._page is not None:
            self._page.unlink(missing_ok=True)
        with contextlib.suppress(Exception):
            atexit.unregister(self.close)

    def __enter__(self) -> ReplayServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"ReplayServer({self.url!r}, {'running' if self.running else 'stopped'})"


def serve(
    run,
    arm: Arm | None = None,
    *,
    speed: float = 1.0,
    fps: float = 50.0,
    port: int | None = None,
    meshes: str = "compact",
    dt: float | None = None,
) -> tuple[str, ReplayServer]:
    """Serve the replay of ``run`` live: a meshcat server on 127.0.0.1, scene and animation loaded.

    The page at the URL is the replay page of :func:`~fault_tolerance.viz.page.export_html` (plots
    in ``#ft-plots``, synced with the animation), connected to the server's websocket, so scene
    commands sent later (``server.send``) show too. ``run`` may be several runs (a folder of run
    folders, a list or a dict): the server holds the first; the page switches between them.

    Returns ``(url, server)``; open the URL in a browser (the animation plays when the page
    connects), call ``server.close()`` (or use it as a context manager) to stop the server.
    ``port`` is the web port (default: the first free one from 7000).
    """
    page = _build_page(run, arm, speed=speed, fps=fps, meshes=meshes, dt=dt)
    server = _serve_page(page, port)
    return server.url, server


def _serve_page(page: _Page, port: int | None) -> ReplayServer:
    """Serve the replay page (viewer and plots), live, with its first scene."""
    return _serve(ReplayServer.start(port, page=_page_html(page, live=True)), page.scenes[0])


def _serve_scene(scene: _Scene, port: int | None) -> ReplayServer:
    """Serve one recorded scene with meshcat's bare viewer (no plots)."""
    return _serve(ReplayServer.start(port), scene)


def _serve(server: ReplayServer, scene: _Scene) -> ReplayServer:
    """Send ``scene`` to a started server (closed again if that fails)."""
    try:
        server.send(scene.commands)
    except BaseException:
        server.close()
        raise
    server.info = scene.info
    return server
