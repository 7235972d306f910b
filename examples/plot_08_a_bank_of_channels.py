"""
A bank of channels: one model per actuator, one kernel for all
==============================================================

A deformable mirror has hundreds to thousands of actuators, each its own piezo, each a
little different. :class:`piezohyst.ModelBank` fits one model per channel of a
(samples x channels) record and keeps them in one file; :class:`piezohyst.BankCompensator`
commands every channel per step in one parallel kernel. Here 64 simulated stacks whose
capacitance and leakage spread by 10 %, and the spread of what the bank identified.
"""

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import PRESETS, Bench, make_signal

rng = np.random.default_rng(0)
base = PRESETS["T226-H4-203X"]
t, v = make_signal("decaying", amplitude=140.0, duration=10.0)
Q = []
for k in range(64):
    unit = dataclasses.replace(base, c0=base.c0 * rng.normal(1.0, 0.1),
                               g_leak=base.g_leak * rng.normal(1.0, 0.1))  # fmt: skip
    Q.append(Bench(unit, seed=k).run(v).charge)
V = np.column_stack([v] * 64)
Q = np.column_stack(Q)

bank = ph.ModelBank(ph.ActivePI(n_operators=8)).fit(V, Q, t=t)
table = bank.summary()
print(f"{len(bank)} channels, NRMSE {100 * np.min(table['nrmse']):.2f}-"
      f"{100 * np.max(table['nrmse']):.2f} %")  # fmt: skip

# %%
# Every channel to the same charge
# --------------------------------
# The same target for all: what the median channel holds at 70 V. Each channel's command
# differs by its own capacitance; the kernel computes them all in one step.
comp = ph.BankCompensator(bank, v_min=float(v.min()), v_max=float(v.max()), slew_rate=None)
at_70 = np.array([m.hysteresis_.predict(np.array([70.0]))[0] for m in bank.complete_models()])
volts = comp.step(np.full(len(bank), np.median(at_70)))
print(f"commands for one charge, {1e6 * np.median(at_70):.3f} µC: "
      f"{volts.min():.1f}-{volts.max():.1f} V")  # fmt: skip

fig, ax = plt.subplots(1, 3, figsize=(11, 3.4))
ax[0].hist(100 * np.asarray(table["nrmse"]), bins=16)
ax[0].set(xlabel="fit NRMSE (%)", ylabel="channels", title="how well each channel fits")
ax[1].hist(1e9 * np.array([m.growth_rate_ for m in bank.complete_models()]), bins=16)
ax[1].set(xlabel="growth rate R (nS)", ylabel="channels", title="the leakage each one has")
ax[2].hist(volts, bins=16)
ax[2].set(xlabel="command (V)", ylabel="channels", title="one charge, each its voltage")
fig.tight_layout()
