"""The same data, fitted under different BLAS kernels, threads and CPU targets.

Run once per arithmetic setting, each writing its fits, then compare::

    python benchmarks/reproducibility.py fit  default.npz
    env -u OPENBLAS_CORETYPE -u OPENBLAS_L2_SIZE OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/reproducibility.py fit own-kernel.npz
    OPENBLAS_CORETYPE=Prescott NUMBA_CPU_NAME=generic NUMBA_CACHE_DIR=$(mktemp -d) \\
        python benchmarks/reproducibility.py fit prescott.npz
    NUMBA_DISABLE_JIT=1 python benchmarks/reproducibility.py fit interpreted.npz
    python benchmarks/reproducibility.py compare default.npz own-kernel.npz prescott.npz \\
        interpreted.npz

Every model kind (with its default settings, and the relaxing Preisach model whose
unidentified density cells made the old solve two-valued) is fitted on the
simulated bench's decaying loops; ``compare`` prints, per model, the largest
difference of the fitted outputs over the record and of the compensator's
commands on a trajectory inside the region, relative to the output span (V span
for commands), against the first file. Not a test: these are measurements.
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Callable

import numpy as np

import piezohyst as ph
from piezohyst.simulation import make_signal

MAKERS: dict[str, Callable[[], ph.HysteresisModel]] = {
    "classical PI": lambda: ph.ClassicalPI(20),
    "active PI": lambda: ph.ActivePI(20),
    "generalized PI": lambda: ph.GeneralizedPI(),
    "Preisach": lambda: ph.PreisachModel(),
    "Preisach + relaxation, auto growth": lambda: ph.PreisachModel(
        relaxation=0.1, creep=(0.02, 0.2), growth_terms="auto"
    ),
    "Duhem": lambda: ph.DuhemModel(),
    "Bouc-Wen": lambda: ph.BoucWenModel(),
}


def fit(out: str) -> None:
    rec = ph.simulate(signal="decaying", duration=40.0, seed=1)
    v, q, t = rec.voltage, rec.charge, rec.t
    arrays: dict[str, np.ndarray] = {}
    for name, make in MAKERS.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = make().fit(v, q, t=t)
            lo, hi = model.input_range_
            _, shape = make_signal("decaying", amplitude=1.0, duration=6.0)
            volts = lo + (hi - lo) * (0.2 + 0.6 * shape)
            tt = np.arange(volts.size) / 1000.0
            desired = np.asarray(model.hysteresis_.predict(volts, t=tt))
            comp = ph.Compensator(model.hysteresis_, v_min=lo, v_max=hi, sample_rate=1000.0)
            arrays[f"{name}|fit"] = np.asarray(model.predict(v, t=t))
            arrays[f"{name}|commands"] = comp.process(desired)
        print(f"{name}: NRMSE {100 * model.nrmse_:.4g} %")
    arrays["span"] = np.array([float(np.ptp(q)), float(np.ptp(v))])
    np.savez(out, **arrays)  # type: ignore[arg-type]


def compare(files: list[str]) -> None:
    ref = np.load(files[0])
    span_q, span_v = (float(s) for s in ref["span"])
    print(f"| model | {' | '.join(files[1:])} |")
    print("|---|" + "---|" * (len(files) - 1))
    for name in MAKERS:
        cells = []
        for other in files[1:]:
            o = np.load(other)
            dq = np.max(np.abs(o[f"{name}|fit"] - ref[f"{name}|fit"])) / span_q
            dv = np.max(np.abs(o[f"{name}|commands"] - ref[f"{name}|commands"])) / span_v
            cells.append(f"{dq:.1e} / {dv:.1e}")
        print(f"| {name} | {' | '.join(cells)} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("fit").add_argument("out")
    sub.add_parser("compare").add_argument("files", nargs="+")
    args = parser.parse_args()
    if args.what == "fit":
        fit(args.out)
    else:
        compare(args.files)


if __name__ == "__main__":
    main()
