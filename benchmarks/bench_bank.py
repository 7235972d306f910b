"""Model banks: compensating thousands of channels per step, and fitting a bank.

Run: ``python benchmarks/bench_bank.py [--channels 4096] [--operators 20]
[--fit-channels 1024] [--fit-samples 100000]``. Prints times and ratios
against references measured in the same run: a NumPy step vectorised over the
channels (the natural hand-written bank), and the single-channel kernel's
throughput in operator-samples per second. Not a test: nothing here asserts a
time.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np
from numba import njit

import piezohyst as ph
from piezohyst._kernels import play as K


def units(channels: int, operators: int, seed: int = 0) -> ph.ModelBank:
    """A bank of invertible units with spread weights (no fit needed for the step benchmark)."""
    rng = np.random.default_rng(seed)
    r = np.linspace(0.0, 120.0, operators)
    models = []
    for _ in range(channels):
        w = np.r_[1e-8, rng.uniform(0.5e-9, 2e-9, operators - 1)] * rng.uniform(0.8, 1.2)
        m = ph.ClassicalPI.from_operator(ph.PIHysteresis(r, w))
        m.input_range_ = (0.0, 140.0)
        models.append(m)
    return ph.ModelBank.from_models(models)


def numpy_bank_step(comp: ph.BankCompensator):  # type: ignore[no-untyped-def]
    """The same inverse written with NumPy over (C, n) arrays, one sample at a time."""
    tab = comp.tables
    r, ri, wi = tab[:, K.TAB_R], tab[:, K.TAB_RI], tab[:, K.TAB_WI]
    ci = comp.config[:, K.CFG_INV_OFFSET]
    n = r.shape[1]
    zeta = comp._state[:, n : 2 * n].copy()
    z = comp._state[:, :n].copy()
    lo, hi = comp.v_min, comp.v_max

    def step(q: np.ndarray) -> np.ndarray:
        np.clip(zeta, q[:, None] - ri, q[:, None] + ri, out=zeta)
        v = np.clip(ci + np.einsum("cn,cn->c", wi, zeta), lo, hi)
        np.clip(z, v[:, None] - r, v[:, None] + r, out=z)
        return v

    return step


@njit
def step_loop(desired, tables, config, state, out):  # type: ignore[no-untyped-def]
    """The one-sample kernel over a record, from compiled code."""
    for k in range(desired.shape[0]):
        out[k] = K.compensator_step(desired[k], tables, config, state)


def best(fn, repeats: int) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_step(channels: int, operators: int) -> None:
    bank = units(channels, operators)
    comp = ph.BankCompensator(bank, v_min=0.0, v_max=140.0)
    steps = 2000
    t = np.arange(steps) / 1e4
    amp = np.linspace(0.3, 1.0, channels)
    qs = 7e-7 + 6e-7 * np.sin(2 * np.pi * 50 * t)[:, None] * amp[None, :]
    out = np.empty(channels)
    comp.step(qs[0], out=out)

    def run_step() -> None:
        for row in qs:
            comp.step(row, out=out)

    per_step = best(run_step, 3) / steps
    ref = numpy_bank_step(comp)
    ref_steps = 200

    def run_ref() -> None:
        for row in qs[:ref_steps]:
            ref(row)

    per_ref = best(run_ref, 3) / ref_steps
    # process: a block of samples for all channels
    comp.reset()
    comp.process(qs[:10])
    per_proc = best(lambda: comp.process(qs), 3) / steps
    # the single-channel kernel on one long record: its op-sample throughput
    single = ph.Compensator(bank[0], v_min=0.0, v_max=140.0)
    long = np.tile(qs[:, 0], 100)
    single.process(long[:10])
    per_single = best(lambda: single.process(long), 3) / long.size
    op_single = operators / per_single
    # the single-channel one-sample kernel, called in a compiled loop (no Python per sample)
    step_state = single.kernel_state.copy()
    step_out = np.empty(long.size)
    tabs, conf = single.inverse.tables, single.inverse.config
    step_loop(long[:10], tabs, conf, step_state, step_out[:10])
    per_step_single = best(lambda: step_loop(long, tabs, conf, step_state, step_out), 3) / long.size
    op_step = channels * operators / per_step
    op_proc = channels * operators / per_proc
    print(f"bank step, {channels} channels x {operators} operators:")
    print(
        f"  step():   {per_step * 1e6:8.1f} us per step of all channels "
        f"({1 / per_step / 1e3:.1f} kHz sustained)"
    )
    print(
        f"  NumPy vectorised over channels: {per_ref * 1e6:8.1f} us  "
        f"-> step is {per_ref / per_step:.1f}x faster"
    )
    print(f"  process(): {per_proc * 1e6:8.1f} us per sample of all channels")
    print(
        f"  single-channel process: {per_single * 1e9:.2f} ns/sample = "
        f"{op_single / 1e6:.0f} M op-samples/s"
    )
    print(
        f"  single-channel step kernel in a compiled loop: {per_step_single * 1e9:.2f} ns/sample"
        f" -> bank step {op_step / (operators / per_step_single):.2f}x its op-sample throughput"
    )
    print(
        f"  bank step {op_step / 1e6:.0f} M op-samples/s = {op_step / op_single:.2f}x single; "
        f"bank process {op_proc / 1e6:.0f} M = {op_proc / op_single:.2f}x single"
    )
    # the self-sensing controller over the same bank: measured charge fed back per channel
    ctl = ph.BankController(bank, v_min=0.0, v_max=140.0, sample_rate=1e4)
    measured = qs * 1.02
    ctl.step(qs[0], measured[0], out=out)

    def run_ctl() -> None:
        for row, meas in zip(qs, measured, strict=True):
            ctl.step(row, meas, out=out)

    per_ctl = best(run_ctl, 3) / steps
    print(
        f"  self-sensing bank step: {per_ctl * 1e6:8.1f} us per step of all channels "
        f"({1 / per_ctl / 1e3:.1f} kHz)"
    )
    # targets in metres, one calibrated map per channel (calibrate_gain): the maps' inverse
    # runs before the fused kernel; the reference is each channel's own compensator with its
    # map, stepped one after another (how a bank with maps ran before)
    rng = np.random.default_rng(3)
    maps = []
    for c in range(channels):
        g = 125.0 * rng.uniform(0.9, 1.1)
        lo, hi = float(qs[:, c].min()), float(qs[:, c].max())
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        maps.append(ph.OutputMap((g * centre, g * half), centre, half, ((0.0, 0.0),) * 2,
                                 (lo, hi)))  # fmt: skip
    mapped = ph.BankCompensator(bank, v_min=0.0, v_max=140.0, output_maps=maps)
    metres = np.column_stack([m.predict(qs[:, c]) for c, m in enumerate(maps)])
    mapped.step(metres[0], out=out)

    def run_mapped() -> None:
        for row in metres:
            mapped.step(row, out=out)

    alone = [mapped.channel(c) for c in range(channels)]

    def run_alone() -> None:
        for row in metres[:20]:
            for c, ch in enumerate(alone):
                out[c] = ch.step(float(row[c]))

    per_map = best(run_mapped, 3) / steps
    per_alone = best(run_alone, 1) / 20
    print(
        f"  with a linear map per channel: {per_map * 1e6:8.1f} us per step of all channels "
        f"({1 / per_map / 1e3:.1f} kHz); each channel's compensator in turn "
        f"{per_alone * 1e3:.2f} ms -> {per_alone / per_map:.0f}x"
    )


def bench_fit(channels: int, samples: int, operators: int) -> None:
    rng = np.random.default_rng(1)
    t = np.arange(samples) / 1e3
    drive = 70.0 - 70.0 * np.cos(2 * np.pi * 0.5 * t) * np.exp(-t / (samples / 1e3 / 3))
    r = np.linspace(0.0, 120.0, operators)
    V = np.empty((samples, channels))
    Q = np.empty((samples, channels))
    for c in range(channels):
        w = np.r_[1e-8, rng.uniform(0.5e-9, 2e-9, operators - 1)]
        V[:, c] = drive + rng.normal(0.0, 0.02, samples)
        Q[:, c] = ph.PIHysteresis(r, w).predict(V[:, c]) + 1e-10 * np.cumsum(V[:, c]) / 1e3
    template = ph.ActivePI(n_operators=operators)
    ph.ModelBank(template).fit(V[:2000, :2], Q[:2000, :2], t=t[:2000])  # compile
    t0 = time.perf_counter()
    bank = ph.ModelBank(template).fit(V, Q, t=t)
    took = time.perf_counter() - t0
    tracemalloc.start()  # memory in a second run: tracing slows allocation down
    ph.ModelBank(template).fit(V[:, :8], Q[:, :8], t=t)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # the reference: one channel fitted alone, times the channel count
    t0 = time.perf_counter()
    for c in range(min(channels, 32)):
        ph.ActivePI(n_operators=operators).fit(V[:, c], Q[:, c], t=t)
    one = (time.perf_counter() - t0) / min(channels, 32)
    nrmse = bank.summary()["nrmse"]
    print(f"bank fit, {channels} channels x {samples} samples x {operators} operators:")
    print(
        f"  {took:.2f} s ({took / channels * 1e3:.1f} ms per channel; single fits "
        f"{one * 1e3:.1f} ms each -> {one * channels / took:.2f}x the serial loop of "
        f"single models)"
    )
    print(
        f"  peak traced memory beyond the input (8 channels): {peak / 2**20:.1f} MiB "
        f"(input {V.nbytes * 2 / 2**20:.0f} MiB); fit NRMSE max {nrmse.max():.2e}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--channels", type=int, default=4096)
    ap.add_argument("--operators", type=int, default=20)
    ap.add_argument("--fit-channels", type=int, default=1024)
    ap.add_argument("--fit-samples", type=int, default=100_000)
    args = ap.parse_args()
    bench_step(args.channels, args.operators)
    bench_fit(args.fit_channels, args.fit_samples, args.operators)


if __name__ == "__main__":
    main()
