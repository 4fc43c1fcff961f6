"""The ``snn-antenna`` command.

    snn-antenna run studies/quickstart.toml [--out DIR] [--set key=value ...] [--quick]

Every subcommand takes ``--out DIR``. Errors a user can cause print one clear line and exit
with status 2; they never show a traceback from deep inside Brian2 or numpy.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import SpecError, guarded


def _run(args) -> int:
    from . import outputs
    from . import spec as specs
    from .studies import check_spec, runner

    # Every check before any work: the spec as resolved, the rules joining its sections, the
    # size of a sweep, the output folder. Nothing here imports Brian2 or starts a worker.
    spec = specs.load(args.spec, args.set, quick=args.quick)
    study = spec.get("study")
    module = runner(study)
    check_spec(spec, user_keys=[item.split("=", 1)[0].strip() for item in args.set])
    out = Path(args.out) if args.out else Path("out") / Path(args.spec).stem
    folder = outputs.prepare(out, study, force=args.force, fresh=args.fresh)  # and lock it
    try:
        _check_cost(spec, args)
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
    """A sweep expected to run beyond the limit is refused without ``--yes``."""
    from .studies import plan

    estimate = plan(spec)
    if estimate is not None:
        from .engine.cost import LONG_SWEEP_S

        print(f"sweep: {estimate.describe()}", file=sys.stderr, flush=True)
        if estimate.seconds > LONG_SWEEP_S and not args.yes:
            raise SpecError("axes", f"{estimate.points:,} points",
                            f"a sweep expected to take at most {LONG_SWEEP_S / 3600:g} h "
                            f"(this one: about {estimate.seconds / 3600:.3g} h); shrink an "
                            "axis, or pass --yes to run it anyway")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="snn-antenna",
        description="Spiking neural networks (Brian2) that read an insect-inspired antenna.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a study spec (studies/*.toml) and write its report")
    run.add_argument("spec", help="path of a study spec, e.g. studies/quickstart.toml")
    run.add_argument("--out", help="output folder (default out/SPEC-NAME)")
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
    run.add_argument("--yes", action="store_true",
                     help="sweeps: run even when the estimate is beyond the limit (1 h)")
    run.set_defaults(func=_run)
    try:
        from .bridge.cli import add_subcommands
    except ImportError:
        pass
    else:
        add_subcommands(sub)
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
