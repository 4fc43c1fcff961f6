"""What a study will simulate, from its spec alone: the runs behind ``plan``'s estimate.

Each study's largest part (its scene, its bench set, its sweep of scenes) as a list of Brian2
runs ``(simulated_s, dt_ms, n_neurons, engine)`` for ``engine.cost.job_estimate``. Nothing is
built: a value of the wrong type gives no estimate here (the study's own check names it).
The numbers are the shipped defaults where the spec leaves a key out.
"""
from __future__ import annotations

from ..core.errors import is_number
from ..core.spec import get_field as _get

ENGINES = {"cpp_standalone": "standalone"}


def _num(spec, dotted, default) -> float:
    value = _get(spec, dotted, default)
    if not is_number(value) or value <= 0:
        raise _Skip
    return float(value)


def _count(spec, dotted, default) -> int:
    value = _get(spec, dotted, default)
    if not isinstance(value, (list, tuple)):
        raise _Skip
    return len(value)


def _engine(spec, dotted, default="cython") -> str:
    value = _get(spec, dotted, default)
    return ENGINES.get(value, value) if isinstance(value, str) else "numpy"


class _Skip(Exception):
    """A value that the study's own check will refuse: no estimate."""


def _workers(spec, dotted) -> int:
    """Worker processes the runs are shared among (0: one per core, as the studies do)."""
    from ..engine.cost import max_workers

    value = _get(spec, dotted, 0)
    most = max_workers()
    return most if value == 0 or not isinstance(value, int) else max(1, min(value, most))


def _array(spec, prefix="network"):
    return (_num(spec, f"{prefix}.dt_ms", 0.1), int(_num(spec, f"{prefix}.n_neurons", 24)),
            _engine(spec, f"{prefix}.target"))


def _quickstart(spec):
    dt, n, eng = _array(spec)
    return "the scene", "stimulus.duration_s", [(_num(spec, "stimulus.duration_s", 8.0), dt, n, eng)]


def _exploration(spec):
    dt, n, eng = _array(spec, "network.resonators")
    return "the closed loop", "loop.duration_s", [(_num(spec, "loop.duration_s", 12.0), dt, n, eng)]


def _gating(spec):
    dt, n, eng = _array(spec)
    scenes = _count(spec, "sweep.speeds_cm_s", [0]) * int(_num(spec, "sweep.n_scenes", 6))
    neurons = n * _count(spec, "sweep.thresholds_g", [0])
    engine = _engine(spec, "sweep.target")
    scenes = -(-scenes // _workers(spec, "sweep.workers"))     # scenes run side by side
    return "the threshold sweep", "sweep.n_scenes", [
        (_num(spec, "sweep.scene_s", 15.0), dt, neurons, engine)] * scenes


def _speed_accuracy(spec):
    n = int(_num(spec, "network.n_neurons", 24))
    scene_s = {"tuning": _num(spec, "tuning.duration_s", 2.0),
               "quickstart": _num(spec, "stimulus.duration_s", 8.0),
               "bench": _num(spec, "bench.duration_s", 2.0)}
    neurons = {"tuning": n * int(_num(spec, "tuning.n_freqs", 12))}
    scenes, dts = _get(spec, "sweep.scenes", []), _get(spec, "sweep.dt_ms", [])
    if not isinstance(scenes, list) or not isinstance(dts, list) or \
            not all(is_number(d) and d > 0 for d in dts):
        raise _Skip
    engine = _engine(spec, "sweep.target")
    return "the method x dt sweep", "sweep.dt_ms", [
        (scene_s.get(s, 0.0), float(d), neurons.get(s, n), engine)
        for s in scenes if isinstance(s, str) for d in dts] * _count(spec, "sweep.methods", [0])


def _baseline(spec):
    events = (_count(spec, "stimulus.materials", [0] * 8)
              * _count(spec, "stimulus.positions_cm", [0] * 16)
              * int(_num(spec, "stimulus.repetitions", 100)))
    bands = _get(spec, "spiking.bank.bands", {})
    if not isinstance(bands, dict):
        raise _Skip
    duration = _num(spec, "spiking.bank.duration_s", 0.5)
    batch = int(_num(spec, "spiking.bank.batch_events", 400))
    runs = []
    for name, band in bands.items():
        prefix = f"spiking.bank.bands.{name}"
        dt = _num(spec, f"{prefix}.dt_ms", _get(spec, "spiking.bank.dt_ms", 0.1))
        n = int(_num(spec, f"{prefix}.n_neurons", 24))
        engine = _engine(spec, "spiking.bank.target")
        chunks = -(-events // batch)
        runs += [(duration, dt, n * batch, engine)] * max(1, -(-chunks // _workers(
            spec, "spiking.workers")))
    return "the bench set's spiking read-out", "stimulus.repetitions", runs


STUDY_RUNS = {"quickstart": _quickstart, "exploration": _exploration,
              "gating_threshold": _gating, "speed_accuracy": _speed_accuracy,
              "baseline_comparison": _baseline}


def estimate(spec: dict):
    """The study's expected simulation time (``engine.cost.JobEstimate``), or None."""
    from ..engine.cost import job_estimate

    runs = STUDY_RUNS.get(spec.get("study"))
    if runs is None:
        return None
    try:
        what, key, items = runs(spec)
    except _Skip:
        return None
    return job_estimate(what, items, key)
