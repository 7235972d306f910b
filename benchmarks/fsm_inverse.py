"""The structure's inverse on the CubeSpec fine-steering mirror's measured records.

``StructureCompensator`` takes the displacements a held-out realization measured (R5-R6 of
each level, the benchmark's training sets; its test sets are not used) as its targets and
sends commands. A measured record says what inputs made those displacements, so the
commands can be checked against them: how much of each input the inverse recovers, over
the whole band and below 500 and 1500 Hz (the mirror's first mode is near 640 Hz; above it
the displacements hold little of the inputs). Beside it, the model run on the commands (the
inverse's own error, against the targets) and what the same identification without the
loop's operators recovers. Each model is fitted on R1-R4 of every level as
``fsm_benchmark.py`` fits it, or loaded (``--model``, ``--linear``: files
``StructureModel.save`` wrote).

Run: ``python benchmarks/fsm_inverse.py DATA_DIR [--model F] [--linear F] [--no-refine]``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from fsm_benchmark import FS, LEVELS, SETTLE, load

import piezohyst as ph

LIMIT = 3.0  # V, each actuator's limits (the records' inputs stay within +-1.2 V; the first
# sample's jump from rest to a measured target is out of reach, and counted)


def band_error(got: np.ndarray, want: np.ndarray, top: float) -> float:
    """RMS error of ``got`` over ``want``'s spread, in %, below ``top`` Hz (no 0 Hz)."""
    err, ref = np.fft.rfft(got - want, axis=0), np.fft.rfft(want - want.mean(axis=0), axis=0)
    f = np.fft.rfftfreq(want.shape[0], 1 / FS)
    sel = (f > 0) & (f <= top)
    share = (np.abs(err[sel]) ** 2).sum(axis=0) / (np.abs(ref[sel]) ** 2).sum(axis=0)
    return float(100 * np.mean(np.sqrt(share)))


def nrmse(got: np.ndarray, want: np.ndarray) -> float:
    return float(100 * np.mean(np.sqrt(np.mean((got - want) ** 2, axis=0)) / want.std(axis=0)))


def fitted(data: dict, operators: int, refine: bool, path: Path | None) -> ph.StructureModel:  # type: ignore[type-arg]
    if path is not None:
        return ph.StructureModel.load(path)
    # as fsm_benchmark.py fits it: each realization's two periods averaged
    us = [data[lv][0][:, :, r, :].mean(axis=2) for lv in LEVELS for r in range(4)]
    ys = [data[lv][1][:, :, r, :].mean(axis=2) for lv in LEVELS for r in range(4)]
    start = time.perf_counter()
    model = ph.StructureModel(operators=operators, refine=refine).fit(
        us, ys, sample_rate=FS, initial_state="periodic"
    )
    print(f"fitted in {time.perf_counter() - start:.0f} s: {model.describe()}", flush=True)
    return model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", type=Path, help="the folder of the training .npy files")
    parser.add_argument("--model", type=Path, help="a saved StructureModel (else fitted)")
    parser.add_argument("--linear", type=Path, help="a saved linear one (operators=0)")
    parser.add_argument("--no-refine", action="store_true", help="least squares only")
    parser.add_argument("--save", type=Path, help="a folder to save the fitted models in")
    args = parser.parse_args()
    data = load(args.data)
    models = {
        "with the loop's operators": fitted(data, 6, not args.no_refine, args.model),
        "linear (operators=0)": fitted(data, 0, not args.no_refine, args.linear),
    }
    if args.save is not None:
        args.save.mkdir(parents=True, exist_ok=True)
        for stem, model in zip(("structure", "linear"), models.values(), strict=True):
            model.save(args.save / f"{stem}.json")
    print(
        "| model | level | inputs recovered, < 500 Hz | < 1500 Hz | whole band "
        "| the model on the commands | the model on the true inputs | 16384 samples "
        "| commands at a limit |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, model in models.items():
        for level in LEVELS:
            u, y = data[level]
            # a model scheduled by the drive's level is inverted at the scan's: the inputs' RMS
            rms = float(np.sqrt(np.mean(np.sum(u[:, :, 4:, :] ** 2, axis=1))))
            start = time.perf_counter()
            comp = ph.StructureCompensator(model, v_min=-LIMIT, v_max=LIMIT, level=rms)
            setup = time.perf_counter() - start
            n = u.shape[0]
            rows = []
            for r in (4, 5):
                targets = np.vstack([y[:, :, r, 0], y[:, :, r, 1]])  # a period to settle in
                inputs = np.vstack([u[:, :, r, 0], u[:, :, r, 1]])
                comp.reset()
                start = time.perf_counter()
                with warnings.catch_warnings():  # the limits' counts are in the table
                    warnings.simplefilter("ignore")
                    cmd = comp.process(targets)
                took = time.perf_counter() - start
                keep = slice(n + SETTLE, None)
                rows.append((
                    band_error(cmd[n:], inputs[n:], 500.0),
                    band_error(cmd[n:], inputs[n:], 1500.0),
                    nrmse(cmd[keep], inputs[keep]),
                    nrmse(model.predict(cmd)[keep], targets[keep]),
                    nrmse(model.predict(inputs)[keep], targets[keep]),
                    took,
                    comp.saturated_count.sum(),
                ))  # fmt: skip
            f = np.mean(rows, axis=0)
            print(f"| {name} | {level} mV | {f[0]:.2f} % | {f[1]:.2f} % | {f[2]:.2f} % | "
                  f"{f[3]:.4f} % | {f[4]:.2f} % | {1000 * f[5]:.0f} ms | {f[6]:.1f} |",
                  flush=True)  # fmt: skip
        print(f"({name}: preview {comp.preview} samples, gains in {setup:.2f} s)")


if __name__ == "__main__":
    main()
