"""The ``data`` subcommand: ``snn-antenna data import RECORDINGS LABELS --out DIR``."""
from __future__ import annotations

import sys

from ..core import bounds
from ..core.commands import POSITIONAL, SWITCH, Command, Option
from ..core.outputs import output_folder
from .importer import STUDY, plan_import, write_import
from .inputs import Options as InputOptions
from .segment import Segmentation

DEFAULTS, SEGMENTATION = InputOptions(), Segmentation()
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


def cmd_import(options) -> int:
    log = lambda text: print(text, file=sys.stderr, flush=True)    # noqa: E731
    with output_folder(options.out, STUDY, force=options.force) as folder:  # before any reading
        inputs = InputOptions(rate_hz=options.rate, adc_bits=options.adc_bits,
                              full_scale_g=options.full_scale_g, topic=options.topic)
        seg = Segmentation(**{name: getattr(options, name) for name, _ in SEGMENTATION_HELP})
        plan = plan_import(options.recordings, options.labels, inputs, seg, log=log)
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
        Option("out", "the data set's folder (new or empty, or an earlier import's)",
               check=bounds.out_path, text=True, required=True),
        Option("force", "use an --out folder holding other files: what snn-antenna wrote "
                        "there is replaced, other files are kept", kind=SWITCH),
        Option("rate", "sample rate of recordings that state none (.npy, CSV without t_s); "
                       "must agree with the rate any recording states", check=bounds.rate_hz,
               metavar="HZ"),
        Option("adc_bits", f"ADC bits of CSV/NumPy counts (default {DEFAULTS.adc_bits}, the "
                           "board's)", check=_adc_bits, default=DEFAULTS.adc_bits),
        Option("full_scale_g", f"the sensor's range ± g (default {DEFAULTS.full_scale_g:g}, "
                               "the board's)", check=_full_scale_g,
               default=DEFAULTS.full_scale_g),
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
