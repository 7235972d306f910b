"""Self-sensing closed loop: its targets on the bench, and its cost per sample.

Run: ``python benchmarks/bench_selfsensing.py [--seeds 3] [--operators 20]``.

1. Targets (issue 10), on the simulated bench for each seed: an ActivePI
   identified on a 20 s ``hold`` record; the loop's bench has a bias current
   40 pA above the identification's; a hold record (0..140..0 V in 35 V
   steps, 10 s each) on that bench calibrates the leakage; 60 s of
   ``decaying`` loops are driven by feedforward alone, by the loop with the
   model's identified leakage, and by the loop with the calibrated leakage.
   Width and NRMSE are desired -> laser displacement; the first and last 20 s
   are RMS errors over the whole trajectory's span.
2. Plants of other physics (issue 26), for each seed: the model ``select_model``
   chooses (among the cores the loop runs) on what ``piezohyst excite`` writes,
   leakage from 10 s holds up and down, 60 s of ``decaying`` loops over the range
   the identification record reached (its leakage-corrected charge at the lowest
   and highest voltage, from every history in it, less 3 %). ``--every-core``: only
   this, through each core the loop runs instead of the one chosen; ``--flat-guard``:
   with the controllers' ``flat_guard`` (the gain they then use is printed).
3. Cost: ``step`` called from Python, against the same algorithm written as a
   plain Python function (measured in the same run); ``process`` throughput,
   against a NumPy loop over time.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import piezohyst as ph
from piezohyst.workflows import demo


def python_controller(ctl: ph.SelfSensingController):  # type: ignore[no-untyped-def]
    """The controller's step written plainly in Python (lists, one operator at a time)."""
    op = ctl.compensator.spec.operator
    inv = op.inverse()
    r, w, s = op.thresholds.tolist(), op.weights.tolist(), op.loading_slopes.tolist()
    ri, wi = inv.thresholds.tolist(), inv.weights.tolist()
    c, ci = op.offset, inv.offset
    z = op.initial_state.tolist()
    n = len(r)
    lk = ctl.leakage
    st = {"last": ctl.last_command, "leak": 0.0, "frame": 0.0, "integral": 0.0,
          "d_prev": math.nan, "started": False, "q": 0.0}  # fmt: skip
    zeta = [0.0] * n

    def sync() -> None:
        tail = 0.0
        for i in range(n - 1, -1, -1):
            zeta[i] = c + s[i] * z[i] + tail
            tail += w[i] * z[i]

    sync()

    def step(desired: float, measured: float) -> float:
        last = st["last"]
        if math.isfinite(measured):
            st["q"] = measured
        if st["started"]:
            i_leak = lk.conductance * last + lk.quadratic * last * abs(last) / lk.scale
            st["leak"] += (i_leak + lk.bias - lk.discharge * st["q"]) / ctl.sample_rate
        e = 0.0
        if math.isfinite(measured):
            qc = measured - st["leak"]
            if not st["started"]:
                st["frame"] = c + sum(wi_ * zi for wi_, zi in zip(w, z, strict=True)) - qc
                st["started"] = True
            if math.isfinite(st["d_prev"]):
                e = st["d_prev"] - (qc + st["frame"])
        integral = st["integral"] + ctl.ki * e
        u = desired + integral
        x = ci
        for i in range(n):
            zeta[i] = min(max(zeta[i], u - ri[i]), u + ri[i])
            x += wi[i] * zeta[i]
        v = min(max(x, ctl.v_min), ctl.v_max)
        for i in range(n):
            z[i] = min(max(z[i], v - r[i]), v + r[i])
        if v != x:
            sync()
        else:
            st["integral"] = integral
        st["d_prev"] = desired
        st["last"] = v
        return v

    return step


def numpy_process(ctl: ph.SelfSensingController, desired: np.ndarray, measured: np.ndarray):  # type: ignore[no-untyped-def]
    """A NumPy loop over time: the same loop with vector operations over the operators."""
    op = ctl.compensator.spec.operator
    inv = op.inverse()
    z = op.initial_state.copy()
    lk = ctl.leakage
    last, leak, integral, d_prev, frame = ctl.last_command, 0.0, 0.0, math.nan, None
    out = np.empty_like(desired)
    for k in range(desired.size):
        if frame is not None:
            leak += (lk.conductance * last + lk.bias - lk.discharge * measured[k]) / 1000.0
        qc = measured[k] - leak
        if frame is None:
            frame = op.offset + op.weights @ z - qc
        e = 0.0 if math.isnan(d_prev) else d_prev - (qc + frame)
        u = desired[k] + integral + ctl.ki * e
        tail = np.concatenate([np.cumsum((op.weights * z)[::-1])[::-1][1:], [0.0]])
        zeta = op.offset + op.loading_slopes * z + tail
        x = inv.offset + inv.weights @ np.clip(zeta, u - inv.thresholds, u + inv.thresholds)
        v = min(max(x, 0.0), 140.0)
        if v == x:
            integral += ctl.ki * e
        z = np.clip(z, v - op.thresholds, v + op.thresholds)
        d_prev, last = desired[k], v
        out[k] = v
    return out


