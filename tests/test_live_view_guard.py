"""The live view checks Host and Origin on every HTTP and websocket request (DNS rebinding),
prints the address it is bound to, and listens beyond loopback only when told an address."""
import argparse
import base64
import os
import socket

import pytest

from snn_antenna.bridge.online.pipeline import build_online
from snn_antenna.bridge.view.view import LiveView, live_view
from snn_antenna.core.errors import SpecError

NETWORK = "networks/live.toml"


def status(host, port, path="/", headers=()):
    with socket.create_connection((host, port), timeout=10) as conn:
        lines = [f"GET {path} HTTP/1.1", *headers]
        conn.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return int(conn.recv(200).split(b" ", 2)[1])


def websocket_upgrade(host_header, origin):
    key = base64.b64encode(os.urandom(16)).decode()
    return (f"Host: {host_header}", "Upgrade: websocket", "Connection: Upgrade",
            f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13", f"Origin: {origin}")


@pytest.fixture(scope="module")
def view():
    view = LiveView(build_online(NETWORK), host="127.0.0.1", port=0)
    view.start()
    yield view
    view.stop()


def test_the_url_printed_is_the_address_bound(view):
    assert view.url == f"http://127.0.0.1:{view.port}/"


@pytest.mark.parametrize("path", ["/", "/state.json"])
def test_a_foreign_host_is_refused_on_every_path(view, path):
    port = view.port
    assert status("127.0.0.1", port, path, [f"Host: 127.0.0.1:{port}"]) == 200
    assert status("127.0.0.1", port, path, [f"Host: localhost:{port}"]) == 200
    assert status("127.0.0.1", port, path, [f"Host: attacker.example:{port}"]) == 403
    assert status("127.0.0.1", port, path, []) == 403
    assert status("127.0.0.1", port, path, [f"Host: 127.0.0.1:{port}",
                                             "Origin: http://attacker.example"]) == 403


@pytest.mark.parametrize("path", ["/ws", "/feed?page=0"])
def test_a_websocket_from_a_foreign_origin_or_host_is_refused(view, path):
    port = view.port
    assert status("127.0.0.1", port, path, websocket_upgrade(
        f"127.0.0.1:{port}", f"http://attacker.example:{port}")) == 403
    assert status("127.0.0.1", port, path, websocket_upgrade(
        f"rebound.example:{port}", f"http://rebound.example:{port}")) == 403
    assert status("127.0.0.1", port, path, websocket_upgrade(
        f"127.0.0.1:{port}", f"http://127.0.0.1:{port}")) == 101


def test_a_page_socket_for_no_page_of_this_view_is_closed_saying_so(view):
    """``/feed`` with a token no page of this view was built with: closed (4404), nothing
    sent."""
    from tornado.ioloop import IOLoop
    from tornado.websocket import websocket_connect

    async def first_message():
        socket = await websocket_connect(f"ws://127.0.0.1:{view.port}/feed?page=nope")
        message = await socket.read_message()
        return message, socket.close_code, socket.close_reason

    assert IOLoop().run_sync(first_message, timeout=30) == (None, 4404,
                                                            "no such page: reload it")


def view_args(host):
    return argparse.Namespace(view=True, view_host=host, view_port=0, view_hold=0)


def test_binding_every_interface_needs_an_explicit_address():
    with pytest.raises(SpecError, match="view-host"):
        with live_view(view_args(""), build_online(NETWORK)):
            pass


def test_listening_beyond_loopback_warns_and_prints_the_bound_address(capsys):
    with live_view(view_args("127.0.0.2"), build_online(NETWORK)) as view:
        assert view.url == f"http://127.0.0.2:{view.port}/"
        assert status("127.0.0.2", view.port, "/state.json",
                      [f"Host: 127.0.0.2:{view.port}"]) == 200
    err = capsys.readouterr().err
    assert f"live view: http://127.0.0.2:{view.port}/" in err and "warning" in err


def test_a_drain_of_runs_too_short_to_plot_loses_nothing():
    """Port reads of one or two samples between two shown points (every 4th sample is plotted)
    used to raise in the server's drain (SpecError from to_g on no rows, a Tornado traceback)
    after the items had been taken from the inbox: they were lost uncounted."""
    from snn_antenna.bridge.wire.protocol import Sample
    from snn_antenna.bridge.wire.source import Batch
    from snn_antenna.bridge.view.history import ViewHistory

    view = LiveView(build_online(NETWORK), port=0)        # no view process: drain by hand
    history = ViewHistory(view.config)
    for batch in ([Sample(0, 500, 500)], [Sample(1, 500, 500), Sample(2, 500, 500)],
                  [Sample(3, 500, 500), Sample(4, 510, 500)]):
        view.handle(Batch(0.0, samples=batch))
        view.flush()                                     # indices 1, 2: nothing to plot
        history.drain(view._inbox, wait_s=5)
    assert history.received == 3 and history.dropped == 0
    assert history.xy.total == 2 and history.xy.rows[-1, 0] == 4 / 1000
