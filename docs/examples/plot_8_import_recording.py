"""
A recording imported and read out
=================================

A real antenna's recordings and a labels table become a data set in the generator's layout
(``snn-antenna data import``), which the studies and the read-outs take in place of generated
contacts. Here the "recording" is a CSV file the way other equipment would write it: the
board's ADC counts of the rod struck at six places, 1.5 s apart, at the board's 1 kHz; the
labels table names the file and says where and when (to within 0.1 s). The import finds each
contact's exact onset by the paper's rule and cuts its window; the spiking read-out then
decodes each contact's distance without seeing the labels.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from snn_antenna.cli import main
from snn_antenna.engine.events import run_bank
from snn_antenna.readout.spiking import LOW_BAND, CentroidDistance, SpikingBank
from snn_antenna.sources import antenna, bench, recorded

RATE_HZ = 1000.0
onsets_s = [1.0, 2.5, 4.0, 5.5, 7.0, 8.5]
distances_cm = [10.0, 15.0, 20.0, 25.0, 30.0, 35.0]

# the rod's low mode ringing after each strike, with sensor noise, through the board's ADC
rng = np.random.default_rng(0)
t = np.arange(int(10.0 * RATE_HZ)) / RATE_HZ
g = rng.standard_normal((len(t), 2)) * 0.01
for onset, d in zip(onsets_s, distances_cm):
    s = np.clip(t - onset, 0.0, None)
    ring = (t >= onset) * 2.0 * np.exp(-s / 0.15) * np.cos(2 * np.pi * antenna.low_mode_hz(d) * s)
    g += np.c_[ring * np.cos(0.5), ring * np.sin(0.5)]
counts = antenna.ADC(bits=10, full_scale_g=18.0).to_counts(g)

folder = Path(tempfile.mkdtemp())
(folder / "recordings").mkdir()
np.savetxt(folder / "recordings" / "bench1.csv", np.c_[t, counts], fmt=["%.3f", "%d", "%d"],
           delimiter=",", header="t_s,x,y", comments="")
labels = ["recording,onset_s,distance_cm,material"] + [
    f"bench1.csv,{onset + 0.03:.2f},{d:g},wood" for onset, d in zip(onsets_s, distances_cm)]
(folder / "labels.csv").write_text("\n".join(labels) + "\n")
status = main(["data", "import", str(folder / "recordings"), str(folder / "labels.csv"),
               "--out", str(folder / "bench1")])
assert status == 0, "the import refused its input (the line above says why)"

# %%
# The data set reads back as the generator's would (``sources.recorded``); the spiking bank
# reads each contact's window.

source = recorded.open_bench(folder / "bench1", cache_dir=str(folder / "cache"))
events = bench.load(source, log=lambda *_: None)
rate_hz, bits, full_scale = (events.attrs[k] for k in ("rate_hz", "adc_bits", "full_scale_g"))
bank = SpikingBank(bands={"low": LOW_BAND}, duration_s=0.5, target="numpy")
spikes = run_bank(bank, events["counts"].values, rate_hz, bits, full_scale, progress=False)
decoded = CentroidDistance(spikes.neuron_hz).fit(spikes.counts).predict(spikes.counts)
for true, found in zip(events["distance_cm"].values, decoded):
    print(f"labelled {true:4.1f} cm, decoded {found:4.1f} cm")

# %%
# The recording with its labels, and each contact's decoded distance.

fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 4.6), layout="constrained")
top.plot(t, g[:, 0], lw=0.6)
for onset, d in zip(onsets_s, distances_cm):
    top.annotate(f"{d:g} cm", (onset, 2.0), ha="center", fontsize=8)
top.set(xlabel="time (s)", ylabel="x axis (g)", title="the recording and its labels")
bottom.plot(events["distance_cm"].values, decoded, "o")
bottom.plot(antenna.CALIBRATED_RANGE_CM, antenna.CALIBRATED_RANGE_CM, color="0.7", lw=1)
bottom.set(xlabel="labelled distance (cm)", ylabel="decoded (cm)",
           title="read out by the spiking bank")
plt.show()
