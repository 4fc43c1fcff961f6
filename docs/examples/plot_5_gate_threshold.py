"""
The speed gate's Th(speed)
==========================

The robot's own motion shakes the antenna, so the coder's threshold Th must rise with speed.
The speed gate is an associative memory in Brian2: class-I neurons tuned to speeds feed a
read-out neuron through plastic synapses, and a spike-driven delta rule teaches it the
threshold for each trained speed. Here it learns a Th*(speed) given as a table and recalls Th
at speeds it never saw.
"""

import matplotlib.pyplot as plt
import numpy as np

from snn_antenna.networks.gate import SpeedGate

train = np.array([0.0, 6.0, 12.0, 18.0, 24.0, 30.0])
th_star = 0.03 * np.exp(train / 10.0)             # 0.03 g at rest, 0.6 g at 30 cm/s
held_out = np.array([3.0, 15.0, 27.0])
gate = SpeedGate(curve_points=1, seed=1).fit(train, th_star)
recalled = gate.predict(held_out)
for v, th in zip(held_out, recalled):
    print(f"{v:4.0f} cm/s: Th = {th:.3f} g (trained law: {0.03 * np.exp(v / 10):.3f} g)")

# %%
# Th against speed on a log scale: the trained values, the law they come from, and what the
# gate recalls at the trained speeds and between them.

speeds = np.linspace(0.0, 30.0, 61)
fig, ax = plt.subplots(figsize=(6, 3.4), layout="constrained")
ax.plot(speeds, 0.03 * np.exp(speeds / 10.0), color="0.6", label="Th*(speed) law")
ax.plot(train, th_star, "s", color="0.3", label="trained on")
ax.plot(train, gate.predict(train), "o", color="C0", label="recalled")
ax.plot(held_out, recalled, "o", mfc="none", color="C1", label="recalled, not trained")
ax.set(xlabel="speed (cm/s)", ylabel="Th (g)", yscale="log", title="the speed gate")
ax.legend()
plt.show()
