"""What the emulated board streams for a stimulus file: ADC counts at the board's rate, labelled.

Every file in ``stimuli/`` can be streamed (``snn-antenna emulate --stimulus stimuli/NAME.toml``):

- a scene (``kind = "robot"`` or ``"course"``; ``sources.scenes.scene_from_spec``) is generated
  with the emulator's seed and streamed as it is; it must be sampled as the board samples
  (``protocol.BOARD_RATE_HZ``, ``BOARD_ADC_BITS``, ``BOARD_FULL_SCALE_G``);
- the bench (``kind = "bench"``, ``sources.bench.BenchSpec``: clamped-rod contacts recorded by a
  lab converter) is played back as a bench rig with the robot's board on it would send it: its
  events (the cached data set ``bench.load`` makes for the studies) in a seeded random order,
  back to back, each converted from the lab converter to the board (counts → g, resampled to
  the board's rate behind an anti-aliasing filter, the board's ADC). Only as many events as the
  frames asked for are converted; without ``--frames`` the whole bench plays once.

Either way the result is a :class:`~snn_antenna.core.signals.Recording` whose ``truth`` labels each
contact; :func:`played_events` lists those that fall in the frames actually streamed (the
emulator's ``--log`` keeps them, since a recording of the stream has no labels of its own).
"""
from __future__ import annotations

import math
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np

from ...core.errors import SpecError, check
from ...core.signals import Recording
from ...core.truth import Event, GroundTruth
from ...sources import antenna
from ..wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G, BOARD_RATE_HZ
from ...sources.stimuli import Contact, RobotScene
from ...sources.scenes import scene_from_spec
from ...sources import bench

DEFAULT_SCENE_S = 8.0
EVENTS_PER_CHUNK = 500          # bench events converted at a time (bounds the float copies)


def default_scene(seed: int = 0) -> Recording:
    """A robot scene with two contacts (19 cm and 27 cm), as the board sends it."""
    scene = RobotScene(duration_s=DEFAULT_SCENE_S,
                       contacts=[Contact(2.0, 19.0), Contact(5.0, 27.0)])
    return scene.generate(seed)


def stimulus_recording(path: str | Path | None, seed: int = 0,
                       n_frames: int | None = None) -> Recording:
    """The labelled counts to stream for a stimulus spec (its ``[stimulus]`` table, or the
    file's top level), or for the default scene; ``n_frames`` bounds what a bench converts."""
    if path is None:
        return default_scene(seed)
    import tomllib

    path = Path(path)
    if not path.is_file():
        raise SpecError("stimulus", str(path), "an existing TOML file (e.g. stimuli/*.toml)")
    try:
        spec = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SpecError("stimulus", str(path), f"a TOML file ({exc})") from None
    table = spec.get("stimulus", spec)
    if table.get("kind") == "bench":
        return bench_on_board(table, seed, n_frames)

    recording = scene_from_spec(table).generate(seed)
    check_board_sampling(recording, str(path))
    return recording


def check_board_sampling(recording: Recording, where: str) -> None:
    """A scene is streamed sample for sample: it must be sampled as the board samples."""
    board = {"rate_hz": BOARD_RATE_HZ, "adc_bits": BOARD_ADC_BITS,
             "full_scale_g": BOARD_FULL_SCALE_G}
    found = {"rate_hz": recording.rate_hz, "adc_bits": recording.meta.get("adc_bits"),
             "full_scale_g": recording.meta.get("full_scale_g")}
    check(recording.units == "counts" and recording.samples.ndim == 2, "stimulus", where,
          "a scene that yields 2-axis ADC counts")
    for name, value in found.items():
        check(value == board[name], f"stimulus.{name}", value,
              f"{board[name]:g}, the board's (the emulator streams what the board sends)")


def bench_on_board(table: dict, seed: int, n_frames: int | None = None,
                   log=lambda text: print(text, file=sys.stderr, flush=True)) -> Recording:
    """The bench's contact events, in a seeded random order, as the board would send them.

    ``seed`` is the bench data set's (as a study's seed) and the playback order's; ``log``
    gets the data set's progress (stderr: the emulator's stdout names the port).
    """
    spec = bench.spec_from_table(table, seed)
    data = bench.load(spec, log=log)
    n_events = data.sizes["event"]
    ratio = (Fraction(BOARD_RATE_HZ).limit_denominator()
             / Fraction(spec.rate_hz).limit_denominator())
    event_len = math.ceil(data.sizes["sample"] * ratio)   # resample_poly's output length
    wanted = n_events if n_frames is None else min(n_events, math.ceil(n_frames / event_len))
    order = np.random.default_rng(seed).permutation(n_events)[:wanted]
    lab = antenna.ADC(spec.adc_bits, spec.full_scale_g)
    counts = _to_board(data["counts"].values, order, lab, ratio)
    pre_s, ring_s = float(spec.pre_trigger_s), event_len / BOARD_RATE_HZ - spec.pre_trigger_s
    materials, distances = data["material"].values, data["distance_cm"].values
    events = tuple(Event("contact", k * event_len / BOARD_RATE_HZ + pre_s, ring_s,
                         float(distances[i]), str(materials[i])) for k, i in enumerate(order))
    return Recording(counts, BOARD_RATE_HZ, GroundTruth(events), units="counts",
                     meta={"adc_bits": BOARD_ADC_BITS, "full_scale_g": BOARD_FULL_SCALE_G,
                           "bench_events": order.tolist()})


def _to_board(lab_counts: np.ndarray, order: np.ndarray, lab: antenna.ADC,
              ratio: Fraction) -> np.ndarray:
    """Events ``order`` of the lab's counts (event, sample, axis), back to back, as the
    board's counts (samples, 2)."""
    from scipy.signal import resample_poly

    board = antenna.ADC(BOARD_ADC_BITS, BOARD_FULL_SCALE_G)
    pieces = []
    for start in range(0, len(order), EVENTS_PER_CHUNK):
        g = lab.to_g(lab_counts[order[start:start + EVENTS_PER_CHUNK]])
        if ratio != 1:
            g = resample_poly(g, ratio.numerator, ratio.denominator, axis=1)
        pieces.append(board.to_counts(g).astype(np.int16).reshape(-1, 2))
    return np.concatenate(pieces)


def played_events(recording: Recording, n_frames: int) -> list[dict]:
    """The labels of the first ``n_frames`` frames of ``recording`` streamed in a loop: each
    event with the frame index (and stream time) of its onset."""
    rate, n = recording.rate_hz, recording.n_samples
    played = []
    for lap in range(math.ceil(n_frames / n)):
        for event in recording.truth.events:
            frame = lap * n + int(round(event.t_s * rate))
            if frame < n_frames:
                played.append({"frame": frame, **event.as_dict(), "t_s": frame / rate})
    return played
