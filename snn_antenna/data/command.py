"""The ``data`` subcommand: ``snn-antenna data import RECORDINGS LABELS --out DIR``."""
from __future__ import annotations

import sys

from ..bridge.wire.protocol import BOARD_ADC_BITS, BOARD_FULL_SCALE_G
from ..core import bounds
from ..core.commands import POSITIONAL, SWITCH, Command, Option
from ..core.outputs import output_folder
from .importer import STUDY, check_outside_recordings, plan_import, write_import
from .inputs import UNITS, Options as InputOptions, parse_columns
from .segment import Segmentation

SEGMENTATION = Segmentation()
SEGMENTATION_HELP = (
    ("onset_threshold_g", "a contact starts where |main axis| first exceeds this (g)"),
    ("quiet_s", "below the threshold this long just before an onset (s)"),
    ("dead_s", "at least this long after the previous onset (s)"),
    ("match_s", "a label and an onset at most this far apart are one contact (s)"),
    ("pre_trigger_s", "each event starts this long before its onset (s)"),
    ("duration_s", "and lasts this long after it (s)"))


def _adc_bits(field: str, value) -> int:
    return bounds.integer(field, value, 4, 24)


def _full_scale_g(field: str, value) -> float:
    return bounds.number(field, value, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)


def _columns(field: str, value) -> dict:
    return value if isinstance(value, dict) else parse_columns(value)


def cmd_import(options) -> int:
    log = lambda text: print(text, file=sys.stderr, flush=True)    # noqa: E731
    check_outside_recordings(options.out, options.recordings)      # before any reading
    with output_folder(options.out, STUDY, force=options.force) as folder:
        inputs = InputOptions(rate_hz=options.rate, adc_bits=options.adc_bits,
                              full_scale_g=options.full_scale_g, topic=options.topic,
                              units=options.units, signed=options.signed, axes=options.axes,
                              columns=options.columns or {})
        seg = Segmentation(**{name: getattr(options, name) for name, _ in SEGMENTATION_HELP})
        plan = plan_import(options.recordings, options.labels, inputs, seg, log=log,
                           clock_offset_s=options.clock_offset_s)
        folder.claim()
        write_import(plan, folder.path, log=log)
    print(options.out)
    return 0


COMMANDS = (
    Command("import", "check recordings and their labels, then write the data set", cmd_import, (
        Option("recordings", "a folder of recordings (or one `record` folder)",
               kind=POSITIONAL),
        Option("labels", "the labels table (CSV: recording, onset_s, distance_cm, material, "
                         "optionally repetition)", kind=POSITIONAL),
        Option("out", "the data set's folder (new or empty, or an earlier import's; not inside "
                      "the recordings folder)", check=bounds.out_path, text=True, required=True),
        Option("force", "use an --out folder holding other files: what snn-antenna wrote "
                        "there is replaced, other files are kept", kind=SWITCH),
        Option("rate", "sample rate of recordings that state none (.npy, CSV without t_s); "
                       "must agree with the rate any recording states", check=bounds.rate_hz,
               metavar="HZ"),
        Option("units", "what CSV and NumPy values are: ADC counts (default), g or m/s2 "
                        "(quantised to --adc-bits, 16 by default)", choices=UNITS),
        Option("adc_bits", f"bits of the ADC: of CSV/NumPy counts (default {BOARD_ADC_BITS}, "
                           "the board's), of a WAV's PCM when narrower than its container, of "
                           "the counts accelerations are quantised to (default 16); refused "
                           "where a format fixes it", check=_adc_bits),
        Option("full_scale_g", f"the sensor's range ± g (default {BOARD_FULL_SCALE_G:g}, the "
                               "board's)", check=_full_scale_g),
        Option("signed", "counts are signed (two's complement, 0 at rest), not offset binary",
               kind=SWITCH),
        Option("axes", "the two axes of the antenna's plane, of x, y, z (default xy)",
               default="xy"),
        Option("columns", "a CSV's column of each of t_s, x, y, z, when its header names them "
                          "otherwise (e.g. t_s=time,x=ax,y=ay); other columns are then ignored",
               check=_columns, text=True, metavar="NAME=COLUMN,..."),
        Option("clock_offset_s", "seconds added to every label's time: the labels' clock runs "
                                 "this much behind the recordings' (default 0; an import whose "
                                 "labels fit the recordings only when shifted says by how "
                                 "much)", check=bounds.number, default=0.0, metavar="S"),
        Option("topic", "ROS 2 bags: the sensor_msgs/msg/Imu topic (default: the bag's only "
                        "one)"),
        *(Option(name, f"{text}; default {getattr(SEGMENTATION, name):g}",
                 check=bounds.number, default=getattr(SEGMENTATION, name))
          for name, text in SEGMENTATION_HELP)),
        description="Read every recording (folders written by `snn-antenna record`, CSV, "
                    "NumPy, WAV, ROS 2 bags) and the labels table, find the contacts by the "
                    "paper's onset rule, match them to the labels, and write the data set whole "
                    "(every check first; nothing is written when one fails). A study reads it "
                    "with data = \"DIR\" in its spec.",
        group=("data", "turn recordings of a real antenna into a labelled data set the "
                       "studies read", "import: recordings and their labels into a data set")),
)
