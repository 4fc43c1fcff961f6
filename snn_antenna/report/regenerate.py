"""Every full result again, in one command: ``snn-antenna results --regenerate``.

Run from the repository's checkout. For each study of ``studies/*.toml`` it takes, in this
order, a run whose ``summary.json`` was made by this checkout's code (its provenance's
``code_sha256`` is :func:`~snn_antenna.core.provenance.code_hash`) with the profile asked
for (the full one; ``--quick-check`` for the quick profiles):

1. the run in ``RUNS/STUDY`` (``--runs``, default ``out/results-runs``), from an earlier
   regeneration, or one the user made there;
2. the source stored beside the results page (``docs/results/STUDY.json``);
3. otherwise a new run: ``snn-antenna run studies/STUDY.toml --yes --out RUNS/STUDY``, in a
   process of its own, one study at a time (a killed run resumes in its folder).

Every benchmark of ``benchmarks/`` has its page command in :data:`PAGE_BENCHMARKS` (a test
fails on a script without one). For each, in this order, it takes an output made by this
checkout's code and this script, with the page command's options:

1. the output in ``RUNS/bench/NAME.json``, from an earlier regeneration;
2. the output stored beside the page (``docs/results/NAME.json``);
3. otherwise the page command runs (with this interpreter, its output in ``RUNS/bench``; a
   benchmark without an output file is recorded from what it prints,
   ``results.record_benchmark``).

``--keep NAME`` keeps a stored study or benchmark as it is whatever code made it: its section
still names its own commit and code hash.

Then it writes the page from those runs and outputs (``results.make_page``): the page, its
sources, the guides' figures and run times. ``--plan`` prints what it would reuse and run,
and stops.
"""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import SpecError
from ..core.provenance import code_hash, file_digest

#: the studies in the order the page shows them (from a first look to the deepest study);
#: a study not listed follows them, by name
PAGE_ORDER = ("quickstart", "tuning_sweep", "gating_threshold", "baseline_comparison",
              "model_selection", "speed_accuracy", "exploration", "bank_tuning")

#: a benchmark's option naming the JSON file it writes
OUTPUT_OPTIONS = ("--json", "--out")

#: every script ``benchmarks/NAME.py``, in the order the page shows them, with the options of
#: its page command (``python benchmarks/NAME.py OPTIONS``; ``{out}``: the JSON file it
#: writes, none for a benchmark recorded from what it prints). Each is sized to finish in
#: minutes on a 2-core machine and still measure what its script is for, the size in its
#: options and so on the page: the coders and the stage ceilings on the bench set's first
#: repetitions (every material and site, a split per seed of the study: intervals with n),
#: the bands on their 8 sample events cut to 0.25 s, the live view with 0 and 1 open pages.
PAGE_BENCHMARKS = {
    "bench_array": "--seconds 2 --json {out}",
    "bench_bands": "--cost-events 8 --seconds 0.25 --json {out}",
    "bench_coders": "--repetitions 5 --out {out}",
    "bench_events": "--cost-only --sizes 24 48 --json {out}",
    "bench_lab_readouts": "--json {out}",
    "bench_stage_ceilings": "--repetitions 30 --out {out}",
    # the whole robot network (gate, CPG, control beside the resonators), the heaviest the
    # live page streams, with no page and with three open
    "bench_stream": "--network networks/live_robot.toml --browsers 0,3 --repeats 1 "
                    "--view-seconds 10 --baseline none",
    "bench_studies": "--json {out}",
    "bench_sweep": "--sizes 10000 100000 --runtime-max 0 --naive-sample 1 --workers "
                   "--json {out}",
}


@dataclass
class Step:
    """One study or benchmark of the page: what it is, where its output will be, and why."""
    name: str
    output: Path                 # a run folder, a summary or a benchmark's JSON
    command: list[str] | None    # None: reused as it is
    why: str
    record: bool = False         # a benchmark recorded from what it printed


