"""
An amplifier's lag, identified from records at several rates
============================================================

At one frequency an amplifier's lag and hysteresis look alike: both open the loop. At
several frequencies they do not (the lag's phase grows with the rate, rate-independent
hysteresis does not), so a model fitted with ``input_dynamics="auto"`` on a record that
drives several rates identifies a delay and/or a first-order lag beside the hysteresis,
and the compensator inverts both. Here a bench behind a 4 ms amplifier, compensated at
40 Hz by a model identified at the record's own rates, with and without the lag.
"""

import matplotlib.pyplot as plt
import numpy as np

import piezohyst as ph
from piezohyst.simulation import make_signal

lagged = "T226-H4-203X-amp4ms"  # the bench's preset behind a 4 ms amplifier
t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
rec = ph.simulate(v, t, preset=lagged)
plain = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
dynamic = ph.ActivePI(10, input_dynamics="auto").fit(rec.voltage, rec.charge, t=rec.t)
dyn = dynamic.input_dynamics_
print(f"identified: {dyn.kind}, tau {1e3 * dyn.tau:.2f} ms, delay {1e3 * dyn.delay:.2f} ms")

# %%
# A 40 Hz scan, compensated by each
# ---------------------------------
t40, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=2.0)
keep = t40 >= 1.0
fig, ax = plt.subplots(figsize=(5.5, 4))
for name, model in (("no dynamics", plain), ("lag identified", dynamic)):
    lo, hi = model.input_range_  # the voltages it was identified on
    top, bottom = model.operator_.predict(np.array([hi, lo]))  # the hysteresis alone
    desired = bottom + (top - bottom) * (0.25 + 0.5 * shape)
    comp = ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=1000.0, slew_rate=30e3)
    run = ph.simulate(comp.process(desired), t40, preset=lagged, seed=2)
    width = ph.metrics.hysteresis_width(desired[keep], run.true_displacement[keep])
    print(f"{name}: loop width {width:.2%}")
    ax.plot(1e6 * desired[keep], 1e6 * run.true_displacement[keep], lw=0.7,
            label=f"{name}: width {width:.2%}")  # fmt: skip
ax.set(xlabel="desired charge (µC)", ylabel="displacement (µm)",
       title="40 Hz behind a 4 ms amplifier")  # fmt: skip
ax.legend(loc="upper left", fontsize=8)
fig.tight_layout()
