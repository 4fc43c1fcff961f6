"""The speed/accuracy study's report: what ``speed_accuracy.run`` measured, as the reader's
page (reference convergence, recommendation, Pareto fronts, cost, stability map, every run)
and the short summary printed at the end."""
from __future__ import annotations

from ...networks import neurons
from ...evaluation import accuracy, tradeoff
from ...evaluation.accuracy import StabilityGrid
from ...report.page import Calibrated, Predicted, Report, fmt


def convergence_text(conv: dict) -> str:
    head = (f"Each scene's reference is solve_ivp (DOP853, rtol {conv['rtol']:g}) from input "
            f"switch to switch with exact threshold crossings and resets. Re-run at rtol "
            f"{conv['check_rtol']:g} on the {conv['scene']} scene, ")
    if not conv["same_spike_counts"]:
        return head + (f"some neurons fire a different number of spikes (spike-time "
                       f"difference {fmt(conv['max_shift_ms'])} ms): the reference is not "
                       f"converged at rtol {conv['rtol']:g}, and Brian2 errors of that size "
                       f"or smaller say nothing.")
    text = (head + f"every neuron fires the same number of spikes and spike times move by at "
            f"most {fmt(conv['max_shift_ms'])} ms. ")
    if conv["smallest_brian2_error_ms"] is None:
        return text + "No Brian2 run finished to compare that with."
    compare = (f"The smallest Brian2 spike-time error here is "
               f"{fmt(conv['smallest_brian2_error_ms'])} ms ({conv['smallest_error_setting']})")
    if conv["max_shift_ms"] == 0:
        return text + compare + ": the reference did not move at all."
    ratio = fmt(conv["error_over_shift"], digits=2)
    if conv["far_below"]:
        return text + compare + f", {ratio}× the reference's shift: the reference is " \
            "converged far below every Brian2 error reported here."
    return text + compare + f", only {ratio}× the reference's shift: errors near that size " \
        "are partly the reference's own, read them with that margin."


def calibrated_and_predicted(report: Report, summary: dict) -> None:
    """The shipped stability limits are set from this map (calibrated); the integration
    errors are measured against the reference (predicted; the paper has none)."""
    unchecked = []
    for m, v in summary["stability_limits"].items():
        supported = v["measured_max_stable_k_dt"] >= v["shipped_max_stable_k_dt"]
        if not supported and report.quick:
            unchecked.append(m)    # a coarse quick map cannot reach the shipped grid point
            continue
        report.calibrated(Calibrated(
            f"largest stable k·dt, {m}", value=v["shipped_max_stable_k_dt"],
            target=v["measured_max_stable_k_dt"], unit="model ms per step",
            source="this run's stability map; the shipped value is the full profile's "
                   "largest finite grid point, rounded down",
            how="neurons.MAX_STABLE_K_DT (refuses a coarser dt unless force=True)" + (
                "" if supported else "; NOT supported by this run's map, which finds a "
                "lower limit: the shipped value must come down")))
    if unchecked:
        report.text("Shipped stability limits not checked by this quick run "
                    f"({', '.join(unchecked)}): "
                    "its map's k·dt grid is too coarse to reach them, so they are not listed "
                    "under 'Calibrated to'; the full profile's map sets and checks them.")
    d = summary["shipped_default"]
    for r in d["default_rows"]:
        if r.get("rate_map_error") is not None:
            report.predicted(Predicted(
                f"rate-map error of the shipped default ({d['method']}, dt {d['dt_ms']:g} "
                f"ms), {r['scene']} scene", value=r["rate_map_error"], unit="relative",
                source="this run against the solve_ivp reference", n=1,
                note="one scene run with one seed (deterministic); the paper reports no "
                     "integration error"))


def _recommendation_section(report: Report, summary: dict) -> None:
    report.heading("Recommendation")
    if report.quick:
        report.text("Quick profile: the settings below are the best of the few the quick "
                    "sweep ran (see the banner), not a recommendation for the toolkit.")
    q = summary["quickstart_fastest_matching"]
    if q:
        report.text(
            f"Quickstart scene: the fastest setting whose decoded distance and detection match "
            f"the reference is {q['method']} at dt = {q['dt_ms']:g} ms ({q['target']}, "
            f"{q['dtype']}): {fmt(q['cpu_s'], 's')} CPU ({fmt(q['wall_s'], 's')} wall), "
            f"{q['speedup_vs_reference']:.0f}× faster than the reference "
            f"({fmt(q['reference_cpu_s'], 's')} CPU) and "
            f"{q['speedup_vs_slowest_brian2']:.0f}× faster than the slowest Brian2 setting "
            f"({q['slowest_brian2_setting']}).")
    cols = ("scene", "criterion", "method", "dt_ms", "target", "dtype", "cpu_s", "wall_s",
            "speedup_vs_reference") + tradeoff.ERRORS
    report.table([{c: r.get(c) for c in cols} for r in summary["recommendations"]],
                 "Recommended settings per scene, with their measured cost and error")
    d = summary["shipped_default"]
    report.table([dict(setting=f"{d['method']} dt={d['dt_ms']:g} ms", **r)
                  for r in d["default_rows"]], "The shipped default, as measured")


