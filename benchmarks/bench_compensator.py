"""Compensator speed: step() from Python, process() throughput, and the exported C code.

Run: ``python benchmarks/bench_compensator.py [--operators 20]``. Prints times
and ratios against naive references measured in the same run (a pure-Python
loop over the operators for one step; a NumPy loop over time for a block).
Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.control.export import write_c


def python_step_reference(h: ph.PIHysteresis, inv: ph.PIHysteresis):  # type: ignore[no-untyped-def]
    """The kernel's algorithm written plainly in Python (lists, one operator at a time).

    Like the kernel it keeps the inverse states and advances them by their
    own play recursion, rebuilding them from the forward states only when a
    limit acted.
    """
    r, w, s = h.thresholds.tolist(), h.weights.tolist(), h.loading_slopes.tolist()
    ri, wi = inv.thresholds.tolist(), inv.weights.tolist()
    c, ci = h.offset, inv.offset
    z = h.initial_state.tolist()
    n = len(r)
    zeta = [0.0] * n

    def rebuild() -> None:
        tail = 0.0
        for i in range(n - 1, -1, -1):
            zeta[i] = c + s[i] * z[i] + tail
            tail += w[i] * z[i]

    rebuild()

    def step(q: float) -> float:
        x = ci
        for i in range(n):
            zeta[i] = min(max(zeta[i], q - ri[i]), q + ri[i])
            x += wi[i] * zeta[i]
        v = min(max(x, 0.0), 140.0)
        for i in range(n):
            z[i] = min(max(z[i], v - r[i]), v + r[i])
        if v != x:
            rebuild()
        return v

    return step


def numpy_block_reference(h: ph.PIHysteresis, inv: ph.PIHysteresis, q: np.ndarray) -> np.ndarray:
    """A NumPy loop over time: vector operations over operators at each sample."""
    z = h.initial_state.copy()
    s, w = h.loading_slopes, h.weights
    out = np.empty_like(q)
    for k, qk in enumerate(q):
        tail = np.concatenate([np.cumsum((w * z)[::-1])[::-1][1:], [0.0]])
        zeta = h.offset + s * z + tail
        v = inv.offset + inv.weights @ np.clip(zeta, qk - inv.thresholds, qk + inv.thresholds)
        v = min(max(v, 0.0), 140.0)
        z = np.clip(z, v - h.thresholds, v + h.thresholds)
        out[k] = v
    return out


C_BENCH = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>
#include "ph_comp.h"
int main(void)
{
    ph_comp_t s;
    long k, n = 20000000;
    double acc = 0, t0, t1;
    struct timespec a, b;
    ph_comp_init(&s);
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (k = 0; k < n; ++k) {
        double u = (k % 1000) / 1000.0;
        double d = 1e-6 * (1.0 + 0.9 * ((k % 2000) < 1000 ? u : 1.0 - u));
        acc += ph_comp_step(&s, d);
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    t0 = a.tv_sec + 1e-9 * a.tv_nsec;
    t1 = b.tv_sec + 1e-9 * b.tv_nsec;
    printf("%.3f %g\n", (t1 - t0) / n * 1e9, acc);
    return 0;
}
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--operators", type=int, default=20)
    args = parser.parse_args()
    m = args.operators
    rec = ph.simulate(duration=20.0, seed=0)
    model = ph.ActivePI(m).fit(rec.voltage, rec.charge, t=rec.t)
    h = model.operator_
    inv = h.inverse()
    t = np.arange(200_000) / 1000.0
    q = h.predict(70 * (1 - np.cos(2 * np.pi * 0.5 * t)) * 0.95)
    print(f"piezohyst {ph.__version__} compensator benchmark: {m} operators")

    comp = ph.Compensator(model, v_min=0.0, v_max=140.0)
    comp.step(float(q[0]))
    values = q[:200_000].tolist()
    start = time.perf_counter()
    for d in values:
        comp.step(d)
    fast = (time.perf_counter() - start) / len(values)
    ref = python_step_reference(h, inv)
    start = time.perf_counter()
    for d in values[:50_000]:
        ref(d)
    slow = (time.perf_counter() - start) / 50_000
    print("step() called from Python, one sample per call")
    print(f"  piezohyst (numba)          {fast * 1e6:8.2f} us/sample")
    print(f"  pure-Python operator loop  {slow * 1e6:8.2f} us/sample")
    print(f"  speed-up                   {slow / fast:8.1f} x")

    big = np.resize(q, 10_000_000)
    comp.reset()
    comp.process(big[:1000])
    comp.reset()
    start = time.perf_counter()
    comp.process(big)
    block = time.perf_counter() - start
    start = time.perf_counter()
    numpy_block_reference(h, inv, big[:20_000])
    naive = (time.perf_counter() - start) / 20_000
    print("process() on 10^7 samples")
    print(
        f"  piezohyst (numba)          {big.size / block / 1e6:8.1f} M samples/s "
        f"({block / big.size * 1e9:.1f} ns/sample)"
    )
    print(
        f"  NumPy loop over time       {1 / naive / 1e6:8.3f} M samples/s "
        "(measured on 2*10^4 samples)"
    )
    print(f"  speed-up                   {naive / (block / big.size):8.0f} x")

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        print("exported C: no C compiler found, skipped")
        return
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        comp.reset()
        write_c(comp, d / "ph_comp.c")
        (d / "bench.c").write_text(C_BENCH)
        exe = d / "bench"
        subprocess.run(
            [cc, "-std=c99", "-O2", str(d / "ph_comp.c"), str(d / "bench.c"), "-o", str(exe)],
            check=True,
        )
        ns = float(
            subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()[0]
        )
    print("exported C (double, gcc -O2, this machine)")
    print(f"  ph_comp_step               {ns:8.1f} ns/sample")


if __name__ == "__main__":
    main()
