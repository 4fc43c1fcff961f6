"""The view stops cleanly whatever its pages did: after a storm of reloads in headless Chromium
(ten a second, each leaving a Bokeh session behind), ``LiveView.stop`` gets the view process's
answer well within its timeout, so the run's report knows the frames the view dropped, and
the process is gone.

The pipeline's part is played by test_live_page_chromium's FakePipeline (LiveView's own
gathering API at 1 kHz of stream time), without Brian2.
"""
import os
import time

import pytest

from snn_antenna.bridge.online.pipeline import build_online
from snn_antenna.bridge.view.view import STOP_TIMEOUT_S, LiveView
from snn_antenna.sources.stimuli import Contact, RobotScene
from test_live_controls_chromium import CHROMIUM
from test_live_page_chromium import NETWORK, SCENE_S, FakePipeline
from test_live_view_process import Reloading

STORM_S = 3.0                   # of reloads, ten a second


@pytest.mark.skipif(CHROMIUM is None, reason="no system Chromium (Debian package `chromium`)")
@pytest.mark.parametrize("browser", ["closed", pytest.param("still reloading",
                                                              marks=pytest.mark.slow)])
def test_the_view_answers_at_stop_after_a_storm_of_reloads(browser):
    parts = build_online(NETWORK, ["preprocess.threshold=0.05"])
    counts = RobotScene(duration_s=SCENE_S, contacts=[Contact(1.0, 19.0)]).generate(
        seed=3).samples
    view = LiveView(parts, port=0)
    url = view.start()
    pid = view.process.pid
    pipeline = FakePipeline(view, parts, counts)
    pipeline.start()
    reloading = Reloading(url, period_s=0.1)
    try:
        time.sleep(STORM_S)
        if browser == "closed":
            reloading.close()
        pipeline.stop.set()
        pipeline.join(10)
        started = time.monotonic()
        summary = view.stop()
        took_s = time.monotonic() - started
    finally:
        reloading.close()
        pipeline.stop.set()
        if view.process is not None:
            view.stop()
    assert reloading.loads >= 2 * STORM_S, reloading.loads
    # The view process answered (it was not killed at the timeout): its count is known, and
    # it saw every frame the pipeline handed over.
    assert took_s < STOP_TIMEOUT_S, took_s
    assert summary == {"frames_published": view.published, "frames_dropped": 0,
                       "handoff_full": 0}, summary
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
