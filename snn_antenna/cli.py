"""The ``snn-antenna`` command.

    snn-antenna run studies/quickstart.toml [--out DIR] [--set key=value ...] [--quick]

Every subcommand takes ``--out DIR``. Errors a user can cause print one clear line and exit
with status 2; they never show a traceback from deep inside Brian2 or numpy. ``run`` checks
everything in one first phase (``first_phase``; ``--check`` stops after it), then runs the
study on the plan that phase built.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from .core import bounds, outputs
from .core.bounds import option
from .core.errors import SpecError, guarded
from .report import results as results_page
from .studies import runner
from .studies.contract import scheduler_address


def _run(args) -> int:
    plan, folder, options = first_phase(args)
    if options.check:                   # everything a run would refuse has been said
        for line in plan.left_out:      # and what it would leave out of the spec
            print(f"{args.spec}: {line}")
        print(f"{args.spec}: the spec and --out {folder.path} are accepted ({plan.study}); "
              "nothing was run")
        outputs.release(folder)
        return 0
    try:
        folder.clear()                  # --force: another study's files, now that all passed
        outputs.claim(folder)
    except BaseException:
        outputs.release(folder)
        raise
    from .networks.neurons import raise_on_ctrl_c
    raise_on_ctrl_c()                   # Ctrl-C stops the study, never just one Brian2 run
    try:
        runner(plan.study).run(plan, folder.path, options)
    finally:
        outputs.record(folder)          # what this run wrote, however it ended; unlock
    return 0


def first_phase(args):
    """Every check a run makes before its work, in one path (``--check`` stops after it):
    the options against what the study takes, the spec as resolved (its seeds included),
    the rules joining its sections, every part the study builds without simulating, the
    output folder and the names the run will write there, the caches, and the cost. Nothing
    here imports Brian2 or starts a worker. Returns the plan the run goes on with, the
    prepared (locked) output folder and the options."""
    from .core import spec as specs
    from .engine.spec_rules import check_spec
    from .core.files import cache_root
    from .studies.contract import Options, cache_folder, refused_options

    options = Options(**{f.name: getattr(args, f.name) for f in dataclasses.fields(Options)})
    spec = specs.load(args.spec, args.set, quick=args.quick)
    study = spec.get("study")
    module = runner(study)
    refusal = refused_options(study, module.OPTIONS, options)
    if refusal:
        args.parser.error(refusal)
    if options.data is not None:
        spec["data"] = options.data
    check_spec(spec, user_keys=[item.split("=", 1)[0].strip() for item in args.set])
    plan = module.plan(spec)            # every field in its bounds, every part built
    out = Path(args.out) if args.out else Path("out") / Path(args.spec).stem
    check_out(out)
    from .engine.executor import probe_scheduler

    probe_scheduler(options.scheduler)  # what listens there, before --out is touched
    folder = outputs.prepare(out, study, force=options.force, fresh=options.fresh)  # locked
    try:
        check_names(folder)
        if uses_standalone(spec):
            cache_folder("SNN_ANTENNA_CACHE", cache_root())
        check_cost(plan, options)
    except BaseException:
        outputs.release(folder)
        raise
    return plan, folder, options


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
    import os

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
    import os

    from .core.files import not_ours

    if not folder.path.is_dir():
        return
    ours = folder.listed | folder.replace
    for name in sorted(os.listdir(folder.path)):
        if name not in ours and (name in WRITTEN_NAMES or name.endswith(WRITTEN_SUFFIXES)):
            raise not_ours(folder.path, name)


def check_cost(plan, options) -> None:
    """A study expected to run beyond the limit is refused without ``--yes``, naming the key
    that sets its length. The estimate is the plan's own."""
    from .engine.cost import LONG_SWEEP_S

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


class OneLineParser(argparse.ArgumentParser):
    """Bad options are one line too (the usage is one ``-h`` away), exit status 2; the
    subcommands' parsers are of this class as well."""

    def error(self, message):
        hint = ""
        if message.startswith("unrecognized arguments:"):    # a misspelt option: suggest
            import difflib

            known = [o for a in self._actions for o in a.option_strings]
            close = {m for given in message.split(":", 1)[1].split()
                     for m in difflib.get_close_matches(given, known, n=1)}
            hint = f"; did you mean {', '.join(sorted(close))}?" if close else ""
        self.exit(2, f"{self.prog}: error: {message}{hint} (see {self.prog} -h)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="snn-antenna",
        description="Spiking neural networks (Brian2) that read an insect-inspired antenna.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a study spec (studies/*.toml) and write its report")
    run.add_argument("spec", help="path of a study spec, e.g. studies/quickstart.toml")
    run.add_argument("--out", type=option(bounds.out_path, text=True),
                     help="output folder (default out/SPEC-NAME)")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a spec field, e.g. --set network.n_neurons=48 (repeatable)")
    run.add_argument("--quick", action="store_true",
                     help="apply the spec's [quick] profile: "
                          "a small run for tests and first looks")
    run.add_argument("--fresh", action="store_true",
                     help="studies that keep results or caches: discard them and start over")
    run.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                     type=option(scheduler_address, text=True),
                     help="studies with Dask workers: run on an existing Dask cluster instead "
                          "of a local one")
    run.add_argument("--data", metavar="PATH", type=option(bounds.out_path, text=True),
                     help="studies that read recorded data sets: the folder they are in (sets "
                          "the spec's data)")
    run.add_argument("--force", action="store_true",
                     help="reuse an --out folder that holds another study's outputs or other "
                          "files: what snn-antenna wrote there is replaced, other files are kept")
    run.add_argument("--check", action="store_true",
                     help="check the spec, its estimate and --out as a run would, then stop "
                          "without running or writing anything")
    run.add_argument("--yes", action="store_true",
                     help="run even when the estimate is beyond the limit (1 h)")
    run.set_defaults(func=_run, parser=run)
    results_page.add_subcommand(sub)
    from .bridge.cli import add_subcommands
    from .data.command import add_subcommands as add_data_subcommands

    add_subcommands(sub)
    add_data_subcommands(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:   # a misspelt option (--quik) gets its own command's usage, not the top one
        commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        commands.choices[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
    return guarded(args.func, args, "snn-antenna")


if __name__ == "__main__":
    sys.exit(main())
