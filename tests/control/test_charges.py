"""The displacement front end (:class:`piezohyst.control.charges.Charges`): one sample at a
time, as a loop's ``step`` calls it, equals a block to the bit (a loop's ``step`` and
``process`` must agree), with the same count and warning, on rising and falling maps, inside
the calibrated range, beyond either edge and at NaN."""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.control.charges import Charges
from piezohyst.errors import ExtrapolationWarning


def _map(gain: float) -> ph.OutputMap:
    """A linear map over 0-2.5 uC: ``gain`` m/C (negative: the displacement falls)."""
    c, h = 1.25e-6, 1.25e-6
    return ph.OutputMap((1e-5, gain * h), c, h, ((0.0, 0.0), (0.0, 0.0)), (0.0, 2.5e-6))


@settings(max_examples=60, deadline=None)
@given(
    gain=st.sampled_from([125.0, -80.0]),
    where=st.lists(st.sampled_from(["inside", "below", "above", "nan"]), min_size=1, max_size=12),
    spread=st.floats(0.0, 1.0),
)
def test_one_sample_equals_the_block(gain: float, where: list[str], spread: float) -> None:
    om = _map(gain)
    lo_s, hi_s = sorted(om.edges()[2:4])
    span = hi_s - lo_s
    at = {"inside": lo_s + spread * span, "below": lo_s - (0.01 + spread) * span,
          "above": hi_s + (0.01 + spread) * span, "nan": np.nan}  # fmt: skip
    s = np.array([at[w] for w in where])
    one, block = Charges(om), Charges(om)
    with warnings.catch_warnings(record=True) as said_one:
        warnings.simplefilter("always")
        got = np.array([one.one(float(x), None)[0] for x in s])
    with warnings.catch_warnings(record=True) as said_block:
        warnings.simplefilter("always")
        want = np.concatenate([block.block(np.array([x])) for x in s])
    np.testing.assert_array_equal(got, want)  # to the bit: the same operations, in floats
    assert one.outside == block.outside == sum(w in ("below", "above") for w in where)
    assert one.last == block.last
    kinds = [
        [str(w.message) for w in said if issubclass(w.category, ExtrapolationWarning)]
        for said in (said_one, said_block)
    ]
    assert kinds[0] == kinds[1] and len(kinds[0]) == (1 if one.outside else 0)
