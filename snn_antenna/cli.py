"""The ``snn-antenna`` command.

    snn-antenna run studies/quickstart.toml [--out DIR] [--set key=value ...] [--quick]

:data:`COMMANDS` is the registry: every subcommand, declared where it is implemented (``run``
here, ``results`` in report/results.py, the bridge's in bridge/cli.py, ``data import`` in
data/command.py), each with its options declared once (``core.commands``). Errors a user can
cause print one clear line and exit with status 2 (``core.errors.guarded`` maps every exit);
they never show a traceback from deep inside Brian2 or numpy. ``run`` checks everything in one
first phase (``first_phase``; ``--check`` stops after it), then runs the study on the plan that
phase built, in the output folder that phase checked.
"""
from __future__ import annotations

import argparse
import os
import sys
from contextlib import contextmanager
from pathlib import Path

from . import __version__
from .bridge import cli as bridge_cli
from .core import bounds, commands, outputs
from .core import spec as specs
from .core.commands import LIST, POSITIONAL, Command, Option
from .core.errors import SpecError, guarded
from .core.files import cache_root, not_ours
from .data import command as data_command
from .engine import executor
from .engine.cost import LONG_SWEEP_S
from .engine.spec_rules import check_spec
from .networks.neurons import raise_on_ctrl_c
from .report import results as results_page
from .studies import runner
from .studies.contract import STUDY_OPTIONS, Options, cache_folder, check_options


def _run(options) -> int:
    with first_phase(options) as (plan, folder, study_options):
        if study_options.check:         # everything a run would refuse has been said
            for line in plan.left_out:  # and what it would leave out of the spec
                print(f"{options.spec}: {line}")
            print(f"{options.spec}: the spec and --out {folder.path} are accepted "
                  f"({plan.study}); nothing was run")
            return 0                    # the folder is released as it was
        folder.claim()                  # --force: another study's files go, now all passed
        raise_on_ctrl_c()               # Ctrl-C stops the study, never just one Brian2 run
        runner(plan.study).run(plan, folder.path, study_options)
    return 0                            # what the run wrote is recorded, however it ended


@contextmanager
def first_phase(options):
    """Every check a run makes before its work, in one path (``--check`` stops after it):
    the options against what the study takes, the spec as resolved (its seeds included),
    the rules joining its sections, every part the study builds without simulating, the
    output folder and the names the run will write there, the caches, and the cost. Nothing
    here imports Brian2 or starts a worker. Yields the plan the run goes on with, the output
    folder (checked and locked: the first phase of ``outputs.output_folder``) and the
    study's options."""
    study_options = Options(**{o.name: getattr(options, o.name) for o in STUDY_OPTIONS})
    spec = specs.load(options.spec, options.set, quick=study_options.quick)
    study = spec.get("study")
    module = runner(study)
    check_options(study, module.OPTIONS, study_options)
    if study_options.data is not None:
        spec["data"] = study_options.data
    check_spec(spec, user_keys=[item.split("=", 1)[0].strip() for item in options.set])
    plan = module.plan(spec)            # every field in its bounds, every part built
    out = Path(options.out) if options.out else Path("out") / Path(options.spec).stem
    check_out(out)
    executor.probe_scheduler(study_options.scheduler)  # what listens there, before --out
    with outputs.output_folder(out, study, force=study_options.force,
                               fresh=study_options.fresh) as folder:
        check_names(folder)
        if uses_standalone(spec):
            cache_folder("SNN_ANTENNA_CACHE", cache_root())
        check_cost(plan, study_options)
        yield plan, folder, study_options


# Names a study writes at the top of its output folder (its report, summary, log, figures,
# stores and run logs): one the user owns there is refused before the run, not by the run.
WRITTEN_NAMES = ("report.html", "summary.json", "run.log", "runs.jsonl", "predictions.json")
WRITTEN_SUFFIXES = (".png", ".zarr")
ROOM_IN_OUT = 160       # bytes below --out the deepest file a run writes needs (stores' chunks)


def uses_standalone(spec) -> bool:
    """Whether any part of the resolved spec runs on Brian2's standalone target (its compiled
    projects are kept in the toolkit's cache, which the run must be able to create)."""
    if isinstance(spec, dict):
        return ("standalone" in (spec.get("target"), spec.get("engine"))
                or any(map(uses_standalone, spec.values())))
    if isinstance(spec, list):
        return any(map(uses_standalone, spec))
    return False


def check_out(out: Path) -> None:
    """An --out the file system can hold with what a run writes below it, reached by no
    link that leads nowhere."""
    absolute = os.path.abspath(out)
    if len(absolute.encode("utf-8", "surrogateescape")) + ROOM_IN_OUT > bounds.PATH_MAX:
        raise SpecError("--out", str(out), f"a path short enough for the files a run writes "
                                           f"in it (at most {bounds.PATH_MAX - ROOM_IN_OUT} "
                                           "bytes as an absolute path)")
    path = Path(absolute)
    for place in (path, *path.parents):
        if os.path.islink(place) and not place.exists():
            raise SpecError("--out", str(out), f"a folder path; {place} is a symbolic link "
                                               "to nothing")


def check_names(folder) -> None:
    """No file of the user's where the run will write one of its own."""
    if not folder.path.is_dir():
        return
    ours = folder.listed | folder.replace
    for name in sorted(os.listdir(folder.path)):
        if name not in ours and (name in WRITTEN_NAMES or name.endswith(WRITTEN_SUFFIXES)):
            raise not_ours(folder.path, name)


def check_cost(plan, options) -> None:
    """A study expected to run beyond the limit is refused without ``--yes``, naming the key
    that sets its length. The estimate is the plan's own."""
    estimate = plan.estimate()
    if estimate is None:
        return
    sweep = hasattr(estimate, "points")
    print(f"{'sweep: ' if sweep else ''}{estimate.describe()}", file=sys.stderr, flush=True)
    if estimate.seconds > LONG_SWEEP_S and not options.yes:
        key = "axes" if sweep else estimate.key
        value = f"{estimate.points:,} points" if sweep else estimate.value
        raise SpecError(key, value,
                        f"a {'sweep' if sweep else 'run'} expected to take at most "
                        f"{LONG_SWEEP_S / 3600:g} h (this one: about "
                        f"{estimate.seconds / 3600:.3g} h); "
                        f"{'shrink an axis' if sweep else 'make it shorter'}, or pass "
                        "--yes to run it anyway")


RUN = Command(
    "run", "run a study spec (studies/*.toml) and write its report", _run, (
        Option("spec", "path of a study spec, e.g. studies/quickstart.toml", kind=POSITIONAL),
        Option("out", "output folder (default out/SPEC-NAME)", check=bounds.out_path,
               text=True),
        Option("set", "override a spec field, e.g. --set network.n_neurons=48 (repeatable)",
               kind=LIST, metavar="KEY=VALUE"),
        *STUDY_OPTIONS))

# Every subcommand, in the order ``snn-antenna -h`` lists them.
COMMANDS = (RUN, *results_page.COMMANDS, *bridge_cli.COMMANDS, *data_command.COMMANDS)


def build_parser() -> argparse.ArgumentParser:
    return commands.build_parser(
        "snn-antenna", "Spiking neural networks (Brian2) that read an insect-inspired antenna.",
        __version__, COMMANDS)


def main(argv=None) -> int:
    args = commands.parse(build_parser(), argv)
    return guarded(args.command, args, "snn-antenna")


if __name__ == "__main__":
    sys.exit(main())
