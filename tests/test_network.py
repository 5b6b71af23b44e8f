"""Every server the toolkit starts listens on 127.0.0.1 only.

The only server is the live meshcat replay (``viz.serve``, ``viz.replay(open=True)``, the
command ``replay --open``): a meshcat server in a child process. The listening sockets of that
process and of the test process itself are read with psutil.
"""

from __future__ import annotations

import io
from urllib.parse import urlparse

import numpy as np
import pytest
from conftest import default_sigint

psutil = pytest.importorskip("psutil")
pytest.importorskip("meshcat")


def listening(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every TCP socket process ``pid`` listens on (IPv4 and IPv6)."""
    conns = psutil.Process(pid).net_connections(kind="inet")
    return sorted((c.laddr.ip, c.laddr.port) for c in conns if c.status == psutil.CONN_LISTEN)


def own_listening() -> list[tuple[str, int]]:
    """Listening sockets of this process and every child it has."""
    me = psutil.Process()
    return [s for p in [me, *me.children(recursive=True)] for s in listening(p.pid)]


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory):
    """A short planar 3R run, saved (for the command-line path)."""
    import fault_tolerance as ft
    from fault_tolerance.paper.cases import CASES
    from fault_tolerance.simulation.simulate import simulate

    arm = ft.load_arm("planar_3r")
    run = simulate(arm, CASES["fig2"].path(0.05), "jvja", q0=np.array([0.3, 1.2, 1.0]))
    folder = tmp_path_factory.mktemp("net") / "run"
    run.save(folder)
    return run, arm, folder


def test_live_replay_server_listens_on_loopback_only(saved_run):
    """viz.serve: the server process listens (web and ZMQ ports) on 127.0.0.1 and nowhere else,
    the URL points there, and closing it leaves no listening socket behind."""
    from fault_tolerance.viz import server as viz

    run, arm, _ = saved_run
    before = own_listening()
    url, server = viz.serve(run, arm, fps=10)
    try:
        socks = listening(server.process.pid)
        assert socks, "the server listens on nothing"
        assert {ip for ip, _ in socks} == {"127.0.0.1"}, socks
        web = urlparse(url)
        assert web.hostname == "127.0.0.1" and ("127.0.0.1", web.port) in socks
        zmq = urlparse(server.zmq_url)
        assert zmq.hostname == "127.0.0.1" and ("127.0.0.1", zmq.port) in socks
        assert {ip for ip, _ in own_listening()} <= {"127.0.0.1"}
    finally:
        server.close()
    assert own_listening() == before


def test_replay_command_serves_on_loopback_only(saved_run):
    """`fault-tolerance replay RUN --open` (replay_main): while it waits, every socket it listens
    on is on 127.0.0.1, and it says so."""

    _, _, folder = saved_run
    seen = []
    out = io.StringIO()

    def wait():  # called while the server runs, instead of sleeping until Ctrl-C
        seen.extend(own_listening())

    from fault_tolerance.viz import replay_main

    assert replay_main(folder, open=True, fps=10, wait=wait, stdout=out) == 0
    assert seen and {ip for ip, _ in seen} == {"127.0.0.1"}, seen
    assert "127.0.0.1" in out.getvalue()


# -- DNS rebinding: only loopback names in Host and Origin ----------------------------------------


def _http_status(port: int, host: str, path: str = "/static/", headers=None) -> int:
    import http.client

    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest("GET", path, skip_host=True)
        conn.putheader("Host", host)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        conn.endheaders()
        return conn.getresponse().status
    finally:
        conn.close()


def _ws_status(port: int, host: str, origin: str | None) -> int:
    """Status line of a websocket handshake on ``/`` (101: accepted)."""
    import socket

    lines = [
        "GET / HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
        "Sec-WebSocket-Version: 13",
    ] + ([f"Origin: {origin}"] if origin is not None else [])
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        head = sock.recv(4096).decode("latin-1")
    return int(head.split()[1])


def test_live_server_refuses_foreign_host_and_origin(saved_run):
    """HTTP and the websocket answer only a loopback Host (a rebinding page's own name is refused
    with 403) and websockets open only from a loopback Origin."""
    from fault_tolerance.viz import server as viz

    run, arm, _ = saved_run
    url, server = viz.serve(run, arm, fps=10)
    try:
        port = urlparse(url).port
        assert _http_status(port, f"127.0.0.1:{port}") == 200
        assert _http_status(port, f"localhost:{port}") == 200
        assert _http_status(port, f"rebind.example:{port}") == 403
        assert _http_status(port, "127.0.0.1.rebind.example") == 403
        assert _http_status(port, f"127.0.0.1:{port}", headers={"Origin": "http://evil"}) == 403
        loop = f"127.0.0.1:{port}"
        assert _ws_status(port, loop, f"http://{loop}") == 101
        assert _ws_status(port, loop, None) == 101
        assert _ws_status(port, loop, "http://evil.example") == 403
        assert _ws_status(port, loop, "null") == 403
        assert _ws_status(port, f"evil.example:{port}", f"http://evil.example:{port}") == 403
        assert server.running
    finally:
        server.close()


@pytest.mark.parametrize(
    "host, ok",
    [
        ("127.0.0.1", True),
        ("127.0.0.1:7000", True),
        ("LOCALHOST:7001", True),
        ("[::1]:7000", True),
        ("localhost.evil.example", False),
        ("evil.example:7000", False),
        ("127.0.0.1:70x0", False),
        ("", False),
        (None, False),
    ],
)
def test_loopback_host(host, ok):
    """Host names accepted by the live server: the loopback by address or name, with a port."""
    from fault_tolerance.viz.server import loopback_host

    assert loopback_host(host) is ok


def test_ctrl_c_stops_the_live_replay_with_exit_130(saved_run):
    """`fault-tolerance replay RUN --open` stopped by SIGINT: exit 130, one line on stderr, no
    traceback, and the server process is gone."""
    import signal
    import subprocess
    import sys

    _, _, folder = saved_run
    proc = subprocess.Popen(
        [sys.executable, "-m", "fault_tolerance", "replay", str(folder), "--open"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )
    try:
        line = proc.stdout.readline()
        assert "127.0.0.1" in line, line
        children = psutil.Process(proc.pid).children(recursive=True)
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert stderr.count("\n") == 1 and "Traceback" not in stderr and "interrupted" in stderr
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive


@pytest.mark.browser
def test_dns_rebinding_in_chromium(saved_run):
    """A real browser that resolves an outside name to 127.0.0.1 (DNS rebinding, emulated with
    Chromium's host resolver rules) gets 403 for the viewer page, and a page of that name cannot
    open the websocket; the same browser on 127.0.0.1 loads the viewer."""
    from headless import browser_missing, launched

    from fault_tolerance.viz import server as viz

    reason = browser_missing()
    if reason:
        pytest.skip(reason)

    run, arm, _ = saved_run
    url, server = viz.serve(run, arm, fps=10)
    port = urlparse(url).port
    rules = "--host-resolver-rules=MAP rebind.test 127.0.0.1"
    try:
        with launched([rules]) as browser:
            page = browser.new_page()
            assert page.goto(url).status == 200
            foreign = page.goto(f"http://rebind.test:{port}/static/")
            assert foreign.status == 403
            opened = page.evaluate(
                """(port) => new Promise(done => {
                    const ws = new WebSocket(`ws://127.0.0.1:${port}/`);
                    ws.onopen = () => done("open");
                    ws.onerror = () => done("refused");
                    setTimeout(() => done("timeout"), 10000);
                })""",
                port,
            )
            assert opened == "refused"
    finally:
        server.close()
