"""The search: Optuna's seeded multi-objective TPE over a bank's placement, b, coder and
read-out; every trial's bank run on the event engine over tuning contacts only.

A trial's bank: ``band_tuning.tune`` places its channels from the tuning contacts' spectra
and labels, with the trial's ``Tuning`` fields, and ``low_band`` adds the trial's
``low_resonators`` on the antenna's low mode (distance, with its own b and coder); the
channels' resonators take the trial's b; it runs on
the event engine (``engine.events.run_bank``, on Dask workers when given a client) and is read
by the trial's read-out (``TUNED_READOUTS``). Objectives: the mean accuracy of the material
MLP (51 hidden) over splits by repetition of the tuning contacts (``inner_seeds``), and the
bank's resonator-steps per contact (its cost, known before it runs). A second stage
(``refine``) scores the most accurate banks within the cost budget again on more contacts of
another seed, and the front the study evaluates is ranked by that score.

Nothing evaluated enters the search: every contact a trial is scored on is registered
(``Scored``: a digest of its samples), and ``check_unseen`` refuses a search that scored any
contact of the evaluated set, before any of its numbers is reported.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import optuna
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from threadpoolctl import threadpool_limits

from ...core.errors import NumericalInstabilityError, SpecError
from ...core.files import write_json
from ...engine.events import run_bank
from ...evaluation import crossval as cv
from ...readout.band_tuning import coarsest_dt_ms, tune
from ...readout.spiking import LOW_BAND, Band, SpikingBank, recording_attrs
from ...readout.spiking_decoders import code_rows, codes_of, mlp_baseline
from .plan import SPACE_KEYS, BankPlan, Parts

OBJECTIVES = ("accuracy", "neuron_steps_per_event")


def event_digests(counts: np.ndarray) -> set[str]:
    """A digest of each contact's samples (rows of ``counts``)."""
    return {hashlib.blake2b(np.ascontiguousarray(row).tobytes(), digest_size=12).hexdigest()
            for row in counts}


class Scored:
    """The contacts the search has scored banks on, by digest; kept in ``path`` (JSON,
    written after every trial) so a resumed search carries what its earlier trials saw."""

    def __init__(self, path: Path | None = None):
        self.path = path
        self.digests: set[str] = set()
        if path is not None and path.is_file():
            self.digests = set(json.loads(path.read_text()))

    def add(self, counts: np.ndarray) -> None:
        self.digests |= event_digests(counts)
        if self.path is not None:
            write_json(self.path, sorted(self.digests), indent=None)


def check_unseen(scored: Scored, evaluated_counts: np.ndarray) -> None:
    """Refuse a search that scored any contact of the evaluated set (its accuracy would not
    be out of sample), naming how many."""
    seen = scored.digests & event_digests(evaluated_counts)
    if seen:
        raise SpecError("search", f"{len(seen)} evaluated contact(s) scored by the search",
                        "a search scored on tuning contacts only (another seed), so the "
                        "reported accuracy comes from contacts it never saw")


def start_params(bank: BankPlan) -> dict:
    """The starting bank as a point of the space (the search's first trial)."""
    t = bank.base
    return {"channels": t.n_channels,
            "per_channel": t.resonators_per_channel // max(1, len(t.gains)),
            "range_low_hz": float(t.range_hz[0]), "range_high_hz": float(t.range_hz[1]),
            "quantile": float(t.quantile), "spread": float(t.spread), "b": float(bank.b),
            "gain": float(np.sqrt(t.gains[0] * t.gains[-1]) if t.gains
                          else t.coder_options.get("gain", 150.0)),
            "gain_levels": max(1, len(t.gains)),
            "gain_ratio": float((t.gains[-1] / t.gains[0]) ** (1 / (len(t.gains) - 1)))
                          if len(t.gains) > 1 else 7.0,
            "k_dt_factor": 1.0,
            "coder_amplitude": float(t.coder_amplitude), "threshold_g": float(t.threshold_g),
            "low_resonators": int(bank.low_resonators), "readout": bank.readout,
            "scaling": bank.scaling, "filter_order": int(bank.filter_order)}


def suggest(trial, space: dict) -> dict:
    """The trial's point: the space's keys suggested, the others left to the start."""
    params = {}
    for key, value in space.items():
        kind = SPACE_KEYS[key][0]
        if kind == "choice":
            params[key] = trial.suggest_categorical(key, list(value))
        elif kind in ("int", "count"):
            params[key] = trial.suggest_int(key, int(value[0]), int(value[1]))
        else:
            params[key] = trial.suggest_float(key, float(value[0]), float(value[1]),
                                              log=kind == "log")
    return params


