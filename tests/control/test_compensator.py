"""The streaming compensator: equals the analytic inverse inside the limits, safe outside."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import piezohyst as ph

from ..strategies import invertible_pi

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
# generated signals hold one-sample jumps, which the record check names (test_records.py)
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.RecordWarning"),
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
]

V_MIN, V_MAX = -20.0, 160.0
wild = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-500.0, 500.0),
    st.floats(-500.0, 500.0),
)


def compensator(h: ph.PIHysteresis, **kwargs: object) -> ph.Compensator:
    return ph.Compensator(ph.ClassicalPI.from_operator(h), v_min=V_MIN, v_max=V_MAX, **kwargs)  # type: ignore[arg-type]


@st.composite
def rest_model(draw: st.DrawFn) -> ph.PIHysteresis:
    """An invertible PI model whose initial state lies inside the limits."""
    h = draw(invertible_pi())
    x0 = draw(st.floats(V_MIN, V_MAX))
    return ph.PIHysteresis(h.thresholds, h.weights, h.offset, np.full(h.n_operators, x0))


@given(
    h=rest_model(), x=hnp.arrays(np.float64, st.integers(1, 200), elements=st.floats(V_MIN, V_MAX))
)
def test_inside_limits_equals_analytic_inverse(h: ph.PIHysteresis, x: np.ndarray) -> None:
    desired = h.predict(x)
    cmd = compensator(h).process(desired)
    # tol: the streaming kernel against eq. 18's inverse: a few roundings of |w| * range per sample;
    # 1e-9 of the range is far above them, far below a wrong branch
    np.testing.assert_allclose(
        cmd, h.inverse().predict(desired), rtol=0, atol=1e-9 * (V_MAX - V_MIN)
    )
    np.testing.assert_allclose(cmd, x, rtol=0, atol=1e-9 * (V_MAX - V_MIN))


@given(
    h=rest_model(),
    d=hnp.arrays(np.float64, st.integers(1, 200), elements=wild),
    slew=st.one_of(st.none(), st.floats(10.0, 1e5)),
)
def test_always_safe_and_exact_where_no_limit_acts(
    h: ph.PIHysteresis, d: np.ndarray, slew: float | None
) -> None:
    kwargs = {} if slew is None else {"slew_rate": slew, "sample_rate": 1000.0}
    comp = compensator(h, **kwargs)
    start = comp.state.command
    cmd = comp.process(d)
    assert np.all(np.isfinite(cmd)) and cmd.min() >= V_MIN and cmd.max() <= V_MAX
    if slew is not None:
        steps = np.abs(np.diff(np.concatenate([[start], cmd])))
        assert steps.max() <= slew / 1000.0 * (1 + 1e-12) + 1e-12
    # the forward model driven by the commands reproduces every finite desired value
    # that needed no limit: the compensator's state tracks what the actuator received
    achieved = h.predict(cmd)
    free = np.isfinite(d) & (cmd > V_MIN) & (cmd < V_MAX)
    if slew is not None:
        free &= np.abs(np.diff(np.concatenate([[start], cmd]))) < slew / 1000.0 * (1 - 1e-9)
    scale = np.abs(h.weights).sum() * (V_MAX - V_MIN) + 1.0
    # tol: forward(compensate(d)) == d: rounding of the output scale |w| * range per sample, no
    # accumulation (play states are clamps)
    np.testing.assert_allclose(achieved[free], d[free], rtol=0, atol=1e-9 * scale)
    assert comp.nonfinite_count == int(np.count_nonzero(~np.isfinite(d)))


@given(
    h=rest_model(),
    d=hnp.arrays(np.float64, st.integers(2, 200), elements=wild),
    cuts=st.lists(st.integers(0, 200), max_size=5),
)
def test_chunks_and_steps_equal_one_batch(
    h: ph.PIHysteresis, d: np.ndarray, cuts: list[int]
) -> None:
    whole = compensator(h, slew_rate=5e4, sample_rate=1e3).process(d)
    chunked = compensator(h, slew_rate=5e4, sample_rate=1e3)
    parts = np.concatenate(
        [chunked.process(c) for c in np.split(d, sorted(x % d.size for x in cuts))]
    )
    stepper = compensator(h, slew_rate=5e4, sample_rate=1e3)
    stepped = np.array([stepper.step(v) for v in d])
    # the block and step kernels are compiled apart with reassociation and FMA contraction
    # allowed (FASTMATH), so they may round differently: an ulp of the voltage range per
    # operation, a few operations per sample, and a play state is a clamp of the input (it
    # carries no accumulated error): 64 ulp of the range bounds every sample
    ulp = 64 * np.spacing(V_MAX - V_MIN)
    # tol: the same 64 ulp, for every output of the three paths
    np.testing.assert_allclose(parts, whole, rtol=0, atol=ulp)
    np.testing.assert_allclose(stepped, whole, rtol=0, atol=ulp)
    # tol: the same 64 ulp
    np.testing.assert_allclose(chunked.state.operators, stepper.state.operators, rtol=0, atol=ulp)
    assert abs(chunked.state.command - stepper.state.command) <= ulp


def test_nan_holds_and_saturation_counts() -> None:
    h = ph.PIHysteresis([0.0, 10.0], [1.0, 0.5])
    comp = compensator(h)
    first = comp.step(30.0)
    assert comp.step(float("nan")) == first and comp.step(float("-inf")) == first
    assert comp.nonfinite_count == 2
    assert comp.step(1e9) == V_MAX and comp.step(-1e9) == V_MIN
    assert comp.saturated_count == 2
    comp.reset()
    assert comp.nonfinite_count == 0 and comp.saturated_count == 0


def test_active_model_drops_the_growth_and_displacement_domain() -> None:
    t = np.arange(4000) / 1000.0
    v = 70 * (1 - np.cos(2 * np.pi * 0.5 * t))
    h = ph.PIHysteresis(
        ph.default_thresholds(v, 5), [1e-8, 2e-9, 1e-9, -1e-9, -5e-10], 0.0, np.zeros(5)
    )
    q = h.predict(v) + 1e-9 * np.cumsum(v) / 1000.0
    act = ph.ActivePI(thresholds=h.thresholds).fit(v, q, t=t)
    gain = 125.0  # m/C
    comp = ph.Compensator(act, v_min=0.0, v_max=140.0, domain="displacement", gain=gain)
    displacement = gain * (h.predict(v) - h.predict([0.0])[0])
    # tol: a model fitted on noise-free data reproduces its record to micro-volts (the fit's
    # conditioning); a wrong inverse is off by volts
    np.testing.assert_allclose(comp.process(displacement), v, atol=1e-6)


def test_reset_projects_onto_a_voltage_and_restores_a_state() -> None:
    h = ph.PIHysteresis([0.0, 10.0, 30.0], [1.0, 0.5, -0.2])
    comp = compensator(h)
    comp.process(h.predict(np.array([0.0, 100.0, 40.0])))
    saved = comp.state
    after = comp.process(h.predict(np.array([60.0])))
    comp.reset(saved)
    np.testing.assert_array_equal(comp.process(h.predict(np.array([60.0]))), after)
    comp.reset(voltage=50.0)
    # eq. 10: the initial state 0 clamped into [50 - r, 50 + r] for r = 0, 10, 30
    np.testing.assert_allclose(comp.state.operators, [50.0, 40.0, 20.0])
    assert comp.state.command == 50.0
    with pytest.raises(ph.ParameterError, match="outside the limits"):
        comp.reset(voltage=500.0)
    with pytest.raises(ph.ShapeError):
        comp.reset([1.0, 2.0])


def test_precondition_wipes_history() -> None:
    h = ph.PIHysteresis([0.0, 10.0, 30.0], [1.0, 0.5, -0.2])
    a, b = compensator(h), compensator(h)
    a.process(h.predict(np.array([0.0, 120.0, 30.0])))
    b.process(h.predict(np.array([0.0, 5.0])))
    cycle_a = a.precondition(500)
    b.precondition(500)
    assert cycle_a.max() == V_MAX and cycle_a.min() == V_MIN
    # different histories, same final voltage: same state after the cycle
    a.reset(np.concatenate([a.state.operators, [30.0]]))
    b.reset(voltage=30.0)
    b.precondition(500)
    np.testing.assert_allclose(a.precondition(500)[-1], b.state.command)
    slow = compensator(h, slew_rate=100.0, sample_rate=1000.0)
    cyc = slow.precondition(10)
    assert cyc.max() == V_MAX and cyc.min() == V_MIN
    assert np.abs(np.diff(cyc)).max() <= 0.1 + 1e-12


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"v_min": 1.0, "v_max": 1.0}, "v_min < v_max"),
        ({"v_min": float("nan"), "v_max": 1.0}, "finite"),
        ({"v_min": 0.0, "v_max": 1.0, "slew_rate": 5.0}, "sample_rate"),
        ({"v_min": 0.0, "v_max": 1.0, "slew_rate": -5.0, "sample_rate": 1.0}, "> 0"),
        ({"v_min": 0.0, "v_max": 1.0, "domain": "position"}, "'charge' or 'displacement'"),
        ({"v_min": 0.0, "v_max": 1.0, "domain": "displacement"}, "needs the gain"),
    ],
)
def test_parameter_errors(kwargs: dict[str, object], match: str) -> None:
    model = ph.ClassicalPI.from_operator(ph.PIHysteresis([0.0], [1.0]))
    with pytest.raises(ph.ParameterError, match=match):
        ph.Compensator(model, **kwargs)  # type: ignore[arg-type]


def test_refuses_unfitted_and_non_invertible_models() -> None:
    with pytest.raises(ph.NotFittedError):
        ph.Compensator(ph.ClassicalPI(), v_min=0.0, v_max=1.0)
    bad = ph.ClassicalPI.from_operator(ph.PIHysteresis([0.0, 1.0], [1.0, -2.0]))
    with pytest.raises(ph.NotInvertibleError):
        ph.Compensator(bad, v_min=0.0, v_max=1.0)
