"""Per-call cost of the model API against a bare kernel call, and the classical/active ratio.

Run: ``python benchmarks/bench_calls.py``. For blocks of 10, 100 and 10^5
samples, times ``ClassicalPI.predict``, ``ActivePI.predict`` and the bare
compiled play-operator kernel on the same block (the reference: what a
caller who skips every check and allocation would pay), best of several
repeats, and prints the ratios. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import time

import numpy as np

import piezohyst as ph
from piezohyst._kernels import play as K


def best(fn, calls: int, repeats: int = 7) -> float:  # type: ignore[no-untyped-def]
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls)
    return min(times)


def main() -> None:
    n_ops = 20
    t = np.arange(200_000) / 1e3
    v = 70.0 - 70.0 * np.cos(2 * np.pi * 0.5 * t) * np.exp(-t / 60.0)
    q = ph.PIHysteresis(np.linspace(0, 120, n_ops), np.r_[1e-8, np.full(n_ops - 1, 1e-9)])
    y = q.predict(v) + 1e-10 * np.cumsum(v) / 1e3
    classical = ph.ClassicalPI(n_ops).fit(v, y)
    active = ph.ActivePI(n_ops).fit(v, y, t=t)
    r, w = active.thresholds_, active.weights_
    print(f"per call, {n_ops} operators (best of 7):")
    print(f"{'samples':>8} {'bare kernel':>12} {'ClassicalPI':>12} {'ActivePI':>12} "
          f"{'C/bare':>7} {'A/bare':>7} {'A/C':>6}")  # fmt: skip
    for m in (10, 100, 100_000):
        x, tt = v[:m].copy(), t[:m].copy()
        z = active.initial_state_.copy()
        out = np.empty(m)
        calls = max(1, 20_000 // m)
        bare = best(lambda: K.pi_forward(x, r, w, z, out), calls)  # noqa: B023
        c = best(lambda: classical.predict(x), calls)  # noqa: B023
        a = best(lambda: active.predict(x, t=tt), calls)  # noqa: B023
        print(f"{m:>8} {bare * 1e6:>10.2f}us {c * 1e6:>10.2f}us {a * 1e6:>10.2f}us "
              f"{c / bare:>7.2f} {a / bare:>7.2f} {a / c:>6.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