def bank_of(params: dict, bank: BankPlan, counts, labels, attrs) -> SpikingBank:
    """The bank of a point of the space, its channels placed from ``counts`` and ``labels``
    (tuning contacts)."""
    t = bank.base
    lo, hi = params["range_low_hz"], params["range_high_hz"]
    if hi <= lo:
        raise SpecError("range_high_hz", hi, f"above range_low_hz {lo:g} Hz")
    options = dict(t.coder_options)
    if t.coder == "analog":
        options["gain"] = float(params["gain"])
    levels = int(params["gain_levels"])
    gains = tuple(options["gain"] * float(params["gain_ratio"]) ** (i - (levels - 1) / 2)
                  for i in range(levels)) if levels > 1 else ()
    per_channel = params["per_channel"] * levels
    tuning = replace(t, n_resonators=params["channels"] * per_channel, gains=gains,
                     max_k_dt=float(t.max_k_dt * params["k_dt_factor"]),
                     per_channel=per_channel, max_channels=params["channels"],
                     range_hz=(lo, hi), quantile=params["quantile"], spread=params["spread"],
                     coder_amplitude=params["coder_amplitude"],
                     threshold_g=params["threshold_g"], coder_options=options)
    n_samples = int(round(bank.duration_s * attrs[0]))
    bands = tune(counts[:, :n_samples], labels, *attrs, tuning)
    order = int(params.get("filter_order", bank.filter_order))
    bands = {k: replace(b, filter_order=order) for k, b in bands.items()}
    bands = {k: replace(b, b=float(params["b"])) for k, b in bands.items()}
    if params.get("low_resonators", 0) > 0:
        bands["low"] = low_band(int(params["low_resonators"]), bank, tuning)
    return SpikingBank(bands=bands, duration_s=bank.duration_s, target=bank.target,
                       batch_events=bank.batch_events, bin_edges_s=bank.bin_edges_s)


def low_band(n: int, bank: BankPlan, tuning) -> Band:
    """``n`` resonators in log over ``bank.low_band_hz`` behind a low-pass (the antenna's
    low mode, whose frequency carries the contact's distance), with the low band's own b and
    square-wave coder (``BankPlan``), at the coarsest step the channels' k·dt allows
    (``LOW_BAND``'s driven Hz per unit k)."""
    lo, hi = (float(f) for f in bank.low_band_hz)
    return Band(n_neurons=n, band_hz=(lo, hi), spacing="log", b=float(bank.low_b),
                coder_amplitude=float(bank.low_coder_amplitude),
                threshold_g=float(bank.low_threshold_g),
                lowpass_hz=float(bank.low_lowpass_hz), highpass_hz=None,
                hz_per_k=LOW_BAND.hz_per_k, method=tuning.method,
                dt_ms=coarsest_dt_ms(hi, LOW_BAND.hz_per_k, tuning.max_k_dt),
                filter_order=LOW_BAND.filter_order, coder="square")


def neuron_steps_per_event(bank: SpikingBank, rate_hz: float) -> float:
    """Resonator-steps a contact costs the bank: each channel's resonators × its steps."""
    return float(sum(b.n_neurons * round(bank.duration_s * 1000.0 / (b.dt_ms or bank.dt_ms))
                     for b in bank.bands.values()))


def readout_matrix(spikes, readout: str, scaling: str, bin_edges_s) -> np.ndarray:
    """The read-out's input rows from ``SpikeFeatures`` (``spiking_decoders.code_rows``) of
    a bank with time bins at ``bin_edges_s``."""
    codes = codes_of(spikes.counts, spikes.latency_s, spikes.span_s, spikes.binned_counts,
                     [0.0, *bin_edges_s])
    return code_rows(codes, readout, scaling)


def inner_accuracy(X, y, repetition, search, evaluation) -> list[float]:
    """The material MLP's accuracy on each inner split by repetition of the tuning set."""
    mlp = mlp_baseline("trial", "material", "trial", evaluation)
    out = []
    for seed in search.inner_seeds:
        train, test = cv.split_by_repetition(repetition, search.test_fraction, seed)
        fold = cv.fit_fold(mlp, X, y, train, test, seed)
        out.append(float(np.mean(fold.prediction == y[test])))
    return out


def most_accurate(trials) -> list:
    """``trials`` by their accuracy on the tuning contacts, the cheaper first on a tie."""
    return sorted(trials, key=lambda t: (-t.values[0], t.values[1], t.number))


