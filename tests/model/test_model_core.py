"""The model core: terms, one fit path, named state, the estimator contract, files."""

from __future__ import annotations

import ast
import itertools
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from sklearn.base import clone
from sklearn.exceptions import NotFittedError as SklearnNotFitted
from sklearn.utils.validation import check_is_fitted

import piezohyst as ph
from piezohyst.simulation import make_signal

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
pytestmark = [
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
]

FS = 1000.0
FIXTURES = Path(__file__).parent.parent / "fixtures" / "schema1"


class TimeSquared(ph.Term):
    """A growth term defined here alone: charge growing with the square of elapsed time."""

    kind = "time_squared_test"
    removed = True
    rate_dependent = True
    state_names: ClassVar[tuple[str, ...]] = ("elapsed",)

    def columns(
        self, x: np.ndarray, t: np.ndarray | None, dt: np.ndarray | None, state: np.ndarray
    ) -> np.ndarray:
        assert dt is not None
        elapsed = state[0] + np.cumsum(dt)
        state[0] = elapsed[-1]
        return (elapsed**2)[:, None]

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        return (f"{output_unit}/s^2",)


class Wobble(ph.Term):
    """A kept term the compensator cannot invert (neither a static shape nor lags)."""

    kind = "wobble_test"
    input_degree = 1

    def columns(
        self, x: np.ndarray, t: np.ndarray | None, dt: np.ndarray | None, state: np.ndarray
    ) -> np.ndarray:
        return np.sin(x)[:, None]


@pytest.fixture(scope="module")
def record() -> Any:
    return ph.simulate(signal="levels", duration=8.0, seed=2)


# ------------------------------------------------------------------ custom terms
def test_a_term_written_in_a_test_file_fits_saves_and_loads(record: Any, tmp_path: Path) -> None:
    t, v = record.t, record.voltage
    truth = ph.PIModel.from_operator(
        ph.PIHysteresis([0.0, 20.0, 40.0], [1e-8, 4e-9, -2e-9], 1e-8, np.full(3, v[0])),
        terms=(ph.terms.Integral(), TimeSquared()),
        coefficients=([6e-10], [3e-10]),
    )
    q = truth.predict(v, t=t)
    model = ph.PIModel(thresholds=[0.0, 20.0, 40.0], terms=("integral", TimeSquared())).fit(
        v, q, t=t
    )
    assert model.nrmse_ < 1e-9
    value, unit = model.coefficients()["time_squared_test"]
    # tol: an identifiable problem fitted exactly: coefficients to the solve's rounding times its
    # conditioning
    assert value == pytest.approx(3e-10, rel=1e-6) and unit == "C/s^2"
    assert model.growth_coefficients().keys() == {"integral", "time_squared_test"}
    # tol: the fitted growth against the truth: the coefficients' 1e-6, on outputs of ~1e-6 C
    np.testing.assert_allclose(model.growth(v, t=t), truth.growth(v, t=t), rtol=1e-6, atol=1e-16)
    path = tmp_path / "custom.json"
    model.save(path)
    loaded = ph.load_model(path)
    assert isinstance(loaded, ph.PIModel)
    np.testing.assert_array_equal(loaded.predict(v, t=t), model.predict(v, t=t))
    # the growth term is removed before compensating: the analytic inverse applies
    comp = ph.Compensator(loaded, v_min=0.0, v_max=140.0)
    assert comp.analytic


def test_a_kept_term_nothing_can_invert_is_refused_clearly(record: Any) -> None:
    model = ph.PIModel(6, terms=(Wobble(),)).fit(record.voltage, record.charge)
    with pytest.raises(ph.ParameterError, match=r"'wobble_test' term .* cannot be inverted"):
        ph.Compensator(model, v_min=0.0, v_max=140.0)
    with pytest.raises(ph.ParameterError, match="wobble_test"):
        model.inverse()


def test_unknown_and_repeated_terms() -> None:
    v = np.linspace(0, 100, 300)
    with pytest.raises(ph.ParameterError, match="unknown term 'nope'"):
        ph.PIModel(4, terms=("nope",)).fit(v, v)
    with pytest.raises(ph.ParameterError, match="must not repeat"):
        ph.PIModel(4, terms=("time", "time")).fit(v, v, t=v)
    with pytest.raises(ph.ParameterError, match="sequence"):
        ph.PIModel(4, terms="integral").fit(v, v, t=v)  # type: ignore[arg-type]
    with pytest.raises(ph.TimeAxisError, match="needs the sample times"):
        ph.PIModel(4, terms=("integral",)).fit(v, v)


