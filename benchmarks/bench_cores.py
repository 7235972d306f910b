"""Preisach, Duhem and Bouc-Wen cores: issue 11's bench targets and their cost.

Run: ``python benchmarks/bench_cores.py [--seeds 3]``.

1. Minor loops (for each seed): every model identified on 40 s of ``decaying``
   loops (2 * 10^4 samples at 1 kHz would be 20 s: the fit time is measured on
   the first 20 s), then a 20 s decaying desired displacement driven through
   its ``Compensator`` on the bench, which starts at rest at 0 V like the
   training record (laser for checking only): width desired -> displacement.
   Then a steady 1 Hz loop run for 20 cycles through the model alone: how far
   its output moves per cycle (a model whose loops do not close ratchets).
2. Cost of one compensator step in the compiled kernel (``process``, ns per
   sample, best of 5) against the naive way to invert a model — a bracketing
   root finder (``scipy.optimize.brentq``) calling the model's forward step
   from Python for every trial — measured in the same run on 300 samples.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable

import numpy as np
from scipy.optimize import brentq

import piezohyst as ph
from piezohyst.simulation import make_signal, simulate

LEAK = ("integral", "abs_integral")
MAKERS: list[tuple[str, Callable[[], ph.HysteresisModel]]] = [
    ("active PI (paper)", lambda: ph.ActivePI(20)),
    ("Preisach", lambda: ph.PreisachModel()),
    ("Duhem", lambda: ph.DuhemModel()),
    ("Bouc-Wen", lambda: ph.BoucWenModel()),
    # the bench's leak depends on the voltage: with both leak terms, then with a relaxing
    # part too (the bench is rate independent: what does it cost where it is not needed?)
    ("Preisach, 2 leak terms", lambda: ph.PreisachModel(growth_terms=LEAK)),
    ("+ relaxation", lambda: ph.PreisachModel(growth_terms=LEAK, relaxation=0.1)),
    ("+ relax. + creep", lambda: ph.PreisachModel(growth_terms=LEAK, relaxation=0.1,
                                                 creep=(0.02, 0.2))),
]  # fmt: skip
FS = 1000.0  # the bench's and the loop's rate (Hz)


def times(n: int) -> np.ndarray:
    return np.arange(n) / FS


def best_of(fn: Callable[[], object], repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        began = time.perf_counter()
        fn()
        times.append(time.perf_counter() - began)
    return min(times)


def naive_inverse(model: ph.HysteresisModel, desired: np.ndarray, hi: float) -> np.ndarray:
    """Per sample: brentq on the core's forward step from the current state (Python calls);
    with kept rate-dependent terms, on the whole model's step (``propagate`` with a state)."""
    if model.terms_:
        return naive_model_inverse(model, desired, hi)
    core = model.operator_
    state = np.array(core.initial_state)
    out = np.empty_like(desired)
    for k, d in enumerate(desired):

        def miss(v: float, z: np.ndarray = state, target: float = float(d)) -> float:
            return float(core.propagate([v], z).output[0]) - target

        lo_miss, hi_miss = miss(0.0), miss(hi)
        v = 0.0 if lo_miss >= 0 else hi if hi_miss <= 0 else brentq(miss, 0.0, hi, xtol=1e-12)
        out[k] = v
        state = core.propagate([v], state).state
    return out


def naive_model_inverse(model: ph.HysteresisModel, desired: np.ndarray, hi: float) -> np.ndarray:
    """brentq on ``model.propagate`` one sample ahead from the state (the model's own path),
    starting where the compensator starts (the model's initial state, its lags at rest)."""
    v0 = float(model.operator_.initial_state[0])
    state: object = model.propagate([v0], np.array([-1.0 / FS])).state
    out = np.empty_like(desired)
    for k, d in enumerate(desired):
        tk = np.array([k / FS])

        def miss(v: float, z: object = state, target: float = float(d), at: object = tk) -> float:
            return float(model.propagate([v], at, z).output[0]) - target  # type: ignore[arg-type]

        lo_miss, hi_miss = miss(0.0), miss(hi)
        v = 0.0 if lo_miss >= 0 else hi if hi_miss <= 0 else brentq(miss, 0.0, hi, xtol=1e-12)
        out[k] = v
        state = model.propagate([v], tk, state).state  # type: ignore[arg-type]
    return out


