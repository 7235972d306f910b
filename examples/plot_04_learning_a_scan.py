"""
Learning a repeated scan from the charge
========================================

A scan that repeats (a raster line, a resonant mirror's sweep) can be learned: after each
trial, the :class:`piezohyst.LearningCompensator` compares the charge it read with the
charge it wanted and corrects the next trial's commands, inside the limits, from the charge
alone. Here a 40 Hz scan, fast enough that the model's rate-independent inverse leaves a
loop; ten one-second trials remove most of it.
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import Bench

rec = ph.simulate(signal="hold", duration=20.0, seed=0)
model = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
top, bottom = model.hysteresis_.predict(np.array([140.0, 0.0]))
n = 1000  # one trial: 1 s at 1 kHz, forty 40 Hz scans
scan = 0.5 - 0.5 * np.cos(2 * np.pi * 40 * np.arange(n) / n)
desired = bottom + (top - bottom) * (0.3 + 0.4 * scan)

ilc = ph.LearningCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
                             slew_rate=30e3)  # fmt: skip
rig = Bench(seed=5, voltage=ilc.last_command)  # stands in for the DAQ
first = None
for _ in range(10):
    run = rig.run(ilc.command(desired))
    first = run if first is None else first
    ilc.learn(run.charge)
last = rig.run(ilc.command(desired))
print(ilc.describe())
print("charge error per trial:", ", ".join(f"{100 * tr.error:.2f} %" for tr in ilc.history))

# %%
# The error per trial, and the loop before and after
# --------------------------------------------------
fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
ax[0].semilogy([100 * tr.error for tr in ilc.history], "o-")
ax[0].set(xlabel="trial", ylabel="charge error (% of span)", title="learning")
keep = slice(n // 2, None)
for name, r in (("first trial", first), ("after 10 trials", last)):
    width = ph.metrics.hysteresis_width(desired[keep], r.true_displacement[keep])
    ax[1].plot(1e6 * desired[keep], 1e6 * r.true_displacement[keep], lw=0.7,
               label=f"{name}: width {width:.2%}")  # fmt: skip
ax[1].set(xlabel="desired charge (µC)", ylabel="displacement (µm)", title="40 Hz, laser")
ax[1].legend(loc="upper left", fontsize=8)
fig.tight_layout()
