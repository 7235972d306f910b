"""Growth terms on charge records: the packed presets' integral against the Prandtl-Ishlinskii
proxy's forward chaining (``growth_terms="auto"``), held out, on the validation matrix's
plants and splits (``docs/validation.md``) for the given batch units.

Run: ``python benchmarks/growth_choice.py 4,5,6 [TERMS]`` (units 4-6: where a default may be
chosen; 1-3 are the matrix's own; TERMS, e.g. ``integral,abs_integral``, instead of the
proxy's choice). Prints the mean held-out NRMSE (%) over the units per cell: the integral,
then the alternative.

``python benchmarks/growth_choice.py 4,5,6 own [CLASSES]``: the integral against the
integral and ``abs_integral``, and the choice between them by each model's *own* forward
chaining inside the training record (fitted on the first 40 %, then on everything before
each of four later blocks, each block predicted from the record's start; the larger set
must beat the smaller by 0.1 %, as the proxy's rule): one fit per fold and candidate.
CLASSES: e.g. ``PreisachModel`` (default: Preisach, Bouc-Wen and Duhem).

``python benchmarks/growth_choice.py 4,5,6 rise``: whether a record's design decides the rise
(a rule that needs no fit): per training record (``excite``; 12 s of ``decaying``), the
variance inflation of the x|x| integral given the integral, time and an offset
(:func:`inflation`), and per unit and model the held-out NRMSE with the integral, then with
the integral and its rise, and the rise found over the conductance (``r2/r1``: the
conductance's relative rise at the top of the range; the bench's truth +0.5, Bouc-Wen's +1).

``python benchmarks/growth_choice.py 4,5,6 holds``: the default (``growth_terms="domain"``:
the integral, and its rise where the record's holds show one, ``holds_show_rise``) against
the integral alone and the integral with its rise: per record, what the holds said on each
unit (the rise over the conductance, ± its standard error, or why none), and per model the
mean held-out NRMSE integral / both / default.

Not a test: nothing here asserts a time.
"""

import itertools
import sys
import warnings

import numpy as np

import piezohyst as ph
from piezohyst.simulation import PLANTS, batch_unit
from piezohyst.workflows.excitation import excitation

warnings.simplefilter("ignore")
units = [int(u) for u in sys.argv[1].split(",")]
OWN = len(sys.argv) > 2 and sys.argv[2] == "own"
RISE = len(sys.argv) > 2 and sys.argv[2] == "rise"
HOLDS = len(sys.argv) > 2 and sys.argv[2] == "holds"
#: the alternative to the presets' integral: "auto" (the proxy's forward chaining) or terms
GROWTH: object = "auto" if len(sys.argv) < 3 else tuple(sys.argv[2].split(","))
played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
designs = {
    "excite": lambda p, u: ph.simulate(played.voltage, played.t, preset=p, seed=u),
    "decaying": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=40.0, seed=u),
}