# -------------------------------------------------------- one model, one path
@pytest.mark.heavy
@given(seed=st.integers(0, 2**16))
def test_active_equals_generalized_with_only_the_integral(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t, v = make_signal("multi", duration=2.0, rate=FS)
    q = 1e-8 * v + 3e-10 * np.cumsum(v) / FS + 1e-9 * rng.standard_normal(v.size)
    act = ph.ActivePI(6).fit(v, q, t=t)
    gen = ph.GeneralizedPI(6, growth_terms=("integral",), asymmetry=0, creep=()).fit(v, q, t=t)
    np.testing.assert_array_equal(gen.predict(v, t=t), act.predict(v, t=t))
    np.testing.assert_array_equal(gen.weights_, act.weights_)
    assert gen.growth_coefs_[0] == act.growth_rate_
    desired = act.hysteresis_.predict(v) * 0.9 + 0.1 * float(np.mean(q))
    ca = ph.Compensator(act, v_min=0.0, v_max=140.0)
    cg = ph.Compensator(gen, v_min=0.0, v_max=140.0)
    assert ca.analytic and cg.analytic  # the method follows the terms, not the class
    np.testing.assert_array_equal(cg.process(desired), ca.process(desired))


@pytest.mark.parametrize("which", ["fixture", "ten cycles"])
def test_selection_scores_from_matrices_equal_refits(record: Any, which: str) -> None:
    """The fold scores of 'auto' equal fitting each subset on the record up to a fold's
    start and predicting the fold (forward chaining: 40 % trains, then folds of cycles)."""
    rec = record if which == "fixture" else ph.simulate(duration=10.0)
    v, q, t = rec.voltage, rec.charge, rec.t
    auto = ph.GeneralizedPI(6, asymmetry=2).fit(v, q, t=t)
    n = v.size
    edges = auto.selection_splits_
    assert edges[-1] == n
    # few reversals after the start: one test block, the last 30 %; many: folds of cycles
    assert len(edges) == (2 if which == "fixture" else 4)
    first = edges[0]
    assert set(auto.selection_) == set(auto.selection_folds_)
    for label, score in auto.selection_.items():
        terms = () if label == "none" else tuple(label.split("+"))
        folds = auto.selection_folds_[label]
        assert len(folds) == len(edges) - 1
        sse = 0.0
        for f, (a, b) in enumerate(itertools.pairwise(edges)):
            part = ph.GeneralizedPI(
                thresholds=auto.thresholds_, growth_terms=terms, asymmetry=2
            ).fit(v[:a], q[:a], t=t[:a])
            # the part fit binds knots and min_slope to its own data; give it the same knots
            part_terms = list(auto.terms_[:1]) + [tm for tm in part.terms_ if tm.removed]
            refit = ph.PIModel(thresholds=auto.thresholds_, terms=part_terms).fit(
                v[:a], q[:a], t=t[:a]
            )
            r = refit.predict(v, t=t)[a:b] - q[a:b]
            # tol: the refit's smallest-slope bound comes from its own part of the record, the
            # matrices' from the whole: where the bound is active the scores part by a few percent
            assert folds[f] == pytest.approx(float(np.sqrt(np.mean(r**2))), rel=3e-2), label
            sse += float(r @ r)
        # tol: the pooled score, as the folds above
        assert score == pytest.approx(np.sqrt(sse / (n - first)), rel=3e-2), label
    best = min(auto.selection_, key=auto.selection_.__getitem__)
    assert auto.selection_["+".join(auto.growth_terms_) or "none"] <= 1.001 * auto.selection_[best]


# ---------------------------------------------------------------- state
def test_named_state_round_trips_and_continues(record: Any) -> None:
    v, q, t = record.voltage, record.charge, record.t
    model = ph.GeneralizedPI(6, growth_terms=("integral", "time"), creep=(0.5,)).fit(v, q, t=t)
    assert model.state_names() == (
        ("up[0]",) * 0 or (),
        ("lag[0.5 s]",),
        ("integral",),
        ("elapsed",),
    )
    k = 3000
    first = model.propagate(v[:k], t=t[:k])
    saved = ph.ModelState.from_dict(json.loads(json.dumps(first.state.to_dict())))
    assert saved.t_last == t[k - 1]
    rest = model.predict(v[k:], t=t[k:], state=saved)
    # tol: the state through JSON is exact (repr); the split only reorders rounding
    np.testing.assert_allclose(rest, model.predict(v, t=t)[k:], rtol=1e-12, atol=1e-18)
    after = model.state_after(v[:k], t=t[:k])
    np.testing.assert_array_equal(after.operators, first.state.operators)
    with pytest.raises(ph.TimeAxisError, match="continue after"):
        model.propagate(v[:10], t=t[:10], state=saved)
    with pytest.raises(ph.ShapeError, match="does not match"):
        model.propagate(v[:10], t=t[:10], state=ph.ModelState(np.zeros(6)))


@pytest.mark.parametrize("name", ["classical-pi", "active-pi", "generalized-pi"])
def test_a_model_at_rest_stays_at_rest(name: str, record: Any) -> None:
    """Constant input from the rest state: the hysteresis part never moves."""
    model = ph.model.presets.model_class(name)(6).fit(record.voltage, record.charge, t=record.t)
    for x0 in (0.0, 55.5, 140.0):
        n = 500
        t = np.arange(n) / FS
        state = model.rest_state(x0)
        out = model.predict(np.full(n, x0), t=t, state=state) - model.growth(
            np.full(n, x0), t=t, state=state
        )
        # tol: a hold: the output changes by its rounding only
        np.testing.assert_allclose(out, out[0], rtol=0, atol=1e-12 * abs(out[0]) + 1e-24)


def test_inputs_are_never_written(record: Any) -> None:
    v = record.voltage.copy()
    q = record.charge.copy()
    t = record.t.copy()
    for arr in (v, q, t):
        arr.flags.writeable = False
    model = ph.GeneralizedPI(6, creep=(0.2,)).fit(v, q, t=t)
    state = model.propagate(v[:100], t=t[:100]).state
    ops = state.operators.copy()
    model.predict(v[100:], t=t[100:], state=state)
    model.growth(v, t=t)
    model.remove_growth(v, q, t=t)
    model.score(v, q, t=t)
    np.testing.assert_array_equal(state.operators, ops)  # a passed state is not mutated
    desired = model.hysteresis_.predict(v, t=t)
    desired.flags.writeable = False
    ph.Compensator(model, v_min=0.0, v_max=140.0, sample_rate=FS).process(desired)
    np.testing.assert_array_equal(v, record.voltage)
    np.testing.assert_array_equal(q, record.charge)


# ------------------------------------------------------- estimator contract
def test_scikit_learn_contract(record: Any) -> None:
    v, q, t = record.voltage, record.charge, record.t
    for est in (
        ph.ClassicalPI(5),
        ph.ActivePI(5, min_slope=1e-2),
        ph.GeneralizedPI(5, creep=(1.0,)),
    ):
        params = est.get_params(deep=True)
        assert params == est.get_params(deep=False)
        fresh = clone(est)
        assert fresh.get_params() == params and fresh is not est
        est.fit(v, q, t=t)
        unfitted = clone(est)  # cloning a fitted model gives an unfitted twin
        assert not unfitted.is_fitted and unfitted.get_params() == params
        # scikit-learn's own check (it asks for __sklearn_tags__ since 1.6: failed before)
        check_is_fitted(est)
        with pytest.raises(SklearnNotFitted):
            check_is_fitted(unfitted)
        assert est.__sklearn_tags__().estimator_type == "regressor"
        with pytest.raises(ph.NotFittedError):
            unfitted.predict(v, t=t)
        assert unfitted.fit(v, q, t=t).score(v, q, t=t) == est.score(v, q, t=t)
        assert 0.9 < est.score(v, q, t=t) <= 1.0
    model = ph.ActivePI(5).set_params(n_operators=7, output_unit="uC")
    assert model.n_operators == 7 and model.output_unit == "uC"
    with pytest.raises(ph.ParameterError, match="Invalid parameter 'n_operator'"):
        model.set_params(n_operator=3)
    with pytest.raises(TypeError):
        ph.ActivePI(5, None)  # type: ignore[misc]  # settings after the first are keyword-only
    assert repr(ph.GeneralizedPI(5, creep=(1.0,))) == "GeneralizedPI(n_operators=5, creep=(1.0,))"


def test_score_is_r2() -> None:
    _t, v = make_signal("fixed", duration=2.0, rate=FS)
    h = ph.PIHysteresis([0.0, 30.0], [1.0, 0.5])
    y = h.predict(v)
    model = ph.ClassicalPI(thresholds=[0.0, 30.0]).fit(v, y)
    # tol: the same formula as scikit-learn's R^2, summed in another order
    assert model.score(v, y) == pytest.approx(1.0, abs=1e-12)
    noise = np.random.default_rng(0).standard_normal(v.size)
    noisy = y + noise
    expected = 1 - np.sum((noisy - model.predict(v)) ** 2) / np.sum((noisy - noisy.mean()) ** 2)
    # tol: the same formula as scikit-learn's R^2, summed in another order
    assert model.score(v, noisy) == pytest.approx(expected, rel=1e-12)


# ----------------------------------------------------------------- files
@pytest.mark.parametrize("name", ["classical", "active", "generalized"])
def test_files_written_by_0_1_0_load_and_predict_identically(name: str) -> None:
    expected = json.loads((FIXTURES / "expected.json").read_text())
    t, v = np.array(expected["t"]), np.array(expected["v"])
    model = ph.load_model(FIXTURES / f"{name}.json")
    assert type(model).__name__ == json.loads((FIXTURES / f"{name}.json").read_text())["model"]
    want = np.array(expected[name])
    # tol: files written by 0.1.0: predictions to rounding, which another CPU or BLAS may do apart
    np.testing.assert_allclose(model.predict(v, t=t), want, rtol=0, atol=1e-12 * np.ptp(want))
    p = model.predict(v, t=t)
    comp = ph.Compensator(model, v_min=0.0, v_max=140.0, sample_rate=250.0)
    commands = comp.process(p * 0.95 + 0.05 * p.mean())
    # tol: commands to Newton's stop and rounding, replayed over the record
    np.testing.assert_allclose(commands, expected[name + "_commands"], rtol=0, atol=1e-9)


SCHEMA2 = FIXTURES.parent / "schema2"
KINDS_OF_TODAY = sorted(p.stem for p in SCHEMA2.glob("*.json") if p.stem != "expected")


@pytest.mark.parametrize("name", KINDS_OF_TODAY)
def test_files_of_every_kind_load_predict_and_compensate_as_written(
    name: str, tmp_path: Path
) -> None:
    """Model files of every kind, written before the core protocol's rewrite
    (``schema2/make_fixtures.py``), mean what they meant: the same predictions, the same
    compensator commands, and a file round trip that changes nothing."""
    expected = json.loads((SCHEMA2 / "expected.json").read_text())[name]
    v = np.array(expected["v"])
    t = np.arange(v.size) / 250.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ph.ExtrapolationWarning)
        model = ph.load_model(SCHEMA2 / f"{name}.json")
        want = np.array(expected["predicted"])
        # tol: the file's numbers, predicted again: rounding, which another CPU or BLAS may do
        # apart (1e-12 of the span)
        np.testing.assert_allclose(model.predict(v, t=t), want, rtol=0, atol=1e-12 * np.ptp(want))
        lo, hi = model.input_range_
        comp = ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=250.0)
        # tol: commands to Newton's stop (1e-12 of a step) and rounding, replayed over the
        # trajectory: 1e-9 of the voltage range
        np.testing.assert_allclose(
            comp.process(np.array(expected["desired"])),
            expected["commands"],
            rtol=0,
            atol=1e-9 * (hi - lo),
        )
        model.save(tmp_path / "again.json")
        back = ph.load_model(tmp_path / "again.json")
        np.testing.assert_array_equal(back.predict(v, t=t), model.predict(v, t=t))


