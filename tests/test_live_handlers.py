"""Every handler of the live stream implements one declared protocol (bridge/wire/handler.py:
``BatchHandler`` for the source loop, ``WindowHandler`` for the online pipeline), with no-op
defaults it overrides with the same signatures; anything else is refused. ``run_online`` hands
each handler the stream's start, every coded piece, every window of the network, every change
the input schedule applied and the end; a window goes down the layers once (the network calls
out only through its stream port); and the input schedule is the one writer of the live
inputs."""
import ast
import inspect
import io
import sys
import typing
from pathlib import Path

import numpy as np
import pytest

from snn_antenna.bridge.cli import Progress
from snn_antenna.bridge.online.controls import RecordedChanges
from snn_antenna.bridge.online.live_state import Decisions
from snn_antenna.bridge.online.pipeline import LiveStream, build_online, run_online
from snn_antenna.bridge.online.report import OnlineReport
from snn_antenna.bridge.online.robot import LiveRobot
from snn_antenna.bridge.online.schedule import InputSchedule
from snn_antenna.bridge.online.terminal import LiveDisplay
from snn_antenna.bridge.view.view import LiveView
from snn_antenna.bridge.wire.handler import BatchHandler, Published, Window, WindowHandler
from snn_antenna.bridge.wire.protocol import BOARD_RATE_HZ
from snn_antenna.bridge.wire.recorder import Recorder, record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.bridge.wire.source import SourceLoop
from snn_antenna.core.errors import SpecError
from snn_antenna.sources.stimuli import Contact, RobotScene
from test_live_view_panels import NETWORK

PACKAGE = Path(__file__).resolve().parents[1] / "snn_antenna"
HANDLERS = [OnlineReport, LiveRobot, RecordedChanges, LiveView, Decisions, LiveDisplay, Recorder]
METHODS = [name for name, value in vars(WindowHandler).items()
           if inspect.isfunction(value) and not name.startswith("_")]


def parameters(function) -> list[tuple[str, object]]:
    return [(p.name, p.kind) for p in inspect.signature(function).parameters.values()]


def test_the_protocols_declare_batches_then_start_pieces_windows_changes_and_end():
    assert [n for n in vars(BatchHandler) if not n.startswith("_")] == ["handle", "idle"]
    assert METHODS == ["stream_started", "coded", "window", "changed", "stream_ended"]
    assert issubclass(WindowHandler, BatchHandler)
    assert typing.get_type_hints(WindowHandler.window)["window"] is Window
    assert typing.get_type_hints(Window)["published"] == Published | None
    # No-op defaults, as pyserial's serial.threaded.Protocol: a handler overrides what it uses.
    handler = WindowHandler()
    assert handler.handle(None) is None and handler.idle() is None
    assert handler.stream_started(None, None) is None and handler.window(None) is None
    assert handler.coded(None, 0.0, None) is None and handler.changed({}) is None


@pytest.mark.parametrize("handler", HANDLERS, ids=lambda cls: cls.__name__)
def test_each_handler_is_a_window_handler_with_the_protocols_signatures(handler):
    assert issubclass(handler, WindowHandler)
    for name in ["handle", "idle", *METHODS]:
        assert parameters(getattr(handler, name)) == parameters(getattr(WindowHandler, name)), \
            f"{handler.__name__}.{name}{inspect.signature(getattr(handler, name))} is not " \
            f"WindowHandler.{name}{inspect.signature(getattr(WindowHandler, name))}"


class DuckHandler:
    """Every method of the protocol, but not declared a WindowHandler."""

    def handle(self, batch): pass

    def idle(self): pass

    def stream_started(self, parts, schedule): pass

    def coded(self, signal_g, th_g, coded): pass

    def window(self, window): pass

    def changed(self, event): pass

    def stream_ended(self, final_event): pass


def test_a_handler_that_is_not_declared_one_is_refused(tmp_path):
    rec = record_counts(tmp_path / "rec", np.full((10, 2), 512))
    parts = build_online(NETWORK)
    for stranger in (DuckHandler(), print, object()):
        with pytest.raises(SpecError, match=r"handlers = '\w+' .*WindowHandler"):
            run_online(ReplaySource(rec).start(), parts, [stranger])
        with pytest.raises(SpecError, match=r"handlers = '\w+' .*BatchHandler"):
            SourceLoop(ReplaySource(rec).start(), [stranger])
    assert isinstance(Progress(io.StringIO()), BatchHandler)


class Spy(WindowHandler):
    """Notes everything the pipeline handed it."""

    def __init__(self):
        self.seen: list = []

    def stream_started(self, parts, schedule) -> None:
        self.seen.append(("started", schedule))

    def coded(self, signal_g, th_g, coded) -> None:
        self.seen.append(("coded", len(coded)))

    def window(self, window: Window) -> None:
        self.seen.append(("window", window))

    def changed(self, event: dict) -> None:
        self.seen.append(("changed", event))

    def stream_ended(self, final_event) -> None:
        self.seen.append(("ended", final_event))


