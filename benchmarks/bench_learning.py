"""Learning from repetition: its targets on the bench behind a 4 ms amplifier, and its cost.

Run: ``python benchmarks/bench_learning.py [--trials 10] [--figure learning.png]``
(``--plants [--only PLANT] [--slew V/s] [--chosen]`` for part 3; ``--noise-gate G``: the learner's
``noise_gate``; ``--anatomy [--only PLANT]``: the error left, repeating or not; ``--carried``:
the noise the correction carries, measured against the design's figure, on every plant;
``--run-on``: how far each plant's charge runs on past a voltage reversal, and the models';
``--floor [--only PLANT]``: the best periodic command within the limits on each plant, and
an idealised Jacobian law; ``--heldout``: the default law against the harmonic law at scan rates
and on a plant no table ran; ``--probe-said``: where the lead-in's probe says the model's
timing is off).

1. Targets (issue 27), on the bench's amplifier-lag preset ``T226-H4-203X-amp4ms`` with
   0.1 % noise on the charge: the leakage calibrated from 10 s holds up and down; an
   ``ActivePI(10)`` identified on what ``piezohyst excite`` writes, learning with the lag
   stated (4 ms, trusted to 25 %), and an ``ActivePI(10, input_dynamics="auto")``
   identified on 30 s of ``multifreq``; one-second trials of a sine over the middle 40 % of
   the charge reached, at 1, 10, 40 and 100 Hz, continuous. Width and offset-free NRMSE of
   the true displacement, first trial (feedforward) and after ``--trials``.
2. Cost of one trial's update (1000 samples): the learner's FFT law against the same law as
   a dense DFT matrix in NumPy (the naive reference), measured in the same run; and a whole
   trial (``command`` + ``learn``) per sample.

3. ``--plants``: the same on every plant of other physics (each behind a 4 ms amplifier
   lag, 0.1 % charge noise, seeds 0-2), with ``BoucWenModel`` and ``ActivePI`` with
   identified input dynamics, and ``ActivePI`` without them and the lag stated (all
   identified on 30 s of ``multifreq``: 0.5, 5 and 20 Hz), learning from the charge
   (sensorless) and from the laser (a sensor, for comparison): after 10 trials, the range
   over the seeds. ``--chosen``: instead, the model ``select_model`` chooses on that record
   with ``input_dynamics="auto"`` (what ``piezohyst fit --model auto --input-dynamics auto``
   saves), per seed.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import PRESETS, Bench, make_signal
from piezohyst.workflows.excitation import excitation

RATE = 1000.0
#: the amplifier's slew limit (V/s); --slew changes it
SLEW = 30e3
#: the learner's noise_gate; --noise-gate changes it
GATE = 0.0
#: the learner's law; --law changes it
LAW = "harmonic"


def rig(preset: object = None, seed: int = 0) -> dict[str, object]:
    p = PRESETS["T226-H4-203X-amp4ms"] if preset is None else preset
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=RATE)
    span = np.ptp(ph.simulate(played.voltage, played.t, preset=p, seed=1).capacitor_charge)
    p = replace(p, amp_noise=1e-3 * span / p.c_ref)  # type: ignore[type-var]
    ident = ph.simulate(played.voltage, played.t, preset=p, seed=1 + 10 * seed)
    holds = excitation("holds", v_min=0.0, v_max=140.0, sample_rate=RATE, hold=10.0)
    cal = ph.simulate(holds.voltage, holds.t, preset=p, seed=2 + 10 * seed)
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    multi = ph.simulate(v, t, preset=p, seed=4 + 10 * seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        leak = ph.calibrate_leakage(cal.t, cal.voltage, cal.charge)
        stated = ph.ActivePI(n_operators=10).fit(ident.voltage, ident.charge, t=ident.t)
        dynamic = ph.ActivePI(n_operators=10, input_dynamics="auto").fit(
            multi.voltage, multi.charge, t=multi.t
        )
        bw = ph.BoucWenModel(input_dynamics="auto").fit(multi.voltage, multi.charge, t=multi.t)
        plain = ph.ActivePI(n_operators=10).fit(multi.voltage, multi.charge, t=multi.t)
    q = ident.charge - leak.charge(ident.voltage, ident.t, ident.charge)
    vv = ident.voltage
    top = float(q[vv >= vv.max() - 1e-9].min() - q[0])
    bottom = float(q[vv <= vv.min() + 1e-9].max() - q[0])
    lo, hi = bottom + 0.3 * (top - bottom), top - 0.3 * (top - bottom)
    return {"preset": p, "leak": leak, "stated": stated, "dynamic": dynamic, "bw": bw,
            "plain": plain, "range": (lo, hi)}  # fmt: skip


def run(r: dict[str, object], model: ph.HysteresisModel, f: float, trials: int, lag: float,  # type: ignore[no-untyped-def]
        sensor: bool = False, seed: int = 3):  # fmt: skip
    p = r["preset"]
    lo, hi = r["range"]  # type: ignore[misc]
    shape = np.sin(2 * np.pi * f * np.arange(int(RATE)) / RATE)
    desired = p.gain * (0.5 * (lo + hi) + 0.5 * (hi - lo) * shape)  # type: ignore[attr-defined]
    v_min, v_max = model.input_range_
    ilc = ph.LearningCompensator(
        model,
        v_min=v_min,
        v_max=v_max,
        sample_rate=RATE,
        leakage=r["leak"],  # type: ignore[arg-type]
        domain="displacement",
        gain=p.gain,
        lag=lag,
        slew_rate=SLEW,  # type: ignore[attr-defined]
        noise_gate=GATE,
        law=LAW,
    )
    bench = Bench(p, seed=seed, voltage=ilc.last_command)  # type: ignore[arg-type]
    scores, loops = [], []
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for _ in range(trials + 1):
            u = ilc.command(desired)
            rec = bench.run(u)
            if sensor:
                ilc.learn(displacement=rec.displacement)
            else:
                ilc.learn(rec.charge)
            s = rec.true_displacement
            e = (desired - desired.mean()) - (s - s.mean())
            scores.append(
                (hysteresis_width(desired, s), float(np.sqrt(np.mean(e**2)) / np.ptp(desired)))
            )
            loops.append(s)
    return ilc, scores, loops, desired, len(said)


def dense_update(
    c: np.ndarray, e: np.ndarray, q: np.ndarray, lf: np.ndarray, g: float
) -> np.ndarray:
    """The law with a dense DFT matrix: the naive NumPy reference."""
    n = c.size
    k = np.arange(n)
    w = np.exp(-2j * np.pi * np.outer(k, k) / n)
    full_q = np.concatenate([q, q[1 : n - q.size + 1][::-1]])
    full_l = np.concatenate([lf, np.conj(lf[1 : n - lf.size + 1][::-1])])
    spectrum = w @ c + g * full_l * (w @ e)
    spectrum[0] = (w @ c)[0]
    return (np.conj(w) @ (full_q * spectrum)).real / n


def main() -> None:
    global SLEW, GATE, LAW
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--figure", default=None, help="write a figure (error per trial, loops)")
    ap.add_argument("--plants", action="store_true", help="the plants of other physics instead")
    ap.add_argument("--only", default=None, help="with --plants: this plant alone")
    ap.add_argument(
        "--chosen",
        action="store_true",
        help="with --plants: the model fit --model auto --input-dynamics auto chooses",
    )
    ap.add_argument(
        "--anatomy",
        action="store_true",
        help="where the error left lies (one plant: --only, default duhem)",
    )
    ap.add_argument("--slew", type=float, default=SLEW, help="the slew limit, V/s (30e3)")
    ap.add_argument("--noise-gate", type=float, default=GATE, help="the learner's noise_gate (0)")
    ap.add_argument("--law", default=LAW, help="the learner's law (harmonic, jacobian)")
    ap.add_argument(
        "--carried", action="store_true", help="the noise the correction carries, every plant"
    )
    ap.add_argument("--run-on", action="store_true", help="the charge's run-on past reversals")
    ap.add_argument(
        "--floor", action="store_true", help="the best command within the limits, per plant"
    )
    ap.add_argument(
        "--heldout", action="store_true", help="the default law against the harmonic one, unseen"
    )
    ap.add_argument(
        "--probe-said", action="store_true", help="where the probe says the model's timing is off"
    )
    args = ap.parse_args()
    SLEW, GATE, LAW = args.slew, args.noise_gate, args.law
    if args.floor:
        floor_rows(args.trials, args.only)
        return
    if args.heldout:
        heldout_rows(args.trials)
        return
    if args.probe_said:
        probe_said()
        return
    if args.run_on:
        run_on()
        return
    if args.carried:
        carried(args.trials)
        return
    if args.anatomy:
        anatomy(args.trials, args.only or "duhem")
        return
    if args.plants and args.chosen:
        chosen_rows(args.trials, args.only)
        return
    if args.plants:
        plants(args.trials, args.only)
        return
    if LAW != "harmonic":
        print("(--law applies to --plants, --chosen, --anatomy and --carried; this table and the "
              "cost below run each law as they say)")  # fmt: skip
        LAW = "harmonic"
    r = rig()
    print(f"bench {r['preset'].name} with 0.1 % charge noise; trials of 1 s; widths and "  # type: ignore[attr-defined]
          "offset-free NRMSE of the true displacement")  # fmt: skip
    print("| model | scan | first trial | after | law | rollbacks |")
    print("|---|---|---|---|---|---|")
    keep = None
    for name, lag in (("stated", 4e-3), ("dynamic", 0.0)):
        model = r[name]
        label = "ActivePI(10) + lag=4 ms stated" if lag else "ActivePI(10), input_dynamics auto"
        for f in (1.0, 10.0, 40.0, 100.0):
            ilc, scores, loops, desired, warned = run(r, model, f, args.trials, lag)  # type: ignore[arg-type]
            a, b = scores[0], scores[-1]
            d = ilc.design
            print(f"| {label} | {f:g} Hz | {100 * a[0]:.2f} %, {100 * a[1]:.2f} % | "
                  f"{100 * b[0]:.2f} %, {100 * b[1]:.2f} % | gain {d.gain:.2g}, cutoff "
                  f"{d.cutoff:.3g} Hz | {ilc.rollbacks} ({warned} warnings) |")  # fmt: skip
            if name == "stated" and f == 40.0:
                keep = ([100 * t.error for t in ilc.history], loops, desired)
            if name == "dynamic" and f == 40.0:
                timed = ilc
    # cost
    n = 1000
    rng = np.random.default_rng(0)
    c, e = rng.standard_normal(n), rng.standard_normal(n)
    assert keep is not None
    ilc = timed
    design = ilc.design
    q, lf = design.q(), design.l()
    spectrum = np.fft.rfft(c) + design.gain * lf * np.fft.rfft(e)
    spectrum[0] = np.fft.rfft(c)[0]
    fast = np.fft.irfft(q * spectrum, n=n)
    naive = dense_update(c, e, q, lf, design.gain)
    assert np.allclose(fast, naive, atol=1e-9)
    reps = 200
    t0 = time.perf_counter()
    for _ in range(reps):
        s2 = np.fft.rfft(c) + design.gain * lf * np.fft.rfft(e)
        np.fft.irfft(q * s2, n=n)
    fft_t = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    for _ in range(5):
        dense_update(c, e, q, lf, design.gain)
    dense_t = (time.perf_counter() - t0) / 5
    print(f"\nupdate of 1000 samples: FFT {fft_t * 1e6:.0f} us, dense DFT (naive NumPy) "
          f"{dense_t * 1e3:.1f} ms: {dense_t / fft_t:.0f}x")  # fmt: skip
    bench = Bench(r["preset"], seed=9, voltage=ilc.last_command)  # type: ignore[arg-type]
    warnings.simplefilter("ignore")  # a new bench: the learner's first trials there roll back
    t0 = time.perf_counter()
    for _ in range(10):
        u = ilc.command()
        rec = bench.run(u)
        ilc.learn(rec.charge)
    per = (time.perf_counter() - t0) / 10
    t0 = time.perf_counter()
    for _ in range(10):
        rec = bench.run(u)
    sim = (time.perf_counter() - t0) / 10
    print(f"a whole trial (command + learn, 1000 samples, ActivePI with input dynamics): "
          f"{(per - sim) * 1e3:.1f} ms, {(per - sim) / n * 1e6:.1f} us per sample")  # fmt: skip
    jac = ph.LearningCompensator(ilc.model, v_min=ilc.compensator.v_min,
                                 v_max=ilc.compensator.v_max, sample_rate=RATE,
                                 leakage=r["leak"], domain="displacement",  # type: ignore[arg-type]
                                 gain=r["preset"].gain, slew_rate=SLEW,  # type: ignore[attr-defined]
                                 law="jacobian")  # fmt: skip
    bench = Bench(r["preset"], seed=9, voltage=jac.last_command)  # type: ignore[arg-type]
    jac.learn(bench.run(jac.command(ilc.desired)).charge)  # the lead-in: nothing learned
    t0 = time.perf_counter()
    for _ in range(3):
        jac.learn(bench.run(jac.command()).charge)
    per_jac = (time.perf_counter() - t0) / 3 - sim
    from piezohyst.control.learning.jacobian import damped_step

    big = rng.standard_normal((n, n))
    t0 = time.perf_counter()
    damped_step(big, e)
    svd_t = time.perf_counter() - t0
    t0 = time.perf_counter()
    lam = 1e-3 * np.linalg.norm(big, 2) ** 2
    np.linalg.solve(big.T @ big + lam * np.eye(n), big.T @ e)  # the naive normal equations
    normal_t = time.perf_counter() - t0
    ratio = per_jac / (per - sim)
    print(f"the same trial with law='jacobian': {per_jac * 1e3:.0f} ms ({ratio:.0f}x "
          f"the harmonic law's); its damped step alone (Cholesky, Lanczos) {svd_t * 1e3:.0f} "
          f"ms against {normal_t * 1e3:.0f} ms for the normal equations in NumPy "
          f"({normal_t / svd_t:.2f}x; their largest singular value included)")  # fmt: skip
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        errs, loops, desired = keep
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        ax1.semilogy(range(len(errs)), errs, "o-")
        ax1.set_xlabel("trial")
        ax1.set_ylabel("error on the leakage-corrected charge (% of span)")
        ax1.set_title("40 Hz scan, 4 ms amplifier, ActivePI + stated lag")
        cut = slice(500, 600)
        dd = desired - desired.mean()
        for s, label in ((loops[0], "first trial (feedforward)"), (loops[-1], "after 10 trials")):
            ax2.plot(dd[cut] * 1e6, (s - s.mean())[cut] * 1e6, label=label)
        ax2.set_xlabel("desired, offset removed (um)")
        ax2.set_ylabel("true displacement, offset removed (um)")
        ax2.legend()
        fig.tight_layout()
        fig.savefig(args.figure, dpi=110)
        print(f"figure: {args.figure}")


def anatomy(trials: int, plant: str = "duhem") -> None:
    """``--anatomy``: where the error left after learning lies, ``ActivePI`` with identified
    dynamics at 40 Hz from the charge on one plant: per trial, the displacement error's part
    that repeats every cycle of the trial and the part that does not (RMS, % of the span),
    seeds 0-2, and seed 0 with the charge's noise off."""
    from piezohyst.simulation import PLANTS

    preset = replace(PLANTS[plant], amp_tau=4e-3)
    for seed, noise in ((0, True), (1, True), (2, True), (0, False)):
        r = rig(preset, seed)
        if not noise:
            r = {**r, "preset": replace(r["preset"], amp_noise=0.0)}  # type: ignore[type-var]
        *_, loops, desired, _ = run(r, r["dynamic"], 40.0, trials, 0.0, seed=3 + seed)  # type: ignore[arg-type]
        parts = []
        for s in loops:
            e = (desired - desired.mean()) - (s - s.mean())
            cycle = np.tile(e.reshape(40, -1).mean(axis=0), 40)  # 40 cycles in the trial
            rms = [100 * np.sqrt(np.mean(p**2)) / np.ptp(desired) for p in (cycle, e - cycle)]
            parts.append(f"{rms[0]:.2f}/{rms[1]:.2f}")
        print(
            f"seed {seed}{'' if noise else ', no noise'}: repeating/not per trial (%):",
            " ".join(parts),
        )