def test_files_honour_the_umask(record: Any, tmp_path: Path) -> None:
    model = ph.ClassicalPI(4).fit(record.voltage, record.charge)
    old = os.umask(0o022)
    try:
        model.save(tmp_path / "shared.json")
        ph.write_table(tmp_path / "t.csv", {"a": [1.0, 2.0]})
        os.umask(0o077)
        model.save(tmp_path / "private.json")
    finally:
        os.umask(old)
    assert (tmp_path / "shared.json").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "t.csv").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "private.json").stat().st_mode & 0o777 == 0o600


# ----------------------------------------------------------------- layering
def test_every_package_and_module_has_a_place_in_the_import_contract() -> None:
    """`lint-imports` (make lint) checks the layers in pyproject.toml, exhaustively: each
    package and module at the top of piezohyst is in one layer, and the layers read as the
    folder listing does."""
    import re
    import tomllib

    root = Path(ph.__file__).parents[2]
    config = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = config["contracts"]
    assert contract["containers"] == ["piezohyst"] and contract["exhaustive"] is True
    placed = {m.strip() for layer in contract["layers"] for m in re.split(r"[|:]", layer)}
    src = Path(ph.__file__).parent
    tops = {p.stem for p in src.glob("*.py") if p.stem != "__init__"}
    tops |= {p.name for p in src.iterdir() if (p / "__init__.py").exists()}
    assert tops == placed
    assert len([p for p in src.glob("*.py") if p.stem != "__init__"]) <= 12
    assert len([p for p in src.iterdir() if (p / "__init__.py").exists()]) >= 6


