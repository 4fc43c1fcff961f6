"""``--scheduler`` pointing at something that is not a Dask scheduler of this toolkit's version is
refused in seconds, with one line naming the address and what is there: nothing listening, a
silent port, a server that speaks another protocol, a Dask scheduler of another version; and the
refusal comes before the study's output folder exists."""
import asyncio
import socket
import subprocess
import sys
import threading
import time

import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.engine.executor import SCHEDULER_PROBE_S, dask_client, probe_scheduler

SHORT_PROBE_S = 1.5


@pytest.fixture(params=["silent", "banner", "http"])
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
            elif request.param == "http":      # answers anything with an HTTP error, closes
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
                conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield request.param, f"tcp://127.0.0.1:{server.getsockname()[1]}"
    stop.set()
    thread.join(2)
    for conn in held:
        conn.close()
    server.close()


@pytest.fixture
def closed_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{probe.getsockname()[1]}"


FOUND = {"silent": "sent nothing", "banner": "another protocol", "http": "another protocol"}


def test_a_port_that_is_not_a_dask_scheduler_is_refused_quickly_saying_what_is_there(
        not_a_scheduler):
    kind, address = not_a_scheduler
    t0 = time.monotonic()
    with pytest.raises(SpecError) as caught:
        with dask_client(scheduler=address):
            pass
    elapsed = time.monotonic() - t0
    message = str(caught.value)
    assert "--scheduler" in message and address in message
    assert FOUND[kind] in message and "\n" not in message
    assert "EiB" not in message and "MemoryError" not in message
    assert elapsed <= SCHEDULER_PROBE_S + 2 <= 10 + 2


def test_nothing_listening_is_named_as_such(closed_port):
    with pytest.raises(SpecError, match="nothing is listening") as caught:
        probe_scheduler(closed_port, SHORT_PROBE_S)
    assert "not a Dask scheduler" not in str(caught.value)


@pytest.mark.parametrize("address", ["127.0.0.1:8786", "tcp://", "tcp://host:port",
                                     "tcp://host:99999", "http://127.0.0.1:8786"])
def test_a_malformed_address_is_refused_before_any_connection(address):
    with pytest.raises(SpecError, match="tcp://HOST:PORT"):
        probe_scheduler(address, SHORT_PROBE_S)


def test_no_scheduler_given_passes():
    assert probe_scheduler(None) is None
    with pytest.raises(SpecError):          # while any address given is probed
        probe_scheduler("tcp://", SHORT_PROBE_S)


@pytest.fixture(scope="module")
def running_scheduler():
    from distributed import Scheduler

    ready, stop = threading.Event(), threading.Event()
    found = {}

    def serve():
        async def main():
            async with Scheduler(host="127.0.0.1", port=0, dashboard=False,
                                 dashboard_address=":0") as scheduler:
                found["address"] = scheduler.address
                ready.set()
                while not stop.is_set():
                    await asyncio.sleep(0.05)
        asyncio.run(main())

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(30)
    yield found["address"]
    stop.set()
    thread.join(10)


def test_a_scheduler_of_this_version_passes_and_of_another_is_named(running_scheduler,
                                                                    monkeypatch):
    probe_scheduler(running_scheduler, SCHEDULER_PROBE_S)
    import distributed

    monkeypatch.setattr(distributed, "__version__", "1999.1.0")
    with pytest.raises(SpecError, match="another version|distributed 20") as caught:
        probe_scheduler(running_scheduler, SCHEDULER_PROBE_S)
    assert "1999.1.0" in str(caught.value)


def test_run_refuses_the_scheduler_before_the_output_folder_exists(closed_port, tmp_path):
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "snn_antenna.cli", "run",
                           "studies/tuning_sweep.toml", "--scheduler", closed_port,
                           "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "nothing is listening" in lines[0], done.stderr
    assert not out.exists()


