"""
From charge to metres: the gain, calibrated once with a sensor
==============================================================

The charge carries the displacement's hysteresis (eq. 6-7: S = g D at zero stress), up to a
gain. A sensor borrowed for one record measures that gain (and how sure it is:
:func:`piezohyst.calibrate_gain`); from then on, targets are given in metres and the
compensator needs no sensor.
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph

rec = ph.simulate(signal="hold", duration=20.0, seed=0)
model = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
gain = ph.calibrate_gain(model, rec.voltage, rec.charge, rec.displacement, t=rec.t)
print(gain.summary())

# %%
# A scan in micrometres
# ---------------------
comp = ph.Compensator(model, v_min=0.0, v_max=140.0, output_map=gain)
lo, hi = np.percentile(rec.displacement, [15, 65])  # m: inside what the record reached
rest = gain.displacement_range()[0]  # m: the lowest the calibration saw, near rest
t = np.arange(6500) / 1000.0
scan = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * 0.5 * t[:6000]))
desired = np.concatenate([np.linspace(rest, lo, 500), scan])  # half a second from rest
run = ph.simulate(comp.process(desired), t, seed=4)
error = run.true_displacement - desired
settled = t >= 1.0
print(f"RMS error {1e9 * np.sqrt(np.mean(error[settled] ** 2)):.0f} nm "
      f"over a {1e6 * (hi - lo):.1f} µm scan")  # fmt: skip

fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
ax[0].plot(1e6 * desired[settled], 1e6 * run.true_displacement[settled], lw=0.8)
ax[0].set(xlabel="desired (µm)", ylabel="measured by the laser (µm)", title="compensated")
ax[1].plot(t[settled], 1e9 * error[settled], lw=0.6)
ax[1].set(xlabel="time (s)", ylabel="error (nm)", title="tracking error")
fig.tight_layout()
