"""The bank-tuning study's plan: the bench set, the event processor and the splits (the
FFT-MLP's), the starting bank (``[bank]``) and the search (``[search]``, its space), all
checked before any long work; its cost."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from ...core import bounds
from ...core import spec as specs
from ...core.errors import SpecError, check, is_number
from ...engine import rates
from ...engine.cost import bench_seconds, max_workers, stages_estimate
from ...evaluation import crossval as cv
from ...readout import events
from ...readout.bank_design import BankDesign
from ...readout.spiking_decoders import LOW_BAND_READOUTS, SCALINGS, TUNED_READOUTS
from ...sources.source import BenchSet
from ..contract import COMMON, Plan
from ..sections import bench_section, evaluation_section, events_section

SECTIONS = ("stimulus", "events", "evaluation", "bank", "search")
OPTIONS = (*COMMON, "fresh", "scheduler")

# The search space's keys: (kind, what a value is). "int", "count" (an int that may be 0)
# and "float" take [low, high] (a "float" range whose low is > 0 may be searched in log:
# "log" kind); "choice" a list.
SPACE_KEYS = {
    "channels": ("int", "channels of the bank (narrow band-passes)"),
    "per_channel": ("int", "resonators reading each channel"),
    "range_low_hz": ("float", "lowest channel edge (Hz)"),
    "range_high_hz": ("float", "highest channel edge (Hz)"),
    "quantile": ("float", "Fisher-ratio quantile above which a bin is the material's"),
    "spread": ("float", "a channel's resonators span centre × (1 ± spread)"),
    "b": ("float", "the resonators' b"),
    "gain": ("log", "the analog coder's current per g"),
    "gain_levels": ("int", "graded analog gains per channel, spread in log around gain "
                           "(each with per_channel resonators)"),
    "gain_ratio": ("log", "the factor between a channel's successive graded gains"),
    "k_dt_factor": ("log", "a channel's step may reach this factor x the starting bank's "
                           "largest k·dt (max_k_dt): coarser steps cost less and move the "
                           "resonators' tuning"),
    "coder_amplitude": ("float", "the coder's saturation"),
    "threshold_g": ("float", "the coder's dead zone (g)"),
    "low_resonators": ("count", "resonators of the low-mode band (0: none)"),
    "filter_order": ("int", "order of each channel's Butterworth high- and low-pass"),
    "readout": ("choice", f"read-outs of the bank, out of {sorted(TUNED_READOUTS)}"),
    "scaling": ("choice", f"scalings of the spike counts, out of {sorted(SCALINGS)}"),
}
# A choice key's accepted values, and the largest value of an integer key where one exists
# (``spiking.Band`` takes filter orders 1-8)
CHOICES = {"readout": tuple(TUNED_READOUTS), "scaling": tuple(SCALINGS)}
MAX_VALUE = {"filter_order": 8}


@dataclass
class BankPlan(BankDesign):
    """``[bank]``: the bank the search starts from (``bank_design.BankDesign``: its
    channels' tuning, b, read-out and low band) and how the study runs banks: on
    ``workers`` Dask worker processes (0: one per core; 1: this process), their cost per
    contact the best of ``cost_repeats`` runs on ``cost_sample_events`` contacts."""
    workers: int = 1
    cost_sample_events: int = 200
    cost_repeats: int = 3

    def __post_init__(self):
        super().__post_init__()
        for name, lo in (("workers", 0), ("cost_sample_events", 2), ("cost_repeats", 1)):
            value = getattr(self, name)
            check(isinstance(value, int) and not isinstance(value, bool) and value >= lo,
                  name, value, f"an integer >= {lo}")


@dataclass
class SearchPlan:
    """``[search]``: ``trials`` trials of Optuna's seeded multi-objective TPE over ``space``
    (``SPACE_KEYS``), each bank scored on tuning contacts (``repetitions`` per material and
    site, generated with the study's seed + ``seed_offset``: never evaluated) by the mean
    accuracy over the splits by repetition of ``inner_seeds``; the front's ``front_limit``
    most accurate banks within ``cost_budget`` × the starting bank's neuron-steps per contact
    are then scored on the bench set.

    ``refine_repetitions`` > 0 adds a second stage: the ``refine_top`` most accurate banks
    within the budget are scored again on as many repetitions of refining contacts (another
    seed, ``seed_offset`` + 1: never evaluated either), and the front is ranked by that
    score. A few hundred tuning contacts rank banks within about a point, which is what
    separates the best ones; a second stage spends more contacts on those alone."""
    trials: int = 24
    repetitions: int = 4
    seed_offset: int = 1000
    inner_seeds: list = field(default_factory=lambda: [0, 1])
    test_fraction: float = 0.3
    cost_budget: float = 1.0
    front_limit: int = 2
    refine_repetitions: int = 0
    refine_top: int = 4
    space: dict = field(default_factory=lambda: {"channels": [6, 16], "b": [0.2, 0.32]})

    def __post_init__(self):
        bounds.declared(self)
        for name, lo in (("trials", 1), ("repetitions", 2), ("seed_offset", 1),
                         ("front_limit", 1), ("refine_repetitions", 0), ("refine_top", 1)):
            value = getattr(self, name)
            check(isinstance(value, int) and not isinstance(value, bool) and value >= lo,
                  name, value, f"an integer >= {lo}")
        check(self.refine_repetitions != 1, "refine_repetitions", self.refine_repetitions,
              "0 (no second stage) or an integer >= 2 (splits by repetition)")
        check(isinstance(self.inner_seeds, list) and len(self.inner_seeds) >= 1 and all(
            isinstance(s, int) and s >= 0 for s in self.inner_seeds), "inner_seeds",
            self.inner_seeds, "a non-empty list of integer seeds >= 0")
        check(is_number(self.test_fraction) and 0 < self.test_fraction < 1, "test_fraction",
              self.test_fraction, "a fraction in (0, 1)")
        bounds.number("cost_budget", self.cost_budget, 0.0, 100.0, lo_open=True)
        check(isinstance(self.space, dict) and len(self.space) >= 1, "space", self.space,
              f"a table of searched keys out of {sorted(SPACE_KEYS)}")
        for key, value in self.space.items():
            check_space_entry(key, value)


def check_space_entry(key: str, value) -> None:
    """One key of ``[search.space]``: known, and a [low, high] range or a list of choices."""
    if key not in SPACE_KEYS:
        raise SpecError(f"space.{key}", value, f"a key out of {sorted(SPACE_KEYS)}")
    kind, what = SPACE_KEYS[key]
    if kind == "choice":
        check(isinstance(value, list) and len(value) >= 1 and all(
            isinstance(v, str) and v in CHOICES[key] for v in value), f"space.{key}", value,
            f"a list of {what}")
        return
    ok = (isinstance(value, list) and len(value) == 2 and all(is_number(v) for v in value)
          and value[0] <= value[1] and value[0] >= 0)
    if kind in ("int", "count"):
        ok = ok and all(isinstance(v, int) and v >= (kind == "int") for v in value)
    if kind == "log":
        ok = ok and value[0] > 0
    top = MAX_VALUE.get(key)
    if top is not None:
        ok = ok and value[1] <= top
    check(ok, f"space.{key}", value, f"[low, high] of {what}" +
          (f", at most {top}" if top is not None else "") +
          (", integers >= 1" if kind == "int" else ", integers >= 0" if kind == "count"
           else ", low > 0" if kind == "log" else ", 0 <= low <= high"))


@dataclass
class Parts:
    """The whole spec, every part built and checked before any long work."""
    bench: BenchSet
    processor: events.EventProcessor
    evaluation: cv.Evaluation
    bank: BankPlan
    search: SearchPlan

    def tuning_bench(self):
        """The tuning contacts' source: the bench set's spec with another seed and
        ``search.repetitions`` repetitions (never evaluated)."""
        return replace(self.bench, seed=self.bench.seed + self.search.seed_offset,
                       repetitions=self.search.repetitions)

    def refine_bench(self):
        """The refining contacts' source (``SearchPlan.refine_repetitions``): the bench set's
        spec with a seed of their own (never evaluated)."""
        return replace(self.bench, seed=self.bench.seed + self.search.seed_offset + 1,
                       repetitions=self.search.refine_repetitions)


def plan(spec: dict) -> Plan:
    """Check the whole spec before any long work; build its parts."""
    specs.check_top_level(spec, SECTIONS)
    bench_spec = bench_section(spec)
    check(spec.get("data") is None, "data", spec.get("data"),
          "none: the search's tuning contacts are generated with another seed")
    processor = events_section(spec, bench_spec.rate_hz)
    evaluation = evaluation_section(spec)
    with specs.section("bank"):
        bank = BankPlan(**specs.check_section(spec, "bank", BankPlan))
    with specs.section("search"):
        search = SearchPlan(**specs.check_section(spec, "search", SearchPlan))
    searched = search.space.get("low_resonators")
    if bank.distance_readout in LOW_BAND_READOUTS and searched is not None:
        check(searched[0] >= 1, "search.space.low_resonators", searched,
              f"a range from 1 up: bank.distance_readout '{bank.distance_readout}' reads "
              "the low band of every trial's bank")
    return Plan("bank_tuning", spec, Parts(bench_spec, processor, evaluation, bank, search),
                estimate)


FIT_S_PER_CONTACT = 60.0 / 12800   # the read-outs' fits, per evaluated contact and split
# the load the constants below were measured at: 8 to 20 (the full profile's whole run took
# 10 min at load 14-20; the quick profile's 11.9 s idle)
MEASURED_LOAD = 20.0


def estimate(parts: Parts):
    """The bench set, the tuning contacts, a bank run per trial (the trials shared among the
    Dask workers) and per front bank (on the bench set). Measured on this project's 2-core
    machine under a load of ~8: a trial ~30 ms per tuning contact with its inner MLPs (12
    trials on 512 contacts: 4 min, compiles included), a front bank ~6 ms per evaluated
    contact (400 contacts per 2.2 s chunk) and ~6 s of code generation and MLPs (the quick
    profile's whole run took 25 s at an idle share), and the read-outs' fits per split 60 s
    on 12,800 contacts (2 s for 2 splits of 256 contacts in the quick profile, load 14)."""
    n, tuning = parts.bench.n_events, parts.tuning_bench().n_events
    workers = parts.bank.workers or max_workers()
    search_s = parts.search.trials * (tuning * 0.03 + 5.0) / workers
    if parts.search.refine_repetitions:
        search_s += parts.search.refine_top * (parts.refine_bench().n_events * 0.03 + 5.0)
    front_s = parts.search.front_limit * (n * 0.006 + 6.0) + (
        FIT_S_PER_CONTACT * n * len(parts.evaluation.seeds))
    stages = [("stimulus.repetitions", parts.bench.repetitions, [],
               bench_seconds(n, parts.bench.n_jobs)
               + rates.measured_at(search_s + front_s, MEASURED_LOAD))]
    return stages_estimate("the bench set, the search and its front", stages)
