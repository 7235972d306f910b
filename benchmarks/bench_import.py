"""What ``import piezohyst`` costs, against bare Python, and which heavy libraries it loads.

Run: ``python benchmarks/bench_import.py [--runs 7]``. Each run is a fresh interpreter
(``python -c ...``); CPU time is the child's user + system time from ``os.wait4``, so a
busy machine inflates the wall time but not this. Bytecode is cached as on a user's machine
(``PYTHONDONTWRITEBYTECODE`` is dropped for the children; a first run writes it). Prints the
median and the range of each, the difference (what the package itself costs), and which of
the heavy libraries the import loaded (each should load only when a feature needs it).

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

HEAVY = [
    "numba", "scipy", "matplotlib", "dask", "distributed", "pyarrow", "pint", "h5py",
    "nptdms", "click", "rich",
]  # fmt: skip


ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def cpu_seconds(code: str) -> float:
    """User + system CPU seconds of a fresh interpreter running ``code``."""
    proc = subprocess.Popen([sys.executable, "-c", code], env=ENV)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{code!r} failed with exit code {proc.returncode}")
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    first_model = "import piezohyst; piezohyst.ActivePI"
    cpu_seconds(first_model)  # warm the file cache and write the bytecode once
    runs = {
        "bare Python": "pass",
        "import numpy": "import numpy",
        "import piezohyst": "import piezohyst",
        # the public names load at first use (PEP 562): what a script that fits pays
        "+ first model": first_model,
        "+ the readers": "import piezohyst; piezohyst.io.read_recording",
    }
    times = {name: [cpu_seconds(code) for _ in range(args.runs)] for name, code in runs.items()}
    for name, xs in times.items():
        print(
            f"{name:>18}: {statistics.median(xs):.3f} CPU-s (min {min(xs):.3f}, max {max(xs):.3f})"
        )
    med = {name: statistics.median(xs) for name, xs in times.items()}
    print(f"{'the package':>18}: {med['import piezohyst'] - med['bare Python']:.3f} CPU-s")
    print(
        f"{'vs numpy alone':>18}: import {med['import piezohyst'] / med['import numpy']:.2f}x, "
        f"with the first model {med['+ first model'] / med['import numpy']:.2f}x"
    )
    probe = f"import sys, piezohyst; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    loaded = subprocess.run(
        [sys.executable, "-c", probe], check=True, capture_output=True, text=True
    ).stdout.split()
    print(f"{'heavy, loaded':>18}: {', '.join(loaded) or 'none'}")
    print(f"{'heavy, deferred':>18}: {', '.join(m for m in HEAVY if m not in loaded)}")


if __name__ == "__main__":
    main()
