"""Hypothesis strategies shared by the tests."""

from __future__ import annotations

import os

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from piezohyst import PIHysteresis

finite = st.floats(min_value=-200.0, max_value=200.0, allow_nan=False, allow_subnormal=False)


@st.composite
def signals(draw: st.DrawFn, min_size: int = 1, max_size: int = 300) -> np.ndarray:
    """Arbitrary finite input signals (V), jumps included."""
    return draw(hnp.arrays(np.float64, st.integers(min_size, max_size), elements=finite))


@st.composite
def thresholds(draw: st.DrawFn, max_n: int = 8) -> np.ndarray:
    """Strictly increasing thresholds starting at 0."""
    steps = draw(hnp.arrays(np.float64, st.integers(0, max_n - 1), elements=st.floats(0.5, 40.0)))
    return np.concatenate([[0.0], np.cumsum(steps)])


@st.composite
def invertible_pi(draw: st.DrawFn, max_n: int = 8) -> PIHysteresis:
    """PI operators meeting eq. 18's conditions, negative weights after the first allowed."""
    r = draw(thresholds(max_n))
    slopes = draw(hnp.arrays(np.float64, r.size, elements=st.floats(0.05, 5.0)))
    w = np.diff(slopes, prepend=0.0)
    offset = draw(st.floats(-50.0, 50.0))
    start = draw(st.floats(-100.0, 100.0))
    return PIHysteresis(r, w, offset, np.full(r.size, start))


def examples(n: int) -> int:
    """A test's own example count, scaled with the profile: as written under ``ci``, five
    times as many under ``dev`` (see ``conftest.py``)."""
    return n * 5 if os.environ.get("HYPOTHESIS_PROFILE") == "dev" else n


def random_structure(rng: np.random.Generator) -> tuple[np.ndarray, list[np.ndarray]]:
    """A structure of 1-3 states, 1-2 inputs and outputs, two actuators of two play
    operators each, drawn from ``rng``: its contracting ``a`` (|a| < 1 on average), then
    ``[b, c, d, e, t, r, off]`` (the operators' widths positive)."""
    order, ni, m, na, k = rng.integers(1, 4), rng.integers(1, 3), rng.integers(1, 3), 2, 2
    a = 0.5 * rng.standard_normal((order, order)) / np.sqrt(order)
    mats = [rng.standard_normal(s) for s in
            [(order, ni), (m, order), (m, ni), (order, na * k), (na, m)]]  # fmt: skip
    return a, [*mats, np.abs(rng.standard_normal((na, k))), rng.standard_normal(m)]
