"""A displacement record of another lab's kind (issue 40): a 10 Hz sine whose amplitude decays
to zero over 10 s, fitted on the first 6 s, predicted over the last 4 s. The record's domain
sets the default terms (no leakage growth on a displacement), and model choice has the
field's standard, PI with creep, among its candidates."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.metrics import nrmse
from piezohyst.simulation import PLANTS

DEFAULTS = {
    "ClassicalPI": ph.ClassicalPI,
    "ActivePI": ph.ActivePI,
    "GeneralizedPI": ph.GeneralizedPI,
    "PreisachModel": ph.PreisachModel,
    "DuhemModel": ph.DuhemModel,
    "BoucWenModel": ph.BoucWenModel,
}


def _record(plant: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(10_000) / 1000.0
    v = 70.0 + 70.0 * (1.0 - t / 10.0) * np.sin(2 * np.pi * 10.0 * t)
    rec = ph.simulate(v, t, preset=replace(PLANTS[plant], amp_tau=0.0), seed=0)
    return t, rec.voltage, rec.displacement


def _held_out(model: ph.HysteresisModel, t: np.ndarray, v: np.ndarray, s: np.ndarray) -> float:
    fit = t < 6.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fits' own notes are not under test
        model.fit(v[fit], s[fit], t=t[fit])
        return nrmse(model.predict(v, t=t)[~fit], s[~fit])


@pytest.fixture(scope="module")
def creeping() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The zoo's Bouc-Wen plant with creep (Debye branches at 0.2 s and 5 s)."""
    return _record("bouc-wen-creep-lag")


def test_a_displacement_record_gets_no_growth_terms_and_no_default_ramps_away(creeping) -> None:
    t, v, s = creeping
    errors = {}
    for name, cls in DEFAULTS.items():
        model = cls(output_unit="m")
        errors[name] = _held_out(model, t, v, s)
        assert model.growth_coefficients() == {}, name  # a displacement sees no leaked charge
        # the drift goes to creep timed by the record; ActivePI's integrator, fixed by the
        # model, gives way to them too (it became ClassicalPI: 0.36 % held out on the
        # measured SmartHysteresis record where creep gives 0.15 %)
        if "creep" in model.get_params() or name == "ActivePI":
            kinds = [term.kind for term in model.terms_]
            assert "creep" in kinds, name
    # measured 0.016-1.17 %; before (an integral growth term by default) 16.6-20.2 % for
    # ActivePI, GeneralizedPI, Preisach and Duhem: the ramp the record could not support
    assert max(errors.values()) < 0.02, errors
    named = ph.PreisachModel(growth_terms=("integral",), output_unit="m")
    _held_out(named, t, v, s)
    assert "integral" in named.growth_coefficients()  # asked for by name: kept


def test_every_default_holds_out_within_3x_of_the_best_default() -> None:
    """Issue 40's bar for a record of another lab's kind, on the Preisach plant: no default
    ramps away, none is far behind. (On the Bouc-Wen plants the generating class fits them to
    0.012-0.016 %, 74-131x below the rest; on the two-state plant the play family's loops
    miss its shape, 0.48 % for Preisach against 5.4 % for classical PI: spreads of the
    plants, measured and said in the issue's note, not a default ramping away.)"""
    t, v, s = _record("preisach")
    errors = {name: _held_out(cls(output_unit="m"), t, v, s) for name, cls in DEFAULTS.items()}
    best = min(errors.values())
    # measured 0.40-0.98 %, 2.4x; before the domain rule the Preisach default ramped to 178 %
    # on the measured record
    assert max(errors.values()) <= 3.0 * best, errors


@pytest.mark.parametrize("plant", ["bouc-wen-creep-lag", "preisach"])
def test_model_choice_reaches_the_fields_standard(plant: str, creeping) -> None:
    t, v, s = creeping if plant == "bouc-wen-creep-lag" else _record(plant)
    fit = t < 6.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sel = ph.select_model(v[fit], s[fit], t[fit], output_unit="m")
    chosen = nrmse(sel.model.predict(v, t=t)[~fit], s[~fit])
    standard = _held_out(ph.GeneralizedPI(20, creep=(0.01, 0.1, 1.0), output_unit="m"), t, v, s)
    assert chosen <= 1.5 * standard, (sel.name, chosen, standard)  # issue 40's bar
    assert any(row.name.endswith("+creep") for row in sel.rows)  # the standard competed


def test_creep_time_constants_come_from_the_time_axis() -> None:
    from piezohyst.analysis.selection import candidate_model, creep_constants, is_candidate

    t = np.arange(6000) / 1000.0
    taus = creep_constants(t)
    # a decade apart, the slowest a fifth of the record (6 s / 5), the fastest >= 10 samples
    assert taus == pytest.approx((0.012, 0.12, 1.2), rel=1e-3)  # tol: t[-1] - t[0] is 5.999 s
    # tol: ten samples, 10 * 0.099 / 99, rounded once
    assert creep_constants(np.arange(100) / 1000.0)[0] == pytest.approx(0.01)
    model = candidate_model("bouc-wen+creep", 10, ("V", "m"), t)
    assert tuple(model.get_params()["creep"]) == taus  # the same numbers, passed through
    assert is_candidate("generalized-pi+creep") and not is_candidate("classical-pi+creep")
    with pytest.raises(ph.ParameterError, match="creep"):
        ph.select_model(t, np.sin(t), t, candidates=["classical-pi+creep"])