def test_every_setting_has_one_declared_rule() -> None:
    for cls in (ph.ClassicalPI, ph.ActivePI, ph.GeneralizedPI, ph.PIModel, ph.PreisachModel,
                ph.DuhemModel, ph.BoucWenModel, ph.HysteresisModel):  # fmt: skip
        rules = cls.parameter_rules()
        assert set(rules) == set(cls().get_params()), cls.__name__
        for name, value in cls().get_params().items():
            rules[name](value, name, cls.__name__)  # the defaults pass their own rules
    bad = [
        (ph.ActivePI(0), "'n_operators' parameter of ActivePI must be an int in \\[1, 1000\\]"),
        (ph.ActivePI(min_slope=0.0), "'min_slope'"),
        (ph.ActivePI(output_unit=""), "'output_unit'"),
        (ph.GeneralizedPI(creep="1"), "'creep'"),  # type: ignore[arg-type]
        (ph.GeneralizedPI(growth_terms=("leak",)), "'growth_terms'"),
        (ph.PIModel(terms=("time", "time")), "must not repeat"),
    ]
    v = np.linspace(0.0, 100.0, 200)
    for model, match in bad:
        with pytest.raises(ph.ParameterError, match=match):
            model.fit(v, v, t=v)


CONSUMERS = [
    "control/compensator", "control/export/c_code", "workflows/model_files", "workflows/demo",
    "cli/_models", "cli/_compensate", "cli/_report", "cli/_loop", "cli/_records",
    "model/persistence", "plotting", "analysis/report",
]  # fmt: skip
MODEL_CLASSES = {"HysteresisModel", "ClassicalPI", "ActivePI", "GeneralizedPI", "PIModel"}


