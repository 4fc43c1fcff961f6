"""Shared fixtures: the quick reports of every study (run as a user runs them) and a headless
Chromium that opens them.

``quick_reports`` runs each study's quick profile through the command line, in its own
working directory (the bench cache, ``out/.cache``, lands there too), at most once per test
session however many tests ask: the re-run test and the browser test share the runs.

A study that keeps a store is first interrupted (killed as soon as its store appears on
disk), then run to the end (it resumes) and run once more (it reuses everything); a study
without a store is run twice. Both complete runs' summaries are kept for comparison.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import pytest
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")  # tests never open windows

# Hypothesis profiles: "suite" (the default: a hundred examples per property, the same ones
# every run) and "slow" (ten thousand, freshly drawn); HYPOTHESIS_PROFILE=slow selects it for
# the properties that take the profile's count, and the slow-marked ones always use it.
_PROFILE_COMMON = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                             HealthCheck.function_scoped_fixture])
settings.register_profile("suite", max_examples=40, derandomize=True, **_PROFILE_COMMON)
settings.register_profile("slow", max_examples=10_000, **_PROFILE_COMMON)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))

REPO = Path(__file__).resolve().parents[1]

# study -> the file or folder whose appearance means "a store exists" (None: keeps no store)
STORES = {
    "quickstart": None,
    "exploration": None,
    "tuning_sweep": "results.zarr",
    "gating_threshold": "sweep.zarr",
    "speed_accuracy": "runs.jsonl",
    "baseline_comparison": "out/.cache",   # relative to the run's working directory
    "model_selection": "out/.cache",
    "bank_tuning": "scored_contacts.json",   # written after each trial: killed mid-search
}
RUN_TIMEOUT_S = 900


@dataclass
class QuickRun:
    """Two complete quick runs of one study in the same folder (after an interrupted one
    when the study keeps a store)."""
    study: str
    out: Path
    summaries: list[dict] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    interrupted_after_s: float | None = None
    outputs: list[str] = field(default_factory=list)
    failure: str | None = None     # the output of a complete run that failed, if one did

    @property
    def report(self) -> Path:
        return self.out / "report.html"


def _run_cli(study: str, cwd: Path, out: Path, stop_when: Path | None = None):
    """``snn-antenna run studies/STUDY.toml --quick --out OUT`` from ``cwd``; with
    ``stop_when``, killed (SIGKILL, like a crash or a closed laptop) once that path exists."""
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""),
               MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", "snn_antenna.cli", "run", str(REPO / "studies" / f"{study}.toml"),
           "--quick", "--out", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    if stop_when is not None:
        while proc.poll() is None and not _has_store(stop_when):
            if time.perf_counter() - t0 > RUN_TIMEOUT_S:
                break
            time.sleep(0.05)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    try:
        output, _ = proc.communicate(timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        output, _ = proc.communicate()
    return proc.returncode, output, time.perf_counter() - t0


def _has_store(path: Path) -> bool:
    if path.name == "runs.jsonl":      # a run log counts once it holds a finished run
        return path.is_file() and len(path.read_text().splitlines()) >= 2
    return path.exists() and (path.is_file() or any(path.iterdir()))


class QuickReports:
    def __init__(self, root: Path):
        self.root = root
        self.runs: dict[str, QuickRun] = {}

    def get(self, study: str) -> QuickRun:
        if study not in self.runs:
            self.runs[study] = self._run(study)
        return self.runs[study]

    def _run(self, study: str) -> QuickRun:
        cwd = self.root / study
        cwd.mkdir(parents=True)
        out = cwd / "report"
        run = QuickRun(study, out)
        if STORES[study] is not None:
            store = (cwd if STORES[study].startswith("out/") else out) / STORES[study]
            code, output, seconds = _run_cli(study, cwd, out, stop_when=store)
            run.interrupted_after_s = seconds
            run.outputs.append(output)
            if code == 0:   # finished before its store appeared: nothing was interrupted
                run.interrupted_after_s = None
        for _ in range(2):
            code, output, seconds = _run_cli(study, cwd, out)
            run.outputs.append(output)
            if code != 0:   # recorded, not raised: the tests that need the run say what failed
                run.failure = f"run {len(run.summaries) + 1} failed:\n{output[-4000:]}"
                break
            run.summaries.append(json.loads((out / "summary.json").read_text()))
            run.seconds.append(seconds)
        return run


def run_main(argv: list[str]) -> int:
    """``snn_antenna.cli.main(argv)`` in this process, its stderr kept: a test that needs the
    run to succeed fails with what the run said (the one-line error), not a bare ``1 == 0``."""
    import contextlib
    import io

    from snn_antenna.cli import main

    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        status = main(argv)
    sys.stderr.write(said.getvalue())
    assert status == 0, f"{' '.join(argv[:2])} exited {status}:\n{said.getvalue()[-3000:]}"
    return status


@pytest.fixture(autouse=True)
def _brian_console_on_an_open_stream():
    """Brian2's console handler keeps the stream it was made with. Imported during a test that
    captured stderr (``capsys``), it is left on that test's closed stream, and every later Brian2
    warning in the worker prints a "Logging error" traceback instead, long enough to bury the
    message of a real failure. After each test, point it at the current stderr if so."""
    yield
    logger = sys.modules.get("brian2.utils.logger")
    handler = getattr(getattr(logger, "BrianLogger", None), "console_handler", None)
    if handler is not None and getattr(handler.stream, "closed", False):
        handler.stream = sys.stderr      # not setStream: it flushes the closed one first


@pytest.fixture(scope="session")
def quick_reports(tmp_path_factory) -> QuickReports:
    return QuickReports(tmp_path_factory.mktemp("quick_reports"))


def find_chromium() -> str | None:
    """Debian's ``chromium`` (installed by .ci/run when it can), or another Chromium."""
    for name in (os.environ.get("SNN_CHROMIUM", ""), "chromium", "chromium-browser",
                 "google-chrome", "google-chrome-stable"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


@pytest.fixture(scope="session")
def chromium() -> str:
    path = find_chromium()
    if path is None:
        pytest.skip("no headless Chromium on this machine (Debian: apt-get install chromium; "
                    ".ci/run installs it when it runs as root)")
    return path
