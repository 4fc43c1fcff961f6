"""The ``data`` subcommand: ``snn-antenna data import RECORDINGS LABELS --out DIR``."""
from __future__ import annotations

import sys

from ..core import bounds
from ..core.bounds import option
from ..bridge.wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G
from .inputs import UNITS, Options, parse_columns
from .segment import Segmentation


def add_subcommands(subparsers) -> None:
    """Add ``data import`` to an argparse subparsers object."""
    data = subparsers.add_parser("data", help="turn recordings of a real antenna into a "
                                              "labelled data set the studies read")
    actions = data.add_subparsers(dest="data_command", required=True, metavar="ACTION",
                                  help="import: recordings and their labels into a data set")
    p = actions.add_parser(
        "import", help="check recordings and their labels, then write the data set",
        description="Read every recording (folders written by `snn-antenna record`, CSV, NumPy, "
                    "WAV, ROS 2 bags) and the labels table, find the contacts by the paper's "
                    "onset rule, match them to the labels, and write the data set whole (every "
                    "check first; nothing is written when one fails). A study reads it with "
                    "data = \"DIR\" in its spec.")
    p.add_argument("recordings", help="a folder of recordings (or one `record` folder)")
    p.add_argument("labels", help="the labels table (CSV: recording, onset_s, distance_cm, "
                                  "material, optionally repetition)")
    p.add_argument("--out", required=True, type=option(bounds.out_path, text=True),
                   help="the data set's folder (new or empty, or an earlier import's)")
    p.add_argument("--force", action="store_true",
                   help="use an --out folder holding other files: what snn-antenna wrote there "
                        "is replaced, other files are kept")
    p.add_argument("--rate", type=option(bounds.rate_hz), default=None, metavar="HZ",
                   help="sample rate of recordings that state none (.npy, CSV without t_s); "
                        "must agree with the rate any recording states")
    seg = Segmentation()
    p.add_argument("--units", choices=UNITS, default=None,
                   help="what CSV and NumPy values are: ADC counts (default), g or m/s2 "
                        "(quantised to --adc-bits, 16 by default)")
    p.add_argument("--adc-bits", type=option(lambda f, v: bounds.integer(f, v, 4, 24)),
                   default=None,
                   help=f"bits of the ADC: of CSV/NumPy counts (default {BOARD_ADC_BITS}, the "
                        "board's), of a WAV's PCM when narrower than its container, of the "
                        "counts accelerations are quantised to (default 16); refused where a "
                        "format fixes it")
    p.add_argument("--full-scale-g", type=option(lambda f, v: bounds.number(
        f, v, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)), default=None,
        help=f"the sensor's range ± g (default {BOARD_FULL_SCALE_G:g}, the board's)")
    p.add_argument("--signed", action="store_true",
                   help="counts are signed (two's complement, 0 at rest), not offset binary")
    p.add_argument("--axes", default="xy",
                   help="the two axes of the antenna's plane, of x, y, z (default xy)")
    p.add_argument("--columns", type=option(lambda f, v: parse_columns(v), text=True),
                   default={}, metavar="NAME=COLUMN,...",
                   help="a CSV's column of each of t_s, x, y, z, when its header names them "
                        "otherwise (e.g. t_s=time,x=ax,y=ay); other columns are then ignored")
    p.add_argument("--clock-offset-s", type=option(bounds.number), default=0.0, metavar="S",
                   help="seconds added to every label's time: the labels' clock runs this "
                        "much behind the recordings' (default 0; an import whose labels fit "
                        "the recordings only when shifted says by how much)")
    p.add_argument("--topic", default=None, help="ROS 2 bags: the sensor_msgs/msg/Imu topic "
                                                 "(default: the bag's only one)")
    for name, help_text in (
            ("onset_threshold_g", "a contact starts where |main axis| first exceeds this (g)"),
            ("quiet_s", "below the threshold this long just before an onset (s)"),
            ("dead_s", "at least this long after the previous onset (s)"),
            ("match_s", "a label and an onset at most this far apart are one contact (s)"),
            ("pre_trigger_s", "each event starts this long before its onset (s)"),
            ("duration_s", "and lasts this long after it (s)")):
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, default=getattr(seg, name),
                       type=option(bounds.number),
                       help=f"{help_text}; default {getattr(seg, name):g}")
    p.set_defaults(func=cmd_import)


def cmd_import(args) -> int:
    from .importer import check_out, plan_import, write_import

    log = lambda text: print(text, file=sys.stderr, flush=True)    # noqa: E731
    check_out(args.out, args.force, args.recordings)     # before reading anything
    options = Options(rate_hz=args.rate, adc_bits=args.adc_bits,
                      full_scale_g=args.full_scale_g, topic=args.topic, units=args.units,
                      signed=args.signed, axes=args.axes, columns=args.columns)
    seg = Segmentation(**{name: getattr(args, name) for name in (
        "onset_threshold_g", "quiet_s", "dead_s", "match_s", "pre_trigger_s", "duration_s")})
    plan = plan_import(args.recordings, args.labels, options, seg, log=log,
                       clock_offset_s=args.clock_offset_s)
    write_import(plan, args.out, force=args.force, log=log)
    print(args.out)
    return 0
