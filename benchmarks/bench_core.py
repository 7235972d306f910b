"""Core speed and memory: forward PI and ActivePI identification on 10^6 samples.

Run: ``python benchmarks/bench_core.py [--samples N] [--operators M]``.
Prints times and ratios against naive NumPy references measured in the same
run. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

import piezohyst as ph
from piezohyst._kernels import play as K
from piezohyst._kernels import signal as S


def excitation(n: int, fs: float = 1000.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / fs
    v = 70.0 * (1.0 - np.cos(2 * np.pi * 0.5 * t)) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.013 * t))
    return t, v


def naive_forward(x: np.ndarray, r: np.ndarray, w: np.ndarray, z0: np.ndarray) -> np.ndarray:
    """The NumPy loop over time that users write: vector ops over operators per sample."""
    z = z0.copy()
    y = np.empty_like(x)
    for k in range(x.size):
        z = np.maximum(x[k] - r, np.minimum(x[k] + r, z))
        y[k] = w @ z
    return y


def naive_fit(x: np.ndarray, y: np.ndarray, t: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Dense regressor matrix (N x p) and an unconstrained lstsq: the obvious approach."""
    cols = np.empty((x.size, r.size + 2))
    z = np.full(r.size, x[0])
    K.play_states(x, r, z, cols)
    cols[:, r.size] = 1.0
    cols[:, r.size + 1] = np.concatenate([[0.0], np.cumsum(x[1:] * np.diff(t))])
    return np.linalg.lstsq(cols, y, rcond=None)[0]


def best_of(fn, repeat: int = 3) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--operators", type=int, default=50)
    parser.add_argument("--naive-samples", type=int, default=20_000)
    args = parser.parse_args()
    n, m = args.samples, args.operators

    t, v = excitation(n)
    r = ph.default_thresholds(v, m)
    slopes = np.linspace(1.0, 0.4, m)
    h = ph.PIHysteresis(r, np.diff(slopes, prepend=0.0), 0.0, np.full(m, v[0]))
    q = 1e-8 * h.predict(v) + 2e-9 * np.concatenate([[0.0], np.cumsum(v[1:] * np.diff(t))])
    K.warm_up()
    S.warm_up()
    h.predict(v[:100])

    print(f"piezohyst {ph.__version__} core benchmark: {n:,} samples x {m} operators")
    fast = best_of(lambda: h.predict(v))
    k = args.naive_samples
    slow = best_of(lambda: naive_forward(v[:k], h.thresholds, h.weights, h.initial_state), 1)
    fast_ns = fast / (n * m) * 1e9
    slow_ns = slow / (k * m) * 1e9
    print("forward ClassicalPI")
    print(f"  piezohyst (numba)        {fast * 1e3:9.1f} ms   {fast_ns:6.2f} ns/operator-sample")
    print(
        f"  naive NumPy time loop    {slow / k * n * 1e3:9.1f} ms   "
        f"{slow_ns:6.2f} ns/operator-sample"
        f"   (measured on {k:,} samples, scaled)"
    )
    print(f"  speed-up                 {slow_ns / fast_ns:9.0f} x")

    model = ph.ActivePI(n_operators=m)
    fit_time = best_of(lambda: model.fit(v, q, t=t), 3)
    tracemalloc.start()
    model.fit(v, q, t=t)
    _, fit_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print("fit ActivePI (constrained, normal equations accumulated in blocks)")
    mib = 2**20
    print(f"  piezohyst   {fit_time:9.3f} s    peak extra memory {fit_peak / mib:7.1f} MiB")
    print(f"  (inputs themselves: 3 arrays x {n * 8 / 2**20:.1f} MiB)")
    print(f"  fit NRMSE {model.nrmse_:.2e}, growth rate {model.growth_rate_:.6e} S (true 2e-9)")

    dense_time = best_of(lambda: naive_fit(v, q, t, r), 1)
    tracemalloc.start()
    naive_fit(v, q, t, r)
    _, dense_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print("naive dense least squares (N x p matrix, unconstrained np.linalg.lstsq)")
    print(f"  NumPy       {dense_time:9.3f} s    peak extra memory {dense_peak / mib:7.1f} MiB")
    print(f"  speed-up {dense_time / fit_time:.1f} x, memory {dense_peak / fit_peak:.0f} x less")


if __name__ == "__main__":
    main()
