"""The learning tests' rig: a plant of the zoo behind its amplifier, the model a lab would
identify on it, and one-second scans learned trial after trial."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

import piezohyst as ph
from piezohyst.errors import LearningWarning
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import Bench, BenchPreset, BenchRecord, make_signal
from piezohyst.workflows.excitation import excitation

RATE = 1000.0


@dataclass
class Rig:
    preset: BenchPreset
    leak: ph.Leakage
    model: ph.HysteresisModel
    ident: BenchRecord
    range: tuple[float, float]
    seed: int = 0


def make_rig(plant: BenchPreset, model: Callable[[], ph.HysteresisModel], seed: int = 0) -> Rig:
    """``plant`` with 0.1 % noise on the charge, its leakage calibrated from 10 s holds up and
    down, ``model()`` identified on 30 s of multifreq, and the scan's range; ``seed`` draws
    other noise for every record and the scans (0: the tests' own)."""
    s = 10 * seed
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=RATE)
    span = np.ptp(ph.simulate(played.voltage, played.t, preset=plant, seed=1 + s).capacitor_charge)
    p = replace(plant, amp_noise=1e-3 * span / plant.c_ref)
    ident = ph.simulate(played.voltage, played.t, preset=p, seed=1 + s)
    holds = excitation("holds", v_min=0.0, v_max=140.0, sample_rate=RATE, hold=10.0)
    cal = ph.simulate(holds.voltage, holds.t, preset=p, seed=2 + s)
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    multi = ph.simulate(v, t, preset=p, seed=4 + s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the relaxing plant's calibration says how sure it is
        leak = ph.calibrate_leakage(cal.t, cal.voltage, cal.charge)
        fitted = model().fit(multi.voltage, multi.charge, t=multi.t)
    # the scan's range: the charge (leakage removed) the record reached at its lowest and highest
    # voltage from every history in it (as the self-sensing loop's test), its middle 40 %
    q = ident.charge - leak.charge(ident.voltage, ident.t, ident.charge)
    vv = ident.voltage
    top = float(q[vv >= vv.max() - 1e-9].min() - q[0])
    bottom = float(q[vv <= vv.min() + 1e-9].max() - q[0])
    middle = (bottom + 0.3 * (top - bottom), top - 0.3 * (top - bottom))
    return Rig(p, leak, fitted, ident, middle, seed)


def scan(
    rig: Rig, model: ph.HysteresisModel, f: float, trials: int, *, lag: float = 0.0,
    gap: int | None = None, sensor: bool = False, law: str = "harmonic", strict: bool = True,
    measure_lag: bool = True,
) -> tuple[ph.LearningCompensator, list[tuple[float, float]]]:  # fmt: skip
    """Trials of one second of a sine at ``f``, continuous; per trial the width and the
    offset-free NRMSE of the true displacement. ``strict``: a learning warning from the
    charge fails (no rollback expected)."""
    p = rig.preset
    lo, hi = rig.range
    shape = np.sin(2 * np.pi * f * np.arange(int(RATE)) / RATE)
    desired = p.gain * (0.5 * (lo + hi) + 0.5 * (hi - lo) * shape)
    v_min, v_max = model.input_range_
    ilc = ph.LearningCompensator(model, v_min=v_min, v_max=v_max, sample_rate=RATE,
                                 leakage=rig.leak, domain="displacement", gain=p.gain,
                                 lag=lag, slew_rate=30e3, law=law,  # type: ignore[arg-type]
                                 measure_lag=measure_lag)  # fmt: skip
    bench = Bench(p, seed=3 + 10 * rig.seed, voltage=ilc.last_command)
    scores = []
    for j in range(trials):
        u = ilc.command(desired)
        assert np.isfinite(u).all() and v_min <= u.min() and u.max() <= v_max
        rec = bench.run(u)
        y = rec.charge.copy()
        if gap is not None and j == gap:
            y[::3] = np.nan  # a third of the readings lost, everywhere in the trial
            y[300:500] = np.nan
        if sensor:  # the laser's reading; its first update learns the offset and may overshoot
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LearningWarning)
                ilc.learn(displacement=rec.displacement)
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("error" if strict else "ignore", LearningWarning)
                ilc.learn(y)
        s = rec.true_displacement
        e = (desired - desired.mean()) - (s - s.mean())
        scores.append((hysteresis_width(desired, s),
                       float(np.sqrt(np.mean(e**2)) / np.ptp(desired))))  # fmt: skip
    return ilc, scores
