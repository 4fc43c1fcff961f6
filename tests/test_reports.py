"""Reports across studies: one formatter, readable files, runs that survive being run again,
and every quick report opened in a real browser (headless Chromium at 1,280 px).

The study runs are shared through the session fixture ``quick_reports`` (tests/conftest.py).
The default suite runs the cheapest study (quickstart: no store) plus a report built here with
every element a study can put on a page; the other six studies (tuning_sweep: a zarr store,
interrupted then resumed; its resume is also in test_sweep's default tests) run under
``-m slow``. The tests check properties
(a second run succeeds with the same numbers, the page opens cleanly), never the values:
the science inside the studies changes.
"""
from __future__ import annotations

import html
import json
import math
import os
import re
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from snn_antenna.report import stats
from snn_antenna.report.figures import draw_rate_map
from snn_antenna.core.files import atomic_write
from snn_antenna.core.logfile import CPG_TOKEN_ORDER, FLOAT32_CHECK, UNSTABLE_ON_PURPOSE, LogFile
from snn_antenna.report.page import Calibrated, Predicted, Report, fmt, label

WIDTH_PX = 1280
STUDIES = [
    "quickstart",
    # interrupted, resumed and run again through the CLI: ~30 s; the default suite covers its
    # resume in test_sweep (killed by SIGKILL and by Ctrl-C, and the tuning study's quick run)
    pytest.param("tuning_sweep", marks=pytest.mark.slow),
    pytest.param("speed_accuracy", marks=pytest.mark.slow),
    pytest.param("exploration", marks=pytest.mark.slow),
    pytest.param("gating_threshold", marks=pytest.mark.slow),
    pytest.param("baseline_comparison", marks=pytest.mark.slow),
    pytest.param("model_selection", marks=pytest.mark.slow),
    pytest.param("bank_tuning", marks=pytest.mark.slow),
]


# -- one formatter ------------------------------------------------------------------------------
def test_numbers_dicts_and_lists_are_formatted_for_a_reader():
    assert fmt(1.3320387601234507) == "1.332"
    assert fmt(-34.99580198960206) == "-35"
    assert fmt(3.1e-5) == "3.1×10⁻⁵"
    assert fmt(0.024, "g") == "0.024 g"
    assert fmt(64245.3, digits=2) == "64000" and fmt(123456.7) == "123500"
    assert fmt({"measured": 1.3320387601234507, "spec": 1.3333333333333333}) == \
        "measured = 1.332, spec = 1.333"
    assert fmt([-34.99580198960206, 54.99964982285057]) == "-35, 55"
    assert fmt({"k": 1.0, "b": 0.26, "I": 0.15}) == "k = 1, b = 0.26, I = 0.15"
    assert fmt({"distance_cm": 19.04}) == "distance = 19.04 cm"
    assert fmt(True) == "yes" and fmt(None) == "–"
    # every ± carries its n
    assert fmt({"mean": 0.9, "std": 0.0, "n": 1}) == "0.9 ± 0 (sd, n = 1)"
    assert "n not given" in fmt({"mean": 0.9, "std": 0.1})
    interval = {"mean": 0.5, "low": 0.1, "high": 0.9, "n": 5, "level": 0.95,
                "verdict": "resolved above zero"}
    assert fmt(interval) == "0.5 (95 % CI 0.1 to 0.9, n = 5; resolved above zero)"
    long = fmt(list(range(40)))
    assert long.endswith("… (40 values)") and "39" not in long


def test_column_names_are_words_with_units():
    assert label("distance_rmse_mm") == "distance RMSE (mm)"
    assert label("speed_cm_s") == "speed (cm/s)"
    assert label("cpu_s") == "CPU time (s)"
    assert label("measured_max_stable_k_dt") == "measured max stable k·dt"
    assert label("rate_hz") == "rate (Hz)" and label("detection_f1") == "detection F1"
    assert label("95 % interval") == "95 % interval"   # already words: left alone
    assert label("s") == "s"                           # a lone unit is not a name


def test_tables_show_human_names_beside_keys_and_nest_dicts(tmp_path):
    rep = Report(tmp_path, "t")
    rep.table([{"distance_rmse_mm": 1.23456, "by_material": {"wood": 0.9, "alu": 0.8},
                "band_hz": [5.0, 900.0], "runs": [{"seed": 1, "f1": 0.5}]}])
    rep.write({}, {"seed": 0})
    page = (tmp_path / "report.html").read_text()
    assert "distance RMSE (mm)" in page and ">distance_rmse_mm<" in page
    assert '<table class="nested">' in page and "1.235" in page and "5, 900" in page
    assert "{'" not in html.unescape(page) and "[5.0" not in page
    assert 'class="table-scroll"' in page


