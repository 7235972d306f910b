"""
A fast raster on a stage that rings: each axis's lag and mode
=============================================================

At 10-40 Hz a stage's amplifiers lag and its axes ring: a raster's corners excite each
axis's mode. Each actuator's model can hold its amplifier's lag and its axis's mode
(``input_dynamics``, ``output_dynamics="second-order"``); identified on a record that drives
several rates on each axis, they are inverted by the coupled compensator with one sample of
preview. The stage here (``simulation.XY_DYNAMIC``): lags of 4 and 3 ms, modes at 150 and
120 Hz, the axes coupled by 4 % and -3 %.
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import XY_DYNAMIC, make_signal, simulate_stage

# each axis its own three rates (2.5 / 25 / 100 Hz and 1.9 / 19 / 76 Hz), 12 s
t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
_, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=12.0)
rec = simulate_stage(np.column_stack([a, b]), t, presets=XY_DYNAMIC, seed=0)
kw = {"output_unit": "m", "input_dynamics": "first-order", "output_dynamics": "second-order"}
dynamic = ph.CoupledModel([ph.ClassicalPI(16, **kw), ph.ClassicalPI(16, **kw)])
dynamic.fit(rec.voltage, rec.position, t=rec.t)
static = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
for axis, channel in zip("xy", dynamic.channels_, strict=True):
    lag, mode = channel.input_dynamics_, channel.output_dynamics_
    print(f"{axis}: lag {1e3 * lag.tau:.2f} ms, mode {mode.f0:.1f} Hz at {mode.zeta:.3f}")

# %%
# A 10 Hz raster line, y held, by each model
# ------------------------------------------
fs = 1000.0
k = np.arange(3000)
tri = np.abs((k / fs * 10.0) % 1.0 * 2 - 1)
fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
for name, model in (("static model", static), ("lags and modes", dynamic)):
    limits = {"v_min": [c.input_range_[0] for c in model.channels_],
              "v_max": [c.input_range_[1] for c in model.channels_]}  # fmt: skip
    xy = ph.CoupledCompensator(model, **limits, sample_rate=fs, slew_rate=None)
    (x0, x1), (y0, y1) = xy.reach
    target = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    rest = model.predict(np.zeros((2, 2)), t=np.array([0.0, 1 / fs]))[0]
    wanted = np.vstack([rest + np.linspace(0, 1, 500)[:, None] * (target[0] - rest), target])
    moved = simulate_stage(xy.process(wanted), np.arange(wanted.shape[0]) / fs,
                           presets=XY_DYNAMIC, seed=5).true_position  # fmt: skip
    keep = slice(1500, 1800)
    width = hysteresis_width(wanted[1500:, 0], moved[1500:, 0])
    held = np.ptp(moved[1500:, 1]) / (y1 - y0)
    print(f"{name}: x loop width {width:.2%}, y moved {held:.2%} of its range")
    ax[0].plot(k[1000:1300] / fs, 1e6 * moved[keep, 0], lw=0.8,
               label=f"{name}")  # fmt: skip
    ax[1].plot(k[1000:1300] / fs, 1e6 * moved[keep, 1], lw=0.8,
               label=f"{name}: {held:.2%}")  # fmt: skip
ax[0].plot(k[1000:1300] / fs, 1e6 * wanted[keep, 0], "k:", lw=1.0, label="wanted")
ax[0].set(xlabel="time (s)", ylabel="x (µm)", title="the fast axis, three periods")
ax[1].set(xlabel="time (s)", ylabel="y (µm)", title="the held axis")
for a_ in ax:
    a_.legend(fontsize=7, loc="lower right")
fig.tight_layout()
