"""
The compensator outside Python: an FMU, checked in FMPy
=======================================================

A compensator that runs in a control loop or on a microcontroller is C: the C export
(:func:`piezohyst.control.export_c`), a shared library for LabVIEW, ctypes or Simulink's
C caller (:func:`piezohyst.control.write_shared`), a MEX gateway for MATLAB
(:func:`piezohyst.control.write_mex`), or an FMI 2.0 co-simulation FMU for any FMI host
(:func:`piezohyst.control.write_fmu`). Each is built from the same C and equals Python's
commands; here the FMU, run by FMPy, against the Python compensator it came from.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

import piezohyst as ph
from piezohyst.control import write_fmu

rec = ph.simulate(signal="hold", duration=20.0, seed=0)
model = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
comp = ph.Compensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0)
path = write_fmu(comp, Path(tempfile.mkdtemp()) / "ph_comp.fmu")  # compiles the C
print("FMPy's own checker:", validate_fmu(str(path)) or "no problem")

# %%
# The same targets through the FMU and through Python
# ---------------------------------------------------
t = np.arange(2000) / 1000.0
target = model.hysteresis_.predict(70.0 + 50.0 * np.sin(2 * np.pi * t))  # C, reachable
inputs = np.array(list(zip(t, target, strict=True)), dtype=[("time", float), ("target", float)])
result = simulate_fmu(str(path), input=inputs, output=["voltage"], step_size=1e-3,
                      stop_time=float(t[-1]), output_interval=1e-3)  # fmt: skip
fmu_volts = result["voltage"][1:]  # row k + 1: the command for the target at row k
python_volts = ph.Compensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0).process(target)
gap = np.max(np.abs(fmu_volts - python_volts[: fmu_volts.size]))
print(f"largest difference, FMU against Python: {gap:.1e} V")

fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
ax[0].plot(t[: fmu_volts.size], fmu_volts, lw=0.8, label="FMU (FMPy)")
ax[0].plot(t, python_volts, "--", lw=0.8, label="Python")
ax[0].set(xlabel="time (s)", ylabel="command (V)", title="the commands")
ax[0].legend(fontsize=8)
ax[1].plot(t[: fmu_volts.size], fmu_volts - python_volts[: fmu_volts.size], lw=0.6)
ax[1].set(xlabel="time (s)", ylabel="FMU - Python (V)", title=f"at most {gap:.1e} V apart")
fig.tight_layout()