def test_report_files_are_readable_by_others(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write(tmp_path / "a.json", "{}")
        rep = Report(tmp_path / "r", "t")
        import matplotlib.pyplot as plt
        rep.figure(plt.figure(), "fig")
        rep.write({"x": 1.0}, {"seed": 0})
        os.umask(0o077)   # a user who wants private files gets them
        atomic_write(tmp_path / "b.json", "{}")
    finally:
        os.umask(old)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o644
    for name in ("report.html", "summary.json", "fig.png"):
        assert (tmp_path / "r" / name).stat().st_mode & 0o777 == 0o644, name
    assert (tmp_path / "b.json").stat().st_mode & 0o777 == 0o600


def test_rate_maps_can_carry_their_colour_scale_in_hz():
    import matplotlib.pyplot as plt

    rates = xr.DataArray(np.random.default_rng(0).uniform(0, 40, (5, 8)),
                         dims=("neuron_hz", "window_s"),
                         coords={"neuron_hz": np.geomspace(7, 30, 5),
                                 "window_s": np.arange(8) * 0.1},
                         attrs={"window_s": 0.1})
    fig, (a, b) = plt.subplots(1, 2)
    draw_rate_map(a, rates)
    draw_rate_map(b, rates, colorbar=True)
    bars = [ax for ax in fig.axes if ax not in (a, b)]
    assert len(bars) == 1 and "Hz" in bars[0].get_ylabel()
    plt.close(fig)


def test_expected_warnings_stay_out_of_the_terminal_but_in_the_run_log(tmp_path):
    import io

    from brian2.utils.logger import BrianLogger, get_logger

    brian_log = get_logger("brian2.groups.group")
    lines = []
    terminal_stream = io.StringIO()   # what Brian2's console handler prints to the user
    before = BrianLogger.console_handler.setStream(terminal_stream)
    try:
        with LogFile(tmp_path, lines.append) as log:
            log("[1/2] mapping")
            with log.expected(UNSTABLE_ON_PURPOSE):
                brian_log.warn("neurons's variable 'v' has NaN, very large values, or "
                               "encountered an error in numerical integration.")
                with warnings.catch_warnings():
                    warnings.simplefilter("always")
                    with np.errstate(over="warn"):
                        np.float32(1e30) * np.float32(1e30)
            brian_log.warn("something nobody expected")
    finally:
        BrianLogger.console_handler.setStream(before)
    terminal = terminal_stream.getvalue()
    assert "has NaN" not in terminal and "overflow" not in terminal
    assert "something nobody expected" in terminal          # unexpected ones still show
    assert any("2 expected warnings" in line and "on purpose" in line for line in lines)
    kept = (tmp_path / "run.log").read_text()
    assert "has NaN" in kept and "overflow encountered" in kept and "[1/2] mapping" in kept
    assert "something nobody expected" in kept
    # each line the run says is timed from its start in the file (the terminal stays plain)
    assert re.search(r"^\+ *\d+\.\d s  \[1/2\] mapping$", kept, re.M)
    assert "[1/2] mapping" in lines
    # once the block is closed the filter is gone from Brian2's console handler
    assert not BrianLogger.console_handler.filters


# -- the browser --------------------------------------------------------------------------------
# Injected at the end of a copy of the page: after the load event (every image decoded or
# failed), measure the layout and write the result into the DOM that --dump-dom prints.
_CHECK = """<script>
window.addEventListener("load", () => {
  const doc = document.documentElement;
  const images = Array.from(document.images);
  const outside = Array.from(document.body.querySelectorAll("*")).filter(
      e => !e.closest(".table-scroll, pre")
           && e.getBoundingClientRect().right > doc.clientWidth + 0.5).map(
      e => e.tagName.toLowerCase() + (e.className ? "." + e.className : ""));
  // a box that hides overflow (scrolls or clips) with content wider than itself hides cells
  const clipped = Array.from(document.body.querySelectorAll("*")).filter(e => {
      const style = getComputedStyle(e);
      return style.overflowX !== "visible" && e.clientWidth > 0
             && e.scrollWidth > e.clientWidth + 1; }).map(
      e => `${e.tagName.toLowerCase()}${e.className ? "." + e.className : ""} ` +
           `${e.scrollWidth} px in ${e.clientWidth} px: ` +
           e.innerText.slice(0, 80).replace(/\\s+/g, " "));
  const banner = document.querySelector(".quick-banner");
  const result = {
    clientWidth: doc.clientWidth, scrollWidth: doc.scrollWidth, outside: outside.slice(0, 8),
    clipped: clipped.slice(0, 8),
    images: images.map(i => ({alt: i.alt, complete: i.complete, naturalWidth: i.naturalWidth,
                              shownWidth: Math.round(i.getBoundingClientRect().width)})),
    banner: banner && banner.getBoundingClientRect().height > 0 ? banner.innerText : null,
    text: document.body.innerText,
  };
  const out = document.createElement("pre");
  out.id = "browser-check";
  out.textContent = JSON.stringify(result);
  document.body.appendChild(out);
});
</script>"""


def open_in_browser(chromium: str, report: Path, width: int = WIDTH_PX) -> dict:
    """What headless Chromium sees of ``report`` in a window ``width`` px wide."""
    page = report.with_name(".browser-check.html")
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", _CHECK + "</body>"),
                    encoding="utf-8")
    try:
        proc = subprocess.run(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
             "--hide-scrollbars",
             "--no-first-run", f"--window-size={width},900", "--virtual-time-budget=20000",
             "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=180)
    finally:
        page.unlink()
    found = re.search(r'<pre id="browser-check">(.*?)</pre>', proc.stdout, re.S)
    assert found, f"Chromium returned no page ({proc.returncode}): {proc.stderr[-2000:]}"
    return json.loads(html.unescape(found.group(1)))


def assert_reads_cleanly(seen: dict, quick: bool) -> None:
    assert seen["clientWidth"] == WIDTH_PX
    assert seen["scrollWidth"] <= seen["clientWidth"], \
        f"page {seen['scrollWidth']} px wide; sticking out: {seen['outside']}"
    assert not seen["clipped"], f"content hidden in boxes narrower than it: {seen['clipped']}"
    assert seen["images"], "no figure on the page"
    broken = [i["alt"] for i in seen["images"] if not (i["complete"] and i["naturalWidth"] > 0)]
    assert not broken, f"images not decoded: {broken}"
    text = seen["text"]
    assert "{'" not in text, text[max(0, text.index("{'") - 200):text.index("{'") + 200]
    raw_float = re.search(r"-?\d+\.\d{9,}", text)   # a float printed with all its digits
    assert raw_float is None, text[max(0, raw_float.start() - 150):raw_float.end() + 50]
    if quick:
        assert seen["banner"] and "quick profile" in seen["banner"].lower()
    else:
        assert seen["banner"] is None


def _everything_report(out: Path, quick: bool) -> Path:
    """A report with every kind of element a study puts on a page."""
    import matplotlib.pyplot as plt

    rep = Report(out, "every element", quick=quick, quick_note="quick profile: a test page")
    rep.calibrated(Calibrated("rod decay time", 0.21, 0.2, "s", "docs/reference.md", "damping"))
    rep.predicted(Predicted("material accuracy", {"mean": 0.91, "low": 0.85, "high": 0.97,
                                                  "n": 5, "level": 0.95}, "", 0.942,
                            "paper Table 2", (0.85, 0.97), 5, "5 seeds"))
    rep.text({"measured": 1.3320387601234507, "spec": 1.3333333333333333})
    rep.table([{f"column_{i}_hz": 1234.56789 * i for i in range(40)}], "forty columns")
    rep.table([{"band_hz": [-34.99580198960206, 54.99964982285057],
                "gains": {"wood": 0.912345678, "aluminium": {"near_cm": 1.0, "far_cm": 2.5}},
                "per_seed": [{"seed": s, "f1": 0.9} for s in range(3)],
                "spread": {"mean": 0.9, "std": 0.01, "n": 3}}])
    rates = xr.DataArray(np.random.default_rng(0).uniform(0, 40, (24, 60)),
                         dims=("neuron_hz", "window_s"),
                         coords={"neuron_hz": np.geomspace(7, 30, 24),
                                 "window_s": np.arange(60) * 0.1}, attrs={"window_s": 0.1})
    fig, ax = plt.subplots(figsize=(14, 3))   # wider than the page: the image must shrink
    draw_rate_map(ax, rates, colorbar=True)
    rep.figure(fig, "rate_map", "a rate map with its colour scale")
    rep.write({"x": 1.0}, {"seed": 0})
    return out / "report.html"


@pytest.mark.parametrize("quick", [True, False])
def test_a_page_with_every_element_reads_cleanly_in_chromium(chromium, tmp_path, quick):
    seen = open_in_browser(chromium, _everything_report(tmp_path, quick))
    assert_reads_cleanly(seen, quick)
    assert seen["images"][0]["shownWidth"] <= 1000 < seen["images"][0]["naturalWidth"]
    assert "1.332" in seen["text"] and "-35, 55" in seen["text"]


# -- every study, run as a user runs it -----------------------------------------------------
# Timings (seconds, µs or ns per event, speed-ups) and run bookkeeping; a key that is a
# result, like tau_low_slope_s_per_cm or spike_time_error_ms, is compared.
_VOLATILE = re.compile(r"(^|_)(wall|cpu|compile|seconds|created|speedup|workers|chunks|"
                       r"computed|skipped|reused|command|timing|cost|costs|us|ns)(_|$)|_s$")


def stable_numbers(obj, path: str = "") -> dict:
    """Every number and string of a summary, by path, except timings and run bookkeeping
    (which chunks were computed or reused, when, on which worker)."""
    out = {}
    if isinstance(obj, dict):
        for key, value in obj.items():
            if key == "provenance" or _VOLATILE.search(str(key)):
                continue
            out.update(stable_numbers(value, f"{path}.{key}"))
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            out.update(stable_numbers(value, f"{path}[{i}]"))
    else:
        out[path] = obj
    return out


def test_stable_numbers_ignore_timings_but_not_results():
    a = {"rmse_mm": 1.0, "wall_s": 3.0, "rows": [{"cpu_s": 1.0, "f1": 0.5}],
         "provenance": {"created": "now"}, "workers": {"vm:1": 2},
         "cost": {"predict_us_per_event": 2.5}, "spike_time_error_ms": 0.25,
         "tau_low_slope_s_per_cm": 0.01}
    b = {"rmse_mm": 1.0, "wall_s": 9.0, "rows": [{"cpu_s": 7.0, "f1": 0.5}],
         "provenance": {"created": "later"}, "workers": {"vm:2": 2},
         "cost": {"predict_us_per_event": 8.0}, "spike_time_error_ms": 0.25,
         "tau_low_slope_s_per_cm": 0.01}
    assert stable_numbers(a) == stable_numbers(b) == {
        ".rmse_mm": 1.0, ".rows[0].f1": 0.5, ".spike_time_error_ms": 0.25,
        ".tau_low_slope_s_per_cm": 0.01}
    assert stable_numbers({"tau_low_slope_s_per_cm": 0.02}) != stable_numbers(a)


def assert_same_numbers(first: dict, second: dict, study: str) -> None:
    a, b = stable_numbers(first), stable_numbers(second)
    assert a.keys() == b.keys(), f"{study}: keys differ: {sorted(a.keys() ^ b.keys())[:10]}"
    differ = [k for k in a if not _same(a[k], b[k])]
    assert not differ, f"{study}: a second run changed {[(k, a[k], b[k]) for k in differ[:10]]}"


def _same(x, y) -> bool:
    if isinstance(x, float) and isinstance(y, (int, float)):
        return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12)
    return x == y


