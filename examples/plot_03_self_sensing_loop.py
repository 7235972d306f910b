"""
The self-sensing loop: feedback on the charge, with a leakage calibrated from holds
===================================================================================

Feedforward alone trusts the model; a charge reading lets a loop correct what the model
missed, without a position sensor. But the charge drifts: a leakage current (a resistor
across the piezo, an amplifier's bias current) adds charge that is not displacement, and a
loop that tracked the raw charge would walk the actuator away. Three minutes of
constant-voltage holds on the rig measure that leakage
(:func:`piezohyst.calibrate_leakage`); the :class:`piezohyst.SelfSensingController`
removes it from every reading.

The day of the experiment here differs from the day of the model: the amplifier's bias
current is 40 pA higher.
"""

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import PRESETS, Bench, make_signal, run_loop

rec = ph.simulate(signal="hold", duration=20.0, seed=0)
model = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)

today = dataclasses.replace(PRESETS["T226-H4-203X"], i_bias=45e-12)
t, v = make_signal("staircase", amplitude=140.0, frequency=0.05, duration=180.0)
holds = Bench(today, seed=1).run(v)
leak = ph.calibrate_leakage(holds.t, holds.voltage, holds.charge)
print(leak.coefficients())

# %%
# A decaying scan, feedforward against the loop
# ----------------------------------------------
top, bottom = model.hysteresis_.predict(np.array([140.0, 0.0]))
_, shape = make_signal("decaying", amplitude=1.0, duration=20.0)
desired = bottom + (top - bottom) * (0.05 + 0.9 * shape)
ff = run_loop(ph.Compensator(model, v_min=0.0, v_max=140.0), desired, Bench(today, seed=2))
ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
                               leakage=leak, ki=0.5)  # fmt: skip
loop = run_loop(ctl, desired, Bench(today, seed=2, voltage=ctl.last_command))

fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
for name, r in (("feedforward", ff), ("self-sensing loop", loop)):
    width = ph.metrics.hysteresis_width(desired, r.true_displacement)
    print(f"{name}: loop width {width:.2%} of the span")
    ax[0].plot(1e6 * desired, 1e6 * r.true_displacement, lw=0.7, label=f"{name} ({width:.2%})")
    ax[1].plot(r.t, 1e6 * r.true_displacement, lw=0.7, label=name)
ax[0].set(xlabel="desired charge (µC)", ylabel="displacement (µm)", title="loops (laser)")
ax[1].set(xlabel="time (s)", ylabel="displacement (µm)", title="along the scan")
ax[0].legend(loc="upper left", fontsize=8)
ax[1].legend(loc="upper right", fontsize=8)
fig.tight_layout()
