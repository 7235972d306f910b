"""Where select_model's forward chaining cuts a record: by the input's turns, so that each
fit has seen loops of the kind it is scored on, and by its samples where it has too few."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from piezohyst._kernels import signal as S
from piezohyst._validation import frozen
from piezohyst.analysis.selection import (
    FOLDS,
    MIN_TURNS,
    NOISE_REACH,
    TURN_BAND,
    _turns,
    fold_bounds,
    input_noise,
    turn_band,
)
from piezohyst.workflows.excitation import excitation

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
    first = S.reversals(frozen(xs[:cut]), band, state)  # read-only, as the library passes it
    assert first + S.reversals(frozen(xs[cut:]), band, state) == len(want)


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


def test_a_measured_voltage_s_noise_does_not_turn() -> None:
    """The turn band grows with the input's noise (NOISE_REACH times its RMS, estimated from
    the record): up to 0.5 % RMS noise on what excite writes, the same 87 turns, and each
    fold ends on the top of the same turn (with the span's band alone, 0.2 % gave 302)."""
    x = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0).voltage
    clean = _turns(x)
    want = fold_bounds(x)
    for level in (0.001, 0.002, 0.005):
        sigma = level * 140.0
        for seed in range(3):
            noisy = x + sigma * np.random.default_rng(seed).standard_normal(x.size)
            # tol: the median absolute deviation's standard error at 5e4 samples is 0.5 %
            assert abs(input_noise(noisy) / sigma - 1.0) < 0.03
            assert _turns(noisy).size == clean.size
            for (got, _), (ref, _) in zip(fold_bounds(noisy), want, strict=True):
                a, b = sorted((got - 1, ref - 1))
                assert not np.any((clean > a) & (clean < b))  # no other turn between them
                # on the same top: the noisy extreme beat the clean one by its noise alone
                assert abs(x[ref - 1] - x[got - 1]) <= NOISE_REACH * sigma


def test_the_noise_estimate_reads_little_of_a_smooth_input() -> None:
    t = np.arange(20000) / 1000.0
    for f, most in ((10.0, 0.01), (50.0, 0.5)):  # V, of a 70 V sine: see input_noise
        assert input_noise(70.0 + 70.0 * np.sin(2 * np.pi * f * t)) < most
    assert input_noise(np.full(100, 3.0)) == 0.0 and input_noise(np.arange(5.0)) == 0.0


@given(
    x=st.lists(st.floats(-5.0, 5.0, allow_nan=False), min_size=0, max_size=60),
    scale=st.sampled_from([-8.0, -0.5, 0.25, 2.0, 1024.0]),
    shift=st.sampled_from([-3.0, 0.0, 100.0]),
)
def test_the_noise_and_the_band_follow_the_input_s_units(
    x: list[float], scale: float, shift: float
) -> None:
    """Volts or millivolts, offset or not: the noise scales with |scale| and ignores the
    offset, and so does the band (powers of two scale exactly; the offset costs rounding)."""
    xs = np.array(x)
    moved = scale * xs + shift
    # tol: the 7-point smoothing and the offset round at 1e-15 of the largest |value|
    tol = 1e-12 * (1.0 + float(np.max(np.abs(moved), initial=0.0)))
    assert abs(input_noise(moved) - abs(scale) * input_noise(xs)) <= tol * 10.0
    assert abs(turn_band(moved) - abs(scale) * turn_band(xs)) <= tol * 100.0
