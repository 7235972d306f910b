"""A signed Preisach density: loops that flatten after each reversal (a PI model's negative
weights, a Bouc-Wen capacitor), every branch still increasing, inverted and exported alike."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.metrics import nrmse
from piezohyst.model.cores.preisach import PreisachHysteresis, branch_sums
from piezohyst.simulation import make_signal

from ..helpers import compare_c_with_python

#: A PI model whose later weights are negative: each branch is steep after a reversal and
#: flattens (a density >= 0 can only steepen)
TRUTH = ph.PIHysteresis([0.0, 10.0, 25.0, 45.0], [1e-8, 6e-9, 3e-9, -2e-9])


@pytest.fixture(scope="module")
def record() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t, v = make_signal("decaying", amplitude=140.0, frequency=0.5, duration=40.0)
    q = TRUTH.predict(v) + 1e-11 * np.random.default_rng(5).standard_normal(v.size)
    return t, v, q


@pytest.fixture(scope="module")
def fitted(record: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict[object, ph.PreisachModel]:
    t, v, q = record
    return {
        signed: ph.PreisachModel(growth_terms=(), signed=signed).fit(v, q, t=t)
        for signed in (False, True, "auto")
    }


def test_a_signed_density_draws_loops_a_positive_one_cannot(
    fitted: dict[object, ph.PreisachModel],
) -> None:
    positive, signed, auto = fitted[False], fitted[True], fitted["auto"]
    assert np.all(positive.operator_.density >= 0)
    assert np.any(signed.operator_.density < 0)
    # the PI truth lies in the signed family: left with the grid's bilinear smoothing of its
    # kinks, a tenth of what the density >= 0 leaves
    assert signed.nrmse_ < 0.1 * positive.nrmse_
    assert signed.nrmse_ < 0.002
    np.testing.assert_array_equal(auto.operator_.density, signed.operator_.density)
    assert branch_sums(signed.operator_.density).min() > 0  # every branch increasing


def test_every_branch_of_a_signed_model_increases(fitted: dict[object, ph.PreisachModel]) -> None:
    """Along any monotone stretch of a random history the output moves the same way."""
    model = fitted[True]
    rng = np.random.default_rng(11)
    lo, hi = model.input_range_
    turns = rng.uniform(lo, hi, 40)
    v = np.concatenate([np.linspace(a, b, 50) for a, b in itertools.pairwise(turns)])
    with warnings.catch_warnings():  # a random history leaves the training's loops
        warnings.simplefilter("ignore", ph.errors.ExtrapolationWarning)
        q = model.hysteresis_.predict(v)
    dv, dq = np.diff(v), np.diff(q)
    moving = np.abs(dv) > 1e-9
    assert np.all(dq[moving] * dv[moving] > 0)


def test_a_density_with_a_falling_branch_is_refused() -> None:
    nodes = np.linspace(0.0, 30.0, 4)
    good = np.triu(np.full((3, 3), -0.2)) + np.diag([1.0, 1.0, 1.0])
    PreisachHysteresis(nodes, good, np.zeros(ph.model.cores.preisach.P.RV_SIZE))  # sums 0.6 > 0
    bad = good.copy()
    bad[0, 2] = -2.0  # the row from cell (0, 0) sums to -1.2 at its end
    with pytest.raises(ph.ParameterError, match="sums from the diagonal"):
        PreisachHysteresis(nodes, bad, np.zeros(ph.model.cores.preisach.P.RV_SIZE))
    with pytest.raises(ph.ParameterError, match="'signed'"):
        ph.PreisachModel(signed="maybe").fit(nodes, nodes)


def test_a_signed_model_is_inverted_and_exported_like_any(
    fitted: dict[object, ph.PreisachModel], tmp_path: Path
) -> None:
    model = fitted[True]
    lo, hi = model.input_range_
    _, shape = make_signal("decaying", amplitude=1.0, frequency=0.5, duration=10.0)
    q = model.hysteresis_.predict(np.array([lo, hi, lo]))
    desired = q[2] + (q[1] - q[2]) * (0.1 + 0.8 * shape)
    comp = ph.Compensator(model, v_min=lo, v_max=hi, slew_rate=None)
    got = model.hysteresis_.predict(comp.process(desired))
    # tol: Newton stops at 1e-12 of each step's change; the bracket holds with the smallest
    # branch slope, not the diagonal's
    np.testing.assert_allclose(got, desired, rtol=0, atol=1e-9 * np.ptp(desired))
    comp.reset()
    compare_c_with_python(comp, desired[:2000], tmp_path, "double", hi)


def test_other_physics_gets_the_signed_density_and_the_bench_keeps_its_own() -> None:
    """``signed="auto"``: the signed density only where it halves the misfit."""
    t, v = make_signal("decaying", amplitude=140.0, frequency=0.5, duration=40.0)
    kept = {}
    for plant in ("preisach", "bouc-wen"):
        rec = ph.simulate(v, t, plant=plant, seed=1)
        model = ph.PreisachModel().fit(rec.voltage, rec.charge, t=rec.t)
        kept[plant] = bool(np.any(model.operator_.density < 0))
        t2, v2 = make_signal("multi", amplitude=140.0, frequency=0.5, duration=12.0)
        test = ph.simulate(v2, t2, plant=plant, seed=2)
        positive = ph.PreisachModel(signed=False).fit(rec.voltage, rec.charge, t=rec.t)
        with warnings.catch_warnings():  # the test record reaches 140 V, the training 132.5 V
            warnings.simplefilter("ignore", ph.errors.ExtrapolationWarning)
            err = nrmse(test.charge, model.predict(test.voltage, t=test.t))
            err_positive = nrmse(test.charge, positive.predict(test.voltage, t=test.t))
        if kept[plant]:
            assert err < 0.7 * err_positive  # measured 5.1 % against 9.2 %
    assert kept == {"preisach": False, "bouc-wen": True}
