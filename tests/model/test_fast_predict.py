"""predict's one-call path equals the general path to rounding, and every input it cannot
vouch for goes the general way (same results, same errors)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import piezohyst as ph

from ..strategies import signals

# generated signals hold one-sample jumps, which the record check names (test_records.py)
# generated inputs reach past the training range: the paths must agree there too
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.ExtrapolationWarning"),
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.RecordWarning"),
]


@pytest.fixture(scope="module")
def models() -> dict[str, ph.HysteresisModel]:
    rng = np.random.default_rng(3)
    t = np.arange(4000) / 1e3
    v = 60.0 + 60.0 * np.sin(2 * np.pi * 1.3 * t) * np.exp(-t / 2.0) + rng.normal(0, 0.05, t.size)
    q = ph.PIHysteresis(np.linspace(0, 90, 6), np.r_[1e-8, np.full(5, 2e-9)]).predict(v)
    q = q + 3e-10 * np.cumsum(v) / 1e3 + 2e-9 * t + 5e-9
    return {
        "classical": ph.ClassicalPI(6).fit(v, q),
        "active": ph.ActivePI(6).fit(v, q, t=t),
        "time": ph.PIModel(6, terms=("time",)).fit(v, q, t=t),
    }


def _general(model: ph.HysteresisModel, x: np.ndarray, t: np.ndarray | None) -> np.ndarray:
    return model.propagate(x, t).output


@given(x=signals(min_size=1, max_size=400), step=st.floats(1e-4, 1.0))
def test_one_call_equals_the_general_path(
    models: dict[str, ph.HysteresisModel], x: np.ndarray, step: float
) -> None:
    t = 5.0 + step * np.arange(x.size)
    for name, model in models.items():
        tt = None if name == "classical" else t
        general = _general(model, x, tt)
        scale = float(np.max(np.abs(general)))
        # tol: the fast and the general path sum the same terms in another order: a few hundred ulp
        # of the output scale
        np.testing.assert_allclose(model.predict(x, t=tt), general, rtol=0, atol=1e-13 * scale)
        assert model.__dict__.get("_fast") is not None, name  # the one-call path ran
    # a rate-independent model given times checks them too
    classical = models["classical"]
    np.testing.assert_array_equal(classical.predict(x, t=t), _general(classical, x, None))


def test_bad_input_takes_the_checked_path(models: dict[str, ph.HysteresisModel]) -> None:
    active = models["active"]
    x = np.linspace(0.0, 50.0, 20)
    t = np.arange(20) / 1e3
    bad = x.copy()
    bad[7] = np.nan
    with pytest.raises(ph.NonFiniteError, match="index 7"):
        active.predict(bad, t=t)
    with pytest.raises(ph.NonFiniteError, match="index 7"):
        models["classical"].predict(bad)
    back = t.copy()
    back[12] = back[11]
    with pytest.raises(ph.TimeAxisError):
        active.predict(x, t=back)
    late = t.copy()
    late[0] = np.inf
    with pytest.raises(ph.NonFiniteError):
        active.predict(x, t=late)
    with pytest.raises(ph.TimeAxisError, match="needs the sample times"):
        active.predict(x)
    with pytest.raises(ph.ShapeError):
        active.predict(x, t=t[:5])
    # lists, other dtypes and explicit states go the general way and agree
    np.testing.assert_array_equal(active.predict(list(x), t=list(t)), active.predict(x, t=t))
    np.testing.assert_array_equal(
        active.predict(x.astype(np.float32), t=t), _general(active, x.astype(np.float32), t)
    )
    state = active.initial_state_.copy()  # operator states alone: the same start
    np.testing.assert_array_equal(active.predict(x, t=t, state=state), _general(active, x, t))
    assert active.predict(np.empty(0), t=np.empty(0)).size == 0


def test_new_parameters_are_used_at_once(models: dict[str, ph.HysteresisModel]) -> None:
    model = ph.ClassicalPI.from_operator(ph.PIHysteresis([0.0, 10.0], [1.0, 0.5]))
    x = np.array([0.0, 20.0, 5.0])
    before = model.predict(x)
    model.set_fitted(ph.PIHysteresis([0.0, 10.0], [2.0, 0.5]), (), ())
    after = model.predict(x)
    np.testing.assert_array_equal(after, _general(model, x, None))
    assert not np.array_equal(before, after)


@pytest.mark.parametrize("name", ["classical", "active"])
def test_a_read_only_or_strided_input_compiles_nothing_more(
    models: dict[str, ph.HysteresisModel], name: str
) -> None:
    """A column read zero-copy from a file is read-only, a record's column a strided view:
    the kernels take every input through one type (``_validation.frozen``), so neither
    compiles another specialization (about 2 s each at its first call), and the results are
    the same."""
    from numba.core.dispatcher import Dispatcher

    from piezohyst._kernels import play as K

    model = models[name]
    t = np.arange(500) / 1e3
    x = 60.0 + 50.0 * np.sin(2 * np.pi * 3.0 * t)
    want = model.predict(x, t=t)
    model.propagate(x, t)
    if not isinstance(K.pi_forward, Dispatcher):  # with the JIT off there is nothing to count
        return
    held = {k: len(getattr(K, k).signatures) for k in ("pi_forward", "fast_predict")}
    ro = x.copy()
    ro.flags.writeable = False
    record = np.stack([t, x], axis=1)  # x as a strided column
    for xs, ts in ((ro, t), (record[:, 1], record[:, 0])):
        np.testing.assert_array_equal(model.predict(xs, t=ts), want)
        model.propagate(xs, ts)
    assert {k: len(getattr(K, k).signatures) for k in held} == held
