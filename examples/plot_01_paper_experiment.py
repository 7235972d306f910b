"""
The paper's experiment: identify, remove the growth, compensate
===============================================================

The bimorph bender of the paper, driven up to 140 V and sampled at 1 kHz, its charge read
with a Sawyer-Tower circuit. A resistor in parallel with the piezo's capacitance makes the
charge grow with time: the classical Prandtl-Ishlinskii model (eq. 11-12) cannot follow it,
the *active* one (eq. 13-16: one integrator term with growth rate R) can (Fig. 7). Removing
R times the integral of the voltage leaves the pure hysteresis (eq. 19, Fig. 8), whose
analytic inverse (eq. 18) is the feedforward compensator; the charge carries the same
hysteresis as the displacement (eq. 6-7), so the inverse identified from charge linearises
the position too, measured here by a laser used only to check (Figs. 9-10).
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph

# %%
# Identify the classical and the active model from voltage and charge
# ---------------------------------------------------------------------
rec = ph.simulate(signal="hold", duration=20.0, seed=0)  # V, C, s (and m: the laser)
classical = ph.ClassicalPI(10).fit(rec.voltage, rec.charge, t=rec.t)
active = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
print(f"classical PI: NRMSE {classical.nrmse_:.2%}")
print(f"active PI:    NRMSE {active.nrmse_:.2%}, R = {active.growth_rate_:.3g} S")

fig, ax = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
for a, model, name in ((ax[0], classical, "classical PI"), (ax[1], active, "active PI")):
    a.plot(rec.voltage, 1e6 * rec.charge, lw=0.8, label="measured")
    a.plot(rec.voltage, 1e6 * model.predict(rec.voltage, t=rec.t), "--", lw=0.8, label=name)
    a.set(xlabel="voltage (V)", title=f"{name}: NRMSE {model.nrmse_:.2%}")
    a.legend(loc="upper left")
ax[0].set_ylabel("charge (µC)")
fig.suptitle("Fig. 7: the growth of the charge is what the active model adds")
fig.tight_layout()

# %%
# Remove the growth (eq. 19)
# --------------------------
pure = active.remove_growth(rec.voltage, rec.charge, t=rec.t)
fig, ax = plt.subplots(figsize=(5, 3.6))
ax.plot(rec.voltage, 1e6 * rec.charge, lw=0.8, label="measured charge")
ax.plot(rec.voltage, 1e6 * pure, lw=0.8, label="growth removed")
ax.set(xlabel="voltage (V)", ylabel="charge (µC)", title="Fig. 8: the pure hysteresis")
ax.legend()
fig.tight_layout()

# %%
# Compensate: the inverse (eq. 18) in front of the actuator
# ----------------------------------------------------------
# A streaming compensator inverts the pure hysteresis sample by sample, inside the
# amplifier's limits. The desired charge is a trajectory the actuator can reach; the bench
# is driven with the commands and its laser says where it went.
top, bottom = active.hysteresis_.predict(np.array([140.0, 0.0]))
t = np.arange(8000) / 1000.0
shape = 0.5 - 0.5 * np.cos(2 * np.pi * 0.5 * t) * np.exp(-t / 4.0)
desired = bottom + (top - bottom) * (0.05 + 0.9 * shape)
comp = ph.Compensator(active, v_min=0.0, v_max=140.0)
commands = comp.process(desired)
run = ph.simulate(commands, t, seed=3)
plain = ph.simulate(np.interp(desired, [bottom, top], [0.0, 140.0]), t, seed=3)
for name, r in (("linear voltage map", plain), ("compensated", run)):
    width = ph.metrics.hysteresis_width(desired, r.true_displacement)
    print(f"{name}: loop width {width:.2%} of the span")

fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
ax[0].plot(1e6 * desired, 1e6 * plain.charge, lw=0.8, label="linear voltage map")
ax[0].plot(1e6 * desired, 1e6 * run.charge, lw=0.8, label="compensated")
ax[0].set(xlabel="desired charge (µC)", ylabel="charge (µC)", title="Fig. 9: charge")
ax[1].plot(1e6 * desired, 1e6 * plain.true_displacement, lw=0.8, label="linear voltage map")
ax[1].plot(1e6 * desired, 1e6 * run.true_displacement, lw=0.8, label="compensated")
ax[1].set(xlabel="desired charge (µC)", ylabel="displacement (µm)",
          title="Fig. 10: displacement (laser)")  # fmt: skip
for a in ax:
    a.legend(loc="upper left")
fig.tight_layout()
