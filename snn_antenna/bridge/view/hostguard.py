"""The live view's guard against DNS rebinding: every HTTP and websocket request must name this
machine (Host) and come from its own page (Origin, when a browser sends one).

A page on any site can make a browser resolve its own name to 127.0.0.1 and then read a local
server as if it were that site; the Host header (and the websocket's Origin) still carry the
foreign name, which is what is checked here, before Bokeh or ``/state.json`` see the request.
"""
from __future__ import annotations

import socket
from urllib.parse import urlsplit

from tornado import httputil

# The addresses that reach only this machine: binding elsewhere needs an explicit address.
LOOPBACK = ("127.0.0.1", "localhost", "::1")


def allowed_hosts(host: str, port: int) -> set[str]:
    """The Host (and Origin) names a request may carry: this machine's loopback names, and when
    the view is exposed deliberately, the address it listens on and this machine's names.
    Anything else is a page on another site reaching in by DNS rebinding."""
    names = {"localhost", "127.0.0.1", "[::1]"}
    if host not in LOOPBACK:
        names.add(f"[{host}]" if ":" in host else host)
        names.add(socket.gethostname())
        names.add(socket.getfqdn())
        if host in ("0.0.0.0", "::"):
            try:
                names.update(socket.gethostbyname_ex(socket.gethostname())[2])
            except OSError:
                pass
    return {f"{name}:{port}" for name in names}


class HostGuard(httputil.HTTPServerConnectionDelegate):
    """Checks Host and Origin on every request (page, websocket, state.json) before the
    application sees it; refuses with 403 otherwise."""

    def __init__(self, app, allowed: set[str]):
        self.app, self.allowed = app, allowed

    def start_request(self, server_conn, request_conn):
        return GuardedRequest(self.app.start_request(server_conn, request_conn),
                              request_conn, self.allowed)

    def on_close(self, server_conn):
        self.app.on_close(server_conn)


class GuardedRequest(httputil.HTTPMessageDelegate):
    def __init__(self, inner, connection, allowed):
        self.inner, self.connection, self.allowed = inner, connection, allowed
        self.refused = False

    def headers_received(self, start_line, headers):
        host = headers.get("Host", "")
        origin = headers.get("Origin")
        origin_ok = origin is None or urlsplit(origin).netloc in self.allowed
        if host in self.allowed and origin_ok:
            return self.inner.headers_received(start_line, headers)
        self.refused = True
        body = b"forbidden: unknown Host or Origin\n"
        self.connection.write_headers(
            httputil.ResponseStartLine("HTTP/1.1", 403, "Forbidden"),
            httputil.HTTPHeaders({"Content-Type": "text/plain",
                                  "Content-Length": str(len(body)),
                                  "Connection": "close"}), body)
        self.connection.finish()
        return None

    def data_received(self, chunk):
        if not self.refused:
            return self.inner.data_received(chunk)

    def finish(self):
        if not self.refused:
            self.inner.finish()

    def on_connection_close(self):
        if not self.refused:
            self.inner.on_connection_close()
