"""What the cores identified on a record in memory share (Preisach, Duhem, Bouc-Wen).

:func:`fit_in_memory` is their identification step around the core's own
solve: the record read in, the growth terms settled first by a play-operator
proxy where the core asks for it (or chosen by its cross-validation), then
the core's solve. The helpers build the terms' columns over the record.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..._validation import FloatArray, as_signal
from ...io.blocks import BLOCK, Blocks, block_dt
from ..terms import Term, term_columns
from .base import Core, CoreFit, FitJob
from .play import growth_proxy

__all__ = ["Solving", "fit_in_memory"]

REFINE_ROWS = 8000  # output-error refinement: residual rows (hashed picks)
REFINE_EVALS = 25  # and evaluations
FIT_ROWS = 40_000  # linear solves and residuals use at most this many samples (hashed picks)
SEARCH_ROWS = 5_000  # Bouc-Wen's shape search runs on a copy decimated to about this many


class Solving(NamedTuple):
    """What a core's own solve gets: the record, the terms, the settings, the start."""

    x: FloatArray
    y: FloatArray
    t: FloatArray | None
    terms: list[Term]
    params: dict[str, Any]
    initial_state: Any
    growth: list[FloatArray] | None  # coefficients fixed by the proxy, or None


#: A core's own solve: (core, one coefficient array per term)
Solve = Callable[[Solving], tuple[Core, list[FloatArray]]]


def fit_in_memory(core: type[Core], job: FitJob, solve: Solve) -> CoreFit:
    """The identification step of a core fitted on the record in memory.

    Parameters
    ----------
    core : type
        The core class (``growth_from_proxy``: settle the growth terms by a
        play-operator proxy first).
    job : FitJob
    solve : callable
        The core's own solve.

    Returns
    -------
    CoreFit
    """
    x, y, t = _collect(job.blocks)
    terms = list(job.terms)
    select = job.subsets is not None
    proxy: list[FloatArray] | None = None
    selection = None
    if terms and (select or core.growth_from_proxy):
        terms, proxy, selection = growth_proxy(x, y, t, terms, job.subsets, job.initial_state)
    fitted, coefs = solve(Solving(x, y, t if terms else None, terms, job.params,
                                  job.initial_state, proxy))  # fmt: skip
    return CoreFit(fitted, tuple(terms), tuple(coefs), selection)


def _picked_rows(n: int, limit: int) -> np.ndarray:
    """All rows, or about ``limit`` of them spread by a hash of the index (no aliasing)."""
    if n <= limit:
        return np.arange(n)
    g = np.arange(n, dtype=np.uint64)
    h = (g * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return np.flatnonzero(h < np.uint64(((1 << 24) * limit) // n))


def _term_blocks(
    terms: Sequence[Term], x: FloatArray, t: FloatArray | None
) -> Iterator[tuple[int, int, FloatArray]]:
    """Every term's columns over the record, from rest at its start, block by block:
    ``(start, stop, columns)`` (the columns array is reused from one block to the next)."""
    width = sum(term.width for term in terms)
    states = [term.rest_state(float(x[0])) for term in terms]
    block = np.empty((min(BLOCK, x.size), width))
    for start in range(0, x.size, BLOCK):
        stop = min(start + BLOCK, x.size)
        dt = block_dt(t, start, stop, None) if t is not None else None
        ts = None if t is None else t[start:stop]
        term_columns(terms, x[start:stop], ts, dt, states, block[: stop - start])
        yield start, stop, block[: stop - start]


def _growth_matrix(
    terms: Sequence[Term], x: FloatArray, t: FloatArray | None, rows: np.ndarray | None = None
) -> FloatArray:
    """Every term's columns over the record (or at ``rows``, increasing), from rest at its
    start; by blocks, so a wide term never holds a column per sample of a long record."""
    picked = np.arange(x.size) if rows is None else rows
    out = np.zeros((picked.size, sum(term.width for term in terms)))
    if out.shape[1]:
        for start, stop, cols in _term_blocks(terms, x, t):
            lo, hi = np.searchsorted(picked, [start, stop])
            out[lo:hi] = cols[picked[lo:hi] - start]
    return out


def _terms_output(
    terms: Sequence[Term], coefs: Sequence[FloatArray], x: FloatArray, t: FloatArray | None
) -> FloatArray:
    """The terms' part of the output over the record, from rest at its start."""
    out = np.zeros(x.size)
    if terms:
        coef = np.concatenate(list(coefs))
        for start, stop, cols in _term_blocks(terms, x, t):
            out[start:stop] = cols @ coef
    return out


def _split(coefficients: FloatArray, terms: Sequence[Term]) -> list[FloatArray]:
    """One coefficient array per term, from the solution's growth columns."""
    out, col = [], 0
    for term in terms:
        out.append(np.asarray(coefficients[col : col + term.width], dtype=np.float64))
        col += term.width
    return out


def _collect(blocks: Blocks) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    xs, ys, ts = [], [], []
    timed = True
    for x, y, t in blocks():
        xs.append(np.asarray(x, dtype=np.float64))
        ys.append(np.asarray(y, dtype=np.float64))
        if t is None:
            timed = False
        else:
            ts.append(np.asarray(t, dtype=np.float64))
    x_all = np.concatenate(xs) if xs else np.zeros(0)
    y_all = np.concatenate(ys) if ys else np.zeros(0)
    return x_all, y_all, (np.concatenate(ts) if timed and ts else None)


def _start_inner(core_rest: Any, x: FloatArray, initial_state: Any) -> FloatArray | None:
    """The core state before the record for a named initial state, or None (fit it)."""
    history = getattr(initial_state, "input", None)
    if history is not None:  # a History
        z = core_rest.history_state(as_signal(history, "history"))
    elif isinstance(initial_state, str) and initial_state == "periodic":
        z = core_rest.periodic_state(x)
    else:
        return None
    return np.asarray(z, dtype=np.float64)