@pytest.mark.parametrize("study", STUDIES)
def test_a_study_run_again_succeeds_with_the_same_numbers(quick_reports, study):
    """Run after run (after an interrupted first one when the study keeps a store): both
    complete runs succeed, reuse what is stored, and report the same numbers."""
    run = quick_reports.get(study)
    assert run.failure is None, f"{study}: {run.failure}"
    assert len(run.summaries) == 2
    assert_same_numbers(*run.summaries, study)
    print(f"{study}: runs took {[round(s, 1) for s in run.seconds]} s"
          + (f", the interrupted one was killed after {run.interrupted_after_s:.1f} s"
             if run.interrupted_after_s is not None else ""))


@pytest.mark.parametrize("study", STUDIES)
def test_a_quick_report_reads_cleanly_in_chromium(quick_reports, chromium, study):
    run = quick_reports.get(study)
    assert run.summaries, f"{study}: no complete run to open: {run.failure}"
    seen = open_in_browser(chromium, run.report)
    assert_reads_cleanly(seen, quick=True)
    for name in ("report.html", "summary.json", "run.log"):   # README: a log in every folder
        assert (run.out / name).stat().st_mode & 0o044 == 0o044, f"{name} unreadable by others"
    assert "=== run started" in (run.out / "run.log").read_text()
    shrunk = [(i["alt"], i["naturalWidth"], i["shownWidth"])
              for i in seen["images"] if i["naturalWidth"] > i["shownWidth"]]
    print(f"{study}: {len(seen['images'])} images, page {seen['scrollWidth']} px, figures "
          f"shrunk to fit: {shrunk}")


