"""The sensor-once calibration and the lab's hosts: times and ratios against naive NumPy
references measured in the same run.

Run: ``python benchmarks/bench_hosts.py``. Measures

* ``calibrate_gain`` on 20 s of the bench at 1 kHz against the naive reference (one
  ``numpy.linalg.lstsq`` of the displacement on the charge): what the delay search, the
  leakage columns, the order by evidence and the Newey-West errors cost;
* the shared library's ``ph_comp_process`` (ctypes, one call for a block) and one FMU
  step through FMPy, against ``Compensator.process`` and a NumPy loop over time (the
  naive reference: eq. 18 written with NumPy per sample);
* how long the controller in C stays with the Python controller in a closed loop on the
  simulated bench (the charge read depends on the commands sent, so rounding differences
  between the compiled kernel and C grow), and with a recorded charge fed open loop.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import ctypes
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.control.export.fmu import write_fmu
from piezohyst.control.export.shared import write_shared


def best(f, repeats: int = 5) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def numpy_reference(h: ph.PIHysteresis, inv: ph.PIHysteresis, d: np.ndarray) -> np.ndarray:
    """Eq. 18 per sample with NumPy vectors (the naive reference: no kernel, no limits)."""
    r, w = inv.thresholds, inv.weights
    zeta = inv.initial_state.copy()
    out = np.empty_like(d)
    for k, q in enumerate(d):
        zeta = np.clip(zeta, q - r, q + r)
        out[k] = inv.offset + w @ zeta
    return out


def main() -> None:
    warnings.simplefilter("ignore")
    rec = ph.simulate(signal="multifreq", duration=20.0, seed=0)
    model = ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t)
    cal = best(lambda: ph.calibrate_gain(model, rec.voltage, rec.charge, rec.displacement, rec.t))
    qc = model.remove_growth(rec.voltage, rec.charge, t=rec.t)
    x = np.column_stack([np.ones_like(qc), qc])
    naive = best(lambda: np.linalg.lstsq(x, rec.displacement, rcond=None))
    print(f"calibrate_gain, 20 000 samples: {cal * 1e3:.1f} ms; one lstsq {naive * 1e3:.2f} ms "
          f"(x{cal / naive:.0f})")  # fmt: skip

    lo, hi = model.input_range_
    comp = ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=1000.0, slew_rate=None)
    d = model.hysteresis_.predict(lo + (hi - lo) * (0.5 + 0.4 * np.sin(np.arange(100_000) / 50)))
    with tempfile.TemporaryDirectory() as tmp:
        _, _, lib = write_shared(comp, Path(tmp) / "ph_comp.c")
        so = ctypes.CDLL(str(lib))
        so.ph_comp_new.restype = ctypes.c_void_p
        doubles = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        so.ph_comp_process.argtypes = [ctypes.c_void_p, doubles, doubles, ctypes.c_long]
        handle = so.ph_comp_new()
        out = np.empty_like(d)
        c_lib = best(lambda: so.ph_comp_process(handle, d, out, d.size)) / d.size
        py = best(lambda: comp.process(d)) / d.size
        short = d[:2000]
        ref = best(lambda: numpy_reference(model.hysteresis_.operator_,
                                           model.hysteresis_.operator_.inverse(), short),
                   3) / short.size  # fmt: skip
        fmu_path = write_fmu(comp, Path(tmp) / "ph_comp.fmu")
        from fmpy import simulate_fmu

        t = np.arange(2000) / 1000.0
        inputs = np.array(list(zip(t, short, strict=True)),
                          dtype=[("time", float), ("target", float)])  # fmt: skip
        fmu = best(lambda: simulate_fmu(str(fmu_path), input=inputs, output=["voltage"],
                                        step_size=1e-3, stop_time=float(t[-1]),
                                        output_interval=1e-3), 3) / short.size  # fmt: skip
    print(
        f"per sample, 20 operators: shared library {c_lib * 1e9:.1f} ns, "
        f"Compensator.process {py * 1e9:.1f} ns, FMU through FMPy {fmu * 1e6:.1f} us, "
        f"NumPy reference {ref * 1e6:.2f} us (library x{ref / c_lib:.0f} faster; "
        f"FMPy's Python loop x{fmu / ref:.1f} of the reference)"
    )
    controller_horizon()


def controller_horizon() -> None:
    """The C controller against the Python one, open loop and closed on the bench, 12 s."""
    from piezohyst.simulation import Bench, make_signal

    rec = ph.simulate(signal="decaying", duration=12.0, seed=3)
    model = ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t)
    lo, hi = model.input_range_
    _, shape = make_signal("decaying", amplitude=1.0, duration=12.0)
    v = lo + (hi - lo) * (0.5 + 0.45 * shape / np.abs(shape).max())
    d = model.hysteresis_.predict(v, t=np.arange(v.size) / 1000.0)
    with tempfile.TemporaryDirectory() as tmp:
        ctl = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=1000.0)
        _, _, lib = write_shared(ctl, Path(tmp) / "ph_comp.c")
        so = ctypes.CDLL(str(lib))
        so.ph_comp_new.restype = ctypes.c_void_p
        doubles = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        so.ph_comp_process.argtypes = [ctypes.c_void_p, doubles, doubles, doubles, ctypes.c_long]
        charge = rec.charge[: d.size].copy()
        out = np.empty_like(d)
        so.ph_comp_process(so.ph_comp_new(), d, charge, out, d.size)
        open_loop = float(np.max(np.abs(out - ctl.process(d, charge))))
        python = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=1000.0)
        handle = so.ph_comp_new()
        b1, b2 = Bench(seed=1), Bench(seed=1)
        one = [np.empty(1) for _ in range(3)]
        errors = np.empty(d.size)
        for k in range(d.size):
            v_py = python.step(float(d[k]), b1.reading.charge)
            one[0][0], one[1][0] = d[k], b2.reading.charge
            so.ph_comp_process(handle, one[0], one[1], one[2], 1)
            b1.apply(v_py)
            b2.apply(float(one[2][0]))
            errors[k] = abs(v_py - one[2][0])
    firsts = []
    for limit in (1e-9, 1e-6, 1e-3):
        bad = np.flatnonzero(errors > limit)
        firsts.append(f"{limit:g} V at {bad[0] / 1000:.2f} s" if bad.size else f"{limit:g}: never")
    print(f"controller in C against Python, 12 s: open loop (a recorded charge) max "
          f"{open_loop:.2g} V; closed on the bench: first beyond {', '.join(firsts)}; max "
          f"{errors.max():.3g} V")  # fmt: skip


if __name__ == "__main__":
    main()