def own_score(cls: type, terms: tuple[str, ...], x: np.ndarray, y: np.ndarray,
              t: np.ndarray) -> float:  # fmt: skip
    """Pooled RMSE of forward chaining with the model's own fits (the proxy's folds)."""
    first = int(0.4 * x.size)
    edges = [first + (x.size - first) * j // 4 for j in range(5)]
    sse, count = 0.0, 0
    for a, b in itertools.pairwise(edges):
        try:
            m = cls(growth_terms=terms).fit(x[:a], y[:a], t=t[:a])
            r = m.predict(x[:b], t=t[:b])[a:b] - y[a:b]
        except ph.PiezohystError:
            return np.inf
        sse, count = sse + float(r @ r), count + b - a
    return float(np.sqrt(sse / count))


def own(classes: list[type]) -> None:
    both = ("integral", "abs_integral")
    for design, rec in designs.items():
        for plant in PLANTS:
            cells: dict[str, list[tuple[float, float, float, int]]] = {}
            for u in units:
                p = batch_unit(PLANTS[plant], u)
                tr = rec(p, u)
                te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
                for cls in classes:
                    err, score = [], []
                    for g in (("integral",), both):
                        m = cls(growth_terms=g).fit(tr.voltage, tr.charge, t=tr.t)
                        err.append(100 * ph.metrics.nrmse(te.charge, m.predict(te.voltage, t=te.t)))
                        score.append(own_score(cls, g, tr.voltage, tr.charge, tr.t))
                    pick = int(score[1] < score[0] * (1 - 1e-3))
                    cells.setdefault(cls.__name__[:-5], []).append((*err[:2], err[pick], pick))
            print(design, plant, " | ".join(
                f"{k}: integral {np.mean([c[0] for c in v]):.2f}, both "
                f"{np.mean([c[1] for c in v]):.2f}, own choice {np.mean([c[2] for c in v]):.2f} "
                f"(picks {[c[3] for c in v]})" for k, v in cells.items()), flush=True)  # fmt: skip


def inflation(x: np.ndarray, t: np.ndarray) -> float:
    """Variance inflation factor of the x|x| integral given the integral, time and an offset:
    1 / (1 - R^2) of that regression (1: independent of them; large: not separable)."""
    dt = np.diff(t, prepend=t[0])
    cols = np.column_stack([t - t[0], np.cumsum(x * dt), np.cumsum(x * np.abs(x) * dt)])
    corr = np.corrcoef(cols, rowvar=False)
    return float(np.linalg.inv(corr)[2, 2])


def rise() -> None:
    both = ("integral", "abs_integral")
    for design in ("excite", "decaying 12 s"):
        for plant in PLANTS:
            row = []
            for u in units:
                p = batch_unit(PLANTS[plant], u)
                tr = (designs["excite"](p, u) if design == "excite" else
                      ph.simulate(preset=p, signal="decaying", duration=12.0, seed=u))  # fmt: skip
                te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
                row.append(f"unit {u} (VIF {inflation(tr.voltage, tr.t):.0f})")
                for cls in (ph.PreisachModel, ph.BoucWenModel, ph.DuhemModel):
                    err = []
                    for g in (("integral",), both):
                        m = cls(growth_terms=g).fit(tr.voltage, tr.charge, t=tr.t)
                        err.append(100 * ph.metrics.nrmse(te.charge, m.predict(te.voltage, t=te.t)))
                    c = m.growth_coefficients()
                    ratio = c["abs_integral"][0] / c["integral"][0]
                    row.append(f"{cls.__name__[:-5]} {err[0]:.2f} -> {err[1]:.2f} ({ratio:+.2f})")
            print(design, plant, " | ".join(row), flush=True)


def said(tr: ph.simulation.BenchRecord) -> str:
    """What the record's holds say of the leak's rise (as ``holds_show_rise`` reads them)."""
    try:
        leak = ph.calibrate_leakage(tr.t, tr.voltage, tr.charge)
    except ph.PiezohystError:
        return "refused"
    se = leak.stderr().get("quadratic", 0.0)
    return f"{leak.quadratic / leak.conductance:+.2f} ± {se / leak.conductance:.2f}"


def holds() -> None:
    both = ("integral", "abs_integral")
    for design, rec in designs.items():
        for plant in PLANTS:
            verdicts, cells = [], {}
            for u in units:
                p = batch_unit(PLANTS[plant], u)
                tr = rec(p, u)
                te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
                verdicts.append(said(tr))
                for cls in (ph.PreisachModel, ph.BoucWenModel, ph.DuhemModel):
                    for g in (("integral",), both, "domain"):
                        m = cls(growth_terms=g).fit(tr.voltage, tr.charge, t=tr.t)
                        e = 100 * ph.metrics.nrmse(te.charge, m.predict(te.voltage, t=te.t))
                        cells.setdefault(cls.__name__[:-5], {}).setdefault(str(g), []).append(e)
            row = " | ".join(f"{k} " + " / ".join(f"{np.mean(v):.2f}" for v in c.values())
                             for k, c in cells.items())  # fmt: skip
            print(f"{plant} ({design}) [{'; '.join(verdicts)}] {row}", flush=True)


if RISE:
    rise()
    sys.exit()
if HOLDS:
    holds()
    sys.exit()
if OWN:
    names = sys.argv[3].split(",") if len(sys.argv) > 3 else ["PreisachModel", "BoucWenModel",
                                                               "DuhemModel"]  # fmt: skip
    own([getattr(ph, n) for n in names])
    sys.exit()
for design, rec in designs.items():
    for plant in PLANTS:
        cells: dict[tuple[str, str], list[float]] = {}
        for u in units:
            p = batch_unit(PLANTS[plant], u)
            tr = rec(p, u)
            te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
            for cls in (ph.PreisachModel, ph.BoucWenModel, ph.DuhemModel):
                for g in (("integral",), GROWTH):
                    m = cls(growth_terms=g)
                    try:
                        m.fit(tr.voltage, tr.charge, t=tr.t)
                        e = ph.metrics.nrmse(te.charge, m.predict(te.voltage, t=te.t))
                    except ph.PiezohystError:
                        e = np.inf
                    cells.setdefault(
                        (cls.__name__[:-5], "int" if g == ("integral",) else "alt"), []
                    ).append(100 * e)
        print(
            design,
            plant,
            " | ".join(f"{k[0]} {k[1]} {np.mean(v):.2f}" for k, v in cells.items()),
            flush=True,
        )
