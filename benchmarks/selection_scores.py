"""Which score of select_model's two parts chooses best on data it was not tuned on?

``python benchmarks/selection_scores.py --units 4,5,6 [DATA_DIR]`` (about 10 minutes on two
cores for three units; ``--units 1,2,3`` for the matrix's own).

The matrix's splits (``docs/validation.md``): every plant trained on what ``piezohyst
excite`` writes or on 40 s of decaying loops and tested on 12 s of ``multi``; with
DATA_DIR, its two measured sets. For each record: every candidate's held-out NRMSE, and
``select_model``'s two part scores per candidate (its folds, ``selection.fold_bounds``: fit
on half the input's turns, score to three quarters; fit to three quarters, score the rest).
Four scores of the same two parts, each choosing the simplest candidate within 2 % of its
best: ``select_model``'s (:data:`~piezohyst.analysis.selection.WEIGHTS`, the plain mean), weights
0.4 and 0.6, the last part alone, the worst part. A score's ratio on a row is the mean
held-out NRMSE of what it chose over the units, divided by the best candidate's mean, as in
the matrix. Units 4-6 are where a score may be chosen; units 1-3 are the matrix's, to check
it. Two rules that weigh the scores' uncertainty as well (:data:`WITHIN`): the simplest
candidate whose paired block-jackknife margin over the best-scoring one is within 1 or 2
standard errors.
"""

from __future__ import annotations

import argparse
import math
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from selection_study import _measured, _record  # the study's records, built alike

import piezohyst as ph
from piezohyst.analysis.selection import (
    CANDIDATES,
    TIE,
    WEIGHTS,
    SelectionRow,
    candidate_model,
    with_margins,
)

SCORES: dict[str, Callable[[list[float]], float]] = {
    f"weights {', '.join(f'{w:.2g}' for w in WEIGHTS)} (select_model)": (
        lambda f: float(np.dot(WEIGHTS, f))
    ),
    "weights 0.4, 0.6": lambda f: 0.4 * f[0] + 0.6 * f[1],
    "last part": lambda f: f[-1],
    "worst part": lambda f: max(f),
}


def row(job: tuple[str, str, int, str | None]) -> dict[str, Any]:
    """Held-out NRMSE of every default and select_model's part scores on one split: a plant's
    (design, plant, unit, None) or a measured set's ("measured", name, 0, DATA_DIR), built
    as the selection study builds them."""
    design, plant, unit, data = job
    if data is None:
        (x, y, t, out), (xt, yt, tt, scored) = _record(design, plant, unit)
    else:
        (x, y, t, out), (xt, yt, tt, scored) = _measured(Path(data), plant)
    errs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in CANDIDATES:
            try:
                m = candidate_model(name, 10, ("V", out), t).fit(x, y, t=t)
                e = float(ph.metrics.nrmse(yt[scored:], m.predict(xt, t=tt)[scored:]))
            except ph.PiezohystError:
                e = math.inf
            errs[name] = e if math.isfinite(e) else math.inf
        sel = ph.select_model(x, y, t, output_unit=out)
    folds = {r.name: list(r.folds) for r in sel.rows}
    picks = {label: choose(folds, score) for label, score in SCORES.items()}
    picks |= {label: simplest_within(sel.rows, k) for label, k in WITHIN.items()}
    return {"errs": errs, "picks": picks}


#: Rules that weigh the scores' uncertainty: the simplest candidate whose paired
#: block-jackknife margin over the best-scoring one is within k standard errors
WITHIN = {"simplest within 1 s.e.": 1.0, "simplest within 2 s.e.": 2.0}


def simplest_within(rows: Sequence[SelectionRow], k: float) -> str:
    """The first candidate (simplest) not told apart from the best-scoring one at k
    standard errors of their paired margin."""
    best = min(rows, key=lambda r: r.score)
    margins = {r.name: r for r in with_margins(rows, best)}
    for name in CANDIDATES:
        r = margins.get(name)
        if r is not None and math.isfinite(r.score) and r.margin <= k * r.margin_stderr:
            return name
    return best.name


def choose(folds: dict[str, list[float]], score: Callable[[list[float]], float]) -> str:
    """The simplest candidate within 2 % of the best score."""
    s = {n: score(f) if all(math.isfinite(x) for x in f) else math.inf for n, f in folds.items()}
    best = min(s.values())
    return next(n for n in CANDIDATES if s[n] <= best * (1 + TIE))


def main() -> None:
    from piezohyst.simulation import PLANTS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?", type=Path, help="the shared data folder (optional)")
    ap.add_argument("--units", default="4,5,6", help="batch units, comma-separated")
    args = ap.parse_args()
    units = [int(u) for u in args.units.split(",")]
    jobs: list[tuple[str, str, int, str | None]] = [
        (d, p, u, None) for d in ("excite", "decaying") for p in PLANTS for u in units
    ]
    if args.data is not None:
        jobs += [
            ("measured", n, 0, str(args.data)) for n in ("SmartHysteresis", "micromanipulator")
        ]
    with ProcessPoolExecutor(2) as ex:
        results = list(ex.map(row, jobs))
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for (design, plant, _, _), res in zip(jobs, results, strict=True):
        rows.setdefault((design, plant), []).append(res)
    print(f"piezohyst {ph.__version__}: select_model's part scores, units {args.units}")
    ratios: dict[str, list[float]] = {s: [] for s in [*SCORES, *WITHIN]}
    for (design, plant), runs in rows.items():
        means = {n: float(np.mean([r["errs"][n] for r in runs])) for n in CANDIDATES}
        best = min(means.values())
        cells = []
        for label in [*SCORES, *WITHIN]:
            picks = [r["picks"][label] for r in runs]
            ratio = float(np.mean([r["errs"][p] for r, p in zip(runs, picks, strict=True)]))
            ratios[label].append(ratio / best)
            cells.append(f"{label} {ratio / best:.2f}")
        print(f"  {plant} ({design}): " + ", ".join(cells))
        for n in CANDIDATES:  # each default's held-out NRMSE per unit
            print(f"    {n}: " + " / ".join(f"{100 * r['errs'][n]:.2f}" for r in runs) + " %")
    for label, rs in ratios.items():
        print(f"{label}: within 1.25x on {sum(r <= 1.25 for r in rs)} of {len(rs)} rows, "
              f"worst {max(rs):.2f}x, mean ratio {np.mean(rs):.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
