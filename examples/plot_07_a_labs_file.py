"""
A lab's MATLAB file, with an ADC glitch and a gap
=================================================

A DAQ's record is checked before it is trusted. This one is what a MATLAB lab saves: a
struct of signals in a ``.mat`` file, in millivolts and microcoulombs, with one sample
logged at 10 kV by an ADC glitch and a second the DAQ dropped. The glitch is named by its
row and column and kept out of the fit (with it, the model's voltage range, and every
compensator's limit with it, would run to 10 kV); the gap is named and the model's state is
held across it.
"""

import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy.io import savemat

import piezohyst as ph

rec = ph.simulate(signal="hold", duration=20.0, seed=0)
v_mV = 1e3 * rec.voltage
v_mV[1234] = 1e7  # row 1235: an ADC glitch, 10 kV
keep = np.ones(rec.t.size, bool)
keep[8000:9000] = False  # a second the DAQ dropped
folder = Path(tempfile.mkdtemp())
savemat(folder / "run.mat", {"meas": {"t": rec.t[keep], "Vout_mV": v_mV[keep],
                                      "Q_uC": 1e6 * rec.charge[keep]}})  # fmt: skip

# %%
# Read it: the units from the names, the glitch and the gap said
# --------------------------------------------------------------
with warnings.catch_warnings(record=True) as said:
    warnings.simplefilter("always")
    run = ph.read_recording(folder / "run.mat", group="meas", input_column="Vout_mV",
                            output_column="Q_uC", time_column="t")  # fmt: skip
for w in said:
    print(f"{w.category.__name__}: {w.message}")
print(f"units read: {run.units}")
print(f"voltage {run.x.min():.2f} to {run.x.max():.2f} V (the glitch replaced by its neighbours)")

# %%
# Fit it as it was read, and look at the gap
# ------------------------------------------
with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # the same two findings, said once above
    model = ph.ActivePI(10).fit(run.x, run.y, t=run.t)
print(f"fitted on {model.input_range_[0]:.1f}-{model.input_range_[1]:.1f} V: "
      f"NRMSE {model.nrmse_:.2%}")  # fmt: skip

fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
ax[0].plot(run.t, run.x, lw=0.6)
ax[0].axvspan(8.0, 9.0, color="0.85", label="the dropped second")
ax[0].set(xlabel="time (s)", ylabel="voltage (V)", title="as read (glitch at row 1235 replaced)")
ax[0].legend(loc="lower right", fontsize=8)
ax[1].plot(run.x, 1e6 * run.y, lw=0.6, label="read")
ax[1].plot(run.x, 1e6 * model.predict(run.x, t=run.t), "--", lw=0.6, label="fitted")
ax[1].set(xlabel="voltage (V)", ylabel="charge (µC)", title="the fit")
ax[1].legend(loc="upper left", fontsize=8)
fig.tight_layout()