def carried(trials: int) -> None:
    """``--carried``: on every plant (seed 0, 40 Hz, ``ActivePI`` with identified dynamics,
    from the charge), the correction's part that differs from cycle to cycle after the
    trials against what the design says it carries (``noise_gain`` times the noise), its
    power by band over the measurement noise's, and the commands a trial at the slew limit."""
    from piezohyst.simulation import PLANTS

    bands = ((1, 40), (40, 100), (100, 250), (250, 500))
    print("| plant | noise | carried: designed | measured | power over the noise's, "
          + ", ".join(f"{a}-{b} Hz" for a, b in bands) + " | slew-limited a trial |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    f = np.fft.rfftfreq(int(RATE), 1.0 / RATE)  # one-second trials
    for name, preset in PLANTS.items():
        preset = replace(preset, amp_tau=4e-3) if preset.amp_tau == 0 else preset
        r = rig(preset, 0)
        ilc, _, _, desired, _ = run(r, r["dynamic"], 40.0, trials, 0.0)  # type: ignore[arg-type]
        span, d = float(np.ptp(desired)), ilc.design
        c = ilc.correction
        rest = c - np.tile(c.reshape(40, -1).mean(axis=0), 40)  # 40 cycles in the trial
        power = np.abs(np.fft.rfft(rest)) ** 2 / rest.size  # per bin; white noise: its variance
        ratio = [float(np.mean(power[(f >= a) & (f < b)])) / d.noise**2 for a, b in bands]
        designed = 100 * d.noise * d.noise_gain / span
        print(f"| {name} | {100 * d.noise / span:.3f} % | {designed:.3f} % | "
              f"{100 * np.std(rest) / span:.3f} % | " + ", ".join(f"{x:.2g}" for x in ratio)
              + f" | {ilc.history[-1].saturated} |")  # fmt: skip


def _run_on(q: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """After the top reversal of one triangle cycle: how far the charge still rises (% of
    the loop's span) and how many volts into the descent it peaks."""
    top = int(np.argmax(v))
    after = q[top:]
    k = int(np.argmax(after[: after.size // 2]))
    return 100 * float(after[k] - after[0]) / float(np.ptp(q)), float(v[top] - v[top + k])


def run_on(amplitudes: tuple[float, ...] = (10.0, 20.0, 28.0, 40.0)) -> None:
    """``--run-on``: every plant's capacitor charge over slow triangles about 70 V (the
    learning scans' middle; 0.025 V per sample, amplifier lag and noise off), after a full
    0-140 V cycle: how far it runs on past the top reversal; and the models identified for
    the learning rows (seed 0, the hysteresis alone, at the middle amplitude)."""
    n = 4000  # samples per triangle cycle

    def triangle(amp: float) -> tuple[np.ndarray, np.ndarray]:
        tri = 70.0 + amp * (2 * np.abs(((np.arange(3 * n) / n) % 1) * 2 - 1) - 1)
        v = np.concatenate([np.linspace(0, 140, 2000), np.linspace(140, 0, 2000),
                            np.linspace(0, 70.0 - amp, 1000), tri])  # fmt: skip
        return v, np.arange(v.size) / RATE

    late = slice(5000 + 2 * n, 5000 + 3 * n)  # the last cycle
    print("charge still rising past the top reversal: % of the loop's span, over how many V")
    print("| plant | " + " | ".join(f"{2 * a:g} V loop" for a in amplitudes) + " |")
    print("|---|" + "---|" * len(amplitudes))
    for name, preset in lagged_plants():
        quiet = replace(preset, amp_noise=0.0, amp_tau=0.0)  # type: ignore[type-var]
        cells = []
        for amp in amplitudes:
            v, t = triangle(amp)
            q = ph.simulate(v, t, preset=quiet, seed=0).capacitor_charge
            rise, volts = _run_on(q[late], v[late])
            cells.append(f"{rise:.2f} % over {volts:.2f} V")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    v, t = triangle(amplitudes[len(amplitudes) // 2])
    print("\nthe models identified for the learning rows (seed 0), hysteresis alone:")
    for name, preset in lagged_plants():
        r = rig(preset, 0)
        cells = []
        for key in ("dynamic", "bw"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                q = r[key].hysteresis_.predict(v, t=t)  # type: ignore[attr-defined]
            rise, volts = _run_on(q[late], v[late])
            cells.append(f"{key} {rise:.2f} % over {volts:.2f} V")
        print(f"{name}: " + ", ".join(cells), flush=True)


def chosen_rows(trials: int, only: str | None = None) -> None:
    """``--plants --chosen``: the model a lab would identify, ``piezohyst fit --model auto
    --input-dynamics auto`` on the same 30 s of ``multifreq`` (every candidate identifying
    the amplifier's lag, the best by forward chaining inside the record), learning at 10
    and 40 Hz from the charge and from the laser, seeds 0-2."""
    print(f"after {trials} trials, the model select_model chose (input dynamics auto) per "
          "seed: width, offset-free NRMSE of the true displacement, seeds 0-2")  # fmt: skip
    print("| plant | chosen (seeds 0-2) | scan | from the charge | from the laser |")
    print("|---|---|---|---|---|")
    for name, preset in lagged_plants(only):
        rigs, picks = [], []
        for seed in range(3):
            r, pick = chosen_rig(preset, seed)
            rigs.append(r)
            picks.append(pick)
        for f in (10.0, 40.0):
            cells = [_cell(rigs, "chosen", f, trials, 0.0, sensor) for sensor in (False, True)]
            print(f"| {name} | {', '.join(picks)} | {f:g} Hz | {cells[0]} | {cells[1]} |",
                  flush=True)  # fmt: skip


def chosen_rig(preset: object, seed: int) -> tuple[dict[str, object], str]:
    """``rig(preset, seed)`` with the model ``select_model`` chooses on its 30 s of
    ``multifreq`` with ``input_dynamics="auto"`` (as ``r["chosen"]``), and that model's name."""
    from piezohyst.analysis.selection import select_model

    r = rig(preset, seed)
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    multi = ph.simulate(v, t, preset=r["preset"], seed=4 + 10 * seed)  # rig()'s record
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sel = select_model(multi.voltage, multi.charge, multi.t, input_dynamics="auto")
    r["chosen"] = sel.model
    return r, sel.name


#: the idealised Jacobian law's regularisation (of the Jacobian's largest singular value
#: squared) and its gain: a one-off choice (0.001-0.1 and 0.5-1 were run on the Duhem and
#: Preisach plants' seed 0), not a design
JAC_LAMBDA, JAC_GAIN = 0.01, 1.0
#: periods run before the one scored: every plant's loop has settled (the commands periodic)
SETTLE = 12


def _periodic(r: dict[str, object], f: float) -> dict[str, object]:
    """One period of the scan of ``run()`` and the chosen model's feedforward command for it
    (the compensator's, no slew limit), on the rig's plant with its noise off."""
    p = replace(r["preset"], amp_noise=0.0)  # type: ignore[type-var]
    lo, hi = r["range"]  # type: ignore[misc]
    n = round(RATE / f)
    desired = p.gain * (0.5 * (lo + hi) + 0.5 * (hi - lo) * np.sin(2 * np.pi * np.arange(n) / n))
    model = r["chosen"]
    v_min, v_max = model.input_range_  # type: ignore[attr-defined]
    comp = ph.Compensator(model, v_min=v_min, v_max=v_max, sample_rate=RATE,
                          domain="displacement", gain=p.gain, slew_rate=None)  # fmt: skip
    u = comp.process(np.tile(desired, SETTLE))[-n:]
    return {"plant": p, "desired": desired, "u": u, "model": model, "bounds": (v_min, v_max)}


def _settled(u: np.ndarray, respond) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The last period's response to ``u`` repeated ``SETTLE`` times from rest."""
    t = np.arange(SETTLE * u.size) / RATE
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(respond(np.tile(u, SETTLE), t))[-u.size :]


def _scored(desired: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    e = (desired - desired.mean()) - (s - s.mean())
    return (100 * hysteresis_width(np.tile(desired, 2), np.tile(s, 2)),
            100 * float(np.sqrt(np.mean(e**2)) / np.ptp(desired)))  # fmt: skip


def _within_slew(u: np.ndarray, du: np.ndarray, step: float) -> np.ndarray:
    """The move nearest ``du`` (least squares) that keeps ``u + du`` within the slew limit,
    over the periodic trial."""
    from scipy.optimize import minimize

    def gaps(x: np.ndarray) -> np.ndarray:
        w = u + x
        return step - np.abs(np.diff(np.r_[w, w[0]]))

    if gaps(du).min() >= 0:
        return du
    res = minimize(lambda x: float(np.sum((x - du) ** 2)), np.zeros_like(du),
                   jac=lambda x: 2 * (x - du), method="SLSQP",
                   constraints=[{"type": "ineq", "fun": gaps}])  # fmt: skip
    return np.asarray(res.x)


def floor_rows(trials: int, only: str | None = None) -> None:
    """``--floor``: what the bars ask of the command, per plant, on the chosen model's rigs
    (seeds 0-2), the plant's noise off and the loop periodic (one period of the scan
    repeated until settled). An idealised Jacobian law, ``u += (J'J + lambda |J|^2 I)^-1 J'
    e``, ``J`` the chosen model's Jacobian along the commands (finite differences, its lag
    included: the effect of each command on every later output, through the memory of its
    reversals too), the move brought within the slew limit, learning from the true
    displacement plus 0.1 % of the span's noise averaged over a second's periods; then the
    plant's own gradient from where that law ends, on the squared error, within the slew
    limit and the model's voltage range (a lower error the commands can reach; its width
    may be larger)."""
    from scipy.optimize import minimize

    from piezohyst.control.learning.jacobian import damped_step, trial_jacobian

    step = SLEW / RATE
    print("noise off, periodic: width, NRMSE of the true displacement (range over seeds 0-2)")
    print(f"| plant | chosen | scan | feedforward | Jacobian law after {trials} trials | "
          "best found within the limits |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for name, preset in lagged_plants(only):
        picked = [chosen_rig(preset, seed) for seed in range(3)]
        for f in (10.0, 40.0):
            ff, best, law = [], [], []
            for seed, (r, _) in enumerate(picked):
                k = _periodic(r, f)
                p, d, u0, model = k["plant"], k["desired"], k["u"], k["model"]
                n = d.size

                def plant(v: np.ndarray, t: np.ndarray, p=p) -> np.ndarray:  # type: ignore[no-untyped-def]
                    return ph.simulate(v, t, preset=p, seed=0).true_displacement

                def mod(v: np.ndarray, t: np.ndarray, model=model, p=p) -> np.ndarray:  # type: ignore[no-untyped-def]
                    return p.gain * model.hysteresis_.predict(v, t)

                ff.append(_scored(d, _settled(u0, plant)))

                def cost(u: np.ndarray, d=d, plant=plant) -> float:  # type: ignore[no-untyped-def]
                    s = _settled(u, plant)
                    e = (d - d.mean()) - (s - s.mean())
                    return float(np.mean(e**2) / np.ptp(d) ** 2) * 1e4

                rng = np.random.default_rng(seed)
                u = u0.copy()
                for _ in range(trials):
                    s = _settled(u, plant)
                    s = s + 1e-3 * np.ptp(d) * rng.standard_normal(n) / np.sqrt(RATE / n)
                    e = (d - d.mean()) - (s - s.mean())
                    jac = trial_jacobian(lambda v, mod=mod: _settled(v, mod), u, 0.0)  # 1 mV
                    jac -= jac.mean(axis=0)  # the offset-free output's
                    du = damped_step(jac, e, JAC_LAMBDA) * JAC_GAIN
                    u = u + _within_slew(u, du, step)
                law.append(_scored(d, _settled(u, plant)))
                res = minimize(cost, u, method="SLSQP", bounds=[k["bounds"]] * n,
                               constraints=[{"type": "ineq", "fun": lambda x: step - np.abs(
                                   np.diff(np.r_[x, x[0]]))}],
                               options={"maxiter": 500, "eps": 1e-4})  # fmt: skip
                best.append(_scored(d, _settled(res.x, plant)))
            cells = []
            for got in (ff, law, best):
                w, e = [g[0] for g in got], [g[1] for g in got]
                cells.append(f"{min(w):.2f}-{max(w):.2f} %, {min(e):.2f}-{max(e):.2f} %")
            chosen = ", ".join(x[1] for x in picked)
            print(f"| {name} | {chosen} | {f:g} Hz | {' | '.join(cells)} |", flush=True)


def _cell(rigs: list[dict[str, object]], key: str, f: float, trials: int, lag: float,
          sensor: bool) -> str:  # fmt: skip
    """One table cell: width and NRMSE after ``trials``, the range over the rigs' seeds, and
    the rollbacks in all."""
    got, backs = [], 0
    for seed, r in enumerate(rigs):
        ilc, scores, *_ = run(r, r[key], f, trials, lag, sensor, seed=3 + seed)  # type: ignore[arg-type]
        got.append(scores[-1])
        backs += ilc.rollbacks
    w = [100 * g[0] for g in got]
    e = [100 * g[1] for g in got]
    return f"{min(w):.2f}-{max(w):.2f} %, {min(e):.2f}-{max(e):.2f} % ({backs})"


def lagged_plants(only: str | None = None) -> Iterator[tuple[str, object]]:
    """Every plant of other physics (or ``only``), each behind a 4 ms amplifier lag."""
    from piezohyst.simulation import PLANTS

    for name, preset in PLANTS.items():
        if only is None or name == only:
            yield name, (replace(preset, amp_tau=4e-3) if preset.amp_tau == 0 else preset)


def probe_said() -> None:
    """``--probe-said``: where the lead-in's probe measures the loop beyond every timing the
    law allows for (the learner's warning), for each plant behind its 4 ms amplifier, seeds
    0-2, at 10 and 40 Hz, with ActivePI without input dynamics (no lag stated, and the 4 ms
    stated), with identified dynamics, and BoucWen with them: the delay and lag beyond the
    model that fit the probe, or "-" where it said nothing."""
    global LAW
    LAW = "auto"
    print("| plant | model | 10 Hz, seeds 0-2 | 40 Hz, seeds 0-2 |")
    print("|---|---|---|---|")
    for name, preset in lagged_plants():
        rigs = [rig(preset, seed) for seed in range(3)]
        for key, lag, label in (("plain", 0.0, "ActivePI(10), no dynamics"),
                                ("plain", 4e-3, "ActivePI(10), lag=4 ms stated"),
                                ("dynamic", 0.0, "ActivePI(10), auto"),
                                ("bw", 0.0, "BoucWen, auto")):  # fmt: skip
            cells = []
            for f in (10.0, 40.0):
                said = []
                for seed, r in enumerate(rigs):
                    ilc, *_ = run(r, r[key], f, 1, lag, False, seed=3 + seed)  # type: ignore[arg-type]
                    d = ilc.design
                    sized = f"{d.probe_delay * 1e3:.2g} + {d.probe_lag * 1e3:.2g} ms"
                    said.append(sized if d.probe_phase < 0 else "ahead" if d.probe_phase else "-")
                cells.append(", ".join(said))
            print(f"| {name} | {label} | {cells[0]} | {cells[1]} |", flush=True)
    LAW = "harmonic"


def heldout_rows(trials: int) -> None:
    """``--heldout``: the default law (``auto``) against the harmonic law where neither was
    chosen: the plants at scan rates no table ran (25 and 60 Hz, seed 0, ActivePI with
    identified dynamics, from the charge); and the bench's bending-mode preset (150 Hz, 5 %
    damping, behind its 4 ms lag), never used in learning before, from the charge and from
    the laser with that charge model, and from the laser with a displacement model that holds
    the mode (ClassicalPI(20), first-order input and second-order output dynamics, fitted on
    the laser over 30 s of multifreq at 2.5, 25 and 100 Hz)."""
    global LAW
    print(f"after {trials} trials: width, offset-free NRMSE of the true displacement "
          "(rollbacks)")  # fmt: skip
    print("| plant | model, learned from | scan | harmonic | auto (the default) |")
    print("|---|---|---|---|---|")
    mode = PRESETS["T226-H4-203X-mode"]
    cases = [(name, [rig(preset, 0)]) for name, preset in lagged_plants()]
    cases.append((mode.name, [rig(mode, 0)]))
    for name, rigs in cases:
        laser = name == mode.name
        for f in (10.0, 25.0, 40.0) if laser else (25.0, 60.0):
            for sensor in (False, True) if laser else (False,):
                cells = []
                for law in ("harmonic", "auto"):
                    LAW = law  # what run() builds the learner with
                    cells.append(_cell(rigs, "dynamic", f, trials, 0.0, sensor))
                src = "the laser" if sensor else "the charge"
                print(f"| {name} | ActivePI(10), auto; {src} | {f:g} Hz | {cells[0]} | "
                      f"{cells[1]} |", flush=True)  # fmt: skip
    LAW = "harmonic"
    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=30.0)
    rec = ph.simulate(v, t, preset=mode, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ph.ClassicalPI(20, output_unit="m", input_dynamics="first-order",
                               output_dynamics="second-order").fit(rec.voltage, rec.displacement,
                                                                   t=rec.t)  # fmt: skip
    lo, hi = model.input_range_
    top, bottom = (float(q) for q in model.operator_.predict(np.array([140.0, 0.0])))
    for f in (10.0, 25.0, 40.0):
        desired = 0.5 * (top + bottom) + 0.2 * (top - bottom) * np.sin(
            2 * np.pi * f * np.arange(int(RATE)) / RATE)  # fmt: skip
        cells = []
        for law in ("harmonic", "auto"):
            ilc = ph.LearningCompensator(model, v_min=lo, v_max=hi, sample_rate=RATE,
                                         slew_rate=SLEW, law=law)  # fmt: skip
            bench = Bench(mode, seed=3, voltage=ilc.last_command)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for _ in range(trials + 1):
                    got = bench.run(ilc.command(desired))
                    ilc.learn(displacement=got.displacement)
            s = got.true_displacement
            e = (desired - desired.mean()) - (s - s.mean())
            cells.append(f"{100 * hysteresis_width(desired, s):.2f} %, "
                         f"{100 * np.sqrt(np.mean(e**2)) / np.ptp(desired):.2f} % "
                         f"({ilc.rollbacks})")  # fmt: skip
        print(f"| {mode.name} | ClassicalPI(20) + mode, of the displacement; the laser | "
              f"{f:g} Hz | {cells[0]} | {cells[1]} |", flush=True)  # fmt: skip


def plants(trials: int, only: str | None = None) -> None:
    print(f"after {trials} trials: width, offset-free NRMSE of the true displacement, range over "
          "seeds 0-2 (rollbacks in all)")  # fmt: skip
    print("| plant | model | scan | from the charge | from the laser |")
    print("|---|---|---|---|---|")
    for name, preset in lagged_plants(only):
        rigs = [rig(preset, seed) for seed in range(3)]
        for key, label, lag in (("dynamic", "ActivePI(10), auto", 0.0),
                                ("bw", "BoucWen, auto", 0.0),
                                ("plain", "ActivePI(10) + lag=4 ms stated", 4e-3),
                                ("plain", "ActivePI(10), no dynamics, no lag", 0.0)):  # fmt: skip
            if lag and LAW == "jacobian":  # refused: the lag is identified with the model
                continue
            for f in (10.0, 40.0):
                cells = [_cell(rigs, key, f, trials, lag, sensor) for sensor in (False, True)]
                print(f"| {name} | {label} | {f:g} Hz | {cells[0]} | {cells[1]} |")


if __name__ == "__main__":
    main()