def targets(seed: int, operators: int, ki: float = 0.5) -> dict[str, dict[str, float]]:
    ident = ph.simulate(signal="hold", duration=20.0, seed=seed)
    active = ph.ActivePI(operators).fit(ident.voltage, ident.charge, t=ident.t)
    pure = active.remove_growth(ident.voltage, ident.charge, t=ident.t)
    gain = demo._calibration_gain(ident, pure)
    study = demo._closed_loop_study(
        active, gain=gain, seed=seed + 700, preset=demo.DEFAULT_PRESET, ki=ki
    )
    return {
        name: {k: v for k, v in run.items() if k != "record"} for name, run in study["runs"].items()
    }


def plants(seed: int, every_core: bool = False, flat_guard: bool = False) -> None:
    """The loop on each plant of ``ph.simulation.PLANTS`` (issue 26's protocol); with
    ``every_core``, the loop through each core the loop runs, not only the one chosen."""
    import warnings

    from piezohyst.analysis.selection import LOOP_CANDIDATES, candidate_model
    from piezohyst.metrics import hysteresis_width
    from piezohyst.simulation import PLANTS, Bench, make_signal, run_loop
    from piezohyst.workflows.excitation import excitation

    cores = ("classical-pi", "active-pi", "bouc-wen", "preisach", "duhem")  # every_core's
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    holds = excitation("holds", v_min=0.0, v_max=140.0, sample_rate=1000.0, hold=10.0)
    _, shape = make_signal("decaying", amplitude=1.0, frequency=0.5, duration=60.0)
    for name, p in PLANTS.items():
        ident = ph.simulate(played.voltage, played.t, preset=p, seed=3 * seed + 1)
        cal = ph.simulate(holds.voltage, holds.t, preset=p, seed=3 * seed + 2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            leak = ph.calibrate_leakage(cal.t, cal.voltage, cal.charge)
            if every_core:
                models = {c: candidate_model(c, 10, ("V", "C")).fit(ident.voltage, ident.charge,
                                                               t=ident.t)
                          for c in cores[1:]}  # fmt: skip
            else:
                sel = ph.select_model(
                    ident.voltage, ident.charge, t=ident.t, candidates=LOOP_CANDIDATES
                )
                models = {sel.name: sel.model}
        q = ident.charge - leak.charge(ident.voltage, ident.t, ident.charge)
        v = ident.voltage
        top = float(q[v >= v.max() - 1e-9].min() - q[0])
        bottom = float(q[v <= v.min() + 1e-9].max() - q[0])
        lo, hi = bottom + 0.03 * (top - bottom), top - 0.03 * (top - bottom)
        desired = p.gain * (lo + (hi - lo) * shape)
        for model in models.values():
            if isinstance(model, ph.PreisachModel):  # its slope just after a reversal
                core = model.operator_
                step, reach = core.nodes[1] - core.nodes[0], core.nodes[-1] - core.nodes[0]
                first = float(np.diag(core.density).min() / step)
                share = 100 * first / (core.density.sum() / reach)
                print(f"  {name:19s} Preisach: first slope down to {share:.1f} % of its mean")
            ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
                                           leakage=leak, domain="displacement", gain=p.gain,
                                           slew_rate=30e3, flat_guard=flat_guard)  # fmt: skip
            run = run_loop(ctl, desired, Bench(p, seed=3 * seed + 3, voltage=ctl.last_command))
            err = run.displacement - desired
            thirds = [100 * math.sqrt(float(np.mean(e * e))) / float(np.ptp(desired))
                      for e in np.array_split(err, 3)]  # fmt: skip
            # the error above 100 Hz (a loop that chatters), RMS in % of the span
            spec = np.fft.rfft(err)
            fast = np.fft.rfftfreq(err.size, 1e-3) >= 100.0
            chatter = 100 * math.sqrt(2 * float(np.sum(np.abs(spec[fast]) ** 2))) / err.size
            chatter /= float(np.ptp(desired))
            print(
                f"  {name:19s} {type(model).__name__:13s} width "
                f"{100 * hysteresis_width(desired, run.displacement):5.3f} %, RMS error by "
                "thirds "
                + ", ".join(f"{x:5.3f}" for x in thirds)
                + f" %, above 100 Hz {chatter:5.3f} %, saturated {ctl.saturated_count}"
                + (f", ki {ctl.ki_used:.3g}" if flat_guard else "")
            )


