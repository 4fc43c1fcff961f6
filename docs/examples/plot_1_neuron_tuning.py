"""
A resonator neuron's tuning curve
=================================

An Izhikevich resonator fires about once per input cycle over a narrow band of input
frequencies and falls silent outside it. The time-scale factor k moves that band:
``neurons.k_for_frequency`` gives the k whose neuron prefers a frequency. Here one Brian2
``NeuronGroup`` holds one neuron per input frequency, all with the k for 7 Hz, each driven by
the square wave the coder would make at its frequency (``input_index`` picks each neuron's
column of the input).
"""

import matplotlib.pyplot as plt
import numpy as np

from snn_antenna.networks import neurons
from snn_antenna.sources import stimuli

RATE_HZ = 2_000.0      # input samples per second, held over the neuron's 0.1 ms steps
DURATION_S = 2.0
k = neurons.k_for_frequency(7.0)
freqs = np.arange(3.0, 15.01, 0.5)
drive = np.stack([stimuli.square(f, DURATION_S, RATE_HZ, amplitude=0.15).samples
                  for f in freqs], axis=1)                    # samples × frequencies
result = neurons.simulate("resonator", drive, dt_ms=0.1, k=k, n_neurons=len(freqs),
                          input_dt_ms=1000.0 / RATE_HZ, input_index=np.arange(len(freqs)))
per_cycle = result.spike_counts / (freqs * DURATION_S)
print(f"k = {k:.3f}; spikes per input cycle at 7 Hz: {per_cycle[freqs == 7.0][0]:.2f}")

# %%
# Spikes per input cycle against the input's frequency. The neuron follows the input near
# 7 Hz (about one spike a cycle), skips cycles below its band and stays silent above it.

fig, ax = plt.subplots(figsize=(6, 3.2), layout="constrained")
ax.plot(freqs, per_cycle, "o-")
ax.axvline(7.0, color="0.6", ls="--", label="7 Hz (k_for_frequency)")
ax.set(xlabel="input frequency (Hz)", ylabel="spikes per input cycle",
       title=f"resonator with k = {k:.3f}")
ax.legend()
plt.show()
