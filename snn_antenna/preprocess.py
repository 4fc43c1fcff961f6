"""Preprocessing as scikit-learn transformers with a streaming form.

The paper's chain (Fig. 8J): ADC counts → g → PCA alignment (2 axes → 1) → low-pass at 30 Hz →
centring → square-wave coder with amplitude threshold Th. The coder is one of
``CODERS`` (square wave, level crossing, analog current), selected by name in ``make_chain``.

Every stage is causal and keeps its state between calls, so the offline form (``transform`` on
the whole array) and the streaming form (``partial_transform`` on successive chunks) give the
same numbers on the same data, whatever the chunk boundaries. ``transform`` is ``reset`` then
one ``partial_transform``. Parameters are stored as given and validated in ``fit``, as in
scikit-learn, so the stages sit in a ``Pipeline`` and cross-validate with familiar tools.

What a fit learns (the PCA axis and mean) must come from what a robot has before it reads:
``fit_warmup(chain, samples, rate_hz, warmup_s)`` fits on the first ``warmup_s`` of a recording
only (the spec key ``preprocess.warmup_s``), or fit on a separate calibration recording.
Never fit on the recording being read out: its contacts would leak into the alignment.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.pipeline import Pipeline

from .core import bounds
from .core import spec as specs
from .core.errors import SpecError, check, is_number
from .core.signals import validate_samples
from .sources.antenna import ADC


class _Causal(TransformerMixin, BaseEstimator):
    """Shared mechanics: fit validates, transform = reset + partial_transform."""

    def fit(self, X, y=None):
        validate_samples(X, "X")
        bounds.declared(self, **self.get_params())
        self._validate_params_()
        self.reset()
        return self

    def _validate_params_(self) -> None:
        pass

    def reset(self) -> _Causal:
        self.state_ = None
        return self

    def transform(self, X):
        self._require_fit()
        self.reset()
        return self.partial_transform(X)

    def partial_transform(self, X):
        self._require_fit()
        return finite_output(self._step(np.asarray(validate_samples(X, "X"), dtype=float)))

    def _require_fit(self) -> None:
        if not hasattr(self, "state_"):
            raise SpecError(type(self).__name__, "not fitted", "call fit(X) first")

    def _step(self, X):
        raise NotImplementedError


def finite_output(Y: np.ndarray) -> np.ndarray:
    """``Y``, a stage's output, or a SpecError when input finite in itself (values near the
    float64 limit) overflowed the stage: never an inf or a NaN handed on."""
    if not np.all(np.isfinite(Y)):
        raise SpecError("X", "samples whose processing overflows float64",
                        f"samples of magnitude well below {np.finfo(float).max:.3g} "
                        "(real signals are within a few thousand)")
    return Y


class CountsToG(_Causal):
    """ADC counts → acceleration in g (``adc_bits``, ``full_scale_g`` as the sensor board)."""

    def __init__(self, adc_bits: int = 10, full_scale_g: float = 18.0):
        self.adc_bits = adc_bits
        self.full_scale_g = full_scale_g

    def _validate_params_(self):
        bounds.integer("adc_bits", self.adc_bits, 4, 24)
        bounds.number("full_scale_g", self.full_scale_g, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)
        self.adc_ = ADC(self.adc_bits, self.full_scale_g)

    def _step(self, X):
        return self.adc_.to_g(X)


class PCAAlign(_Causal):
    """Project two axes onto their principal axis (the paper's alignment).

    ``fit`` learns the mean and the axis from calibration data; the projection itself is a
    fixed linear map, so streaming needs only a fitted aligner. The axis's sign is fixed (its
    largest component positive) so repeated fits give the same polarity.
    """

    def fit(self, X, y=None):
        X = np.asarray(validate_samples(X, "X"), dtype=float)
        if X.ndim != 2 or X.shape[1] < 2:
            raise SpecError("X", f"array of shape {X.shape}",
                            "two or more axes, shape (n_samples, n_axes)")
        self.mean_ = X.mean(axis=0)
        cov = np.cov((X - self.mean_).T)
        eigval, eigvec = np.linalg.eigh(cov)
        axis = eigvec[:, -1]
        self.axis_ = axis * np.sign(axis[np.argmax(np.abs(axis))])
        self.explained_variance_ratio_ = float(eigval[-1] / max(eigval.sum(), 1e-300))
        self.reset()
        return self

    def _step(self, X):
        if X.ndim != 2 or X.shape[1] != len(self.axis_):
            raise SpecError("X", f"array of shape {X.shape}",
                            f"shape (n_samples, {len(self.axis_)}) as in fit")
        return (X - self.mean_) @ self.axis_


@lru_cache(maxsize=512)
def butter_sos(order: int, cutoff_hz: float, rate_hz: float, btype: str) -> np.ndarray:
    """A Butterworth filter's second-order sections, designed once per (order, cut-off,
    rate, type): a bank's channels fit their chains again on every batch of events, and an
    order-8 design costs more than filtering a batch with it. Callers take a copy (scipy's
    filters want a writable array; a shared one must not change)."""
    from scipy.signal import butter

    return butter(order, cutoff_hz, btype=btype, fs=rate_hz, output="sos")


class LowPass(_Causal):
    """Butterworth low-pass (default 30 Hz, order 4) with the filter state carried across calls.

    The state starts at the steady state of the first sample, so a DC offset does not ring.
    """
    btype = "lowpass"

    def __init__(self, rate_hz: float = 1000.0, cutoff_hz: float = 30.0, order: int = 4):
        self.rate_hz = rate_hz
        self.cutoff_hz = cutoff_hz
        self.order = order

    def _validate_params_(self):
        bounds.rate_hz("rate_hz", self.rate_hz)
        # a cut-off below a millionth of the rate underflows the filter design (and no
        # antenna signal lives there)
        bounds.number("cutoff_hz", self.cutoff_hz, self.rate_hz * 1e-6, self.rate_hz / 2,
                      hi_open=True, unit=f" Hz (below Nyquist at rate_hz = {self.rate_hz:g})")
        bounds.integer("order", self.order, 1, 8)
        self.sos_ = butter_sos(int(self.order), float(self.cutoff_hz), float(self.rate_hz),
                               self.btype).copy()

    def _step(self, X):
        from scipy.signal import sosfilt, sosfilt_zi

        X = np.atleast_1d(X)
        if self.state_ is None:
            zi = sosfilt_zi(self.sos_)
            self.state_ = zi[..., None] * X[0] if X.ndim == 2 else zi * X[0]
        y, self.state_ = sosfilt(self.sos_, X, axis=0, zi=self.state_)
        return y


class HighPass(LowPass):
    """Butterworth high-pass with the filter state carried across calls (e.g. to keep only a
    resonator band's own mode). The state starts at rest, so a first-sample offset passes
    as a step and decays within a few periods of the cut-off."""
    btype = "highpass"

    def _step(self, X):
        from scipy.signal import sosfilt

        X = np.atleast_1d(X)
        if self.state_ is None:
            self.state_ = np.zeros((self.sos_.shape[0], 2) + X.shape[1:])
        y, self.state_ = sosfilt(self.sos_, X, axis=0, zi=self.state_)
        return y


class Centre(_Causal):
    """Remove the slowly varying mean (gravity, drift): x − EMA(x) with time constant tau_s.

    The paper subtracted the mean offline and noted a sliding window would do online; an
    exponential moving average is that sliding window, and it is the same in both forms.
    """

    def __init__(self, rate_hz: float = 1000.0, tau_s: float = 1.0):
        self.rate_hz = rate_hz
        self.tau_s = tau_s

    def _validate_params_(self):
        bounds.rate_hz("rate_hz", self.rate_hz)
        bounds.number("tau_s", self.tau_s, 0.0, lo_open=True, unit=" s")
        self.alpha_ = 1.0 - np.exp(-1.0 / (self.tau_s * self.rate_hz))

    def _step(self, X):
        from scipy.signal import lfilter

        X = np.atleast_1d(X)
        if self.state_ is None:
            # Start the mean at the first sample: no step response from an offset.
            self.state_ = np.asarray((1 - self.alpha_) * X[0])[None, ...]
        mean, self.state_ = lfilter([self.alpha_], [1.0, -(1 - self.alpha_)], X, axis=0,
                                    zi=self.state_)
        return X - mean


class SquareWaveCoder(_Causal):
    """Code the signal's sign as ±``amplitude``; samples with |x| ≤ ``threshold`` give 0.

    The square wave removes amplitude so zero crossings alone trigger the resonators (the
    paper's Fig. 8I); the threshold Th discards sub-threshold fluctuations such as the robot's
    self-motion (Fig. 9). Th is in the units of the incoming signal (g after the chain above).

    Every coder shares ``amplitude`` (the largest current it feeds the neurons) and
    ``threshold`` (at or below it, nothing), and takes a per-sample ``threshold`` from the
    speed gate in ``partial_transform``.
    """

    def __init__(self, amplitude: float = 0.15, threshold: float = 0.0):
        self.amplitude = amplitude
        self.threshold = threshold

    def _validate_params_(self):
        bounds.number("amplitude", self.amplitude, 0.0, bounds.MAX_AMPLITUDE, lo_open=True)
        # a threshold above the signal simply codes silence
        bounds.number("threshold", self.threshold, 0.0)

    def _step(self, X, threshold=None):
        th = self.threshold if threshold is None else threshold
        return np.where(np.abs(X) > th, self.amplitude * np.sign(X), 0.0)

    def partial_transform(self, X, threshold=None):
        """Code a chunk; ``threshold`` (scalar or per sample) overrides Th, e.g. from the gate."""
        self._require_fit()
        return self._step(np.asarray(validate_samples(X, "X"), dtype=float), threshold)


class LevelCoder(SquareWaveCoder):
    """Level-crossing (send-on-delta) coder: the signal's level on a grid of ``levels`` edges
    each side of zero, fed to the neurons as ``amplitude`` × sign × level / ``levels``.

    The edges sit at ``threshold`` + ``step_g`` · (1 + r + … + r^(i−1)) for i = 0 … levels − 1
    (r = ``ratio``: 1 spaces them evenly, 2 doubles each step, so a ringing line decaying
    over decades still crosses a level every few periods). The output changes only when the
    signal crosses an edge: each change is one send-on-delta event, and the staircase is what
    a receiver of those events rebuilds. With ``levels = 1`` it is the square wave; more
    levels keep the amplitude (and so the decay) that the square wave reduces to its sign.
    Stateless per sample, so the streaming and offline forms agree trivially.
    """

    def __init__(self, amplitude: float = 0.15, threshold: float = 0.0, step_g: float = 0.01,
                 levels: int = 4, ratio: float = 2.0):
        super().__init__(amplitude, threshold)
        self.step_g = step_g
        self.levels = levels
        self.ratio = ratio

    def _validate_params_(self):
        super()._validate_params_()
        bounds.number("step_g", self.step_g, 0.0, bounds.MAX_AMPLITUDE, lo_open=True,
                      unit=" g")
        bounds.integer("levels", self.levels, 1, MAX_LEVELS)
        bounds.number("ratio", self.ratio, 1.0, MAX_LEVEL_RATIO)
        i = np.arange(self.levels)
        steps = i if self.ratio == 1.0 else (self.ratio ** i - 1.0) / (self.ratio - 1.0)
        self.edges_above_threshold_ = self.step_g * steps

    def _step(self, X, threshold=None):
        th = self.threshold if threshold is None else np.asarray(threshold, dtype=float)
        over = np.abs(X) - th
        level = np.zeros(np.shape(X))
        for edge in self.edges_above_threshold_:      # a few edges: a count per sample
            level += over > edge
        return (self.amplitude / self.levels) * np.sign(X) * level


class AnalogCoder(SquareWaveCoder):
    """The conditioned signal itself as the neurons' current: ``gain`` (current per g) ×
    (|x| − ``threshold``), with x's sign, saturating at ±``amplitude``; 0 within ±threshold.

    Nothing of the band-passed signal is discarded (amplitude, decay and every component in
    the band reach the resonators); the saturation keeps an impact within the current the
    resonators were validated at. Stateless per sample, like the square wave.
    """

    def __init__(self, amplitude: float = 0.15, threshold: float = 0.0, gain: float = 10.0):
        super().__init__(amplitude, threshold)
        self.gain = gain

    def _validate_params_(self):
        super()._validate_params_()
        bounds.number("gain", self.gain, 0.0, MAX_CODER_GAIN, lo_open=True, unit=" per g")

    def _step(self, X, threshold=None):
        return np.clip(self.gain * self.dead_zone(X, threshold), -self.amplitude,
                       self.amplitude)

    def dead_zone(self, X, threshold=None):
        """The signal less the threshold, with its sign: sign(x) · max(|x| − threshold, 0),
        what the gain scales. Coders that differ only in their gain share it (a resonator
        bank's graded gains: ``SpikingBank.inputs``)."""
        th = self.threshold if threshold is None else np.asarray(threshold, dtype=float)
        out = np.abs(X) - th
        np.maximum(out, 0.0, out=out)
        return np.copysign(out, X, out=out)


# Bounds of the coders' own parameters: more levels than this resolve nothing the sensor's
# 10-bit ADC holds (and cost a pass per level); a ratio above 10 leaves one decade per
# level; a gain above 1e4 per g saturates on the sensor's noise floor.
MAX_LEVELS = 64
MAX_LEVEL_RATIO = 10.0
MAX_CODER_GAIN = 1e4
# The coders by the name a spec selects them with (``preprocess.coder``), and which of
# make_chain's ``coder_*`` arguments each takes (as its own parameter of the same name).
CODERS = {"square": SquareWaveCoder, "delta": LevelCoder, "analog": AnalogCoder}
CODER_OPTIONS = {"square": (), "delta": ("step_g", "levels", "ratio"), "analog": ("gain",)}


def make_coder(coder: str = "square", amplitude: float = 0.15, threshold: float = 0.0,
               **options) -> SquareWaveCoder:
    """The coder named ``coder`` (``CODERS``) with its own options (``CODER_OPTIONS``),
    checked: an option the coder does not take is refused, not ignored."""
    bounds.choice("coder", coder, tuple(CODERS))
    for name in options:
        owners = [c for c, takes in CODER_OPTIONS.items() if name in takes]
        check(name in CODER_OPTIONS[coder], name, options[name],
              f"no value with coder = '{coder}' (it is coder "
              f"{' or '.join(repr(o) for o in owners) or 'nothing'}'s option)")
    stage = CODERS[coder](amplitude, threshold, **options)
    stage._validate_params_()
    return stage


def make_chain(rate_hz: float, adc_bits: int = 10, full_scale_g: float = 18.0,
               lowpass_hz: float = 30.0, lowpass_order: int = 4, centre_tau_s: float = 1.0,
               coder_amplitude: float = 0.15, threshold: float = 0.0,
               highpass_hz: float | None = None, coder: str = "square",
               coder_step_g: float | None = None, coder_levels: int | None = None,
               coder_ratio: float | None = None, coder_gain: float | None = None) -> Pipeline:
    """The paper's preprocessing chain from ADC counts (n, 2) to the coded input current.

    ``highpass_hz`` (default: none) adds a high-pass of the same order after the low-pass,
    making the chain a band-pass, e.g. for resonators above the rod's low mode; it must lie
    below ``lowpass_hz``. A band-pass chain is not centred: its high-pass removes the slowly
    varying mean already, and the moving average, which starts at its input's first sample
    (the high-pass passes a window's first offset as a step), would subtract that sample
    from the whole window: a standing offset as large as the lines a narrow channel codes
    (a 200-resonator tuned bank read the bench's material 3 points worse with it).
    ``coder`` picks the last stage (``CODERS``: the paper's
    ``"square"`` wave, the level-crossing ``"delta"`` coder, the ``"analog"`` current);
    ``coder_amplitude`` and ``threshold`` are every coder's, ``coder_step_g``,
    ``coder_levels``, ``coder_ratio`` (delta) and ``coder_gain`` (analog) its own (None: the
    coder's default; given to a coder that does not take it: refused).
    """
    if highpass_hz is not None and is_number(highpass_hz) and is_number(lowpass_hz):
        check(highpass_hz < lowpass_hz, "highpass_hz", highpass_hz,
              f"a cut-off below lowpass_hz = {lowpass_hz:g} Hz (a band-pass)")
    options = {name: value for name, value in (("step_g", coder_step_g),
                                               ("levels", coder_levels),
                                               ("ratio", coder_ratio), ("gain", coder_gain))
               if value is not None}
    steps = [
        ("to_g", CountsToG(adc_bits, full_scale_g)),
        ("align", PCAAlign()),
        ("lowpass", LowPass(rate_hz, lowpass_hz, lowpass_order)),
    ]
    centre = ("centre", Centre(rate_hz, centre_tau_s))
    if highpass_hz is not None:
        steps.append(("highpass", HighPass(rate_hz, highpass_hz, lowpass_order)))
    else:
        steps.append(centre)
    for name, stage in [*steps, centre]:   # refused where the values enter, not at a fit
        try:
            stage._validate_params_()
        except SpecError as exc:  # named as make_chain's caller wrote it
            raise SpecError(CHAIN_ARGS.get((name, exc.field), exc.field), exc.value,
                            exc.accepted) from None
    try:
        steps.append(("coder", make_coder(coder, coder_amplitude, threshold, **options)))
    except SpecError as exc:
        raise SpecError(CHAIN_ARGS.get(("coder", exc.field), exc.field), exc.value,
                        exc.accepted) from None
    return Pipeline(steps)


# (stage, its parameter) -> make_chain's argument
CHAIN_ARGS = {("to_g", "adc_bits"): "adc_bits", ("to_g", "full_scale_g"): "full_scale_g",
              ("lowpass", "cutoff_hz"): "lowpass_hz", ("lowpass", "order"): "lowpass_order",
              ("highpass", "cutoff_hz"): "highpass_hz", ("highpass", "order"): "lowpass_order",
              ("centre", "tau_s"): "centre_tau_s", ("coder", "amplitude"): "coder_amplitude",
              ("coder", "threshold"): "threshold", ("coder", "step_g"): "coder_step_g",
              ("coder", "levels"): "coder_levels", ("coder", "ratio"): "coder_ratio",
              ("coder", "gain"): "coder_gain"}


# make_chain's arguments that describe the sensor: each source gives its own
SENSOR = ("rate_hz", "adc_bits", "full_scale_g")


@dataclass(frozen=True)
class Preprocessing:
    """``[preprocess]``, checked: ``make_chain``'s settings besides the sensor's."""
    settings: dict

    def chain(self, sensor):
        """An unfitted chain for ``sensor``'s samples (anything with ``rate_hz``,
        ``adc_bits`` and ``full_scale_g``: a scene, a set of recorded drives)."""
        return make_chain(sensor.rate_hz, sensor.adc_bits, sensor.full_scale_g, **self.settings)


def chain_section(spec: dict, sensors: Iterable, gated: bool = False,
                  extra: tuple = ()) -> tuple[Preprocessing, dict]:
    """``[preprocess]``, checked by building its chain for each of ``sensors``; ``gated``: the
    study sets the coder's Th itself, so the section may not. Returns the settings and the
    study's own ``extra`` keys (those the section holds)."""
    exclude = [*SENSOR, "threshold"] if gated else list(SENSOR)
    with specs.section("preprocess"):
        table = dict(specs.check_section(spec, "preprocess", make_chain, exclude=exclude,
                                         extra=list(extra)))
        own = {key: table.pop(key) for key in extra if key in table}
        pre = Preprocessing(table)
        for sensor in sensors:
            pre.chain(sensor)
    return pre, own

def warmup_samples(samples, rate_hz: float, warmup_s: float) -> np.ndarray:
    """The first ``warmup_s`` of ``samples``: what a robot has recorded before it reads out.

    Refuses a warm-up shorter than ten samples or longer than the recording.
    """
    samples = validate_samples(samples, "samples")
    rate_hz = bounds.rate_hz("rate_hz", rate_hz)
    warmup_s = bounds.number("preprocess.warmup_s", warmup_s, 0.0, lo_open=True, unit=" s")
    n = int(round(warmup_s * rate_hz)) if warmup_s * rate_hz < 2**62 else -1
    check(10 <= n <= samples.shape[0], "preprocess.warmup_s",
          warmup_s, f"a warm-up of at least {10 / rate_hz:g} s and at most the recording's "
          f"{samples.shape[0] / rate_hz:g} s")
    return samples[:n]


def fit_warmup(pipeline: Pipeline, samples, rate_hz: float, warmup_s: float) -> Pipeline:
    """Fit the chain on the first ``warmup_s`` of ``samples`` only (see ``warmup_samples``).

    The fitted chain then transforms the whole recording causally, offline or streaming;
    read-outs should ignore what it codes before ``warmup_s`` (the chain was calibrating).
    """
    return pipeline.fit(warmup_samples(samples, rate_hz, warmup_s))


def partial_transform(pipeline: Pipeline, X):
    """Stream one chunk through a fitted chain, each stage continuing from its state."""
    for _, step in pipeline.steps:
        X = step.partial_transform(X)
    return X


def reset(pipeline: Pipeline) -> Pipeline:
    for _, step in pipeline.steps:
        step.reset()
    return pipeline


class CalibratedChain:
    """The preprocessing chain on a stream whose first ``n_calibration`` samples fit it.

    The PCA alignment needs a fit. The first samples are held back until there are
    ``n_calibration`` of them; the chain is fitted on exactly those (however the stream chunked
    them, the same data give the same numbers), then they and every later chunk go through it
    with ``partial_transform``: the same numbers as the offline chain fitted on the same
    samples.
    """

    def __init__(self, chain: Pipeline, n_calibration: int):
        check(isinstance(n_calibration, int) and n_calibration >= 1, "n_calibration",
              n_calibration, "a number of samples >= 1")
        self.chain, self.n_calibration = chain, n_calibration
        self._held: list[np.ndarray] = []
        self.fitted = False

    def push(self, counts: np.ndarray) -> np.ndarray | None:
        """ADC counts (n, 2) in, coded samples out (None while calibrating)."""
        counts = self.take(counts)
        return None if counts is None else self.code(counts)[1]

    def take(self, counts: np.ndarray) -> np.ndarray | None:
        """ADC counts (n, 2) in; the counts ready to code out (the held ones first, once the
        chain is fitted on them), None while calibrating."""
        if not self.fitted:
            self._held.append(counts)
            counts = np.concatenate(self._held)
            if len(counts) < self.n_calibration:
                self._held = [counts]
                return None
            reset(self.chain.fit(counts[:self.n_calibration]))
            self._held, self.fitted = [], True
        return counts

    def code(self, counts: np.ndarray, threshold=None) -> tuple[np.ndarray, np.ndarray]:
        """Counts that ``take`` made ready through the fitted chain: the coder's input (the
        conditioned signal its gate compares with Th) and its output, coded with
        ``threshold`` (None: the coder's own)."""
        signal = counts
        for _, step in self.chain.steps[:-1]:
            signal = step.partial_transform(signal)
        return signal, self.chain.steps[-1][1].partial_transform(signal, threshold)
