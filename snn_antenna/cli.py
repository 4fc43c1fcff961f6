"""The ``snn-antenna`` command.

    snn-antenna run studies/quickstart.toml [--out DIR] [--set key=value ...] [--quick]

Every subcommand takes ``--out DIR``. Errors a user can cause print one clear line and exit
with status 2; they never show a traceback from deep inside Brian2 or numpy.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .core import bounds
from .core.bounds import option
from .core.errors import SpecError, guarded
from .report import results as results_page


def _run(args) -> int:
    from .core import outputs
    from .core import spec as specs
    from .engine.executor import probe_scheduler
    from .engine.spec_rules import check_spec
    from .studies import runner

    # Every check before any work: the spec as resolved, the rules joining its sections, the
    # size of a sweep, the output folder. Nothing here imports Brian2 or starts a worker.
    spec = specs.load(args.spec, args.set, quick=args.quick)
    study = spec.get("study")
    module = runner(study)
    check_spec(spec, user_keys=[item.split("=", 1)[0].strip() for item in args.set])
    module.build(spec)                  # every field in its bounds, before sizing the work
    out = Path(args.out) if args.out else Path("out") / Path(args.spec).stem
    probe_scheduler(getattr(args, "scheduler", None))    # what is there, before --out exists
    folder = outputs.prepare(out, study, force=args.force, fresh=args.fresh)  # and lock it
    try:
        _check_cost(spec, args)
        if args.check:                  # everything a run would refuse has been said
            print(f"{args.spec}: the spec and --out {out} are accepted ({study}); "
                  "nothing was run")
            outputs.release(folder)
            return 0
        folder.clear()                  # --force: another study's files, now that all passed
        outputs.claim(folder)
    except BaseException:
        outputs.release(folder)
        raise
    extra = {}
    if getattr(args, "fresh", False):
        extra["fresh"] = True
    if getattr(args, "scheduler", None):
        extra["scheduler"] = args.scheduler
    from .networks.neurons import raise_on_ctrl_c
    raise_on_ctrl_c()                   # Ctrl-C stops the study, never just one Brian2 run
    try:
        module.run(spec, out, quick=args.quick, **extra)
    finally:
        outputs.record(folder)          # what this run wrote, however it ended; unlock
    return 0


def _check_cost(spec: dict, args) -> None:
    """A study (a scene, a bench set, a sweep) expected to run beyond the limit is refused
    without ``--yes``, naming the key that sets its length."""
    from .core import spec as specs
    from .studies import plan

    estimate = plan(spec)
    if estimate is not None:
        from .engine.cost import LONG_SWEEP_S

        sweep = hasattr(estimate, "points")
        print(f"{'sweep: ' if sweep else ''}{estimate.describe()}", file=sys.stderr, flush=True)
        if estimate.seconds > LONG_SWEEP_S and not args.yes:
            key = estimate.key if not sweep else "axes"
            value = f"{estimate.points:,} points" if sweep else specs.get_field(spec, key)
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
                     help="apply the spec's [quick] profile: a small run for tests and first looks")
    run.add_argument("--fresh", action="store_true",
                     help="sweeps: discard stored results and start over")
    run.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                     help="sweeps: run on an existing Dask cluster instead of a local one")
    run.add_argument("--force", action="store_true",
                     help="reuse an --out folder that holds another study's outputs or other "
                          "files: what snn-antenna wrote there is replaced, other files are kept")
    run.add_argument("--check", action="store_true",
                     help="check the spec, its estimate and --out as a run would, then stop "
                          "without running or writing anything")
    run.add_argument("--yes", action="store_true",
                     help="run even when the estimate is beyond the limit (1 h)")
    run.set_defaults(func=_run)
    results_page.add_subcommand(sub)
    try:
        from .bridge.cli import add_subcommands
    except ImportError:
        pass
    else:
        add_subcommands(sub)
    from .data.command import add_subcommands as add_data_subcommands; add_data_subcommands(sub)  # noqa: E702
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
