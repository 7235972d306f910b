"""
A fast stage without position sensors: each actuator's mode in its map
======================================================================

A charge does not ring; a stage does. At a 10 Hz raster each turn excites the stage's modes
(here 150 and 120 Hz, behind 4 and 3 ms amplifiers: ``simulation.XY_DYNAMIC``), which the
lasers see and no charge does. :func:`piezohyst.calibrate_stage` finds each actuator's mode
in the calibration record by evidence and keeps it in that actuator's map from its charge to
what it moves; :class:`piezohyst.CoupledSelfSensingController` then inverts each mode from
the desired trajectory before closing each actuator's loop on its own charge. Beside it, the
same models with maps fitted without the modes (``output_dynamics="none"``).
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import XY_DYNAMIC, Stage, make_signal, run_stage_loop, simulate_stage

# each axis at its own three rates; the lasers record once
t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
_, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=12.0)
record = simulate_stage(np.column_stack([a, b]), t, presets=XY_DYNAMIC)
models = [ph.ActivePI(10, input_dynamics="first-order").fit(record.voltage[:, i],
                                                            record.charge[:, i], t=record.t)
          for i in range(2)]  # fmt: skip
limits = {"v_min": [m.input_range_[0] for m in models],
          "v_max": [m.input_range_[1] for m in models]}  # fmt: skip

# %%
# A 10 Hz raster line, y held, on the charges alone
# -------------------------------------------------
fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
k = np.arange(2500)
tri = np.abs((k / 1000 * 10.0) % 1.0 * 2 - 1)
for mode in ("none", "auto"):
    stage = ph.calibrate_stage(models, record.voltage, record.charge, record.position,
                               record.t, output_dynamics=mode)  # fmt: skip
    print(stage.describe())
    loop = ph.CoupledSelfSensingController(models, stage, sample_rate=1000.0, slew_rate=None,
                                           **limits)  # fmt: skip
    (x0, x1), (y0, y1) = loop.reach
    own = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    wanted = own @ stage.coupling.T + stage.offset  # in the stage's frame, y held
    wanted[:, 1] = wanted[0, 1]
    rest = stage.predict(np.zeros((1, 2)))[0]  # where the stage rests
    ramp = np.minimum(k / 500.0, 1.0)[:, None]
    wanted = rest * (1 - ramp) + ramp * wanted
    run = run_stage_loop(loop, wanted, Stage(XY_DYNAMIC, seed=5))  # the next row as preview
    keep = slice(1500, None)
    moved, want = run.true_position[keep], wanted[keep]
    width = ph.metrics.hysteresis_width(want[:, 0], moved[:, 0])
    held = np.ptp(moved[:, 1]) / (y1 - y0)
    name = "each actuator's mode in its map" if mode == "auto" else "maps without modes"
    print(f"{name}: x loop width {width:.2%}, y moved {held:.2%} of its range")
    ax[0].plot(1e6 * want[:, 0], 1e6 * (moved[:, 0] - want[:, 0]), lw=0.7,
               label=f"{name}: {width:.2%}")  # fmt: skip
    ax[1].plot(run.t[keep], 1e6 * moved[:, 1], lw=0.7, label=f"{name}: {held:.2%}")
ax[0].set(xlabel="x wanted (µm)", ylabel="x error (µm)", title="the fast axis: its loop")
ax[1].set(xlabel="time (s)", ylabel="y moved (µm)", title="the held axis")
for a_ in ax:
    a_.legend(fontsize=7, loc="upper left")
fig.tight_layout()

# %%
# On a microcontroller
# --------------------
# Each step takes the next desired position too (``loop.previews`` is 1): in C
# ``ph_xy_step(s, desired, measured, next, command)``, its FMU an input ``next_k`` per axis
# after the targets, its library and MEX each row's next from the block; each equal to
# Python to 1e-9 V. From the shell: ``piezohyst calibrate-stage ... --output-dynamics auto``
# (the default) and ``piezohyst export-c stage-map.json --models ax.json,ay.json``.
