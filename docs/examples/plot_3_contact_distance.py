"""
A contact's distance, decoded from spikes
=========================================

When the rod touches an object it is clamped there, and its free end rings at a frequency set
by the distance along the rod (the paper's low-mode law, log10 F = 0.0268 d + 0.69). The
contact detector (``ContactDetector``) reads only the rate map: it finds the windows whose
activity left the self-motion band, takes the centroid frequency of that activity and
inverts the law. The ground truth is used afterwards, to score.
"""

import matplotlib.pyplot as plt
import numpy as np

from snn_antenna.networks.resonators import ResonatorArray
from snn_antenna.preprocess import fit_warmup, make_chain
from snn_antenna.readout.contacts import ContactDetector
from snn_antenna.sources import antenna, stimuli

true_cm = [15.0, 21.0, 27.0]
scene = stimuli.RobotScene(
    duration_s=8.0, stop_after_contact_s=None,      # keeps driving after each contact
    contacts=[stimuli.Contact(2.5 + 2.0 * i, d, "wood") for i, d in enumerate(true_cm)])
rec = scene.generate(seed=2)
chain = fit_warmup(make_chain(rec.rate_hz, threshold=0.05), rec.samples, rec.rate_hz,
                   warmup_s=2.0)
rates = ResonatorArray().run(rec.with_samples(chain.transform(rec.samples))).rate_map
found = ContactDetector().detect(rates)
for contact in found:
    print(f"contact at {contact.onset_s:.1f} s: {contact.frequency_hz:.1f} Hz, "
          f"{contact.distance_cm:.1f} cm along the rod")

# %%
# Each detection against the true contact nearest in time, on the low-mode law that both
# the generator and the read-out use.

truth = {c.t_s: c.distance_cm for c in rec.truth.contacts}
d = np.linspace(*antenna.CALIBRATED_RANGE_CM, 100)
fig, ax = plt.subplots(figsize=(6, 3.4), layout="constrained")
ax.plot(d, 10 ** (antenna.LOW_LAW[0] * d + antenna.LOW_LAW[1]), color="0.6",
        label="low-mode law")
for contact in found:
    t_true = min(truth, key=lambda t: abs(t - contact.onset_s))
    ax.plot(truth[t_true], contact.frequency_hz, "o", color="C0")
    ax.annotate(f"{contact.distance_cm:.1f} cm decoded", (truth[t_true], contact.frequency_hz),
                textcoords="offset points", xytext=(6, -12))
ax.set(xlabel="true distance along the rod (cm)", ylabel="ringing frequency read (Hz)",
       title="contacts decoded from the rate map")
ax.legend(loc="upper left")
plt.show()