# A quantity's range from its name: these can never be negative; F1 and fractions never pass 1.
_NON_NEGATIVE = re.compile(r"rmse|f1|accuracy|fp_per_min|latency|rate|_hz|_mm|_s$|fraction",
                           re.I)
_AT_MOST_ONE = re.compile(r"(^|[_ .])f1", re.I)


def claims_beyond_their_rules(obj, path: str = "") -> list[str]:
    """Intervals that leave their quantity's range, and verdicts resting on too few values."""
    bad = []
    if isinstance(obj, dict):
        name = path + " " + str(obj.get("quantity", ""))
        low, high = obj.get("low"), obj.get("high")
        if obj.get("interval") and "quantity" in obj:
            low, high = obj["interval"]
        if isinstance(low, (int, float)) and isinstance(high, (int, float)):
            signed = re.search(r"minus|−|differ", name)     # a paired difference a − b
            if _NON_NEGATIVE.search(name) and not signed and low < 0:
                bad.append(f"{path}: {name} interval {low:g} to {high:g} below zero")
            if _AT_MOST_ONE.search(name) and high > 1 + 1e-12:
                bad.append(f"{path}: {name} interval {low:g} to {high:g} above one")
        if str(obj.get("verdict", "")).startswith("resolved") and \
                (obj.get("n") or 0) < stats.MIN_N_TO_RESOLVE:
            bad.append(f"{path}: '{obj['verdict']}' on n = {obj.get('n')}")
        for key, value in obj.items():
            if key != "provenance":
                bad += claims_beyond_their_rules(value, f"{path}.{key}")
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            bad += claims_beyond_their_rules(value, f"{path}[{i}]")
    return bad


