"""
An XY stage: a raster and a Lissajous, the coupling inverted
============================================================

Most piezo positioners are several actuators moving one structure: in an XY flexure stage,
moving x moves y by a few per cent. :class:`piezohyst.CoupledModel` identifies a hysteresis
model per actuator and the coupling between them from one record;
:class:`piezohyst.CoupledCompensator` inverts the coupling, then each actuator's hysteresis,
inside each amplifier's limits. The stage here is the simulator's (``simulate_stage``: two
bench actuators, 4 % and -3 % cross-coupling, a laser per axis).
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import make_signal, simulate_stage

t, a = make_signal("decaying", duration=8.0)  # x: decaying loops
_, b = make_signal("triangle", duration=8.0, frequency=1.3)  # y: its own rate
record = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t)
stage = ph.CoupledModel().fit(record.voltage, record.position, t=record.t)
print(stage.describe())
xy = ph.CoupledCompensator(stage, v_min=0.0, v_max=140.0, sample_rate=1000.0, slew_rate=None)
(x0, x1), (y0, y1) = xy.reach  # what each actuator alone moves


rest = stage.predict(np.zeros((2, 2)), t=np.array([0.0, 1e-3]))[0]  # where 0 V leaves it


def from_rest(target):
    """Half a second from the rest position to the target's start, then the target: the
    actuators start at 0 V, and a jump asks more than an amplifier gives."""
    ramp = np.linspace(0.0, 1.0, 500)[:, None]
    return np.vstack([rest + ramp * (target[0] - rest), target])


def linear_map(target):
    """The naive alternative: each axis's voltage in proportion to its target."""
    return np.column_stack([140.0 * (target[:, 0] - x0) / (x1 - x0),
                            140.0 * (target[:, 1] - y0) / (y1 - y0)])  # fmt: skip


# %%
# A raster line: x a 2 Hz triangle, y held
# ----------------------------------------
k = np.arange(4000)
tri = np.abs((k / 1000 * 2.0) % 1.0 * 2 - 1)
raster = from_rest(np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri),
                                    np.full(k.size, 0.5 * (y0 + y1))]))  # fmt: skip
k = np.arange(raster.shape[0])
fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
for name, volts in (
    ("linear voltage map", linear_map(raster)),
    ("coupled compensator", xy.process(raster)),
):
    moved = simulate_stage(volts, k / 1000.0, seed=5).true_position
    held = np.ptp(moved[1500:, 1]) / (y1 - y0)
    width = ph.metrics.hysteresis_width(raster[1500:, 0], moved[1500:, 0])
    print(f"{name}: x loop width {width:.2%}, y moved {held:.2%} of its range")
    ax[0].plot(1e6 * raster[1500:, 0], 1e6 * moved[1500:, 0], lw=0.7, label=f"{name}: {width:.2%}")
    ax[1].plot(k[1500:] / 1000.0, 1e6 * moved[1500:, 1], lw=0.7, label=f"{name}: {held:.2%}")
ax[0].set(xlabel="x wanted (µm)", ylabel="x moved (µm)", title="the fast axis")
ax[1].set(xlabel="time (s)", ylabel="y moved (µm)", title="the held axis")
for a_ in ax:
    a_.legend(fontsize=7, loc="upper left")
fig.tight_layout()

# %%
# A Lissajous figure
# ------------------
xy.reset()
phase = 2 * np.pi * np.arange(4000) / 1000.0
liss = from_rest(
    np.column_stack(
        [
            x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(3 * phase)),
            y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(2 * phase + 0.5)),
        ]
    )
)
fig, ax = plt.subplots(figsize=(4.8, 4.4))
ax.plot(1e6 * liss[1500:, 0], 1e6 * liss[1500:, 1], "k", lw=1.5, label="wanted")
for name, volts in (
    ("linear voltage map", linear_map(liss)),
    ("coupled compensator", xy.process(liss)),
):
    moved = simulate_stage(volts, k / 1000.0, seed=6).true_position
    err = np.sqrt(np.mean((moved[1500:] - liss[1500:]) ** 2, axis=0)) / np.array([x1 - x0, y1 - y0])
    print(f"{name}: RMS error x {err[0]:.2%}, y {err[1]:.2%} of the range")
    ax.plot(1e6 * moved[1500:, 0], 1e6 * moved[1500:, 1], lw=0.7, label=name)
ax.set(xlabel="x (µm)", ylabel="y (µm)", title="3:2 Lissajous at 1 Hz")
ax.legend(fontsize=7)
fig.tight_layout()
