"""Where the tuned bank's input chain loses the material: a neuron-free ceiling per step.

    python benchmarks/bench_stage_ceilings.py [--repetitions 100] [--out PATH.json]
    ... [--stages coded centred] [--set spiking.tuned.tuning.coder_options={gain=60.0}]

The baseline study's tuned bank (``studies/baseline_comparison.toml``'s ``[spiking.tuned]``: its
channels placed from calibration contacts of another seed, its coder) and its contacts (the
bench set's first ``--repetitions`` repetitions of every material and site; 100: the whole
set): every step of the bank's input chain is read the same way
(``evaluation.stage_ceilings``) and classified by the same MLP (51 hidden, the material
MLPs' epoch budget) on the same splits by repetition, one per seed of ``[evaluation] seeds``,
beside the full-spectrum FFT-MLP on the same splits. Each row: the accuracy's mean over the
splits with its 95 % interval, and the ratio to the FFT-MLP (per split, then its interval),
with n. No neuron runs: this bounds what any read-out after that step can reach.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))   # the bench set bench_coders reads

from snn_antenna.evaluation import crossval as cv  # noqa: E402
from snn_antenna.evaluation import stage_ceilings as sc  # noqa: E402
from snn_antenna.readout import baselines as bl  # noqa: E402
from snn_antenna.readout.spiking import recording_attrs  # noqa: E402
from snn_antenna.readout.spiking_decoders import mlp_baseline  # noqa: E402
from snn_antenna.report import stats  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402

from bench_coders import bench_set  # noqa: E402


def interval_row(values, scale: float = 1.0, bounds=(0.0, np.inf)) -> dict:
    """Mean, 95 % interval and n of per-split ``values`` (× ``scale``)."""
    x = scale * np.asarray(values, dtype=float)
    if len(x) < 2:
        return {"mean": float(x.mean()), "low": None, "high": None, "n": len(x)}
    iv = stats.mean_interval(x, bounds=bounds)
    return {"mean": iv.mean, "low": iv.low, "high": iv.high, "n": iv.n,
            **({"verdict": iv.verdict} if iv.n < stats.MIN_N_TO_RESOLVE else {})}


def ceilings(features, F: dict, evaluation, log=print) -> tuple[list[dict], dict]:
    """Each stage's MLP and the FFT-MLP on the same splits: (rows, the FFT-MLP's row)."""
    feats = features.copy()
    for name, X in F.items():
        feats[f"stage_{name}"] = (("event", f"stage_{name}_feature"), X)
    fft = bl.material_baselines([], evaluation.material_mlp, evaluation.nmf_max_iter)[0]
    chosen = [fft] + [mlp_baseline(f"stage_{n}", "material", f"stage_{n}", evaluation,
                                   sc.STAGE_TEXT[n]) for n in F]
    results = cv.evaluate(feats, chosen, evaluation, log)
    reference = results[fft.name].values("accuracy")
    rows = []
    for name in F:
        acc = results[f"stage_{name}"].values("accuracy")
        rows.append({"stage": name, "what": sc.STAGE_TEXT[name], "features": F[name].shape[1],
                     "accuracy_pct": interval_row(acc, 100.0, (0.0, 100.0)),
                     "ratio_to_fft_mlp": interval_row(acc / reference),
                     "per_split": acc.tolist()})
    return rows, {"accuracy_pct": interval_row(reference, 100.0, (0.0, 100.0)),
                  "per_split": reference.tolist()}


def _text(r: dict) -> str:
    if r["low"] is None:
        return f"{r['mean']:.3f} (n={r['n']})"
    return f"{r['mean']:.3f} [{r['low']:.3f}–{r['high']:.3f}] (n={r['n']})"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repetitions", type=int, default=100,
                    help="contacts per material and site (100: the whole bench set)")
    ap.add_argument("--out", default="out/bench_stage_ceilings.json")
    ap.add_argument("--stages", nargs="+", default=list(sc.STAGES), choices=sc.STAGES)
    ap.add_argument("--set", action="append", default=[], dest="overrides",
                    help="a study spec override, e.g. evaluation.seeds=[0,1]")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    parts, plan, data, cmp, bands, where = bench_set(args.repetitions, args.overrides)
    bank = plan.bank(bands[plan.base.n_resonators], parts.bank)
    ids = cmp.features["event"].values
    F = sc.stage_features(bank, data["counts"].values[ids], *recording_attrs(data),
                          max_hz=parts.processor.max_hz, stages=args.stages)
    features_s = time.perf_counter() - t0
    rows, fft = ceilings(cmp.features, F, parts.evaluation)
    out = {"events": int(len(ids)), "repetitions": args.repetitions,
           "seeds": parts.evaluation.seeds, **where,
           "bank": {"resonators": bank.n_neurons,
                    "channel_low_hz": [round(b.highpass_hz, 1) for b in bank.bands.values()],
                    "channel_high_hz": [round(b.lowpass_hz, 1) for b in bank.bands.values()],
               "coder": plan.base.coder, "coder_amplitude": plan.base.coder_amplitude,
               "threshold_g": plan.base.threshold_g,
               "coder_options": dict(plan.base.coder_options),
               "duration_s": bank.duration_s, "bin_edges_s": list(bank.bin_edges_s)},
           "fft_mlp": fft, "stages": rows, "features_s": features_s,
           "load_average": os.getloadavg(), "wall_s": time.perf_counter() - t0}
    write_benchmark_json(args.out, out)
    print(f"{out['events']} events, {len(parts.evaluation.seeds)} splits by repetition; "
          f"FFT-MLP {_text(fft['accuracy_pct'])} %; load average {os.getloadavg()[0]:.1f}")
    print("stage | accuracy % [95 %] | ÷ FFT-MLP [95 %]")
    for r in rows:
        print(f"{r['stage']} | {_text(r['accuracy_pct'])} | {_text(r['ratio_to_fft_mlp'])}")
    print(f"written {args.out}")
    return out


if __name__ == "__main__":
    main()
