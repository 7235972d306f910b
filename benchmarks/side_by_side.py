"""The hot paths, one line per run, for comparing two commits side by side.

Run it alternately against each checkout (``PYTHONPATH=OTHER/src python
benchmarks/side_by_side.py``, then without) and keep the minimum of each run's repeats:
``Compensator.step`` from Python, ``process`` per sample, the 8-channel bank step, an
ActivePI and a Preisach fit. Not a test: nothing here asserts a time. The naive references
of each path are in the other benchmarks (``bench_compensator.py``, ``bench_bank.py``,
``bench_core.py``); this one only compares a commit with another.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

import piezohyst as ph


def best(f, n: int = 5) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    warnings.simplefilter("ignore")
    rec = ph.simulate(signal="decaying", duration=60.0, seed=0)
    m = ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t)
    fit = best(lambda: ph.ActivePI(20).fit(rec.voltage, rec.charge, t=rec.t), 3)
    x, y, t = rec.voltage[:20000], rec.charge[:20000], rec.t[:20000]
    fitp = best(lambda: ph.PreisachModel().fit(x, y, t=t), 3)
    comp = ph.Compensator(m, v_min=0.0, v_max=139.0, allow_extrapolation=True)
    q = m.hysteresis_.predict(70 + 50 * np.sin(np.arange(20000) / 100))
    ql = q.tolist()
    st = comp.step
    for d in ql[:2000]:
        st(d)
    step = best(lambda: [st(d) for d in ql]) / len(ql)
    big = np.tile(q, 50)
    proc = best(lambda: comp.process(big), 3) / big.size
    bank = ph.ModelBank(ph.ActivePI(20)).fit(
        np.column_stack([rec.voltage[:3000]] * 8),
        np.column_stack([rec.charge[:3000]] * 8),
        t=rec.t[:3000],
    )
    bc = ph.BankCompensator(bank, v_min=0.0, v_max=139.0, allow_extrapolation=True)
    qq = np.full(8, float(q[0]))
    out = np.empty(8)
    for _ in range(200):
        bc.step(qq, out=out)
    bstep = best(lambda: [bc.step(qq, out=out) for _ in range(5000)]) / 5000
    print(f"step {step * 1e9:.0f} ns | process {proc * 1e9:.1f} ns/sample | bank step (8 ch) "
          f"{bstep * 1e6:.2f} us | ActivePI(20) fit 60k {fit:.3f} s | Preisach fit 20k "
          f"{fitp:.3f} s")  # fmt: skip


if __name__ == "__main__":
    main()
