"""The cost sweep: the cost scene at a few settings on every code target, float type and
array size.

Cost: what a user's choice costs is measured on the choice itself. A runtime target (numpy,
cython) is timed on a sample of its run (``timing.timed_sample``: its first
``timing.SAMPLE_S`` seconds and its first ``WARM_UP_MS``, costed by steps for the whole
scene); cpp_standalone runs its whole scene in a binary kept on disk per configuration
(``settings_runs.array_standalone``: compiled once, timed without compiling).

Errors, where a reference of the same size exists (the array's own size): a runtime row's
from one compiled run per float type of every setting (``engine.settings_runs``, the
runtime path's model: the same spikes up to the compiler's rounding, ``accuracy_from``); a
standalone row's from its own run.
"""
from __future__ import annotations

from ...core.errors import NumericalInstabilityError
from ...engine.devices import Setting, float_precision
from ...engine.runlog import RunLog
from ...engine.settings_runs import array_standalone, scene_drive, settings_spikes
from ...evaluation.tradeoff import ERRORS, RAISED, check_finite, describe
from ...networks import neurons
from . import timing
from .main_sweep import score


def _identity(scene: str, setting: Setting, own_size: int) -> dict:
    return dict(sweep="cost", scene=scene, method=setting.method, dt_ms=float(setting.dt_ms),
                target=setting.target, dtype=setting.dtype,
                n_neurons=setting.n_neurons or own_size)


def _standalone_row(workload, ref, setting: Setting) -> dict:
    """The whole scene on cpp_standalone: its binary's run timed, scored when own size."""
    row = {"k_dt": workload.k_max * setting.dt_ms, "accuracy_from": "its own run"}
    row["beyond_stable_limit"] = row["k_dt"] > neurons.MAX_STABLE_K_DT[setting.method]
    array = workload.array(setting.method, setting.dt_ms, setting.target, setting.n_neurons)
    try:
        with float_precision(setting.dtype):
            run = array_standalone(array, workload.coded)
    except NumericalInstabilityError as exc:
        return dict(row, status=RAISED, wall_s=None, cpu_s=None, compile_s=0.0,
                    error=str(exc), readout_matches=False, **{e: None for e in ERRORS},
                    distance_cm=None, n_spikes=None)
    row.update(status="ok", wall_s=run.wall_s, cpu_s=run.cpu_s, compile_s=run.compile_s,
               n_spikes=int(len(run.spike_i)), cost_from="cpp_standalone, the whole run")
    if setting.n_neurons is None:
        row.update(workload.errors(run, ref.run, ref.readout))
    else:
        row.update({e: None for e in ERRORS}, distance_cm=None, readout_matches=None)
    return check_finite(row, run)


def _runtime_row(workload, ref, setting: Setting, compiled) -> dict:
    """A runtime setting: cost timed on a sample; errors from the compiled run (own size)."""
    duration = scene_drive(workload).duration_s
    sample = timing.timed_sample(workload, setting, duration)
    if compiled is not None:
        row = score(workload, ref, setting, compiled)
        row.update(accuracy_from=f"cpp_standalone (compiled, {setting.dtype})",
                   sample_agrees=timing.agrees(sample, compiled, setting.dt_ms))
    else:
        row = {"k_dt": workload.k_max * setting.dt_ms, "status": "ok", "compile_s": 0.0,
               "n_spikes": None, **{e: None for e in ERRORS}, "distance_cm": None,
               "readout_matches": None}
        row["beyond_stable_limit"] = row["k_dt"] > neurons.MAX_STABLE_K_DT[setting.method]
    if sample["status"] != "ok":
        row.update(status=RAISED, error=sample.get("error"), wall_s=None, cpu_s=None,
                   readout_matches=False)
        return row
    if row["status"] == "ok":
        row.update(cpu_s=sample["cpu_s"], wall_s=sample["wall_s"],
                   cost_from=f"{setting.target}, {timing.describe(sample)}",
                   sample_s=sample["sample_s"], sample_cpu_s=sample["sample_cpu_s"])
    return row


def run(pairs: list, workloads: dict, refs: dict, runlog: RunLog, log) -> tuple[list, dict]:
    """The cost sweep's rows (one per (scene, ``Setting``) of ``pairs``) and what it did."""
    rows, missing = {}, []
    for j, (scene, setting) in enumerate(pairs):
        own = workloads[scene].n_neurons
        rows[j] = runlog.get(**_identity(scene, setting, own))
        if rows[j] is None:
            missing.append(j)
    # errors of every own-size runtime row: one compiled run per float type
    compiled = {}
    need = {}
    for j in missing:
        scene, setting = pairs[j]
        if setting.target != "cpp_standalone" and setting.n_neurons is None:
            need.setdefault((scene, setting.dtype), []).append(
                (setting.method, float(setting.dt_ms)))
    for (scene, dtype), settings in need.items():
        runs = settings_spikes([scene_drive(workloads[scene])], (), (), dtype, pairs=settings)
        compiled.update({(scene, dtype, m, dt): runs[(scene, m, dt)] for m, dt in settings})
    for n, j in enumerate(missing, 1):
        scene, setting = pairs[j]
        workload, ref = workloads[scene], refs[scene]
        if setting.target == "cpp_standalone":
            row = _standalone_row(workload, ref, setting)
        else:
            own = setting.n_neurons is None   # a larger array has no reference
            row = _runtime_row(workload, ref, setting, compiled.get(
                (scene, setting.dtype, setting.method, float(setting.dt_ms))) if own else None)
        row.update(_identity(scene, setting, workload.n_neurons))
        runlog.add(row)
        rows[j] = row
        log(f"  [{n}/{len(missing)}] {describe(row)}")
    out = [rows[j] for j in range(len(pairs))]
    timed = [r for r in out if str(r.get("cost_from", "")).startswith(("numpy", "cython"))]
    return out, {"runs": len(out), "runtime_sampled": len(timed),
                 "sample_s": timing.SAMPLE_S,
                 "samples_agree": sum(bool(r.get("sample_agrees")) for r in timed),
                 "scored_from_compiled": sum(r.get("accuracy_from", "").startswith(
                     "cpp_standalone (compiled") for r in out)}
