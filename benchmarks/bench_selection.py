"""Model choice on 60 000 samples: ``select_model`` on the bench and the zoo's plants.

Run: ``python benchmarks/bench_selection.py [--seconds 60]``. Each record is 60 s at
1 kHz (``decaying`` and ``multi`` signals, every plant). The naive reference, in the same
run: one ``np.linalg.lstsq`` of a classical PI's play-operator columns built in NumPy on
the same record (the least a fit can cost), so the ratio says how many such solves a
choice costs. Warm: the kernels are compiled on a short record first. Not a test:
nothing asserts a time.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import piezohyst as ph
from piezohyst.simulation import PLANTS


def naive_pi_solve(v: np.ndarray, q: np.ndarray, n: int = 10) -> float:
    """Seconds for a classical PI fit written plainly: play operators in a Python loop over
    the thresholds (NumPy per sample is far slower), then one least squares."""
    began = time.perf_counter()
    r = np.linspace(0.0, 0.9 * float(np.ptp(v)) / 2, n)
    cols = np.empty((v.size, n + 1))
    cols[:, n] = 1.0
    for i, ri in enumerate(r):
        z = float(v[0])
        out = cols[:, i]
        for k, x in enumerate(v.tolist()):
            z = min(max(z, x - ri), x + ri)
            out[k] = z
    np.linalg.lstsq(cols, q, rcond=None)
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    warm = ph.simulate(signal="decaying", duration=5.0, seed=0)
    ph.select_model(warm.voltage, warm.charge, t=warm.t)
    print(f"piezohyst {ph.__version__}: select_model on {args.seconds:g} s at 1 kHz")
    print("| plant | signal | samples | select_model (s) | naive PI solve (s) | ratio | chosen |")
    print("|---|---|---|---|---|---|---|")
    for plant in PLANTS:
        for signal in ("decaying", "multi"):
            rec = ph.simulate(signal=signal, duration=args.seconds, seed=0, plant=plant)
            began = time.perf_counter()
            sel = ph.select_model(rec.voltage, rec.charge, t=rec.t)
            took = time.perf_counter() - began
            ref = naive_pi_solve(rec.voltage, rec.charge)
            print(f"| {plant} | {signal} | {rec.t.size:,} | {took:.1f} | {ref:.2f} | "
                  f"{took / ref:.1f} | {sel.name} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
