"""A core defined outside the library runs through the library's whole model contract."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.export import export_c

from ..external_core import BacklashCore

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
pytestmark = pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")


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
    comp = ph.Compensator(model, slew_rate=None, v_min=10.0, v_max=130.0)
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


class _TimeSquared(ph.Term):
    """A growth term defined outside the library (a bias that ramps)."""

    kind = "test_time_squared"
    removed = True
    rate_dependent = True
    state_names = ("elapsed",)

    def columns(self, x: np.ndarray, t: np.ndarray | None, dt: np.ndarray | None,
                state: np.ndarray) -> np.ndarray:  # fmt: skip
        assert dt is not None
        elapsed = state[0] + np.cumsum(dt)
        state[0] = elapsed[-1]
        return np.asarray((elapsed**2)[:, None])

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        return (f"{output_unit}/s^2",)


def test_a_term_registered_once_is_a_growth_choice_everywhere() -> None:
    """Defining the term makes it a named growth choice of every model with growth terms;
    the self-sensing loop, which removes leakage currents only, refuses it by name."""
    t = np.arange(4000) / 1000.0
    v = 70.0 - 70.0 * np.cos(2.0 * np.pi * t)
    q = 1e-8 * v + 2e-9 * t**2
    for model in (ph.GeneralizedPI(6, growth_terms=("integral", "test_time_squared")),
                  ph.PreisachModel(nodes=8, growth_terms=("test_time_squared",)),
                  ph.BoucWenModel(growth_terms=("test_time_squared",))):  # fmt: skip
        model.fit(v, q, t=t)
        assert "test_time_squared" in model.growth_coefficients(), type(model).__name__
    with pytest.raises(ph.ParameterError, match="'test_time_squared' is not a leakage current"):
        ph.SelfSensingController(model, v_min=10.0, v_max=130.0, sample_rate=1000.0)
    with pytest.raises(ph.ParameterError, match="test_time_squared"):
        ph.GeneralizedPI(growth_terms=("no_such_term",)).fit(v, q, t=t)
