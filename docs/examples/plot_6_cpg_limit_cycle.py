"""
The CPG's limit cycle
=====================

A central pattern generator in Brian2 sweeps the antenna: a ring of leaky integrate-and-fire
neurons passes one token of excitation around, and the ring's population vector sets the pan
and tilt joints. Pan and tilt are 90 degrees apart, so the tip draws a closed loop; the robot's
speed raises the rhythm's frequency.
"""

import matplotlib.pyplot as plt
import numpy as np

from snn_antenna.networks.cpg import CPG, cycle_periods

cpg = CPG(period_s=2.0, phase_offset_deg=90.0)
runs = {speed: cpg.run(speed, 6.0) for speed in (0.0, 30.0)}
for speed, run in runs.items():
    period = np.median(cycle_periods(run["t_s"], run["pan_deg"]))
    print(f"{speed:4.0f} cm/s: period {period:.2f} s "
          f"(spec: {1 / float(cpg.frequency_hz(speed)):.2f} s)")

# %%
# Left: the joint angles over time at rest. Right: pan against tilt, the limit cycle, after
# the first second (the ring starts from rest); at 30 cm/s the loop is the same, run faster.

fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained")
rest = runs[0.0]
left.plot(rest["t_s"], rest["pan_deg"], label="pan")
left.plot(rest["t_s"], rest["tilt_deg"], label="tilt")
left.set(xlabel="time (s)", ylabel="angle (°)", title="at rest")
left.legend()
for speed, run in runs.items():
    settled = run["t_s"] > 1.0
    right.plot(run["pan_deg"][settled], run["tilt_deg"][settled], label=f"{speed:g} cm/s")
right.set(xlabel="pan (°)", ylabel="tilt (°)", title="limit cycle", aspect="equal")
right.legend()
plt.show()
