"""What a record's input can tell a model choice: where the input turns (a reversal is a
move back by :data:`TURN_BAND` of its span, or :data:`NOISE_REACH` times its noise), the
rates its half-cycles drive, and what it cannot test (no minor loops, one frequency), said
plainly. ``piezohyst.analysis.selection`` places its folds by these turns and its notes
are these sentences; ``fit`` asks :func:`several_rates` before identifying a lag."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import ArrayLike

from .._kernels import signal as S
from .._validation import FloatArray, as_signal, same_length
from ..io.screening import noise_level

__all__ = ["EVEN_BLOCKS", "MAJOR", "MIN_TURNS", "NOISE_REACH", "ONE_RATE", "SEVERAL_RATES",
           "SINE_RISE", "TURN_BAND", "block_starts", "drive_rates", "input_noise",
           "record_notes", "several_rates", "turn_band"]  # fmt: skip

#: A turn: the input back by this fraction of its span from its last extreme
TURN_BAND = 0.01
#: Fewest turns for folds placed by turns: two per scored part at the least
MIN_TURNS = 8
#: A turn must also move back this many times the input's noise (RMS): over a hold of
#: 10^4-10^5 samples Gaussian noise spans 8.6-9.5 of its RMS from highest to lowest, so a
#: smaller band counts the noise of a hold as turns
NOISE_REACH = 10.0
#: Reversals spanning at least this share of the input's range belong to the major loop
MAJOR = 0.9
#: After its first turn the input never comes back within this share of its range to one of
#: its ends: the branches at that end are seen on the first move only
UNSEEN_END = 0.05

#: A scored part with fewer than two turns inside is cut into this many equal blocks
EVEN_BLOCKS = 8

#: the input's noise (RMS): one estimator with the record's check
input_noise = noise_level


def block_starts(turns: np.ndarray, a: int, b: int) -> np.ndarray:
    """Where the blocks of part ``a:b`` start, relative to ``a``: after each turn inside it
    (a half-cycle a block: a model selection's jackknife leaves each out in turn), or
    :data:`EVEN_BLOCKS` equal blocks with fewer than two turns.

    Parameters
    ----------
    turns : ndarray
        The input's turns (sample indices).
    a, b : int
        The part.

    Returns
    -------
    ndarray of int64
    """
    inside = turns[(turns > a) & (turns < b - 1)] + 1 - a
    if inside.size >= 2:
        return np.concatenate([[0], inside]).astype(np.int64)
    k = max(1, min(EVEN_BLOCKS, (b - a) // 2))
    return np.unique(np.linspace(0, b - a, k + 1)[:-1].astype(np.int64))


def turn_band(x: FloatArray) -> float:
    """How far the input must move back from its last extreme to turn: :data:`TURN_BAND` of
    its span, or :data:`NOISE_REACH` times its noise (:func:`input_noise`) where larger.

    Parameters
    ----------
    x : ndarray, shape (N,)

    Returns
    -------
    float
        In the input's units; 0 for a constant input.
    """
    span = float(np.ptp(x)) if x.size else 0.0
    if span <= 0.0:
        return 0.0
    return max(TURN_BAND * span, NOISE_REACH * input_noise(x))


def _turns(x: FloatArray) -> np.ndarray:
    """The index of each turn's extreme (:func:`turn_band`); none for a constant input."""
    band = turn_band(x)
    turns = np.empty(x.size, np.int64)
    if band <= 0.0:
        return turns[:0]
    return turns[: int(S.turn_points(x, band, np.zeros(3), turns))]


def record_notes(x: FloatArray) -> tuple[str, ...]:
    """What a record's input cannot test, said plainly (for :attr:`Selection.notes`).

    Parameters
    ----------
    x : ndarray, shape (N,)
        The record's input (V).

    Returns
    -------
    tuple of str
        One sentence per thing the input cannot test (empty: nothing to say).
    """
    return _record_notes(x, _turns(x))


#: half-cycles all within this factor of their median length: a record of one frequency
ONE_RATE = 2.0
#: The 5th and 95th percentiles of a record's half-cycle rates this far apart: it drives
#: several rates, and a lag between the command and the piezo can be told from loop width
#: (measured on the simulator's signals: one frequency 1.0-1.7, ``multifreq`` 4.2,
#: ``two-rate`` 4.0, ``piezohyst excite`` 11.8; the measured 1 Hz sets 1.0-1.1)
SEVERAL_RATES = 3.0


#: The share of a sine's half-period its rise from 10 % to 90 % of the half-cycle takes:
#: (acos(-0.8) - acos(0.8)) / pi
SINE_RISE = 0.59033


def drive_rates(x: ArrayLike, t: ArrayLike) -> FloatArray:
    """The rate (Hz) of each half-cycle of a record's drive, from its rise time: a half-cycle
    between two turns of the input, of at least 5 % of its range, takes the time ``d`` from
    10 % to 90 % of its own amplitude, ``0.59 / (2 d)`` for a sine of that period (a
    triangle's reads 1.36x higher; holds at its ends do not count, nor the noise in them).

    Parameters
    ----------
    x : array_like
        The input.
    t : array_like
        Its times (s).

    Returns
    -------
    ndarray
        One rate per half-cycle, in time order.
    """
    xs, ts = as_signal(x, "x"), as_signal(t, "t")
    same_length(xs, ts, "x", "t")
    turns = _turns(xs)
    span = float(np.ptp(xs)) if xs.size else 0.0
    rates = []
    for a, b in itertools.pairwise(turns):
        seg = xs[a : b + 1]
        amp = float(seg[-1] - seg[0])
        if abs(amp) < 0.05 * span:
            continue
        frac = (seg - seg[0]) / amp
        rise = float(ts[a + int(np.argmax(frac >= 0.9))] - ts[a + int(np.argmax(frac >= 0.1))])
        if rise > 0.0:
            rates.append(SINE_RISE / (2.0 * rise))
    return np.array(rates)


def several_rates(x: ArrayLike, t: ArrayLike) -> tuple[bool, FloatArray]:
    """Whether a record drives several rates (:data:`SEVERAL_RATES`), and its half-cycles'
    rates (:func:`drive_rates`).

    Parameters
    ----------
    x, t : array_like

    Returns
    -------
    (bool, ndarray)
    """
    rates = drive_rates(x, t)
    if rates.size < 4:
        return False, rates
    low, high = np.percentile(rates, [5.0, 95.0])
    return bool(high >= SEVERAL_RATES * low), rates


def _record_notes(x: FloatArray, turns: np.ndarray) -> tuple[str, ...]:
    notes = []
    if turns.size < MIN_TURNS:
        notes.append(
            f"The input turns {turns.size} times (fewer than {MIN_TURNS}): the folds split its "
            "samples, and each scored part holds few loops."
        )
    span = float(np.ptp(x)) if x.size else 0.0
    if turns.size >= 2 and span > 0.0:
        widths = np.abs(np.diff(x[turns])) / span
        if np.all(widths >= MAJOR):
            notes.append(
                f"Every reversal spans at least {100 * MAJOR:.0f} % of the input's range: the "
                "record holds no minor loops, so the scores rank how each candidate follows the "
                "major loop, not how it predicts smaller loops (a Preisach density or a Duhem "
                "grid inside the loop is then a guess). Record loops of several amplitudes "
                "(piezohyst excite) to choose for them."
            )
    if turns.size >= 2 and span > 0.0:
        notes += _unseen_ends(x, turns, span)
    halves = np.diff(turns)[1:-1]  # the first and last may be cut by the record's ends
    middle = float(np.median(halves)) if halves.size else 0.0
    if halves.size >= 3 and np.all((halves >= middle / ONE_RATE) & (halves <= middle * ONE_RATE)):
        notes.append(
            "Every half-cycle lasts about as long as the others (within "
            f"{ONE_RATE:g}x of their median): the record drives one frequency, where a "
            "lag of the amplifier or sensor and hysteresis look alike, so the scores cannot "
            "rank how the candidates follow another rate, and each holds the lag this drive "
            "showed as loop width. Record several frequencies (piezohyst excite, or the "
            "multifreq signal) to choose for other rates."
        )
    return tuple(notes)


def unseen_ends(x: FloatArray, turns: np.ndarray) -> tuple[str, ...]:
    """The ends of the input's range (``"lowest"``, ``"highest"``) it reaches only before
    its first turn, by more than :data:`UNSEEN_END` of its range.

    Parameters
    ----------
    x : ndarray, shape (N,)
        The input.
    turns : ndarray
        Its turns (:func:`turn_points`).

    Returns
    -------
    tuple of str
    """
    span = float(np.ptp(x)) if x.size else 0.0
    if turns.size < 2 or span <= 0.0:
        return ()
    after = x[turns[0] :]
    gaps = {"lowest": float(after.min() - x.min()), "highest": float(x.max() - after.max())}
    return tuple(end for end, gap in gaps.items() if gap / span > UNSEEN_END)


def _unseen_ends(x: FloatArray, turns: np.ndarray, span: float) -> list[str]:
    """A note for each end of the input's range it reaches only before its first turn."""
    after = x[turns[0] :]
    notes = []
    for end, reached, back in (("lowest", float(x.min()), float(after.min())),
                               ("highest", float(x.max()), float(after.max()))):  # fmt: skip
        gap = abs(back - reached) / span
        if end in unseen_ends(x, turns):
            notes.append(
                f"After its first turn the input never comes back to its {end} values: it "
                f"reaches {reached:.4g} before that turn only, and afterwards {back:.4g} at "
                f"the {end} ({100 * gap:.0f} % of its range short). Loops that return there "
                f"({'a scan from rest, a test from 0 V' if end == 'lowest' else 'full stroke'}) "
                "are predicted by fits that saw that end "
                "on one move, and the scores cannot rank how the candidates predict them: on "
                "plants drawn at random, choices from such records (decaying loops) landed "
                "within 1.25x of the best candidate less often than from records whose loops "
                "reach both ends (docs/selection-study.md). Record loops that reach both ends "
                "(piezohyst excite)."
            )
    return notes
