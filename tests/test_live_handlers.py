"""Every handler the online pipeline drives implements one declared protocol
(bridge/online/handler.py's WindowHandler): the same methods with the same signatures, checked
structurally (names, parameters and their kinds, via ``inspect.signature``) and with
``isinstance`` on real instances; and ``run_online`` hands each of them the stream's start,
every window of the network and its end."""
import inspect
import io
import typing

import numpy as np
import pytest

from snn_antenna.bridge.online.controls import Controls
from snn_antenna.bridge.online.handler import Published, Window, WindowHandler
from snn_antenna.bridge.online.live_state import Decisions
from snn_antenna.bridge.online.pipeline import build_online, run_online
from snn_antenna.bridge.online.report import OnlineReport
from snn_antenna.bridge.online.robot import LiveRobot
from snn_antenna.bridge.online.terminal import LiveDisplay
from snn_antenna.bridge.view.view import LiveView
from snn_antenna.bridge.wire.protocol import BOARD_RATE_HZ
from snn_antenna.bridge.wire.recorder import record_counts
from snn_antenna.bridge.wire.replay import ReplaySource
from snn_antenna.sources.stimuli import Contact, RobotScene
from test_live_view_panels import NETWORK

HANDLERS = [OnlineReport, LiveRobot, Controls, LiveView, Decisions, LiveDisplay]
METHODS = [name for name, value in vars(WindowHandler).items()
           if inspect.isfunction(value) and not name.startswith("_")]


def parameters(function) -> list[tuple[str, object]]:
    return [(p.name, p.kind) for p in inspect.signature(function).parameters.values()]


def test_the_protocol_declares_start_window_and_end():
    assert METHODS == ["stream_started", "window", "stream_ended"]
    assert typing.get_type_hints(WindowHandler.window)["window"] is Window
    assert typing.get_type_hints(Window)["published"] == Published | None


@pytest.mark.parametrize("handler", HANDLERS, ids=lambda cls: cls.__name__)
def test_each_handler_has_the_protocols_methods_and_signatures(handler):
    for name in METHODS:
        assert callable(getattr(handler, name, None)), f"{handler.__name__} has no {name}"
        assert parameters(getattr(handler, name)) == parameters(getattr(WindowHandler, name)), \
            f"{handler.__name__}.{name}{inspect.signature(getattr(handler, name))} is not " \
            f"WindowHandler.{name}{inspect.signature(getattr(WindowHandler, name))}"


def test_real_instances_are_window_handlers():
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    instances = [OnlineReport(), Controls(parts, rate_hz=BOARD_RATE_HZ), LiveView(parts),
                 Decisions(parts), LiveDisplay(io.StringIO())]
    assert all(isinstance(h, WindowHandler) for h in instances)
    assert not isinstance(object(), WindowHandler)


class Spy:
    """Controls that keep to themselves, noting what the pipeline handed them."""

    def __init__(self, parts):
        self.controls = Controls(parts, rate_hz=BOARD_RATE_HZ)
        self.windows = self.controls.windows
        self.events = self.controls.events
        self.seen: list = []

    def stream_started(self, parts) -> None:
        self.seen.append(("started", parts))

    def window(self, window: Window) -> None:
        self.seen.append(("window", window))

    def stream_ended(self, final_event) -> None:
        self.seen.append(("ended", final_event))

    def __getattr__(self, name):            # the pipeline's own calls (poll, due, ...)
        return getattr(self.controls, name)


def test_the_pipeline_hands_every_handler_the_start_each_window_and_the_end(tmp_path):
    counts = RobotScene(duration_s=2.0, contacts=[Contact(1.2, 19.0)]).generate(
        seed=3).samples
    rec = record_counts(tmp_path / "rec", counts)
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    spy, out = Spy(parts), io.StringIO()
    assert isinstance(spy, WindowHandler)
    report = run_online(ReplaySource(rec).start(), parts, controls=spy, no_data_timeout_s=1e9,
                        display=LiveDisplay(out))
    kinds = [kind for kind, _ in spy.seen]
    assert kinds == ["started"] + ["window"] * report["windows"] + ["ended"]
    windows = [w for kind, w in spy.seen if kind == "window"]
    assert [w.end_index for w in windows] == [round((i + 1) * parts.window_s * BOARD_RATE_HZ)
                                              for i in range(report["windows"])]
    assert all(w.published is not None for w in windows)       # one network window each
    # The report took each window first: the factor the others saw counts it.
    assert np.isfinite(windows[-1].published.realtime_factor)
    # The terminal saw the same windows: its header, then its lines and the contact.
    assert out.getvalue().startswith("rate map: 24 resonators")
    assert "contact" in out.getvalue()
