"""Fleet calibration throughput: ``fit_many`` on the local Dask pool against a serial loop.

Run: ``python benchmarks/bench_fleet.py [--units 200] [--samples 100000]
[--format npz]``. Writes the simulated recordings to a temporary folder, then
fits them three ways in this run: a plain serial loop of ``fit_file`` (the
reference), ``fit_many`` with one worker, and ``fit_many`` on the local
process pool (one process per core). Prints wall times and throughput ratios.
Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.workflows import fit_file
from piezohyst.workflows.fleet import fit_many


def write_units(folder: Path, units: int, samples: int, suffix: str) -> list[Path]:
    rng = np.random.default_rng(0)
    t = np.arange(samples) / 1e3
    v = 70.0 - 70.0 * np.cos(2 * np.pi * 0.5 * t) * np.exp(-t / (samples / 3e3))
    paths = []
    for i in range(units):
        w = np.array([1e-8, 3e-9, 2e-9, 1e-9]) * (1 + 0.05 * rng.standard_normal())
        q = ph.PIHysteresis([0.0, 10.0, 25.0, 45.0], w).predict(v)
        q += 1e-10 * np.cumsum(v) / 1e3 + rng.normal(0.0, 1e-10, samples)
        path = folder / f"unit{i:04d}{suffix}"
        ph.io.write_table(path, {"time": t, "voltage": v, "charge": q})
        paths.append(path)
    return paths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--units", type=int, default=200)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--operators", type=int, default=10)
    ap.add_argument("--format", choices=["npz", "csv", "parquet"], default="npz")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        paths = write_units(folder, args.units, args.samples, "." + args.format)
        fit_file(paths[0], operators=args.operators)  # compile in this process
        t0 = time.perf_counter()
        for p in paths:
            fit_file(p, folder / "serial" / f"{p.stem}.json", operators=args.operators)
        serial = time.perf_counter() - t0
        timings = {}
        for workers in (1, os.cpu_count() or 1):
            t0 = time.perf_counter()
            result = fit_many(paths, folder / f"pool{workers}", operators=args.operators,
                              workers=workers)  # fmt: skip
            timings[workers] = time.perf_counter() - t0
            assert not result.failed
        print(
            f"fleet: {args.units} units x {args.samples} samples ({args.format}), "
            f"{args.operators} operators, {os.cpu_count()} cores"
        )
        print(f"  serial loop of fit_file: {serial:6.2f} s ({args.units / serial:.1f} units/s)")
        for workers, took in timings.items():
            print(
                f"  fit_many, {workers} worker(s): {took:6.2f} s "
                f"({args.units / took:.1f} units/s) -> {serial / took:.2f}x the serial loop"
            )


if __name__ == "__main__":
    main()