def minor_loops(seed: int) -> list[dict[str, float]]:
    train = simulate(signal="decaying", duration=40.0, seed=seed)
    _, shape = make_signal("decaying", amplitude=1.0, duration=20.0)
    _, cycle = make_signal("fixed", amplitude=1.0, frequency=1.0, duration=1.0)
    gain = 125.0
    rows = []
    for name, make in MAKERS:
        fit_s = best_of(lambda make=make: make().fit(
            train.voltage[:20000], train.charge[:20000], t=train.t[:20000]), 3)  # fmt: skip
        model = make().fit(train.voltage, train.charge, t=train.t)
        hi = model.input_range_[1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ph.ExtrapolationWarning)
            sweep = np.concatenate([np.linspace(0.0, hi, 2000), np.linspace(hi, 0.0, 2000)])
            ramp = model.hysteresis_.predict(sweep, t=times(sweep.size))
            loops = np.tile(0.25 * hi + 0.5 * hi * cycle, 20)
            steady = model.hysteresis_.predict(loops, t=times(loops.size))
        top, bottom = float(ramp[1999]), float(ramp[-1])
        q_des = bottom + (top - bottom) * (0.05 + 0.9 * shape)
        comp = ph.Compensator(model, v_min=0.0, v_max=hi, domain="displacement", gain=gain,
                              sample_rate=FS)  # fmt: skip
        command = comp.process(gain * q_des)
        run = simulate(np.concatenate([[0.0], command]), np.arange(command.size + 1) / 1000.0,
                       seed=seed + 7)  # fmt: skip
        width = ph.metrics.hysteresis_width(gain * q_des, run.displacement[1:])
        per = steady.reshape(20, -1)[:, -1]
        drift = abs(per[-1] - per[-2]) / float(np.ptp(steady))
        rows.append({"model": name, "fit_s": fit_s, "width_pct": 100 * width,
                     "drift_per_cycle": drift, "train_pct": 100 * model.nrmse_})  # fmt: skip
    return rows


def cost() -> list[dict[str, float]]:
    train = simulate(signal="decaying", duration=40.0, seed=1)
    _, shape = make_signal("decaying", amplitude=1.0, duration=20.0)
    rows = []
    for name, make in MAKERS:
        model = make().fit(train.voltage, train.charge, t=train.t)
        hi = model.input_range_[1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ph.ExtrapolationWarning)
            sweep = np.concatenate([np.linspace(0.0, hi, 2000), np.linspace(hi, 0.0, 2000)])
            ramp = model.hysteresis_.predict(sweep, t=times(sweep.size))
        desired = ramp[-1] + (ramp[1999] - ramp[-1]) * (0.05 + 0.9 * shape)
        # no slew limit: the naive reference has none (with the trained default the first
        # samples ramp up from 0 V and the two differed by tens of volts there)
        comp = ph.Compensator(model, v_min=0.0, v_max=hi, sample_rate=FS, slew_rate=None)
        comp.process(desired[:10])

        def block(comp: ph.Compensator = comp, desired: np.ndarray = desired) -> None:
            comp.reset()
            comp.process(desired)

        ns = best_of(block) / desired.size * 1e9
        comp.reset()
        first = desired[:2000]
        step_us = best_of(lambda comp=comp, first=first: [comp.step(float(d)) for d in first], 3)
        step_us = step_us / 2000 * 1e6
        row = {"model": name, "process_ns": ns, "step_us": step_us, "naive_us": float("nan")}
        if name != "active PI (paper)":
            began = time.perf_counter()
            naive = naive_inverse(model.hysteresis_, desired[:300], hi)
            row["naive_us"] = (time.perf_counter() - began) / 300 * 1e6
            comp.reset()
            check = comp.process(desired[:300])
            row["naive_agrees_V"] = float(np.max(np.abs(naive - check)))
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    print(f"piezohyst {ph.__version__}: Preisach, Duhem, Bouc-Wen on the bench")
    print("1. decaying loops, identified on 40 s of decaying loops (fit time: 2e4 samples)")
    by: dict[str, list[dict[str, float]]] = {}
    for seed in range(args.seeds):
        for row in minor_loops(seed):
            by.setdefault(str(row["model"]), []).append(row)
    for name, rows in by.items():
        w = [r["width_pct"] for r in rows]
        f = [r["fit_s"] for r in rows]
        d = [r["drift_per_cycle"] for r in rows]
        print(f"  {name:18s} width {min(w):.2f}-{max(w):.2f} %  fit {min(f):.2f}-{max(f):.2f} s  "
              f"steady-loop drift per cycle {max(d):.1e}")  # fmt: skip
    print("2. one compensator step")
    for row in cost():
        naive = row["naive_us"]
        extra = ""
        if naive == naive:
            ratio = naive * 1e3 / row["process_ns"]
            extra = (f"  naive brentq {naive:.0f} us ({ratio:.0f}x the kernel; agrees to "
                     f"{row['naive_agrees_V']:.1e} V)")  # fmt: skip
        print(f"  {row['model']:18s} process {row['process_ns']:.0f} ns/sample, step() from "
              f"Python {row['step_us']:.2f} us{extra}")  # fmt: skip


if __name__ == "__main__":
    main()
