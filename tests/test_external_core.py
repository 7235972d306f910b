"""A core defined outside the library runs through the library's whole model contract."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.export import export_c

from .external_core import BacklashCore


def _record() -> tuple[np.ndarray, np.ndarray]:
    v = 70.0 - 70.0 * np.cos(np.linspace(0.0, 6.0 * np.pi, 900))
    truth = BacklashCore(0.1 * float(np.ptp(v)), 2e-8, 5e-8, 1e-7, np.array([v[0]]))
    return v, truth.predict(v)


def test_an_outside_core_fits_predicts_and_round_trips(tmp_path: Path) -> None:
    v, q = _record()
    model = ph.HysteresisModel(BacklashCore).fit(v, q)
    # tol: the data are the core's own output; the solve's rounding on 900 rows
    assert model.nrmse_ < 1e-12
    assert isinstance(model.operator_, BacklashCore)
    assert ph.HysteresisModel("test-backlash").fit(v, q).nrmse_ == model.nrmse_
    path = tmp_path / "backlash.json"
    model.save(path)
    again = ph.load_model(path)
    assert type(again) is ph.HysteresisModel
    assert again.get_params() == {**model.get_params(), "core": "test-backlash"}
    np.testing.assert_array_equal(again.predict(v), model.predict(v))
    np.testing.assert_array_equal(again.predict(v, state="periodic"),
                                  model.predict(v, state="periodic"))  # fmt: skip


def test_an_outside_core_is_compared_beside_the_built_in_ones() -> None:
    v, q = _record()
    result = ph.compare_models({"backlash": ph.HysteresisModel(BacklashCore),
                                "classical": ph.ClassicalPI(8)}, v, q)  # fmt: skip
    scores = {row.name: row.test_nrmse for row in result.rows}
    # tol: the held-out part is the core's own output again
    assert scores["backlash"] < 1e-12 < scores["classical"]


def test_the_one_compensator_inverts_an_outside_core() -> None:
    """No compiled step: the Python engine finds each command by a root search on the core."""
    v, q = _record()
    model = ph.HysteresisModel(BacklashCore).fit(v, q)
    comp = ph.Compensator(model, v_min=10.0, v_max=130.0)
    assert comp.inverse.name == "python"
    wanted = 20.0 + 100.0 * (0.5 - 0.5 * np.cos(np.linspace(0.0, 4.0 * np.pi, 400)))
    target = model.predict(wanted)
    commands = comp.process(target)
    # tol: Brent's method stops at 1e-12 of the reachable interval (120 V)
    np.testing.assert_allclose(commands, wanted, rtol=0, atol=1e-9)
    assert comp.saturated_count == 0
    assert comp.step(float("nan")) == commands[-1] and comp.nonfinite_count == 1
    assert comp.step(1.0) == 130.0 and comp.saturated_count == 1  # out of reach: the limit
    slow = ph.Compensator(model, v_min=10.0, v_max=130.0, slew_rate=1000.0, sample_rate=1000.0)
    assert np.all(np.abs(np.diff(slow.process(target))) <= 1.0 + 1e-12)


def test_what_an_outside_core_lacks_is_refused_in_one_line() -> None:
    v, q = _record()
    model = ph.HysteresisModel(BacklashCore).fit(v, q)
    with pytest.raises(ph.ParameterError, match="runs in Python"):
        export_c(ph.Compensator(model, v_min=10.0, v_max=130.0))
    with pytest.raises(ph.ParameterError, match="SelfSensingController"):
        ph.SelfSensingController(model, v_min=10.0, v_max=130.0, sample_rate=1000.0)
    with pytest.raises(ph.NotInvertibleError, match="closed-form inverse"):
        model.inverse()
    with pytest.raises(ph.ParameterError, match="must be a registered core"):
        ph.HysteresisModel("no-such-core").fit(v, q)
