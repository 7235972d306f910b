"""Large files: fit from a 5-million-row CSV, predict a 10-million-row CSV into CSV.

Run: ``python benchmarks/bench_io.py [--rows 5000000] [--predict-rows 10000000]``.
Each command runs as a user runs it (``piezohyst ...`` in a fresh process);
peak memory is the child's maximum resident set. The naive reference, in the
same run: ``np.loadtxt`` reading the same CSV. Not a test: nothing asserts a time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import piezohyst as ph

BIN = Path(sys.executable).parent


def record(n: int) -> dict[str, np.ndarray]:
    """A long 1 kHz record: cycles of varying amplitude through a PI model with leakage."""
    t = np.arange(n) / 1000.0
    v = 70.0 * (1.0 - np.cos(2 * np.pi * 0.5 * t)) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.013 * t))
    h = ph.PIHysteresis(ph.default_thresholds(v, 10), np.diff(np.linspace(1, 0.4, 10), prepend=0))
    q = 1e-8 * h.predict(v) + 2e-9 * np.concatenate([[0.0], np.cumsum(v[1:] * np.diff(t))])
    return {"time": t, "voltage": v, "charge": q}


def measured(args: list[str]) -> tuple[float, float]:
    """Run in a fresh helper so each peak RSS is its own (ru_maxrss keeps the maximum)."""
    code = (
        "import resource,subprocess,sys,time;t=time.perf_counter();"
        "subprocess.run(sys.argv[1:],check=True,capture_output=True);"
        "print(time.perf_counter()-t, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
    )
    out = subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True)
    seconds, kib = out.stdout.split()
    return float(seconds), float(kib) / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rows", type=int, default=5_000_000)
    parser.add_argument("--predict-rows", type=int, default=10_000_000)
    args = parser.parse_args()
    piezohyst = str(BIN / "piezohyst")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        cols = record(args.rows)
        ph.write_table(d / "big.csv", cols, units={"time": "s", "voltage": "V", "charge": "C"})
        ph.write_table(d / "big.npz", cols)
        size = os.path.getsize(d / "big.csv") / 2**20
        print(f"piezohyst {ph.__version__}: fit ActivePI (10 operators) from {args.rows:,} rows")
        columns_mib = 3 * args.rows * 8 / 2**20
        print(f"  CSV {size:.0f} MiB; the three columns themselves: {columns_mib:.0f} MiB")
        fit = [piezohyst, "fit", "--operators", "10", "--force", "-o", str(d / "m.json")]
        t_npz, m_npz = measured([*fit[:2], str(d / "big.npz"), *fit[2:]])
        t_csv, m_csv = measured([*fit[:2], str(d / "big.csv"), *fit[2:]])
        loadtxt = "import numpy as np,sys;np.loadtxt(sys.argv[1],delimiter=',',skiprows=2)"
        t_ref, m_ref = measured([sys.executable, "-c", loadtxt, str(d / "big.csv")])
        ours = (
            "import piezohyst as ph,sys;t=ph.read_table(sys.argv[1]);[t.get(c) for c in t.columns]"
        )
        t_read, m_read = measured([sys.executable, "-c", ours, str(d / "big.csv")])
        short = args.rows // 5  # the same fit on a fifth of the record: memory must not follow
        ph.write_table(d / "short.csv", {k: v[:short] for k, v in cols.items()},
                       units={"time": "s", "voltage": "V", "charge": "C"})  # fmt: skip
        t_short, m_short = measured([*fit[:2], str(d / "short.csv"), *fit[2:]])
        print(f"  fit from .npz             {t_npz:7.2f} s   peak RSS {m_npz:7.0f} MiB")
        print(f"  fit from CSV              {t_csv:7.2f} s   peak RSS {m_csv:7.0f} MiB")
        print(f"  fit from CSV, {short:,} rows {t_short:5.2f} s   peak RSS {m_short:7.0f} MiB")
        print(f"  CSV / npz                 {t_csv / t_npz:7.2f} x")
        print(f"  read only: piezohyst       {t_read:7.2f} s   peak RSS {m_read:7.0f} MiB")
        print(f"  read only: np.loadtxt      {t_ref:7.2f} s   peak RSS {m_ref:7.0f} MiB (naive)")
        print(f"  piezohyst / loadtxt        {t_read / t_ref:7.2f} x time, "
              f"{m_read / m_ref:.2f} x memory")  # fmt: skip
        del cols
        big = record(args.predict_rows)
        ph.write_table(d / "huge.csv", big, units={"time": "s", "voltage": "V", "charge": "C"})
        del big
        predict = [piezohyst, "predict", str(d / "m.json"), str(d / "huge.csv"), "--force",
                   "-o", str(d / "pred.csv")]  # fmt: skip
        t_pred, m_pred = measured(predict)
        comp = [piezohyst, "compensate", str(d / "m.json"), str(d / "target.csv"), "--force",
                "-o", str(d / "cmd.csv")]  # fmt: skip
        model = ph.load_model(d / "m.json")
        t = np.arange(args.predict_rows) / 1000.0
        lo, hi = model.input_range_
        v = lo + (hi - lo) * (0.3 + 0.3 * (1 - np.cos(2 * np.pi * 0.5 * t)))
        ph.write_table(d / "target.csv", {"time": t, "desired": model.hysteresis_.predict(v)},
                       units={"time": "s", "desired": model.output_unit})  # fmt: skip
        del t, v
        t_comp, m_comp = measured(comp)
        print(f"predict {args.predict_rows:,} rows CSV -> CSV")
        print(f"  piezohyst predict          {t_pred:7.2f} s   peak RSS {m_pred:7.0f} MiB")
        print(f"compensate {args.predict_rows:,} rows CSV -> CSV")
        print(f"  piezohyst compensate       {t_comp:7.2f} s   peak RSS {m_comp:7.0f} MiB")


if __name__ == "__main__":
    main()
