"""Growth terms on charge records: the packed presets' integral against the Prandtl-Ishlinskii
proxy's forward chaining (``growth_terms="auto"``), held out, on the validation matrix's
plants and splits (``docs/validation.md``) for the given batch units.

Run: ``python benchmarks/growth_choice.py 4,5,6 [TERMS]`` (units 4-6: where a default may be
chosen; 1-3 are the matrix's own; TERMS, e.g. ``integral,abs_integral``, instead of the
proxy's choice). Prints the mean held-out NRMSE (%) over the units per cell: the integral,
then the alternative.

Not a test: nothing here asserts a time.
"""

import sys
import warnings

import numpy as np

import piezohyst as ph
from piezohyst.simulation import PLANTS, batch_unit
from piezohyst.workflows.excitation import excitation

warnings.simplefilter("ignore")
units = [int(u) for u in sys.argv[1].split(",")]
#: the alternative to the presets' integral: "auto" (the proxy's forward chaining) or terms
GROWTH: object = "auto" if len(sys.argv) < 3 else tuple(sys.argv[2].split(","))
played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
designs = {
    "excite": lambda p, u: ph.simulate(played.voltage, played.t, preset=p, seed=u),
    "decaying": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=40.0, seed=u),
}
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