def cost(operators: int) -> None:
    rec = ph.simulate(signal="hold", duration=10.0, seed=0)
    model = ph.ActivePI(operators).fit(rec.voltage, rec.charge, t=rec.t)
    n = 200_000
    t = np.arange(n) / 1000.0
    desired = model.hysteresis_.predict(70 + 50 * np.sin(2 * np.pi * 0.5 * t))
    measured = desired * 1.01 + 1e-9 * np.random.default_rng(0).standard_normal(n)

    def make() -> ph.SelfSensingController:
        return ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=1000.0)

    ctl = make()
    ctl.step(float(desired[0]), float(measured[0]))  # compiled
    reps = 20_000
    best_step = best_ref = math.inf
    for _ in range(5):
        ctl = make()
        t0 = time.perf_counter()
        for k in range(reps):
            ctl.step(float(desired[k]), float(measured[k]))
        best_step = min(best_step, (time.perf_counter() - t0) / reps)
        ref = python_controller(make())
        t0 = time.perf_counter()
        for k in range(reps):
            ref(float(desired[k]), float(measured[k]))
        best_ref = min(best_ref, (time.perf_counter() - t0) / reps)
    best_block = math.inf
    for _ in range(5):
        ctl = make()
        t0 = time.perf_counter()
        ctl.process(desired, measured)
        best_block = min(best_block, time.perf_counter() - t0)
    print(f"cost, ActivePI with {operators} operators, best of 5:")
    print(f"  step() from Python        {best_step * 1e6:6.2f} us")
    print(f"  pure-Python step          {best_ref * 1e6:6.2f} us   ({best_ref / best_step:.1f}x)")
    m = 20_000
    t0 = time.perf_counter()
    numpy_process(make(), desired[:m], measured[:m])
    numpy_rate = m / (time.perf_counter() - t0)
    rate = n / best_block
    print(f"  process() {n:,} samples  {rate / 1e6:6.1f} M samples/s")
    ratio = rate / numpy_rate
    print(f"  NumPy loop over time      {numpy_rate / 1e6:6.3f} M samples/s ({ratio:.0f}x)")