def test_consumers_use_public_methods_and_never_branch_on_model_class() -> None:
    src = Path(ph.__file__).parent
    for module in CONSUMERS:
        tree = ast.parse((src / f"{module}.py").read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_"):
                owner = node.value.id if isinstance(node.value, ast.Name) else ""
                private = not node.attr.startswith("__")
                assert not private or owner in {"self", "cls", "K"}, (
                    f"{module}.py:{node.lineno} reads {owner or '...'}.{node.attr}"
                )
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "isinstance":
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                assert not names & MODEL_CLASSES, f"{module}.py:{node.lineno} branches on a class"


def test_an_active_model_built_without_its_integral_has_no_leakage() -> None:
    model = ph.ActivePI.from_operator(ph.PIHysteresis([0.0, 10.0], [1.0, 0.5]))
    assert model.growth_rate_ == 0.0
    np.testing.assert_array_equal(model.growth([1.0, 2.0], t=[0.0, 1.0]), [0.0, 0.0])


def test_import_loads_no_heavy_library() -> None:
    """``import piezohyst`` stays light: numba loads when a model first runs, the file,
    plotting, cluster, CLI and state-space libraries when a feature needs them."""
    heavy = ["numba", "scipy", "matplotlib", "dask", "pyarrow", "pint", "h5py", "nptdms",
             "click", "rich", "control"]  # fmt: skip
    probe = f"import sys, piezohyst; print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    # and the first model run loads the kernels it needs
    run = (
        "import sys, numpy as np, piezohyst as ph; "
        "ph.PIHysteresis([0.0], [1.0]).predict(np.zeros(3)); print('numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", run], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"
