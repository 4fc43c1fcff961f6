"""The ``snn-antenna`` command.

    snn-antenna run studies/quickstart.toml [--out DIR] [--set key=value ...] [--quick]

Every subcommand takes ``--out DIR``. Errors a user can cause print one clear line and exit
with status 2; they never show a traceback from deep inside Brian2 or numpy.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import NumericalInstabilityError, SpecError


def _run(args) -> int:
    from . import spec as specs
    from .studies import runner

    spec = specs.load(args.spec, args.set, quick=args.quick)
    study = spec.get("study")
    module = runner(study)
    out = Path(args.out) if args.out else Path("out") / Path(args.spec).stem
    extra = {}
    if getattr(args, "fresh", False):
        extra["fresh"] = True
    if getattr(args, "scheduler", None):
        extra["scheduler"] = args.scheduler
    module.run(spec, out, quick=args.quick, **extra)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="snn-antenna",
        description="Spiking neural networks (Brian2) that read an insect-inspired antenna.")
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
    run.set_defaults(func=_run)
    try:
        from .bridge.cli import add_subcommands
    except ImportError:
        pass
    else:
        add_subcommands(sub)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SpecError as exc:
        print(f"snn-antenna: error: {exc}", file=sys.stderr)
        return 2
    except NumericalInstabilityError as exc:
        print(f"snn-antenna: numerical instability: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print("snn-antenna: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
