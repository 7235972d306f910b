"""Play operators and the PI operator: kernels against the reference, and properties."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst._kernels import play as K

from .. import reference
from ..strategies import invertible_pi, signals, thresholds

pytestmark = pytest.mark.kernels


@given(x=signals(), r=thresholds(), y0=st.floats(-300, 300))
def test_play_kernel_matches_reference(x: np.ndarray, r: np.ndarray, y0: float) -> None:
    z = np.full(r.size, y0)
    out = np.empty((x.size, r.size))
    K.play_states(x, r, z, out)
    for i, ri in enumerate(r):
        np.testing.assert_array_equal(out[:, i], reference.play(x.tolist(), ri, y0))
    np.testing.assert_array_equal(z, out[-1])


@given(x=signals(), h=invertible_pi())
def test_pi_kernel_matches_reference(x: np.ndarray, h: ph.PIHysteresis) -> None:
    expected = reference.classical_pi(
        x.tolist(), h.thresholds.tolist(), h.weights.tolist(), h.initial_state.tolist(), h.offset
    )
    # tol: the kernel against the pure-Python reference sums the same terms in another order (values
    # up to ~1e4)
    np.testing.assert_allclose(h.predict(x), expected, rtol=1e-12, atol=1e-9)


@given(a=signals(2, 200), b=signals(2, 200), r=st.floats(0, 50), y0=st.floats(-100, 100))
def test_play_is_one_lipschitz(a: np.ndarray, b: np.ndarray, r: float, y0: float) -> None:
    n = min(a.size, b.size)
    a, b = a[:n], b[:n]
    h = ph.PIHysteresis([0.0, r + 1e-9], [0.0, 1.0], initial_state=[y0, y0])
    za = h.predict(a)
    zb = h.predict(b)
    # sup-norm Lipschitz: |H[a] - H[b]|_inf <= |a - b|_inf on every prefix
    gap = np.maximum.accumulate(np.abs(a - b))
    assert np.all(np.abs(za - zb) <= gap + 1e-9)


@given(x=signals(2, 100), h=invertible_pi(), reps=st.lists(st.integers(1, 4), min_size=1))
def test_classical_pi_is_rate_independent(
    x: np.ndarray, h: ph.PIHysteresis, reps: list[int]
) -> None:
    """Holding samples longer (a slower time axis) changes nothing at the kept samples."""
    counts = np.resize(np.asarray(reps), x.size)
    slow = np.repeat(x, counts)
    keep = np.cumsum(counts) - 1
    # tol: repeated samples repeat the same clamps on the same values: rounding of the weighted sum
    np.testing.assert_allclose(h.predict(slow)[keep], h.predict(x), rtol=0, atol=1e-12)
    # and inserting monotone intermediate points between samples changes nothing either
    mid = np.empty(2 * x.size - 1)
    mid[0::2] = x
    mid[1::2] = 0.5 * (x[:-1] + x[1:])
    # tol: a midpoint adds one rounding of the input per sample, weighted by |w|: 1e-9
    np.testing.assert_allclose(h.predict(mid)[0::2], h.predict(x), rtol=0, atol=1e-9)


@given(x=signals(1, 100), h=invertible_pi(), lo=st.floats(-700, -600), hi=st.floats(600, 700))
def test_wiping_out(x: np.ndarray, h: ph.PIHysteresis, lo: float, hi: float) -> None:
    """After a swing wider than every threshold, earlier history is forgotten.

    Inputs stay in [-200, 200] and thresholds below 280, so a swing to +-600
    sets every operator to a state that depends on the swing alone.
    """
    other = x[::-1] * 0.3
    swing = np.array([hi, lo])
    tail = np.linspace(lo, hi, 7)
    ya = h.predict(np.concatenate([x, swing, tail]))[-tail.size :]
    yb = h.predict(np.concatenate([other, swing, tail]))[-tail.size :]
    # tol: after the swing both runs hold the same states up to rounding of the clamps
    np.testing.assert_allclose(ya, yb, rtol=0, atol=1e-9)


@given(x=signals(2, 300), h=invertible_pi(), cut=st.lists(st.integers(0, 300), max_size=4))
def test_chunks_equal_one_call(x: np.ndarray, h: ph.PIHysteresis, cut: list[int]) -> None:
    whole = h.propagate(x)
    parts = []
    state = None
    for chunk in np.split(x, sorted(c % x.size for c in cut)):  # empty chunks included
        res = h.propagate(chunk, state)
        parts.append(res.output)
        state = res.state
    # tol: chunks against one call: the same clamps, rounding only in the weighted sum
    np.testing.assert_allclose(np.concatenate(parts), whole.output, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(state, whole.state)


@given(x=signals(1, 300), h=invertible_pi())
def test_inverse_identity(x: np.ndarray, h: ph.PIHysteresis) -> None:
    """inverse().predict(predict(x)) == x to 1e-9 of the input range (eq. 18)."""
    y = h.predict(x)
    back = h.inverse().predict(y)
    scale = max(float(np.ptp(x)), 1.0)
    # tol: eq. 18's inverse composed with the forward: rounding of weight products (weights to 5,
    # thresholds to 280)
    np.testing.assert_allclose(back, x, rtol=0, atol=1e-9 * scale)


@given(h=invertible_pi())
def test_inverse_of_inverse_is_original(h: ph.PIHysteresis) -> None:
    again = h.inverse().inverse()
    # tol: eq. 18 applied twice: rounding of its sums and ratios
    np.testing.assert_allclose(again.thresholds, h.thresholds, atol=1e-9)
    np.testing.assert_allclose(again.weights, h.weights, atol=1e-9)
    np.testing.assert_allclose(again.offset, h.offset, atol=1e-9)
    np.testing.assert_allclose(again.initial_state, h.initial_state, atol=1e-9)


@given(x=signals(2, 200), h=invertible_pi(), k=st.integers(1, 199))
def test_inverse_state_continues_mid_signal(x: np.ndarray, h: ph.PIHysteresis, k: int) -> None:
    k = 1 + k % (x.size - 1)
    first = h.propagate(x[:k])
    y = h.predict(x[k:], first.state)
    back = h.inverse().predict(y, h.inverse_state(first.state))
    # tol: as test_inverse_identity, from a state mid-signal
    np.testing.assert_allclose(back, x[k:], rtol=0, atol=1e-9 * max(float(np.ptp(x)), 1.0))


@given(h=invertible_pi())
def test_inverse_parameters_match_paper_eq18(h: ph.PIHysteresis) -> None:
    r_inv, w_inv = reference.inverse_parameters(h.thresholds.tolist(), h.weights.tolist())
    inv = h.inverse()
    # tol: eq. 18 written out by hand in Python: the same formula, summed apart
    np.testing.assert_allclose(inv.thresholds, r_inv, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(inv.weights, w_inv, rtol=1e-12, atol=1e-15)


def test_hand_worked_play() -> None:
    # r = 1 from y0 = 0: x = 0, 2, 1.5, 0, -1 -> 0, 1, 1, 1, 0
    assert reference.play([0, 2, 1.5, 0, -1], 1.0, 0.0) == [0, 1, 1, 1, 0]
    h = ph.PIHysteresis([0.0, 1.0], [0.0, 1.0])
    assert h.predict([0, 2, 1.5, 0, -1]).tolist() == [0, 1, 1, 1, 0]
    # eq. 10: the first sample clamps the initial state into [x0 - r, x0 + r]
    h = ph.PIHysteresis([0.0, 1.0], [0.0, 1.0], initial_state=[0.0, 5.0])
    assert h.predict([2.0]).tolist() == [3.0]


def test_hand_worked_inverse() -> None:
    # r = [0, 1], w = [1, 0.5]: r' = [0, 1], w' = [1, -0.5 / (1.5 * 1)] = [1, -1/3]
    h = ph.PIHysteresis([0.0, 1.0], [1.0, 0.5])
    inv = h.inverse()
    np.testing.assert_allclose(inv.thresholds, [0.0, 1.0])
    np.testing.assert_allclose(inv.weights, [1.0, -1.0 / 3.0])
    # y = 0, 2.5, 0.5 (see the PIHysteresis doctest) maps back to x = 0, 2, 0
    np.testing.assert_allclose(inv.predict([0.0, 2.5, 0.5]), [0.0, 2.0, 0.0], atol=1e-15)


def test_not_invertible_is_refused() -> None:
    h = ph.PIHysteresis([0.0, 1.0, 2.0], [1.0, -0.6, -0.6])  # slopes 1, 0.4, -0.2
    assert not h.is_invertible
    with pytest.raises(ph.NotInvertibleError, match=r"operator 2 is -0\.2"):
        h.inverse()


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"thresholds": [0.0, 1.0], "weights": [1.0]}, ph.ShapeError, "same length"),
        ({"thresholds": [0.5, 1.0], "weights": [1.0, 1.0]}, ph.ParameterError, "start at 0"),
        ({"thresholds": [0.0, 2.0, 1.0], "weights": [1, 1, 1]}, ph.ParameterError, "increasing"),
        ({"thresholds": [0.0], "weights": [np.nan]}, ph.NonFiniteError, "finite"),
    ],
)
def test_operator_checks(kwargs: dict[str, object], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        ph.PIHysteresis(**kwargs)  # type: ignore[arg-type]
