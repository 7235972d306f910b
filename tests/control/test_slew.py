"""A learning trial's commands meet the slew limit as a whole (the kernel's hulls): against
their O(N^2) definition, and over generated commands."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph

from .. import reference

pytestmark = pytest.mark.kernels


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 140.0, allow_nan=False), min_size=2, max_size=40),
    st.floats(0.5, 30.0),
)
def test_a_trial_meets_the_slew_limit_with_moves_centred(values: list[float], step: float) -> None:
    """The trial's commands within the slew limit: the midpoint of the two hulls (against
    their O(N^2) definition), within the limit around the period, inside the commands' range,
    and the commands themselves where they keep to the limit."""
    u = np.array(values)
    got = ph.control.learning.trial.centred_slew(u, step)
    upper, lower = reference.slew_hulls(values, step)
    # tol: sums of up to 3N steps of at most 140 V, a few ulps each
    np.testing.assert_allclose(got, 0.5 * (np.array(upper) + np.array(lower)), rtol=0, atol=1e-11)
    moves = np.diff(np.concatenate([got, got[:1]]))  # into the next trial too
    assert np.all(np.abs(moves) <= step * (1 + 1e-12))
    assert got.min() >= u.min() - 1e-12 and got.max() <= u.max() + 1e-12
    if np.all(np.abs(np.diff(np.concatenate([u, u[:1]]))) <= step):
        # tol: a sequence within the limit is its own hull, to the rounding of one step's sum
        np.testing.assert_allclose(got, u, rtol=0, atol=1e-12)


def test_a_cut_move_is_spread_evenly_around_its_sample() -> None:
    """A jump ten steps high is spread over the ten samples before it and the ten after,
    symmetric about it: a causal limiter would start it at the jump and end ten samples late."""
    u = np.where(np.arange(60) < 30, 0.0, 10.0)  # the fall back at the wrap is 30 samples away
    got = ph.control.learning.trial.centred_slew(u, 1.0)
    assert got[20] == 0.0 and got[39] == 10.0 and 0.0 < got[21] < got[38] < 10.0
    np.testing.assert_allclose(got[30:40] + got[29:19:-1], 10.0, atol=1e-12)  # symmetric
    assert np.abs(np.diff(got)).max() <= 1.0
