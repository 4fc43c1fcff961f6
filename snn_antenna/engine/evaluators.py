"""Evaluators: spike counts of one Izhikevich neuron per grid point, a chunk as one group.

- ``NeuronSweep``: neurons driven by the square-wave coder's input; axes may be any neuron
  parameter (``k, a, b, c, d``), the input frequency ``input_hz`` and amplitude ``I``. All
  points of a chunk are neurons of ONE NeuronGroup. Engines: ``"standalone"`` (Brian2
  cpp_standalone, compiled once per process and re-run per chunk with new parameters,
  ``engine.standalone``) or ``"numpy"`` / ``"cython"`` (runtime, through ``neurons.simulate``
  with a 2-D input current and ``input_index``). ``benchmarks/bench_sweep.py`` measures which
  is faster: once compiled, standalone is the fastest per neuron-step, and its one-off compile
  (cached on disk) pays off on large grids, so small first looks use ``numpy``.
- ``SceneSweep``: the same for neurons driven by coded robot scenes, with axes over scene and
  preprocessing fields (``stimulus.speed_cm_s``, ``stimulus.contacts.0.distance_cm``,
  ``preprocess.threshold``) beside ``k, a, b, c, d``: each distinct scene is generated and
  coded once and becomes one input column (runtime engines).

An evaluator is called as ``evaluate(points) -> {output: array}`` on a worker (so it is a
picklable dataclass); ``for_grid(grid, block_shape)`` checks the grid before any work.
Brian2's cython cache is shared by the workers of a machine (Brian2 locks each extension while
it compiles it), so each extension compiles once, not once per worker.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..core import bounds
from ..core.errors import SpecError, check
from ..networks import neurons
from ..core.store import Output
from .devices import DTYPES, float_precision
from .grid import Grid
from .standalone import standalone_counts
from ..sources.stimuli import square
from ..preprocess import Preprocessing
from ..sources.scenes import scene_from_spec
from ..core.spec import set_field

NEURON_AXES = {"k": "", "a": "", "b": "", "c": "", "d": "", "input_hz": "Hz", "I": ""}


@dataclass(frozen=True)
class NeuronSweep:
    """Spike counts of Izhikevich neurons driven by a square wave, one neuron per grid point.

    The input is the square-wave coder's output for a pure tone: ``±I`` switching every half
    period of ``input_hz``, sampled at ``input_rate_hz`` and held (``stimuli.square``). Spikes
    are counted from ``settle_s`` to ``duration_s`` (the onset transient is left out);
    ``rate_hz`` is that count per second. Parameters not swept take the values given here
    (``None``: the preset's). Neurons start at rest for the first input sample.
    ``dtype``: Brian2's float type, ``"float64"`` or ``"float32"`` (faster, a few spikes
    off at some points: the speed/accuracy study measures it, docs/reference.md).
    """
    preset: str = "resonator"
    duration_s: float = 2.0
    settle_s: float = 0.25
    dt_ms: float = 0.1
    method: str = "euler"
    engine: str = "standalone"
    input_rate_hz: float = 1000.0
    k: float = 1.0
    a: float | None = None
    b: float | None = None
    c: float | None = None
    d: float | None = None
    input_hz: float = 10.0
    I: float = 0.15
    dtype: str = "float64"
    force: bool = False
    group_size: int | None = None  # standalone: neurons per compiled group (set by for_grid)
    shared: tuple[str, ...] = ()   # standalone: parameters the grid does not sweep, one value
    # for all its points (set by for_grid)

    OUTPUTS = {"spike_count": Output("i4", "1", "spikes counted after settle_s"),
               "rate_hz": Output("f8", "Hz", "spike rate after settle_s")}

    def __post_init__(self):
        bounds.declared(self)
        bounds.number("k", self.k, 0.0, lo_open=True)
        bounds.number("input_hz", self.input_hz, 0.0, bounds.MAX_RATE_HZ, unit=" Hz")
        if self.group_size is not None:
            bounds.positive_integer("group_size", self.group_size)
        check(self.preset in neurons.PRESETS, "preset", self.preset,
              f"one of {sorted(neurons.PRESETS)}")
        check(self.method in neurons.METHODS, "method", self.method,
              f"one of {list(neurons.METHODS)}")
        check(self.engine in ("standalone", "cython", "numpy"), "engine", self.engine,
              "'standalone' (compiled C++, re-run per chunk), 'cython' or 'numpy'")
        check(self.dtype in DTYPES, "dtype", self.dtype,
              f"one of {list(DTYPES)} (Brian2's float type; float32 trades spike-count "
              "accuracy for speed, docs/reference.md)")
        bounds.dt_ms("dt_ms", self.dt_ms)        # the same bounds as every other step
        check(math.isfinite(self.input_rate_hz) and self.input_rate_hz > 0 and
              1000.0 / self.input_rate_hz >= self.dt_ms * (1 - 1e-9), "input_rate_hz",
              self.input_rate_hz,
              f"a sample rate > 0 Hz and at most 1/dt ({1 / self.dt_ms:g} kHz)")
        check(math.isfinite(self.duration_s) and self.duration_s * 1000 >= 10 * self.dt_ms,
              "duration_s", self.duration_s, "a duration of at least 10 steps")
        check(math.isfinite(self.settle_s) and 0 <= self.settle_s < self.duration_s,
              "settle_s", self.settle_s, f"a time in [0, duration_s = {self.duration_s:g}) s")

    # the grid's checks, before any work
    def for_grid(self, grid: Grid, block_shape) -> NeuronSweep:
        for name in grid.dims:
            check(name in NEURON_AXES, f"axes.{name}", list(grid.axes[name]),
                  f"a parameter of the neuron sweep: {', '.join(NEURON_AXES)}")
        values = {name: grid.axes.get(name, np.atleast_1d(getattr(self, name)))
                  for name in ("k", "input_hz", "I")}
        check(bool(np.all(values["k"] > 0)), "axes.k", list(values["k"]),
              "time-scale factors > 0")
        limit = neurons.MAX_STABLE_K_DT[self.method]
        k_max = float(np.max(values["k"]))
        if not self.force and k_max * self.dt_ms > limit:
            raise SpecError("axes.k", list(grid.axes.get("k", [self.k])),
                            f"k <= {limit / self.dt_ms:g} at dt = {self.dt_ms:g} ms with "
                            f"method {self.method!r} (the stable range k·dt <= {limit:g} "
                            f"model-ms, neurons.MAX_STABLE_K_DT), or a smaller dt_ms")
        nyquist = self.input_rate_hz / 4  # the coder needs both half-cycles sampled twice
        check(bool(np.all((values["input_hz"] > 0) & (values["input_hz"] <= nyquist))),
              "axes.input_hz", list(values["input_hz"]),
              f"frequencies in (0, {nyquist:g}] Hz (4 samples per cycle at "
              f"{self.input_rate_hz:g} Hz)")
        check(bool(np.all(values["I"] >= 0)), "axes.I", list(values["I"]),
              "amplitudes >= 0")
        return dataclasses.replace(self, group_size=int(np.prod(block_shape)),
                                   shared=tuple(name for name in NEURON_AXES
                                                if name not in grid.dims))

    @property
    def bytes_per_point(self) -> int:
        """Memory a chunk holds per point: the runtime engines keep one input column each."""
        if self.engine == "standalone":
            return 64
        return int(8 * self.duration_s * self.input_rate_hz) + 64

    def parameters(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Every parameter per point, axes first, then this sweep's fixed values."""
        return _parameters(self, points, NEURON_AXES)

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        p = self.parameters(points)
        n = len(p["k"])
        if self.engine == "standalone":
            counts = standalone_counts(self, p)
        else:
            with float_precision(self.dtype):
                counts = _runtime_counts(self, p)
        counts = counts[:n]
        return {"spike_count": counts.astype(np.int32),
                "rate_hz": counts / (self.duration_s - self.settle_s)}

    def initial_state(self, p: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Rest for the first input sample (+I), as ``neurons.simulate`` starts."""
        return neurons.resting_state(self.preset, p["b"], p["I"])


def _parameters(sweep, points: dict[str, np.ndarray], names) -> dict[str, np.ndarray]:
    n = len(next(iter(points.values())))
    preset = neurons.PRESETS[sweep.preset].params()
    out = {}
    for name in names:
        if name in points:
            out[name] = np.asarray(points[name], dtype=float)
        else:
            fixed = getattr(sweep, name)
            out[name] = np.full(n, preset[name] if fixed is None else fixed, dtype=float)
    return out


def _runtime_counts(sweep: NeuronSweep, p: dict[str, np.ndarray]) -> np.ndarray:
    """All points as one group through ``neurons.simulate`` (2-D input + input_index)."""
    pairs = np.stack([p["input_hz"], p["I"]], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    current = np.stack([square(f, sweep.duration_s, sweep.input_rate_hz, amplitude=I).samples
                        for f, I in unique], axis=1)
    return count_spikes(sweep, p, current, 1000.0 / sweep.input_rate_hz, inverse.ravel(),
                        sweep.settle_s)


def count_spikes(sweep, p: dict[str, np.ndarray], current: np.ndarray, input_dt_ms: float,
                 input_index: np.ndarray, count_from_s: float) -> np.ndarray:
    """Spikes per neuron from ``count_from_s`` on: one NeuronGroup, neuron i driven by
    column ``input_index[i]`` of ``current`` (runtime target ``sweep.engine``)."""
    # a chunk cut short by Ctrl-C must raise, never be stored with truncated counts as done
    neurons.raise_on_ctrl_c()
    result = neurons.simulate(sweep.preset, current, sweep.dt_ms, k=p["k"], method=sweep.method,
                              input_dt_ms=input_dt_ms, input_index=input_index,
                              target=sweep.engine, force=sweep.force,
                              a=p["a"], b=p["b"], c=p["c"], d=p["d"])
    counted = result.spike_t_ms >= count_from_s * 1000.0
    return np.bincount(result.spike_i[counted], minlength=len(p["k"]))


SCENE_PREFIXES = ("stimulus.", "preprocess.")


@dataclass(frozen=True)
class SceneSweep:
    """Spike counts of neurons driven by coded robot scenes; axes may be scene fields.

    Axes: neuron parameters (``k, a, b, c, d``), ``stimulus.FIELD`` (a ``RobotScene`` field,
    e.g. ``stimulus.speed_cm_s`` or ``stimulus.contacts.0.distance_cm``) and
    ``preprocess.FIELD`` (a ``make_chain`` argument, e.g. ``preprocess.threshold``). Each
    distinct scene is generated (seeded), preprocessed and coded once and becomes one column of
    a 2-D input; every point is a neuron reading its scene's column (``neurons.simulate`` with
    ``input_index``). Spikes are counted from ``count_from_s`` to the scene's end. Runtime
    engines only: a standalone TimedArray's shape is fixed at compile time.
    """
    stimulus: dict = dataclasses.field(default_factory=dict)
    preprocess: dict = dataclasses.field(default_factory=dict)
    seed: int = 0
    preset: str = "resonator"
    dt_ms: float = 0.1
    method: str = "euler"
    engine: str = "cython"
    count_from_s: float = 0.0
    k: float = 1.0
    a: float | None = None
    b: float | None = None
    c: float | None = None
    d: float | None = None
    force: bool = False

    OUTPUTS = {"spike_count": Output("i4", "1", "spikes counted from count_from_s")}

    def __post_init__(self):
        bounds.declared(self)
        bounds.seed("seed", self.seed)
        bounds.seconds("count_from_s", self.count_from_s)
        bounds.number("k", self.k, 0.0, lo_open=True)
        check(self.engine in ("cython", "numpy"), "engine", self.engine,
              "'cython' or 'numpy' (scene inputs need a runtime target)")
        NeuronSweep(preset=self.preset, dt_ms=self.dt_ms, method=self.method)  # same checks

    def _scene_and_chain(self, values: dict):
        spec = {"stimulus": copy.deepcopy(self.stimulus),
                "preprocess": copy.deepcopy(self.preprocess)}
        for name, value in values.items():
            set_field(spec, name, value.item() if hasattr(value, "item") else value)
        scene = scene_from_spec(spec["stimulus"])
        scene.validate()
        chain = Preprocessing(spec["preprocess"]).chain(scene)
        return scene, chain

    def for_grid(self, grid: Grid, block_shape) -> SceneSweep:
        scene_axes = [d for d in grid.dims if d.startswith(SCENE_PREFIXES)]
        for name in grid.dims:
            check(name in NEURON_AXES and name not in ("input_hz", "I") or name in scene_axes,
                  f"axes.{name}", list(grid.axes[name]),
                  "k, a, b, c, d, stimulus.FIELD or preprocess.FIELD")
        # every value of every scene axis must make a valid scene and chain, before any work
        for name in scene_axes:
            for value in grid.axes[name]:
                try:
                    scene, chain = self._scene_and_chain({name: value})
                    for _, step in chain.steps:
                        getattr(step, "_validate_params_", lambda: None)()
                except SpecError as exc:
                    raise SpecError(f"axes.{name}", float(value), str(exc)) from None
                except (TypeError, KeyError, IndexError) as exc:
                    raise SpecError(f"axes.{name}", float(value),
                                    f"a field of the scene or the chain ({exc})") from None
        k = grid.axes.get("k", np.atleast_1d(self.k))
        check(bool(np.all(k > 0)), "axes.k", list(k), "time-scale factors > 0")
        limit = neurons.MAX_STABLE_K_DT[self.method]
        if not self.force and float(np.max(k)) * self.dt_ms > limit:
            raise SpecError("axes.k", list(k), f"k <= {limit / self.dt_ms:g} at dt = "
                            f"{self.dt_ms:g} ms (neurons.MAX_STABLE_K_DT[{self.method!r}] = "
                            f"{limit:g}), or a smaller dt_ms")
        return self

    @property
    def bytes_per_point(self) -> int:
        scene, _ = self._scene_and_chain({})
        return int(8 * scene.duration_s * scene.rate_hz) + 64

    def __call__(self, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        n = len(next(iter(points.values())))
        p = _parameters(self, {"k": np.full(n, float(self.k)), **points}, "kabcd")
        scene_names = [k for k in points if k.startswith(SCENE_PREFIXES)]
        if scene_names:
            combos = np.stack([points[k] for k in scene_names], axis=1)
            unique, inverse = np.unique(combos, axis=0, return_inverse=True)
        else:
            unique, inverse = np.zeros((1, 0)), np.zeros(n, int)
        columns, rate_hz = [], None
        for row in unique:
            scene, chain = self._scene_and_chain(dict(zip(scene_names, row)))
            rec = scene.generate(self.seed)
            columns.append(chain.fit(rec.samples).transform(rec.samples))
            rate_hz = scene.rate_hz
        current = np.stack(columns, axis=1)
        counts = count_spikes(self, p, current, 1000.0 / rate_hz, inverse.ravel(),
                              self.count_from_s)
        return {"spike_count": counts.astype(np.int32)}
