"""The main sweep: every method × dt on every scene, scored on the compiled engine, its cost
on the sweep's runtime target timed on a sample.

Accuracy: one compiled run steps every (scene, method, dt) of the grid
(``engine.settings_runs``: the runtime path's model, so the spikes are the runtime run's up
to the compiler's rounding), each scored against its scene's reference as a runtime run is.

Cost: what a user's choice costs is a run on the sweep's target (numpy or cython), so that is
timed, on a sample (``timing``): per scene and method, the finest step whose compiled run
stayed finite within the method's stable limit, compiled first, then timed over its first
``devices.WARM_UP_MS`` and its first ``timing.SAMPLE_S`` seconds. The two give the run's
fixed cost (building the network) and its cost per step, and every step of that scene and
method is costed as fixed + per step × its steps (the row's ``cost_from`` says so). The
sample's spike count beside the compiled run's over the same window is kept as a check
(``agrees``).
"""
from __future__ import annotations

import time

import numpy as np

from ...core.errors import NumericalInstabilityError
from ...engine.batches import Batches
from ...engine.devices import Setting
from ...engine.runlog import RunLog
from ...evaluation.bands import Spikes, array_of
from ...engine.settings_runs import SceneDrive, SettingsRuns, scene_drive, settings_spikes
from ...evaluation.tradeoff import ERRORS, RAISED, check_finite, describe
from ...networks import neurons
from . import timing


def score(workload, ref, setting: Setting, result) -> dict:
    """One grid point's row from its compiled run, as ``devices.measure`` makes a runtime
    run's (its cost filled in later, from the timed sample)."""
    row = {"sweep": "main", "scene": workload.name, "method": setting.method,
           "dt_ms": float(setting.dt_ms), "target": setting.target, "dtype": setting.dtype,
           "n_neurons": workload.n_neurons, "k_dt": workload.k_max * setting.dt_ms,
           "accuracy_from": "standalone", "scene_duration_s": scene_drive(workload).duration_s}
    row["beyond_stable_limit"] = row["k_dt"] > neurons.MAX_STABLE_K_DT[setting.method]
    if isinstance(result, NumericalInstabilityError):
        row.update(status=RAISED, wall_s=None, cpu_s=None, compile_s=0.0, error=str(result),
                   readout_matches=False, **{e: None for e in ERRORS}, distance_cm=None,
                   n_spikes=None)
        return row
    row.update(status="ok", compile_s=0.0, n_spikes=int(len(result.spike_i)),
               engine_cpu_s=result.cpu_s)
    row.update(workload.errors(result, ref.run, ref.readout))
    return check_finite(row, result)


def _sample_dt(rows: list[dict]) -> float | None:
    """The finest step of one scene and method that finished within its stable limit: the
    most steps in its sample, so its per-step cost is measured over the most steps and every
    other step is costed by fewer steps than it (the noise of a short run, multiplied up to a
    long one, reordered settings whose costs lie within 20 % of each other)."""
    ok = [r["dt_ms"] for r in rows if r["status"] == "ok" and not r["beyond_stable_limit"]]
    return min(ok) if ok else None


def run(plan, workloads: dict, refs: dict, runlog: RunLog, log) -> tuple[list, dict]:
    """The main sweep's rows and what it did (``summary["main_sweep"]``)."""
    sweep = plan.sweep
    dts, methods = sorted(float(d) for d in sweep.dt_ms), list(sweep.methods)
    keys = [(s, m, dt) for s in sweep.scenes for m in methods for dt in dts]

    def logged(s, m, dt):
        return runlog.get(sweep="main", scene=s, method=m, dt_ms=dt, target=sweep.target,
                          dtype=sweep.dtype, n_neurons=workloads[s].n_neurons)
    rows = {key: logged(*key) for key in keys}
    t0 = time.perf_counter()
    results = {}
    if any(r is None for r in rows.values()):
        drives = tuple(scene_drive(workloads[s]) for s in sweep.scenes)
        # one compiled run of every method (the methods are Batches items: a client would
        # spread them over its workers)
        work = SettingsRuns(drives, tuple(dts), sweep.dtype)
        for part in Batches(work, per_run=len(methods)).run(methods):
            results.update(part)
        for key in keys:
            if rows[key] is None:
                s, m, dt = key
                rows[key] = score(workloads[s], refs[s],
                                  Setting(m, dt, sweep.target, sweep.dtype), results[key])
                rows[key]["cost_from"] = None
    compiled_s = time.perf_counter() - t0
    log(f"  compiled run of {len(keys)} settings: {compiled_s:.1f} s (compiling included)")

    samples = []
    for s in sweep.scenes:
        for m in methods:
            mine = [rows[(s, m, dt)] for dt in dts]
            dt = _sample_dt(mine)
            if dt is None:
                continue
            setting = Setting(m, dt, sweep.target, sweep.dtype)
            identity = dict(scene=s, method=m, dt_ms=dt, target=sweep.target,
                            dtype=sweep.dtype, n_neurons=workloads[s].n_neurons)
            timed = runlog.get(sweep="main_timing", **identity)
            if timed is None:
                sample = timing.timed_sample(workloads[s], setting, mine[0]["scene_duration_s"])
                compiled = results.get((s, m, dt)) if results else None
                timed = dict(identity, sweep="main_timing",
                             **{k: v for k, v in sample.items() if not k.startswith("_")})
                timed["agrees"] = compiled is not None and timing.agrees(sample, compiled, dt)
                runlog.add(timed)
            log(f"  timed sample: {s} {m} dt={dt:g} {sweep.target}: "
                f"{timed.get('sample_cpu_s', float('nan')):.2f} s CPU over "
                f"{timed['sample_s']:g} s, whole scene costed "
                f"{timed.get('cpu_s', float('nan')):.2f} s")
            samples.append(timed)
            _cost(mine, timed)
    for key in keys:
        if rows[key]["status"] == "ok" and rows[key]["cpu_s"] is None:
            rows[key]["cost_from"] = "no finished sample to cost it from"
    for key in keys:
        if logged(*key) is None:
            runlog.add(rows[key])
    out = [rows[key] for key in keys]
    for r in out:
        log(f"  {describe(r) if r['cpu_s'] is not None or r['status'] != 'ok' else r['scene']}")
    return out, {"accuracy": "compiled cpp_standalone, every setting in one run "
                             "(engine.settings_runs)",
                 "settings": len(keys), "compiled_run_s": compiled_s,
                 "cost": f"{sweep.target}, timed on a sample (per scene and method, the "
                         f"finest finished step over its first {timing.SAMPLE_S:g} s, or the "
                         "whole scene when shorter) and costed by steps",
                 "timed_samples": len(samples),
                 "samples_agree": sum(bool(t.get("agrees")) for t in samples),
                 "samples": [{k: t.get(k) for k in ("scene", "method", "dt_ms", "target",
                                                    "sample_s", "sample_cpu_s", "short_cpu_s",
                                                    "cpu_s", "wall_s", "sample_spikes",
                                                    "agrees", "status")}
                             for t in samples]}


