"""Rate: input dynamics identified over several frequencies, predicted and compensated at others.

Run: ``python benchmarks/bench_dynamics.py [--seeds 3]``.

On the bench preset ``T226-H4-203X-amp4ms`` (an amplifier with a 4 ms lag; the
record logs the command), for each seed:

1. Identification on 30 s of ``multifreq`` (0.5, 5 and 20 Hz, decaying loops):
   ActivePI with ``input_dynamics="auto"``; the lag it finds against 4 ms.
2. Prediction of new ``multi`` records at 1, 10 and 40 Hz: NRMSE of the
   rate-aware model, of the same rate-independent model identified on the same
   record, and of one identified at 0.5 Hz only (``hold``).
3. Compensation of a fixed-amplitude trajectory (25-75 % of the charge span)
   at 1, 10 and 40 Hz: displacement hysteresis width with the rate-aware
   inverse against the 0.5 Hz rate-independent one.
4. Either DAC (staircase, interpolating) in front of the lag of a Bouc-Wen capacitor
   (not a PI model): BoucWenModel with ``input_dynamics="auto"`` against the lag
   alone; the identified values with their 95 % intervals, the interval's
   gain and phase at 40 Hz against the truth, and the 40 Hz compensated width.
5. ``input_dynamics="none"`` against a model fitted without the argument
   (must agree to 1e-12), and fit times: plain, each kind, ``auto``, at 3e4
   and 1e6 samples (the latter at 10 kHz).

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width, nrmse
from piezohyst.simulation import PRESETS, make_signal, simulate

PRESET = "T226-H4-203X-amp4ms"


def fit_time(rec: ph.simulation.BenchRecord, kind: str | None, repeats: int = 3) -> float:
    """Best of ``repeats`` fits of ActivePI(20), with ``input_dynamics=kind`` unless None."""
    best = float("inf")
    for _ in range(repeats):
        model = ph.ActivePI(20) if kind is None else ph.ActivePI(20, input_dynamics=kind)
        t0 = time.perf_counter()
        model.fit(rec.voltage, rec.charge, t=rec.t)
        best = min(best, time.perf_counter() - t0)
    return best


def one_seed(seed: int) -> None:
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    rec = simulate(v, t, preset=PRESET, seed=seed)
    aware = ph.ActivePI(20, input_dynamics="auto").fit(rec.voltage, rec.charge, t=rec.t)
    same = ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t)
    slow_rec = simulate(signal="hold", duration=20.0, preset=PRESET, seed=seed + 50)
    slow = ph.ActivePI(20).fit(slow_rec.voltage, slow_rec.charge, t=slow_rec.t)
    dyn = aware.input_dynamics_
    print(
        f"seed {seed}: found {dyn.kind}, lag {dyn.tau * 1e3:.3f} ms, "
        f"delay {dyn.delay * 1e3:.3f} ms "
        f"(bench: 4 ms lag, {100 * (dyn.tau / 4e-3 - 1):+.1f} %)"
    )
    for f in (1.0, 10.0, 40.0):
        tt, vv = make_signal("multi", amplitude=140.0, frequency=f, duration=6.0)
        new = simulate(vv, tt, preset=PRESET, seed=seed + int(f))
        errs = [
            100 * nrmse(new.charge, m.predict(new.voltage, t=new.t)) for m in (aware, same, slow)
        ]
        print(
            f"  predict {f:4.0f} Hz: rate-aware {errs[0]:5.2f} %, rate-independent (same record) "
            f"{errs[1]:5.2f} %, rate-independent (0.5 Hz) {errs[2]:5.2f} %"
        )
    top, bottom = (float(q) for q in aware.operator_.predict(np.array([140.0, 0.0])))
    lo, hi = aware.input_range_
    for f in (1.0, 10.0, 40.0):
        tt, shape = make_signal("fixed", amplitude=1.0, frequency=f, duration=3.0)
        desired = bottom + (top - bottom) * (0.25 + 0.5 * shape)
        keep = tt >= 1.0
        widths = []
        for m in (aware, slow):
            comp = ph.Compensator(
                m, v_min=lo, v_max=hi, sample_rate=1000.0, allow_extrapolation=True
            )
            run = simulate(comp.process(desired), tt, preset=PRESET, seed=seed + 9)
            widths.append(100 * hysteresis_width(desired[keep], run.true_displacement[keep]))
        print(
            f"  compensate {f:4.0f} Hz, 25-75 % of span: rate-aware width {widths[0]:5.2f} %, "
            f"rate-independent (0.5 Hz) {widths[1]:5.2f} %"
        )


def mode(seed: int) -> None:
    """Preset with a 150 Hz bending mode: displacement identification and compensation."""
    preset = "T226-H4-203X-mode"
    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=30.0)
    rec = simulate(v, t, preset=preset, seed=seed)
    kw = {"output_unit": "m", "input_dynamics": "first-order"}
    t0 = time.perf_counter()
    full = ph.ClassicalPI(20, output_dynamics="second-order", **kw).fit(  # type: ignore[arg-type]
        rec.voltage, rec.displacement, t=rec.t
    )
    seconds = time.perf_counter() - t0
    lag = ph.ClassicalPI(20, **kw).fit(rec.voltage, rec.displacement, t=rec.t)  # type: ignore[arg-type]
    m = full.output_dynamics_
    print(
        f"mode, seed {seed}: found {m.f0:.2f} Hz, damping {m.zeta:.4f}, lag "
        f"{full.input_dynamics_.tau * 1e3:.3f} ms (bench 150 Hz, 0.05, 4 ms; fit {seconds:.2f} s)"
    )
    lo, hi = full.input_range_
    top, bottom = (float(q) for q in full.operator_.predict(np.array([140.0, 0.0])))
    for f in (10.0, 40.0, 80.0, 120.0):
        tt, vv = make_signal("multi", amplitude=140.0, frequency=f, duration=3.0)
        new = simulate(vv, tt, preset=preset, seed=seed + int(f))
        errs = [
            100 * nrmse(new.displacement, mm.predict(new.voltage, t=new.t)) for mm in (full, lag)
        ]
        tt, shape = make_signal("fixed", amplitude=1.0, frequency=f, duration=3.0)
        desired = bottom + (top - bottom) * (0.3 + 0.4 * shape)
        keep = tt >= 1.0
        widths = []
        for mm in (full, lag):
            comp = ph.Compensator(mm, v_min=lo, v_max=hi, sample_rate=1000.0)
            pre = comp.precondition(2000)
            commands = np.concatenate([pre, comp.process(desired)])
            run = simulate(commands, np.arange(commands.size) / 1000.0, preset=preset, seed=seed)
            moved = run.true_displacement[pre.size :]
            widths.append(100 * hysteresis_width(desired[keep], moved[keep]))
        print(
            f"  {f:5.0f} Hz: predict NRMSE with mode {errs[0]:5.2f} %, lag only {errs[1]:5.2f} %; "
            f"compensated width (30-70 %) with mode {widths[0]:5.2f} %, lag only {widths[1]:5.2f} %"
        )


def dac(seed: int) -> None:
    """Either DAC behind the 4 ms lag of a Bouc-Wen capacitor."""
    import math

    from piezohyst.model.dynamics import InputDynamics
    from piezohyst.simulation import PLANTS

    plant = dataclasses.replace(PLANTS["bouc-wen"], amp_tau=4e-3)
    e = math.exp(-1e-3 / 4e-3)
    ramp = 1.0 - (1.0 - 4.0 * (1.0 - e)) / (1.0 - e)  # samples of delay a ramping DAC adds
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    for name in ("staircase", "interpolating"):
        rec = simulate(v, t, preset=plant, seed=seed, dac=name)
        truth = InputDynamics("delay+first-order", 4e-3, ramp * 1e-3 if name != "staircase"
                              else 0.0, 1e-3)  # fmt: skip
        h = complex(truth.response(40.0))
        for kind in ("auto", "first-order"):
            t0 = time.perf_counter()
            model = ph.BoucWenModel(input_dynamics=kind).fit(rec.voltage, rec.charge, t=rec.t)
            seconds = time.perf_counter() - t0
            dyn = model.input_dynamics_
            se_d, se_tau = dyn.stderr()
            band = dyn.response_interval(40.0)
            phase = -math.degrees(float(np.angle(h)))
            covered = (band.phase_range[0] <= phase <= band.phase_range[1]
                       and band.gain_range[0] <= abs(h) <= band.gain_range[1])  # fmt: skip
            ramp_v = np.concatenate([np.linspace(0.0, 140.0, 2000), np.full(500, 140.0)])
            q = model.hysteresis_.predict(ramp_v, t=np.arange(ramp_v.size) / 1000.0)
            tt, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=3.0)
            desired = q[0] + (q[-1] - q[0]) * (0.3 + 0.4 * shape)
            lo, hi = model.input_range_
            comp = ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=1000.0,
                                  slew_rate=30e3, allow_extrapolation=True)  # fmt: skip
            run = simulate(comp.process(desired), tt, preset=plant, seed=seed + 9, dac=name)
            keep = tt >= 1.0
            width = 100 * hysteresis_width(desired[keep], run.true_displacement[keep])
            print(
                f"  {name:13s} {kind:11s}: {dyn.kind}, lag {dyn.tau * 1e3:.3f} ± "
                f"{1.96e3 * se_tau:.3f} ms, delay {dyn.delay * 1e3:.3f} ± {1.96e3 * se_d:.3f} ms "
                f"(truth 4 ms, {truth.delay * 1e3:.3f} ms; fit {seconds:.2f} s); 40 Hz phase "
                f"{band.phase:.2f}° [{band.phase_range[0]:.2f}, {band.phase_range[1]:.2f}] "
                f"(truth {phase:.2f}°), covered {covered}, width allowed "
                f"{100 * band.width:.2f} %, measured {width:.2f} %"
            )


def timing() -> None:
    print("fit time, ActivePI with 20 operators, best of 3:")
    for rate, duration in ((1000.0, 30.0), (10_000.0, 100.0)):
        p = dataclasses.replace(PRESETS[PRESET], rate=rate)
        t, v = make_signal(
            "multifreq", amplitude=140.0, frequency=0.5, duration=duration, rate=rate
        )
        rec = simulate(v, t, preset=p, seed=0)
        plain = fit_time(rec, None)
        row = [f"  {t.size:>9,} samples: plain {plain:.3f} s"]
        for kind in ("none", "first-order", "delay", "delay+first-order", "auto"):
            row.append(f"{kind} {fit_time(rec, kind) / plain:.1f}x")
        print(", ".join(row))
    rec = simulate(duration=20.0, seed=0)
    a = ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t)
    b = ph.ActivePI(20, input_dynamics="none").fit(rec.voltage, rec.charge, t=rec.t)
    diff = np.max(np.abs(a.predict(rec.voltage, t=rec.t) - b.predict(rec.voltage, t=rec.t)))
    print(f"input_dynamics='none' vs no argument: largest prediction difference {diff:.1e} C")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    print(f"piezohyst {ph.__version__}: input dynamics on {PRESET}")
    for seed in range(args.seeds):
        one_seed(seed)
    for seed in range(args.seeds):
        mode(seed)
    print("either DAC, Bouc-Wen capacitor behind a 4 ms lag:")
    for seed in range(args.seeds):
        dac(seed)
    timing()


if __name__ == "__main__":
    main()
