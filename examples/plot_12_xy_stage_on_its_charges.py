"""
An XY stage without position sensors: each actuator's charge loop
=================================================================

Each actuator of a stage has its own Sawyer-Tower circuit, and its charge is its own (the
coupling is mechanical). The stage's lasers are used once, to calibrate its positions from
the charges (:func:`piezohyst.calibrate_stage`); then
:class:`piezohyst.CoupledSelfSensingController` turns desired positions into what each
actuator alone must move (the coupling's inverse) and closes each actuator's own loop on its
own charge. Here on the simulator's stage (two bench actuators, 4 % and -3 % coupling),
beside the same models and map as feedforward alone, on decaying loops: the minor loops a
Prandtl-Ishlinskii model makes congruent and the actuator does not.
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import Stage, make_signal, run_stage_loop, simulate_stage

# each axis at its own three rates (as `piezohyst excite` plays); the lasers record once
t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=8.0)
_, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=8.0)
record = simulate_stage(np.column_stack([a, b]), t)
models = [ph.ActivePI(10).fit(record.voltage[:, i], record.charge[:, i], t=record.t)
          for i in range(2)]  # fmt: skip
stage = ph.calibrate_stage(models, record.voltage, record.charge, record.position, record.t)
print(stage.describe())
limits = {"v_min": [m.input_range_[0] for m in models],
          "v_max": [m.input_range_[1] for m in models]}  # fmt: skip

# %%
# Decaying loops on x, y held
# ---------------------------
_, shape = make_signal("decaying", amplitude=1.0, duration=3.0)
fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
for name, ki in (("feedforward (ki = 0)", 0.0), ("charge loops", 0.5)):
    loop = ph.CoupledSelfSensingController(models, stage, sample_rate=1000.0, slew_rate=None,
                                           ki=ki, **limits)  # fmt: skip
    (x0, x1), (y0, y1) = loop.reach
    own = np.column_stack([x0 + (x1 - x0) * (0.05 + 0.9 * shape),
                           np.full(shape.size, 0.5 * (y0 + y1))])  # fmt: skip
    wanted = own @ stage.coupling.T + stage.offset  # in the stage's frame
    wanted[:, 1] = wanted[0, 1]
    run = run_stage_loop(loop, wanted, Stage(seed=5))  # reads the charges, not the lasers
    moved, want = run.true_position[500:], wanted[500:]
    width = ph.metrics.hysteresis_width(want[:, 0], moved[:, 0])
    held = np.ptp(moved[:, 1]) / (y1 - y0)
    print(f"{name}: x loop width {width:.2%}, y moved {held:.2%} of its range")
    ax[0].plot(1e6 * want[:, 0], 1e6 * (moved[:, 0] - want[:, 0]), lw=0.7,
               label=f"{name}: {width:.2%}")  # fmt: skip
    ax[1].plot(run.t[500:], 1e6 * moved[:, 1], lw=0.7, label=f"{name}: {held:.2%}")
ax[0].set(xlabel="x wanted (µm)", ylabel="x error (µm)", title="the fast axis: its loop")
ax[1].set(xlabel="time (s)", ylabel="y moved (µm)", title="the held axis")
for a_ in ax:
    a_.legend(fontsize=7, loc="upper left")
fig.tight_layout()

# %%
# On a microcontroller
# --------------------
# ``piezohyst.control.export.write_stage_c(loop, "ph_xy.c")`` writes the loop as C99
# (``ph_xy_step(s, desired, measured, command)``, each actuator's controller beside it);
# ``write_stage_shared``, ``write_stage_mex`` and ``write_stage_fmu`` its library, MEX
# gateway and FMU, each equal to Python to 1e-9 V. From the shell: ``piezohyst
# calibrate-stage`` and ``piezohyst export-c stage-map.json --models ax.json,ay.json``.