def _cost(rows: list[dict], timed: dict) -> None:
    """Each finished row's cost from the timed sample (``timing.timed_sample``): its fixed
    part plus its per-step part times the row's steps."""
    if timed["status"] != "ok":
        return
    how = (f"{timed['target']}, timed at dt {timed['dt_ms']:g} ms "
           f"({timing.describe(timed)})")
    for r in rows:
        if r["status"] != "ok":
            continue
        for field in ("cpu_s", "wall_s"):
            r[field] = timing.costed(timed, field, r["dt_ms"], r["scene_duration_s"])
        r["cost_from"] = how


def band_spikes(events, settings) -> dict:
    """``evaluation.bands``' compiled runs: every setting of ``settings`` (``BandSetting``)
    over the band's sample ``events`` (``BandEvents``) in one compiled run
    (``engine.settings_runs``), each neuron (event e, resonator j at index e·n + j) starting
    at rest for its event's first sample, as ``neurons.simulate`` starts it; {setting:
    ``Spikes`` or the ``NumericalInstabilityError`` met}. Settings with a window of their
    own are left to the runtime target."""
    whole = [s for s in settings if s.duration_s is None]
    drives, pairs = {}, []
    m = events.n_events
    for s in whole:
        array = array_of(events.band, s)
        key = f"hz_per_k {s.hz_per_k}"
        if key not in drives:
            first = np.repeat(np.asarray(events.coded[0], float), array.n_neurons)
            rest = np.array([neurons.resting_state("resonator", array.b, float(i0))
                             for i0 in first])
            drives[key] = SceneDrive(key, np.asarray(events.coded, float), float(events.rate_hz),
                                     np.tile(np.asarray(array.k, float), m),
                                     np.repeat(np.arange(m), array.n_neurons), rest[:, 0],
                                     rest[:, 1], float(array.b))
        pairs.append((s.method, float(s.dt_ms)))
    if not whole:
        return {}
    runs = settings_spikes(list(drives.values()), (), (), pairs=pairs)
    out = {}
    for s in whole:
        run = runs[(f"hz_per_k {s.hz_per_k}", s.method, float(s.dt_ms))]
        out[s] = run if isinstance(run, NumericalInstabilityError) else Spikes(
            run.spike_i, run.spike_t_ms)
    return out


def tuning_spikes(current, rate_hz: float, k, input_index, b: float, method: str,
                  dt_ms: float) -> np.ndarray:
    """``evaluation.bands.driven_tuning``'s compiled run: every neuron (its ``k``, reading
    column ``input_index`` of ``current``) at ``method`` and ``dt_ms`` in one compiled run
    (``engine.settings_runs``), each starting at rest for its column's first sample, as
    ``neurons.simulate`` starts it; the spikes' neuron indices. A blow-up raises the
    ``NumericalInstabilityError`` the runtime run would have raised."""
    current = np.asarray(current, float)
    first = current[0][np.asarray(input_index)]
    rest = np.array([neurons.resting_state("resonator", float(b), float(i0)) for i0 in first])
    drive = SceneDrive("tuning", current, float(rate_hz), np.asarray(k, float),
                       np.asarray(input_index), rest[:, 0], rest[:, 1], float(b))
    run = settings_spikes([drive], (), (), pairs=[(method, float(dt_ms))])[
        ("tuning", method, float(dt_ms))]
    if isinstance(run, NumericalInstabilityError):
        raise run
    return np.asarray(run.spike_i, dtype=np.int64)