def _summary(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _made_here(data: dict | None, quick: bool | None = None) -> bool:
    """Made by this checkout's code (and, for a study, with the profile asked for)."""
    if not data:
        return False
    if quick is not None and bool(data.get("quick")) != quick:
        return False
    return data.get("provenance", {}).get("code_sha256") == code_hash()


def _program() -> list[str]:
    """``snn-antenna`` as installed beside this interpreter, so a run's provenance records
    the command a user types; the module otherwise."""
    script = Path(sys.executable).parent / "snn-antenna"
    return [str(script)] if script.is_file() else [sys.executable, "-m", "snn_antenna.cli"]


def study_steps(root: Path, store: Path, runs: Path, quick: bool, keep: set[str]) -> list[Step]:
    """What to do for each study of ``root/studies``."""
    specs = sorted((root / "studies").glob("*.toml"), key=lambda p: (
        PAGE_ORDER.index(p.stem) if p.stem in PAGE_ORDER else len(PAGE_ORDER), p.stem))
    if not specs:
        raise SpecError("--regenerate", str(root),
                        "the repository's checkout (its studies/*.toml): run it from there")
    profile = "quick" if quick else "full"
    steps = []
    for spec in specs:
        study = spec.stem
        fresh, stored = runs / study / "summary.json", store / f"{study}.json"
        if study in keep and stored.is_file():
            steps.append(Step(study, stored, None, "kept as stored (--keep)"))
        elif _made_here(_summary(fresh), quick):
            steps.append(Step(study, runs / study, None, f"this code's {profile} run in {runs}"))
        elif _made_here(_summary(stored), quick):
            steps.append(Step(study, stored, None, f"this code's {profile} run, stored"))
        else:
            command = [*_program(), "run", f"studies/{study}.toml", "--yes",
                       "--out", str(runs / study)] + (["--quick"] if quick else [])
            steps.append(Step(study, runs / study, command,
                              f"no {profile} run of this code: running it"))
    return steps


def page_command(name: str, output: Path) -> tuple[list[str], bool]:
    """The page command of ``benchmarks/NAME.py`` (:data:`PAGE_BENCHMARKS`) with this
    interpreter, writing ``output``; and whether it is recorded from what it prints."""
    options = PAGE_BENCHMARKS[name]
    argv = [sys.executable, f"benchmarks/{name}.py",
            *shlex.split(options.replace("{out}", shlex.quote(str(output))))]
    return argv, "{out}" not in options


def page_options(command: str, name: str) -> list[str] | None:
    """The options a benchmark's recorded command gave its script, with the file it wrote
    shown as ``{out}`` (so they compare with :data:`PAGE_BENCHMARKS`); ``None`` when the
    command does not run ``benchmarks/NAME.py``."""
    argv = shlex.split(command or "")
    scripts = [i for i, arg in enumerate(argv) if Path(arg).as_posix().endswith(
        f"benchmarks/{name}.py")]
    if not scripts:
        return None
    options = argv[scripts[0] + 1:]
    for option in OUTPUT_OPTIONS:
        if option in options[:-1]:
            options[options.index(option) + 1] = "{out}"
    return options


def _bench_made_here(record: dict | None, name: str, script: Path) -> bool:
    """Made by this checkout's code and script, with the page command's options."""
    prov = (record or {}).get("provenance", {})
    return (_made_here(record) and script.is_file()
            and prov.get("script_sha256") == file_digest(script)
            and page_options(prov.get("command"), name) == shlex.split(PAGE_BENCHMARKS[name]))


def bench_steps(root: Path, store: Path, runs: Path, keep: set[str]) -> list[Step]:
    """What to do for each benchmark of ``root/benchmarks`` (:data:`PAGE_BENCHMARKS`)."""
    scripts = sorted(p.stem for p in (root / "benchmarks").glob("bench_*.py"))
    missing = [name for name in scripts if name not in PAGE_BENCHMARKS]
    if missing:
        raise SpecError("benchmarks", ", ".join(missing), "a benchmark with its page command "
                        "in snn_antenna.report.regenerate.PAGE_BENCHMARKS")
    steps = []
    for name in (n for n in PAGE_BENCHMARKS if n in scripts):
        stored, fresh = store / f"{name}.json", runs / "bench" / f"{name}.json"
        script = root / "benchmarks" / f"{name}.py"
        if name in keep and stored.is_file():
            steps.append(Step(name, stored, None, "kept as stored (--keep)"))
        elif _bench_made_here(_summary(fresh), name, script):
            steps.append(Step(name, fresh, None, f"this code's page run in {runs}"))
        elif _bench_made_here(_summary(stored), name, script):
            steps.append(Step(name, stored, None, "this code's page run, stored"))
        else:
            command, printed = page_command(name, fresh)
            why = ("not on the page yet" if not stored.is_file() else
                   "stored from other code or another command")
            steps.append(Step(name, fresh, command, f"{why}: running its page command",
                              record=printed))
    return steps


def plan(out: Path, runs: Path, quick: bool, keep: set[str],
         root: Path | None = None) -> tuple[list[Step], list[Step]]:
    """The studies' and the benchmarks' steps, checked before anything runs."""
    root = Path.cwd() if root is None else root
    store = out.parent / "results"
    studies = study_steps(root, store, runs, quick, keep)
    benches = bench_steps(root, store, runs, keep)
    known = {s.name for s in studies + benches}
    unknown = sorted(keep - known)
    if unknown:
        raise SpecError("--keep", ", ".join(unknown),
                        f"a study or benchmark of the page ({', '.join(sorted(known))})")
    return studies, benches


def _run(step: Step, record_benchmark, log) -> None:
    log(f"{step.name}: {shlex.join(step.command)}")
    if step.record:
        record_benchmark(step.output, step.command)
        return
    step.output.parent.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(step.command, check=False)
    if done.returncode != 0:
        raise SpecError("--regenerate", shlex.join(step.command),
                        f"a run that ends well (it exited {done.returncode}; its output is "
                        f"in {step.output}, and running the command again resumes it)")


def regenerate(out: Path, runs: Path, make_page, record_benchmark, quick: bool = False,
               keep: set[str] = frozenset(), plan_only: bool = False, log=print) -> Path | None:
    """Run or reuse every study and benchmark, then write the page with ``make_page(runs,
    benchmarks, out)`` (``results.make_page``; a benchmark recorded from what it printed is
    recorded by ``record_benchmark(out, command)``); with ``plan_only`` only print the plan."""
    studies, benches = plan(out, runs, quick, set(keep))
    for step in studies + benches:
        log(f"{step.name}: {step.why}" + (f" ({step.output})" if not step.command else ""))
        if step.command and plan_only:
            log(f"    {shlex.join(step.command)}")
    if plan_only:
        return None
    for step in studies + benches:
        if step.command:
            _run(step, record_benchmark, log)
    return make_page([s.output for s in studies], [s.output for s in benches], out)