def cost_in_metres() -> None:
    """A step with desired displacements through an output map, and a stage's step (two
    actuators, each its loop and map behind the coupling's inverse), against the charge
    step with the map inverted beside it in plain Python floats (measured in the same run)."""
    from piezohyst.simulation import make_signal, simulate_stage

    t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=8.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=8.0)
    rec = simulate_stage(np.column_stack([a, b]), t, seed=0)
    models = [ph.ActivePI(10).fit(rec.voltage[:, i], rec.charge[:, i], t=rec.t) for i in range(2)]
    stage = ph.calibrate_stage(models, rec.voltage, rec.charge, rec.position, rec.t)
    om, m = stage.maps[0], models[0]
    limits = {"v_min": m.input_range_[0], "v_max": m.input_range_[1], "sample_rate": 1000.0}
    reps = 5000
    s = np.linspace(0.3, 0.7, reps) * (om.displacement_range()[1] - om.displacement_range()[0])
    s += om.displacement_range()[0]
    measured = np.full(reps, np.nan)
    c0, c1 = om.coefficients[:2]

    def best(run) -> float:  # type: ignore[no-untyped-def]
        out = math.inf
        for _ in range(5):
            t0 = time.perf_counter()
            run()
            out = min(out, (time.perf_counter() - t0) / reps)
        return out

    metres = ph.SelfSensingController(m, output_map=om, **limits)
    charge = ph.SelfSensingController(m, **limits)

    def in_metres() -> None:
        metres.reset()
        for k in range(reps):
            metres.step(float(s[k]), float(measured[k]))

    def by_hand() -> None:  # the linear map inverted in floats, then the charge step
        charge.reset()
        for k in range(reps):
            charge.step(om.center + om.scale * (float(s[k]) - c0) / c1, float(measured[k]))

    loop = ph.CoupledSelfSensingController(
        models, stage, sample_rate=1000.0, v_min=[x.input_range_[0] for x in models],
        v_max=[x.input_range_[1] for x in models],
    )  # fmt: skip
    d = np.column_stack([s, np.full(reps, s.mean())]) @ stage.coupling.T + stage.offset
    q2 = np.full((reps, 2), np.nan)

    def stage_step() -> None:
        loop.reset()
        for k in range(reps):
            loop.step(d[k], q2[k])

    # the same map with a 150 Hz mode: step() with the next target as preview, against the
    # charge step with the map and the mode's inverse (OutputDynamics.invert) by hand
    from dataclasses import replace

    ringing = replace(om, mode_f0=150.0, mode_zeta=0.05, mode_dt=1e-3)
    moded = ph.SelfSensingController(m, output_map=ringing, **limits)
    w = 2.0 * math.pi * 150.0

    def with_mode() -> None:
        moded.reset()
        for k in range(reps - 1):
            moded.step(float(s[k]), float(measured[k]), s[k + 1 : k + 2])

    def mode_by_hand() -> None:  # the map, then y + 2 zeta/w y' + y''/w^2 from differences
        charge.reset()
        e2 = e1 = math.nan
        for k in range(reps - 1):
            q = om.center + om.scale * (float(s[k]) - c0) / c1
            nxt = om.center + om.scale * (float(s[k + 1]) - c0) / c1
            b1 = e1 if e1 == e1 else q
            b0 = e2 if e2 == e2 else b1
            target = (
                0.5 * (q + b1)
                + 0.1 / w * (q - b1) / 1e-3
                + ((nxt - q) - (b1 - b0)) / (2e-6 * w * w)
            )
            e2, e1 = e1, q
            charge.step(target, float(measured[k]))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t_m, t_h, t_s = best(in_metres), best(by_hand), best(stage_step)
        t_r, t_rh = best(with_mode), best(mode_by_hand)
    print("cost in metres (ActivePI with 10 operators, a linear output map), best of 5:")
    print(f"  step() with the map       {t_m * 1e6:6.2f} us")
    print(f"  charge step + map by hand {t_h * 1e6:6.2f} us   ({t_m / t_h:.1f}x)")
    print(f"  a stage's step, 2 loops   {t_s * 1e6:6.2f} us   ({t_s / (2 * t_m):.2f}x two steps)")
    print(f"  step() through the map's 150 Hz mode, with the next target {t_r * 1e6:6.2f} us")
    print(f"  charge step + map + mode by hand     {t_rh * 1e6:6.2f} us   ({t_r / t_rh:.1f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--operators", type=int, default=20)
    parser.add_argument("--every-core", action="store_true",
                        help="only the plants, the loop through every core it runs")  # fmt: skip
    parser.add_argument("--flat-guard", action="store_true",
                        help="with --every-core: the controllers' flat_guard on")  # fmt: skip
    parser.add_argument("--cost-only", action="store_true",
                        help="only the costs per sample (charge, metres, a stage)")  # fmt: skip
    args = parser.parse_args()
    if args.cost_only:
        cost(args.operators)
        cost_in_metres()
        return
    if args.every_core:
        print("plants of other physics, the loop through each core (60 s of decaying loops):")
        for seed in range(args.seeds):
            print(f" seed {seed}")
            plants(seed, every_core=True, flat_guard=args.flat_guard)
        return
    print(f"piezohyst {ph.__version__}: self-sensing loop, 60 s decaying loops, +40 pA unseen bias")
    rows = []
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        runs = targets(seed, args.operators)
        rows.append(runs)
        print(f"seed {seed} ({time.perf_counter() - t0:.1f} s)")
        for name, m in runs.items():
            print(
                f"  {name:38s} width {m['width_S_pct']:6.3f} %  "
                f"NRMSE {m['tracking_nrmse_S_pct']:6.3f} %"
                f"  first 20 s {m['first_20s_nrmse_S_pct']:6.3f} %  last 20 s "
                f"{m['last_20s_nrmse_S_pct']:6.3f} %"
            )
    print("integral gain, seed 0, hold-calibrated loop:")
    for ki in (0.2, 0.5, 1.0):
        m = targets(0, args.operators, ki)["closed loop, hold-calibrated leakage"]
        width, err = m["width_S_pct"], m["tracking_nrmse_S_pct"]
        print(f"  ki {ki:3.1f}  width {width:6.3f} %  NRMSE {err:6.3f} %")
    print("plants of other physics, 60 s of decaying loops (target 0.3 % width, no drift):")
    for seed in range(args.seeds):
        print(f" seed {seed}")
        plants(seed)
    cost(args.operators)


if __name__ == "__main__":
    main()
