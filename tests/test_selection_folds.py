"""Where select_model's forward chaining cuts a record: by the input's turns, so that each
fit has seen loops of the kind it is scored on, and by its samples where it has too few."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from piezohyst import _signalkernels as S
from piezohyst.excitation import excitation
from piezohyst.selection import FOLDS, MIN_TURNS, TURN_BAND, fold_bounds

pytestmark = pytest.mark.kernels


def naive_turns(x: list[float], band: float) -> list[int]:
    """The index of each turn's extreme: the input came back ``band`` from the running
    extreme of its current direction, read off sample by sample."""
    turns: list[int] = []
    direction, at = 0, 0
    for k in range(1, len(x)):
        if direction == 0:
            if abs(x[k] - x[at]) >= band:
                direction, at = (1 if x[k] > x[at] else -1), k
        elif direction * (x[k] - x[at]) > 0:
            at = k
        elif direction * (x[at] - x[k]) >= band:
            turns.append(at)
            direction, at = -direction, k
    return turns


@given(
    x=st.lists(st.floats(-5.0, 5.0, allow_nan=False), min_size=1, max_size=60),
    band=st.floats(0.01, 3.0),
    cut=st.integers(0, 60),
)
def test_turn_points_match_a_direct_reading_in_one_call_or_two(
    x: list[float], band: float, cut: int
) -> None:
    xs = np.array(x)
    out = np.empty(xs.size, np.int64)
    n = S.turn_points(xs, band, np.zeros(3), out)
    want = naive_turns(x, band)
    assert out[:n].tolist() == want
    # blocks of one record count like one call (the extreme may lie in the earlier block)
    state, cut = np.zeros(3), min(cut, xs.size)
    first = S.reversals(xs[:cut], band, state)
    assert first + S.reversals(xs[cut:], band, state) == len(want)


def test_the_folds_of_what_excite_writes_end_among_its_fast_loops() -> None:
    """Its 10 Hz loops hold most of its turns: by seconds, the first fit (on half the record)
    would have seen none of them and be scored on them; by turns, each fit has."""
    x = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0).voltage
    out = np.empty(x.size, np.int64)
    turns = out[: S.turn_points(x, TURN_BAND * np.ptp(x), np.zeros(3), out)]
    bounds = fold_bounds(x)
    assert len(bounds) == len(FOLDS) and bounds[-1][1] == x.size
    for (fit, score), (a, b) in zip(bounds, FOLDS, strict=True):
        assert fit < score
        # the fit ends at a turn's extreme, with the share a of the turns behind it
        assert fit - 1 in turns and np.sum(turns < fit) == round(a * turns.size)
        assert b == 1.0 or np.sum(turns < score) == round(b * turns.size)
    assert bounds[0][0] > 0.9 * x.size  # where the fast loops are, not half the seconds


def test_a_record_with_few_turns_is_cut_by_its_samples() -> None:
    x = np.concatenate([np.linspace(0, 1, 500), np.linspace(1, 0, 500)] * (MIN_TURNS // 2 - 1))
    assert fold_bounds(x) == [(round(a * x.size), round(b * x.size)) for a, b in FOLDS]
    assert fold_bounds(np.full(100, 3.0))[0] == (50, 75)  # no span: no turns


def test_noise_up_to_a_tenth_of_a_percent_moves_no_fold() -> None:
    """The turn band (1 % of the span) stands above 0.1 % RMS noise on the input, holds of
    several seconds included; the docstring says where it stops (0.2 %)."""
    x = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0).voltage
    noisy = x + 0.001 * 140.0 * np.random.default_rng(0).standard_normal(x.size)
    out = np.empty(x.size, np.int64)
    clean = S.turn_points(x, TURN_BAND * np.ptp(x), np.zeros(3), out)
    assert S.turn_points(noisy, TURN_BAND * np.ptp(noisy), np.zeros(3), out) == clean
    # tol: noise moves the sample of a loop's extreme within the loop's flat top, at most a
    # quarter cycle of the 10 Hz loops at 1 kHz (25 samples)
    got, want = np.array(fold_bounds(noisy)), np.array(fold_bounds(x))
    assert np.all(np.abs(got - want) <= 25)
