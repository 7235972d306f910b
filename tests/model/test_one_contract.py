"""Every public model kind on the one contract: fit, an exact file round trip, and the one
Compensator class inverting it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.simulation import make_signal

pytestmark = pytest.mark.kernels

KINDS = {
    "classical-pi": lambda: ph.ClassicalPI(6),
    "active-pi": lambda: ph.ActivePI(6),
    "generalized-pi": lambda: ph.GeneralizedPI(6, growth_terms=("integral",), asymmetry=2),
    "pi-model": lambda: ph.PIModel(6, terms=("integral", "time")),
    "preisach": lambda: ph.PreisachModel(nodes=8),
    "duhem": lambda: ph.DuhemModel(grid=(4, 3)),
    "bouc-wen": lambda: ph.BoucWenModel(),
    "one-class": lambda: ph.HysteresisModel(
        "play", settings={"n_operators": 6}, terms=("integral",)
    ),
}


@pytest.fixture(scope="module")
def record() -> ph.simulation.BenchRecord:
    t, v = make_signal("decaying", duration=6.0, rate=1000.0)
    return ph.simulate(v, t)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_fit_round_trip_and_the_one_compensator(
    kind: str, record: ph.simulation.BenchRecord, tmp_path: Path
) -> None:
    model = KINDS[kind]().fit(record.voltage, record.charge, t=record.t)
    assert model.nrmse_ < 0.05, kind
    path = tmp_path / f"{kind}.json"
    model.save(path)
    again = ph.load_model(path)
    assert type(again) is type(model) and type(again.operator_) is type(model.operator_)
    np.testing.assert_array_equal(
        again.predict(record.voltage, t=record.t), model.predict(record.voltage, t=record.t)
    )
    lo, hi = again.input_range_
    comp = ph.Compensator(again, v_min=lo, v_max=hi, sample_rate=1000.0)
    assert type(comp) is ph.Compensator  # one class, the engine by the core's inverse plan
    pure = again.hysteresis_
    wanted = record.voltage[:1500]  # where the model was identified: inside its region
    target = pure.predict(wanted, t=record.t[:1500])  # from the model's initial state
    achieved = pure.predict(comp.process(target), t=record.t[:1500])
    # tol: a per-sample inverse (eq. 18, or Newton to 1e-12 of the step) from the same state
    np.testing.assert_allclose(achieved, target, rtol=0, atol=1e-6 * float(np.ptp(target)))