def contact_labels(data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bench data set's counts, material labels (strings) and material indices."""
    labels = np.asarray(data["material"].values.astype(str))
    materials = sorted(set(labels))
    return data["counts"].values, labels, np.array([materials.index(m) for m in labels])


def bank_accuracy(b: SpikingBank, params: dict, data, parts: Parts, scored: Scored,
                  client) -> list[float]:
    """The material MLP's accuracy on each inner split by repetition of ``data`` (contacts
    the search may see: registered in ``scored``), read by the point's read-out from bank
    ``b``'s spikes."""
    counts, _, y = contact_labels(data)
    spikes = run_bank(b, counts, *recording_attrs(data), client=client, progress=False)
    scored.add(counts)
    with threadpool_limits(1):
        return inner_accuracy(readout_matrix(spikes, params["readout"], params["scaling"],
                                             b.bin_edges_s),
                              y, data["repetition"].values, parts.search, parts.evaluation)


def refine(study, parts: Parts, tuning, refining, budget_steps: float, scored: Scored,
           path: Path, client, log) -> dict[int, list[float]]:
    """The second stage (``SearchPlan.refine_repetitions``): the ``refine_top`` most accurate
    trials within ``budget_steps`` resonator-steps per contact, each bank (its channels
    placed from the tuning contacts, as in its trial) scored on ``refining`` contacts.
    Kept in ``path`` (JSON, trial number → accuracies) after every bank: a resumed run
    scores only the banks it has not."""
    done = {int(k): v for k, v in json.loads(path.read_text()).items()} \
        if path.is_file() else {}
    trials = most_accurate(t for t in study.trials if t.state.name == "COMPLETE"
                           and t.values[1] <= budget_steps)
    counts, labels, _ = contact_labels(tuning)
    attrs = recording_attrs(tuning)
    start = start_params(parts.bank)
    out = {}
    for t in trials[:parts.search.refine_top]:
        if t.number not in done:
            params = {**start, **t.params}
            b = bank_of(params, parts.bank, counts, labels, attrs)
            done[t.number] = bank_accuracy(b, params, refining, parts, scored, client)
            write_json(path, {str(k): v for k, v in sorted(done.items())})
        out[t.number] = done[t.number]
        log(f"      trial {t.number}: accuracy {100 * t.values[0]:.1f} % on the tuning "
            f"contacts, {100 * np.mean(out[t.number]):.1f} % on the refining contacts")
    return out


def run_search(parts: Parts, tuning, storage_path: Path, scored: Scored, client, log):
    """The Optuna study of ``parts.search`` on ``tuning`` (the tuning contacts' data set),
    stored in ``storage_path`` (a journal file: an interrupted search resumes, a finished
    one is reused); trials that did not finish are left out and run again."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    search, bank = parts.search, parts.bank
    storage = JournalStorage(JournalFileBackend(str(storage_path)))
    study = optuna.create_study(
        study_name="bank_tuning", storage=storage, load_if_exists=True,
        directions=["maximize", "minimize"],
        sampler=optuna.samplers.TPESampler(seed=int(parts.bench.seed), n_startup_trials=6))
    attrs = recording_attrs(tuning)
    counts, labels, _ = contact_labels(tuning)
    start = start_params(bank)

    def objective(trial):
        params = {**start, **suggest(trial, search.space)}
        b = bank_of(params, bank, counts, labels, attrs)
        cost = neuron_steps_per_event(b, attrs[0])
        trial.set_user_attr("resonators", b.n_neurons)
        trial.set_user_attr("neuron_hz", [float(f) for f in b.neuron_hz])
        try:
            acc = bank_accuracy(b, params, tuning, parts, scored, client)
        except NumericalInstabilityError as exc:    # a b or k·dt the step cannot carry
            trial.set_user_attr("failed", str(exc).splitlines()[0])
            raise optuna.TrialPruned() from None
        trial.set_user_attr("inner_accuracy", acc)
        log(f"      trial {trial.number}: {b.n_neurons} resonators in {len(b.bands)} "
            f"bands, {params['readout']} ({params['scaling']}): "
            f"accuracy {100 * np.mean(acc):.1f} %, "
            f"{cost:.0f} resonator-steps per contact")
        return float(np.mean(acc)), cost

    done = [t for t in study.trials if t.state.name in ("COMPLETE", "PRUNED")]
    if not done:       # the starting bank first: the front is measured against it
        study.enqueue_trial({k: start[k] for k in search.space})
    todo = search.trials - len(done)
    if todo > 0:
        log(f"      {len(done)} trial(s) stored, {todo} to run")
        study.optimize(objective, n_trials=todo)
    else:
        log(f"      {len(done)} trial(s) stored in {storage_path.name}, reused")
    return study
