"""The rules that join a spec's sections, checked before any work (no Brian2 import).

A low-pass below the stimulus's Nyquist, a band the sample rate can code, a read-out window
inside the scene, a Dask worker count this machine can run: each names the key the user
wrote. Studies and the live bridge check their specs here, before they build anything.
"""
from __future__ import annotations

from ..core import bounds
from ..core.errors import SpecError, check, is_number
from ..core.spec import declared_types
from ..networks.resonators import MIN_SAMPLES_PER_CYCLE
from .cost import max_workers

# Where make_chain's arguments come from in a study spec (the rest: ``preprocess.NAME``).
CHAIN_KEYS = {"adc_bits": "stimulus.adc_bits", "full_scale_g": "stimulus.full_scale_g"}


def check_spec(spec: dict, user_keys=(), rate_hz: float | None = None) -> None:
    """The cross-section rules every study shares, before any work (no Brian2 import).

    ``user_keys`` are the dotted keys the user set (``--set``): when a rule joins two keys,
    the one the user changed is the one named. ``rate_hz`` is the input sample rate when it
    is not the stimulus's (the serial bridge's board).
    """
    stimulus = spec.get("stimulus") if isinstance(spec.get("stimulus"), dict) else {}
    rate = rate_hz if rate_hz is not None else stimulus.get("rate_hz", 1000.0)
    rate_key = "stimulus.rate_hz" if rate_hz is None else "the board's sample rate"
    if not is_number(rate) or rate <= 0:
        raise SpecError("stimulus.rate_hz", rate, "a sample rate > 0 Hz")
    _check_preprocess(spec, stimulus, rate, rate_key)
    _check_readout(spec, stimulus, rate)
    _check_network_rate(spec, rate, rate_key, set(user_keys))
    _check_workers(spec)
    check_seeds(spec)


SEED_KEYS = ("seed", "seeds")   # a seed, or a list of them, wherever a table holds one


def check_seeds(spec: dict) -> None:
    """Every seed of the spec, at any depth, within what every consumer of a seed takes
    (``bounds.seed``): refused here, not when the stage that uses it starts."""
    stack = [("", spec)]
    while stack:
        where, table = stack.pop()
        for key, value in table.items():
            dotted = f"{where}{key}"
            if key in SEED_KEYS:
                for i, one in enumerate(value if isinstance(value, list) else [value]):
                    bounds.seed(dotted if not isinstance(value, list) else f"{dotted}.{i}",
                                one)
            elif isinstance(value, dict):
                stack.append((f"{dotted}.", value))
            elif isinstance(value, list):
                stack += [(f"{dotted}.{i}.", v) for i, v in enumerate(value)
                          if isinstance(v, dict)]


def _check_preprocess(spec, stimulus, rate, rate_key) -> None:
    table = spec.get("preprocess")
    if not isinstance(table, dict) or not table:
        return
    from ..preprocess import make_chain  # lazy: scikit-learn loads with a spec, not the CLI

    # The chain's parameters are numbers (None where optional) but for the coder's name.
    for key, tp in declared_types(make_chain).items():
        value = table.get(key)
        if key in table and tp is not str and not (is_number(value) or
                                                   (value is None and tp is not float)):
            raise SpecError(f"preprocess.{key}", value, "a finite number")
    # keys of the table that are not the chain's (e.g. warmup_s, how long the chain is fitted)
    # have rules of their own in the study; an unknown key is named by the study's own check
    chain_keys = {k: v for k, v in table.items() if k in declared_types(make_chain)}
    try:                                    # the stages' own rules, not a copy of them
        make_chain(rate, stimulus.get("adc_bits", 10), stimulus.get("full_scale_g", 18.0),
                   **chain_keys)
    except SpecError as exc:
        key = rate_key if exc.field == "rate_hz" else CHAIN_KEYS.get(
            exc.field, f"preprocess.{exc.field}")
        raise SpecError(key, exc.value,
                        exc.accepted.replace("rate_hz =", f"{rate_key} =")) from None


def _check_readout(spec, stimulus, rate) -> None:
    table = spec.get("readout")
    if not isinstance(table, dict) or "window_s" not in table:
        return
    window = table["window_s"]
    duration = stimulus.get("duration_s")
    longest = f" and at most stimulus.duration_s = {duration:g} s" if is_number(duration) else ""
    # one input sample at least: a finer rate map only repeats samples (and may not fit)
    check(is_number(window) and window >= 1 / rate
          and (not is_number(duration) or window <= duration),
          "readout.window_s", window, f"a window of at least one sample ({1 / rate:g} s at "
          f"{rate:g} Hz){longest}")


def _check_network_rate(spec, rate, rate_key, user_keys) -> None:
    """A band the input rate can code, blamed on the key the user changed."""
    table = spec.get("network")
    if not isinstance(table, dict) or "band_hz" not in table:
        return
    band = table["band_hz"]
    if not (isinstance(band, (list, tuple)) and len(band) == 2 and all(map(is_number, band))):
        return                  # the type check names it

    top = rate / MIN_SAMPLES_PER_CYCLE
    if float(band[1]) <= top:
        return
    if rate_key == "stimulus.rate_hz" and rate_key in user_keys \
            and "network.band_hz" not in user_keys:
        raise SpecError(rate_key, rate,
                        f"a sample rate of at least {MIN_SAMPLES_PER_CYCLE * band[1]:g} Hz for "
                        f"network.band_hz up to {band[1]:g} Hz ({MIN_SAMPLES_PER_CYCLE} samples "
                        "per cycle)")
    raise SpecError("network.band_hz", band,
                    f"a band up to at most {top:g} Hz at {rate_key} = {rate:g} Hz "
                    f"({MIN_SAMPLES_PER_CYCLE} samples per cycle)"
                    + (", or a higher stimulus.rate_hz" if rate_key == "stimulus.rate_hz"
                       else ""))


def _check_workers(spec) -> None:
    table = spec.get("sweep")
    if not isinstance(table, dict) or "workers" not in table:
        return

    workers, limit = table["workers"], max_workers()
    check(isinstance(workers, int) and not isinstance(workers, bool) and 0 <= workers <= limit,
          "sweep.workers", workers,
          f"an integer in [0, {limit}] (0: one per core; this machine has cores and memory "
          f"for {limit} worker processes)")
