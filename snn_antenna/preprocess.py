"""Preprocessing as scikit-learn transformers with a streaming form.

The paper's chain (Fig. 8J): ADC counts → g → PCA alignment (2 axes → 1) → low-pass at 30 Hz →
centring → square-wave coder with amplitude threshold Th.

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

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.pipeline import Pipeline

from .core import bounds
from .core.errors import SpecError, check
from .core.signals import validate_samples
from .sources.antenna import ADC


class _Causal(TransformerMixin, BaseEstimator):
    """Shared mechanics: fit validates, transform = reset + partial_transform."""

    def fit(self, X, y=None):
        validate_samples(X, "X")
        self._validate_params_()
        self.reset()
        return self

    def _validate_params_(self) -> None:
        pass

    def reset(self) -> "_Causal":
        self.state_ = None
        return self

    def transform(self, X):
        self._require_fit()
        self.reset()
        return self.partial_transform(X)

    def partial_transform(self, X):
        self._require_fit()
        return self._step(np.asarray(validate_samples(X, "X"), dtype=float))

    def _require_fit(self) -> None:
        if not hasattr(self, "state_"):
            raise SpecError(type(self).__name__, "not fitted", "call fit(X) first")

    def _step(self, X):
        raise NotImplementedError


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


class LowPass(_Causal):
    """Butterworth low-pass (default 30 Hz, order 4) with the filter state carried across calls.

    The state starts at the steady state of the first sample, so a DC offset does not ring.
    """

    def __init__(self, rate_hz: float = 1000.0, cutoff_hz: float = 30.0, order: int = 4):
        self.rate_hz = rate_hz
        self.cutoff_hz = cutoff_hz
        self.order = order

    def _validate_params_(self):
        from scipy.signal import butter

        bounds.rate_hz("rate_hz", self.rate_hz)
        # a cut-off below a millionth of the rate underflows the filter design (and no
        # antenna signal lives there)
        bounds.number("cutoff_hz", self.cutoff_hz, self.rate_hz * 1e-6, self.rate_hz / 2,
                      hi_open=True, unit=f" Hz (below Nyquist at rate_hz = {self.rate_hz:g})")
        bounds.integer("order", self.order, 1, 8)
        self.sos_ = butter(self.order, self.cutoff_hz, fs=self.rate_hz, output="sos")

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

    def _validate_params_(self):
        from scipy.signal import butter

        super()._validate_params_()
        self.sos_ = butter(self.order, self.cutoff_hz, btype="highpass", fs=self.rate_hz,
                           output="sos")

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


def make_chain(rate_hz: float, adc_bits: int = 10, full_scale_g: float = 18.0,
               lowpass_hz: float = 30.0, lowpass_order: int = 4, centre_tau_s: float = 1.0,
               coder_amplitude: float = 0.15, threshold: float = 0.0,
               highpass_hz: float | None = None) -> Pipeline:
    """The paper's preprocessing chain from ADC counts (n, 2) to the coded input current.

    ``highpass_hz`` (default: none) adds a high-pass of the same order after the low-pass,
    making the chain a band-pass, e.g. for resonators above the rod's low mode.
    """
    steps = [
        ("to_g", CountsToG(adc_bits, full_scale_g)),
        ("align", PCAAlign()),
        ("lowpass", LowPass(rate_hz, lowpass_hz, lowpass_order)),
    ]
    if highpass_hz is not None:
        steps.append(("highpass", HighPass(rate_hz, highpass_hz, lowpass_order)))
    steps += [("centre", Centre(rate_hz, centre_tau_s)),
              ("coder", SquareWaveCoder(coder_amplitude, threshold))]
    for name, stage in steps:   # refused where the values enter, not at the first fit
        try:
            stage._validate_params_()
        except SpecError as exc:  # named as make_chain's caller wrote it
            raise SpecError(CHAIN_ARGS.get((name, exc.field), exc.field), exc.value,
                            exc.accepted) from None
    return Pipeline(steps)


# (stage, its parameter) -> make_chain's argument
CHAIN_ARGS = {("to_g", "adc_bits"): "adc_bits", ("to_g", "full_scale_g"): "full_scale_g",
              ("lowpass", "cutoff_hz"): "lowpass_hz", ("lowpass", "order"): "lowpass_order",
              ("highpass", "cutoff_hz"): "highpass_hz", ("highpass", "order"): "lowpass_order",
              ("centre", "tau_s"): "centre_tau_s", ("coder", "amplitude"): "coder_amplitude",
              ("coder", "threshold"): "threshold"}


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
