"""``--scheduler`` pointing at something that is not a Dask scheduler is refused in seconds,
with one line naming the address (a silent port, and a server that speaks first)."""
import socket
import threading
import time

import pytest

from snn_antenna.engine.executor import SCHEDULER_PROBE_S, dask_client
from snn_antenna.core.errors import SpecError


@pytest.fixture(params=["silent", "banner"])
def not_a_scheduler(request):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    stop = threading.Event()
    held = []

    def serve():
        server.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            held.append(conn)
            if request.param == "banner":      # like sshd: it speaks first, then waits
                conn.sendall(b"SSH-2.0-OpenSSH_9.6p1 Ubuntu-3ubuntu13\r\n")

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    stop.set()
    thread.join(2)
    for conn in held:
        conn.close()
    server.close()


def test_a_port_that_is_not_a_dask_scheduler_is_refused_quickly(not_a_scheduler):
    t0 = time.monotonic()
    with pytest.raises(SpecError) as caught:
        with dask_client(scheduler=not_a_scheduler):
            pass
    elapsed = time.monotonic() - t0
    message = str(caught.value)
    assert "--scheduler" in message and not_a_scheduler in message
    assert "Dask scheduler" in message and "\n" not in message
    assert elapsed <= SCHEDULER_PROBE_S + 2 <= 10 + 2