def main_sweep_section(report: Report, done: dict | None) -> None:
    """How the main sweep's errors and costs were measured: every setting's spikes from one
    compiled run, its cost timed on a sample of runtime runs and costed by steps."""
    if not done:
        return
    report.heading("How the main sweep was measured")
    report.text(
        f"Errors: all {done['settings']} settings (scene × method × dt) ran as one compiled "
        f"Brian2 project ({done['accuracy']}): the runtime path's equations, threshold, reset "
        f"and state updater, so the same spikes up to the compiler's rounding. Cost: "
        f"{done['cost']}. {done['timed_samples']} runtime sample(s) were timed; in "
        f"{done['samples_agree']} of them the runtime run's spike count over the sample "
        f"equals the compiled run's over the same window. Every cost is the sample's fixed "
        f"part plus its per-step part times the row's steps (cost_from names the sample).")
    report.table(done["samples"], "The timed sample (runtime target)")


def write_report(report: Report, summary: dict, smap) -> None:
    rows = summary["rows"]
    calibrated_and_predicted(report, summary)
    report.heading("Reference")
    report.text(convergence_text(summary["reference_convergence"]))
    report.table([{k: r[k] for k in ("scene", "cpu_s", "wall_s", "n_spikes", "distance_cm")}
                  for r in summary["references"]], "Reference runs")
    _recommendation_section(report, summary)
    main_sweep_section(report, summary.get("main_sweep"))
    report.heading("Pareto fronts")
    report.figure(tradeoff.pareto_figure(rows), "pareto",
                  "Error against CPU time per scene (main sweep): colour is the method, the "
                  "marker's shape the step dt; the black line is the Pareto front. Runs that "
                  "raised NumericalInstabilityError are not drawn. CPU time, not wall time, "
                  "ranks runs: the machine is shared.")
    report.heading("Cost: targets, precision, array size")
    done = summary.get("cost_sweep")
    if done:
        report.text(
            f"Each runtime setting (numpy, cython) was timed on a sample of its run: "
            f"compiled first, then timed over its first {fmt(done['sample_s'])} s of model "
            f"time (the whole scene when shorter) and over its first few milliseconds, and "
            f"the whole scene costed by steps from the two ({done['runtime_sampled']} of "
            f"{done['runs']} runs; cost_from names the source of each row). cpp_standalone "
            f"runs the whole scene. Errors of the array's own size: a runtime row's from the "
            f"compiled run of the same model at its float type "
            f"({done['scored_from_compiled']} rows), checked against the timed sample's "
            f"spikes over its window ({done['samples_agree']} of {done['runtime_sampled']} "
            f"samples agree).")
    cost_cols = ("method", "dt_ms", "target", "dtype", "n_neurons", "cpu_s", "wall_s",
                 "compile_s", "rate_map_error", "readout_matches", "cost_from", "status")
    report.table([{c: r.get(c) for c in cost_cols} for r in rows if r["sweep"] == "cost"],
                 "Cost sweep (errors only where a reference of the same size exists)")
    report.heading("Stability map")
    report.figure(accuracy.stability_figure(smap), "stability_map",
                  "Constant drive I against k·dt, from the reset point: accurate (steady rate "
                  "within tolerance of the reference), inaccurate but finite, non-finite or "
                  f"runaway (|v| or |u| above {neurons.RUNAWAY_LIMIT:g} at any step).")
    report.table([dict(method=m, **v) for m, v in summary["stability_limits"].items()],
                 "Stability limits (k·dt in model ms per step)")
    n_silent = summary["nonfinite_without_exception"]
    report.text(
        f"{summary['raised_instability']} run(s) raised NumericalInstabilityError (shown as "
        f"non-finite); {n_silent} run(s) finished without an exception yet produced a "
        f"non-finite spike time or score" + (" (listed below)." if n_silent else "."))
    bands_section(report, summary["bands"], smap)
    report.heading("All runs")
    all_cols = ("sweep", "scene", "method", "dt_ms", "target", "dtype", "n_neurons", "cpu_s",
                "wall_s", "cost_from", "status") + tradeoff.ERRORS
    report.table([{c: r.get(c) for c in all_cols} for r in rows], "Every configuration")


