"""What a setting costs on a runtime target (numpy, cython), timed on a sample of its run.

A runtime run's cost is a fixed part (building the network, Brian2's set-up) plus a part per
step. Both are measured on the setting's own compiled code without running the whole scene:
a warm-up (compiles, not timed), then its first ``WARM_UP_MS`` and its first ``sample_s``
seconds, each timed. The whole run is costed as fixed + per step × its steps. The sample is
the same network and code as the whole run, stopped early (``ArrayWorkload.run(run_ms=)``),
so its spikes are the whole run's up to the sample's end: ``agrees`` compares them with the
compiled run's over that window, a check that the two engines run the same model.
"""
from __future__ import annotations

import numpy as np

from ...core.errors import NumericalInstabilityError
from ...engine.devices import WARM_UP_MS, Setting, float_precision

SAMPLE_S = 1.0   # model seconds of a runtime run that are timed (at most the scene's)
TIMED = "timed"


def sample_seconds(duration_s: float, sample_s: float = SAMPLE_S) -> float:
    """The sample's length: ``sample_s``, or the whole scene when it is shorter."""
    return min(float(sample_s), float(duration_s))


def timed_sample(workload, setting: Setting, duration_s: float,
                 sample_s: float = SAMPLE_S) -> dict:
    """The setting on its runtime target: compiled first, then timed over its first
    ``WARM_UP_MS`` and its first ``sample_seconds(duration_s)``; its fixed and per-step
    cost and the whole run's (``duration_s``) from them. ``status`` "ok", or the
    instability the sample met."""
    sample = sample_seconds(duration_s, sample_s)
    out = {"sample_s": sample, "short_ms": WARM_UP_MS, "scene_duration_s": float(duration_s)}
    try:
        with float_precision(setting.dtype):
            workload.run(setting, warm_up=True)
            short = workload.run(setting, run_ms=WARM_UP_MS)
            run = workload.run(setting, run_ms=sample * 1000.0)
    except NumericalInstabilityError as exc:
        return dict(out, status="non-finite", error=str(exc))
    out.update(status="ok", short_cpu_s=short.cpu_s, short_wall_s=short.wall_s,
               sample_cpu_s=run.cpu_s, sample_wall_s=run.wall_s,
               sample_spikes=int(len(run.spike_i)))
    short_steps = WARM_UP_MS / setting.dt_ms
    sample_steps = sample * 1000.0 / setting.dt_ms
    for field in ("cpu_s", "wall_s"):
        a, b = out[f"short_{field}"], out[f"sample_{field}"]
        per_step = max(b - a, 0.0) / max(sample_steps - short_steps, 1.0)
        out[f"fixed_{field}"] = max(a - short_steps * per_step, 0.0)
        out[f"per_step_{field}"] = per_step
        out[field] = costed(out, field, setting.dt_ms, duration_s)
    out["_spikes"] = run
    return out


def costed(sample: dict, field: str, dt_ms: float, duration_s: float) -> float:
    """``field`` ("cpu_s" or "wall_s") of a run of ``duration_s`` at ``dt_ms`` from a timed
    sample's fixed and per-step parts."""
    return sample[f"fixed_{field}"] + sample[f"per_step_{field}"] * duration_s * 1000.0 / dt_ms


def spikes_before(spike_i, spike_t_ms, dt_ms: float, sample_s: float) -> int:
    """Spikes at the steps of a sample's run: t = step · dt < ``sample_s``."""
    return int(np.sum(np.rint(np.asarray(spike_t_ms) / dt_ms) < round(sample_s * 1000.0 / dt_ms)))


def agrees(sample: dict, compiled, dt_ms: float) -> bool:
    """Whether the timed sample fired as many spikes as the compiled run over its window."""
    if sample["status"] != "ok" or isinstance(compiled, NumericalInstabilityError):
        return False
    return sample["sample_spikes"] == spikes_before(compiled.spike_i, compiled.spike_t_ms,
                                                    dt_ms, sample["sample_s"])


def describe(sample: dict) -> str:
    return (f"timed over the first {sample['sample_s']:g} s and {sample['short_ms']:g} ms, "
            "costed by steps")
