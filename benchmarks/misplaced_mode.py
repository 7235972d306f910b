"""Learning a scan through a mode the model misplaces: the measured response per harmonic.

The learning laws step through the model; where its mode sits a few per cent off the
actuator's, the harmonics near the mode turn by up to 180 degrees and grow a little every
trial (``control.learning.harmonics``). That was found, and the remedy built, on the coupled
Bouc-Wen + Duhem stage of ``benchmarks/coupled_learning.py``. Scored here, once, on single
actuators nobody tuned it on: the simulator's Preisach, two-state and Bouc-Wen-with-creep
capacitors behind amplifier lags with modes of their own (150, 240 and 130 Hz), each
identified as the coupled stages are (``ClassicalPI(16)`` with a first-order lag and a
second-order mode, on 12 s of three-rate signals), then learning 15 one-second trials of a
10 Hz and a 25 Hz triangle over 20-80 % of its reach from its laser, with the measured
response and without it (the law as written). The true displacement's NRMSE and loop width
(% of the reach), the harmonics learned through their measured response, the rollbacks.
Then the same with a payload mounted after the identification: each plant's mode 8 % lower
(its moving mass 18 % heavier) than the one the model was identified with.

Run: ``python benchmarks/misplaced_mode.py``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import replace

import numpy as np

import piezohyst as ph
from piezohyst.control.learning import harmonics
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import PLANTS, Bench, make_signal

FS = 1000.0
TRIALS = 15
KW = {"output_unit": "m", "input_dynamics": "first-order", "output_dynamics": "second-order"}
PLANTS_HELD = {
    "preisach, 2 ms, mode 150 Hz": replace(PLANTS["preisach"], amp_tau=2e-3, mech_f0=150.0,
                                            mech_zeta=0.04),
    "two-state, 3 ms, mode 240 Hz": replace(PLANTS["two-state"], amp_tau=3e-3, mech_f0=240.0,
                                             mech_zeta=0.03),
    "bouc-wen + creep, 4 ms, mode 130 Hz": replace(PLANTS["bouc-wen-creep-lag"], amp_tau=4e-3,
                                                   mech_f0=130.0, mech_zeta=0.05),
}  # fmt: skip


def identify(preset: object) -> ph.ClassicalPI:
    """The model, from 12 s of three-rate signals (2.5 Hz base), as the coupled stages'."""
    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    rec = Bench(preset, seed=0).run(v)
    return ph.ClassicalPI(16, **KW).fit(v, rec.displacement, t=t)


def learn(model: ph.ClassicalPI, preset: object, scan: np.ndarray) -> tuple[list, object]:  # type: ignore[type-arg]
    """Each trial's true displacement, and the learner."""
    lo, hi = model.input_range_
    ilc = ph.LearningCompensator(model, v_min=lo, v_max=hi, sample_rate=FS, slew_rate=None,
                                 domain="displacement", gain=1.0, voltage=0.0)  # fmt: skip
    bench = Bench(preset, seed=5, voltage=0.0)
    out = []
    for _ in range(TRIALS):
        rec = bench.run(ilc.command(scan))
        ilc.learn(displacement=rec.displacement)
        out.append(rec.true_displacement)
    return out, ilc


def main() -> None:
    warnings.simplefilter("ignore")
    measured = harmonics.Harmonics.steering
    print("| plant | scan | law | trial 1 (feedforward) | trial 5 | trial 10 | trial 15 | "
          "harmonics learned through the measured response | rollbacks |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    cases = [(name, p, p) for name, p in PLANTS_HELD.items()]
    for name, p in PLANTS_HELD.items():  # a payload mounted after the identification
        moved = replace(p, mech_f0=0.92 * p.mech_f0)
        cases.append((f"{name}, a payload: mode at {moved.mech_f0:.0f} Hz", p, moved))
    for name, identified, preset in cases:
        start = time.perf_counter()
        model = identify(identified)
        # what the actuator reaches: the model's output over a slow full-range triangle
        t, v = make_signal("triangle", amplitude=140.0, frequency=0.5, duration=4.0)
        out = model.predict(v, t)
        reach, span = (float(out.min()), float(out.max())), float(np.ptp(out))
        for rate in (10.0, 25.0):
            k = np.arange(1000)
            tri = np.abs((k / FS * rate) % 1.0 * 2 - 1)
            scan = reach[0] + span * (0.2 + 0.6 * tri)

            def written(self: harmonics.Harmonics, own: object = 1.0) -> np.ndarray:
                return np.ones_like(self.response)  # the law as written: every factor 1

            for label, steering in (("measured response", measured), ("as written", written)):
                harmonics.Harmonics.steering = steering  # type: ignore[method-assign]
                moved, ilc = learn(model, preset, scan)
                figs = []
                for trial in (1, 5, 10, TRIALS):
                    m = moved[trial - 1]
                    err = np.sqrt(np.mean((m - scan) ** 2)) / span
                    figs.append(f"{100 * err:.2f} / {100 * hysteresis_width(scan, m):.2f} %")
                taken = ilc._harmonics.steered() * FS / scan.size  # type: ignore[attr-defined]
                said = (f"{taken.size} ({taken[0]:.0f}-{taken[-1]:.0f} Hz)" if taken.size
                        else "0") if label == "measured response" else "-"  # fmt: skip
                print(f"| {name} | {rate:.0f} Hz | {label} | " + " | ".join(figs)
                      + f" | {said} | {ilc.rollbacks} |", flush=True)  # fmt: skip
        harmonics.Harmonics.steering = measured  # type: ignore[method-assign]
        print(f"<!-- {name}: {time.perf_counter() - start:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