def test_the_pipeline_hands_every_handler_the_start_pieces_windows_changes_and_end(tmp_path):
    counts = RobotScene(duration_s=2.0, contacts=[Contact(1.2, 19.0)]).generate(
        seed=3).samples
    rec = record_counts(tmp_path / "rec", counts)
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    spy, out = Spy(), io.StringIO()
    changes = [{"sample": 1500, "field": "th_g", "value": 0.06}]
    report = run_online(ReplaySource(rec).start(), parts,
                        [RecordedChanges(parts, changes), spy, LiveDisplay(out)],
                        no_data_timeout_s=1e9)
    kinds = [kind for kind, _ in spy.seen]
    assert kinds[0] == "started" and kinds[-1] == "ended"
    assert isinstance(spy.seen[0][1], InputSchedule)
    assert kinds.count("window") == report["windows"]
    assert sum(n for kind, n in spy.seen if kind == "coded") == report["samples"] == 2000
    (event,) = [e for kind, e in spy.seen if kind == "changed"]
    assert (event["sample"], event["value"], event["by"]) == (1500, 0.06, "replay")
    assert report["controls"] == [event]
    windows = [w for kind, w in spy.seen if kind == "window"]
    assert [w.end_index for w in windows] == [round((i + 1) * parts.window_s * BOARD_RATE_HZ)
                                              for i in range(report["windows"])]
    assert all(w.published is not None for w in windows)       # one network window each
    # The report took each window first: the factor the others saw counts it.
    assert np.isfinite(windows[-1].published.realtime_factor)
    # The terminal saw the same windows: its header, then its lines and the contact.
    assert out.getvalue().startswith("rate map: 24 resonators")
    assert "contact" in out.getvalue()


def test_a_window_goes_down_the_layers_once(tmp_path):
    """Traced call by call during a replay: code below bridge/ (the network, the chain, the
    read-out) calls bridge code only through the stream's port, its two methods."""
    counts = RobotScene(duration_s=1.5, contacts=[Contact(1.2, 19.0)]).generate(
        seed=3).samples
    rec = record_counts(tmp_path / "rec", counts)
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    view = LiveView(parts)                  # never started: it gathers only
    climbs: dict = {}

    def trace(frame, event, arg):
        if event != "call" or frame.f_back is None:
            return
        callee = frame.f_globals.get("__name__", "")
        caller = frame.f_back.f_globals.get("__name__", "")
        if callee.startswith("snn_antenna.bridge") and caller.startswith("snn_antenna") \
                and not caller.startswith("snn_antenna.bridge"):
            key = f"{callee}.{frame.f_code.co_qualname}"
            climbs[key] = climbs.get(key, 0) + 1

    sys.setprofile(trace)
    try:
        report = run_online(ReplaySource(rec).start(), parts, [view, LiveDisplay(io.StringIO())],
                            no_data_timeout_s=1e9)
    finally:
        sys.setprofile(None)
    port = "snn_antenna.bridge.online.pipeline.LiveStream"
    assert set(climbs) == {f"{port}.fill", f"{port}.window"}, climbs
    assert climbs[f"{port}.window"] == report["windows"]
    assert {"fill", "window"} <= set(vars(LiveStream))


def assigned_attributes(path: Path) -> set[str]:
    """What a module assigns to as ``object.name`` (augmented too), as written."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign))
                   else [])
        for target in targets:
            for part in ast.walk(target):
                if isinstance(part, ast.Attribute):
                    names.add(ast.unparse(part))
    return names


def input_writes(path: Path) -> set[str]:
    """The writes of a live input: Th, its source, the published window's length (a number of
    the network's windows), the speed command, a coder's threshold. ``report.windows`` is the
    run report's count of the network's windows, not a length."""
    inputs = {"th_g", "th_source", "windows", "speed_cm_s", "threshold"}
    return {name for name in assigned_attributes(path)
            if name.rpartition(".")[2] in inputs and name != "report.windows"}


def test_only_the_input_schedule_writes_th_and_the_window():
    """In the pipeline's process (bridge/wire, bridge/online, the view's pipeline side, the
    command) one module assigns Th, its source, the published window's length and the speed
    command; no module of bridge/ assigns a coder's threshold."""
    modules = [*(PACKAGE / "bridge" / "wire").glob("*.py"),
               *(PACKAGE / "bridge" / "online").glob("*.py"),
               PACKAGE / "bridge" / "view" / "view.py", PACKAGE / "bridge" / "cli.py"]
    writers = {path.name: input_writes(path) for path in modules}
    assert {name: found for name, found in writers.items() if found} == \
        {"schedule.py": {"self.th_g", "self.th_source", "self.windows", "self.speed_cm_s"}}
    assert not [path for path in (PACKAGE / "bridge").rglob("*.py")
                if any(name.endswith(".threshold") for name in input_writes(path))]
    # The check sees an assignment where there is one.
    assert "self.threshold" in input_writes(PACKAGE / "preprocess.py")