def test_the_claim_checker_catches_old_overclaims():
    assert claims_beyond_their_rules(
        {"predicted": [{"quantity": "distance rmse", "interval": [-107.8, 140.1], "n": 2}],
         "diff": {"mean": 0.1, "low": 0.02, "high": 0.2, "n": 2, "verdict": "resolved above"},
         "f1": {"gated": {"mean": 0.99, "low": 0.95, "high": 1.03, "n": 5}}}) and \
        len(claims_beyond_their_rules(
            {"predicted": [{"quantity": "distance rmse", "interval": [-107.8, 140.1]}],
             "diff": {"low": 0.02, "high": 0.2, "n": 2, "verdict": "resolved above"},
             "f1": {"gated": {"low": 0.95, "high": 1.03, "n": 5}}})) == 3
    assert not claims_beyond_their_rules({"minus_nmf": {"low": -0.1, "high": 0.1, "n": 2,
                                                        "verdict": "too small to resolve"}})
    assert not claims_beyond_their_rules(
        {"predicted": [{"quantity": "F1 gated − lookup table", "interval": [-0.2, -0.1]}]})


@pytest.mark.parametrize("study", STUDIES)
def test_a_quick_summary_claims_nothing_its_n_cannot_carry(quick_reports, study):
    run = quick_reports.get(study)
    assert run.summaries, f"{study}: no complete run: {run.failure}"
    bad = claims_beyond_their_rules(run.summaries[-1])
    assert not bad, f"{study}: {bad[:6]}"


def test_the_known_expected_warnings_match_what_brian2_prints():
    """Messages as a quick run printed them (exploration, speed_accuracy)."""
    seen = {
        CPG_TOKEN_ORDER: "Came across an abstract code block that may not be well-defined: "
                         "the outcome may depend on the order of execution. You can ignore "
                         "this warning if you are sure that the order of operations does not "
                         "matter. Abstract code: 'token_post = int(j == ((i + 1) % n_ring))'",
        UNSTABLE_ON_PURPOSE: "neurons's variable 'v' has NaN, very large values, or "
                             "encountered an error in numerical integration.",
        FLOAT32_CHECK: "/brian2/groups/group.py:1226: RuntimeWarning: overflow encountered "
                       "in cast",
    }
    for kind, message in seen.items():
        assert any(re.search(p, message, re.S) for p in kind.patterns), kind.why
    # an order warning about any other variable is not explained away
    other = seen[CPG_TOKEN_ORDER].replace("token_post", "v_post")
    assert not any(re.search(p, other, re.S) for p in CPG_TOKEN_ORDER.patterns)
