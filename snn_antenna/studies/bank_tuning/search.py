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
from ...readout.bank_design import bank_of, neuron_steps_per_event, start_params
from ...readout.spiking import SpikingBank, recording_attrs
from ...readout.spiking_decoders import code_rows, codes_of, mlp_baseline
from .plan import SPACE_KEYS, Parts

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
