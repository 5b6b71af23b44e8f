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
    from fault_tolerance.experiments import CASES
    from fault_tolerance.simulation import simulate

    arm = ft.load_arm("planar_3r")
    run = simulate(arm, CASES["fig2"].path(0.05), "jvja", q0=np.array([0.3, 1.2, 1.0]))
    folder = tmp_path_factory.mktemp("net") / "run"
    run.save(folder)
    return run, arm, folder


def test_live_replay_server_listens_on_loopback_only(saved_run):
    """viz.serve: the server process listens (web and ZMQ ports) on 127.0.0.1 and nowhere else,
    the URL points there, and closing it leaves no listening socket behind."""
    from fault_tolerance import viz  # imported here: viz is optional (meshcat)

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
    from fault_tolerance import viz

    _, _, folder = saved_run
    seen = []
    out = io.StringIO()

    def wait():  # called while the server runs, instead of sleeping until Ctrl-C
        seen.extend(own_listening())

    assert viz.replay_main(folder, open=True, fps=10, wait=wait, stdout=out) == 0
    assert seen and {ip for ip, _ in seen} == {"127.0.0.1"}, seen
    assert "127.0.0.1" in out.getvalue()