BAND_COLS = ("role", "setting", "k_dt_min", "k_dt_max", "accurate_k_dt", "inside_accurate_range",
             "spike_count_error", "rate_map_error", "spike_time_error_ms", "n_spikes",
             "reference_spikes", "cpu_ms_per_event", "ns_per_neuron_step", "events_timed",
             "status")


def bands_section(report: Report, bands: dict, smap) -> None:
    """Each bench band before (euler, dt 0.1 ms) and at the settings inside the accurate
    range: k·dt, errors against the reference, cost; the recalibrated tuning."""
    report.heading("Bands of the bench's spiking read-out")
    measured = {m: float(smap.max_accurate_k_dt.sel(integrator=m)) for m in smap.integrator.values}
    report.text(
        "Each method is tried from its accurate step on the stability map (the largest k·dt "
        "up to which every constant drive keeps its steady rate within tolerance; shipped, "
        f"from the full map: {fmt(bands['accurate_k_dt'])}; this run's map: {fmt(measured)}) "
        "to three steps coarser, since a band's own input may stay accurate where the "
        "worst-case drive does not; the chosen setting is the cheapest whose rate map is "
        "within tolerance of the exact reference. Each band runs "
        f"{bands['n_events']} sample bench events through its own chain, all events × neurons "
        "in one group, against the exact reference at the same Hz per unit k. Errors: spike "
        "counts per event-neuron and the rate map (event-neuron × 50 ms windows), relative "
        "to the reference's; cost: CPU ms per event in a group of events_timed events.")
    for name, b in bands["bands"].items():
        report.table([{c: r.get(c) for c in BAND_COLS} for r in b["rows"]],
                     f"{name} band: before, each method from its accurate step to coarser "
                     "ones, chosen")
        cut = "; ".join(f"{t['window_s']:g} s: {fmt(t['rate_map_error'])}"
                        for t in b["truncation"])
        report.text(f"{b['apply']}. A shorter window would cost this rate-map error even with "
                    f"exact integration (reference spikes after it): {cut}.")
        if "tuning" in b:
            t = b["tuning"]
            report.table([dict(stage=k, **{c: v for c, v in t[k].items()
                                           if c != "peak_offset_channels"})
                          for k in ("before", "calibration", "after") if k in t],
                         f"{name} band: driven tuning (square waves as the coder makes them, "
                         f"{len(t['freqs_hz'])} frequencies); peak offsets in channels")
            stages = [k for k in ("before", "calibration", "after") if k in t]
            report.table([{"neuron": j, **{k: t[k]["peak_offset_channels"][j] for k in stages}}
                          for j in range(len(t["before"]["peak_offset_channels"]))],
                         f"{name} band: each neuron's peak, channels above (+) or below (-) "
                         "its target frequency")


def human_summary(s: dict, out_dir) -> str:
    lines = [b["apply"] for b in s.get("bands", {}).get("bands", {}).values()]
    q = s["quickstart_fastest_matching"]
    if q:
        lines.append(f"quickstart: fastest setting matching the reference read-out: "
                     f"{q['method']} dt={q['dt_ms']:g} ms ({q['target']}, {q['dtype']}), "
                     f"{q['cpu_s']:.2f} s CPU, {q['speedup_vs_reference']:.0f}x faster than the "
                     f"reference")
    for m, v in s["stability_limits"].items():
        lines.append(f"{m}: finite to k·dt {v['measured_max_stable_k_dt']:.3g} "
                     f"(shipped limit {v['shipped_max_stable_k_dt']:g})")
    for r in (s.get("precision") or {}).get("rows", []):
        lines.append(f"sweep engine, {r['dtype']}: {r['ns_per_neuron_step']:.2f} ns per "
                     f"neuron-step, spike-count error {r['spike_count_error']:.2e} against "
                     f"float64")
    lines.append(f"report in {out_dir}/report.html ({s['total_wall_s']:.0f} s)")
    return "\n".join(lines)


def quick_note(sweep, stab: StabilityGrid) -> str:
    """What the quick profile leaves out, from the settings that ran."""
    missing = [m for m in neurons.METHODS if m not in sweep.methods]
    note = (f"quick profile: too small to choose a setting. Methods "
            f"{', '.join(sweep.methods)} at dt {fmt(sorted(sweep.dt_ms))} ms on the "
            f"{', '.join(sweep.scenes)} scene{'s' * (len(sweep.scenes) > 1)} "
            f"({sweep.target} target)")
    if missing:
        note += (f"; {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not in the "
                 f"quick sweep, so a recommendation here is only the best of these")
    return note + (f". The stability map has {stab.n_k_dt} k·dt steps × {len(stab.drives)} "
                   f"drives (the full map {StabilityGrid.n_k_dt} × "
                   f"{len(StabilityGrid().drives)}): "
                   f"its limits are grid points, not the shipped ones.")
