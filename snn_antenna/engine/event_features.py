"""A bank's spiking features per (event, neuron) from either path of the event engine
(engine/events.py): the compiled path's per-neuron records (``fused_features``) and the runtime
path's spikes (``band_features``) give the same counts, first-spike latency, firing span and
spikes per time bin, with spike times in the runtime path's arithmetic (``spike_time_s``).
"""
from __future__ import annotations

import numpy as np

from ..networks.neurons import binned_spike_counts, spike_summary


def spike_time_s(step, dt_ms: float):
    """The time (s) of a spike in model step ``step`` at dt ``dt_ms``, in the runtime path's
    arithmetic (Brian2's clock: step · dt in s; ``SpikeMonitor.t / ms``; / 1000), so that a
    spike in the same step has the same time on both paths."""
    return ((np.asarray(step) * (dt_ms * 0.001)) / 0.001) / 1000.0


def fused_features(count, first_step, last_step, before, edge_steps, n_steps: int,
                   dt_ms: float, duration_s: float) -> tuple[np.ndarray, ...]:
    """(counts, latency, span, binned) as ``band_features`` gives them, from a fused group's
    records (``events.RECORDED``; ``before``: the count before each of ``edge_steps``, taken only
    for an edge within the run's ``n_steps``)."""
    count = np.rint(count).astype(np.int64)
    fired = count > 0
    first = np.where(fired, spike_time_s(first_step, dt_ms), duration_s)
    last = np.where(fired, spike_time_s(last_step, dt_ms), duration_s)
    cumulative = [np.rint(b).astype(np.int64) if step < n_steps else count
                  for b, step in zip(before, edge_steps)]
    binned = np.diff(np.stack([np.zeros_like(count), *cumulative, count], axis=-1), axis=-1)
    return count, first, last - first, binned


def band_features(spike_i, spike_t_ms, n_events: int, n_neurons: int, duration_s: float,
                  bin_edges_s) -> tuple[np.ndarray, ...]:
    """(counts, latency, span, binned) of one band's group, each (events, band neurons[,
    bins]): neuron e·n_neurons + j is neuron j of event e."""
    t_s = np.asarray(spike_t_ms) / 1000.0
    total = n_events * n_neurons
    counts, latency, span = spike_summary(spike_i, t_s, total, duration_s)
    binned = binned_spike_counts(spike_i, t_s, total, bin_edges_s)
    return (counts.reshape(n_events, n_neurons), latency.reshape(n_events, n_neurons),
            span.reshape(n_events, n_neurons), binned.reshape(n_events, n_neurons, -1))
