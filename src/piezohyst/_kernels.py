"""Numba kernels: plain functions over arrays and explicit state.

No validation and no allocation of results the caller can provide: the public
layers check inputs once and call these. The play (backlash) operator of
threshold ``r`` is (paper eq. 9, with the recursion on the *unweighted* state)::

    z[k] = max(x[k] - r, min(x[k] + r, z[k-1]))

written here as ``min(max(z, x - r), x + r)``, which is the same for ``r >= 0``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Reassociation lets LLVM vectorise the weighted sum over operators; the play
# recursion itself is exact (min/max), so results differ from a sequential sum by
# rounding only. No 'nnan'/'ninf': inputs are checked finite before they get here.
_FAST = {"reassoc", "contract", "nsz"}


@njit(cache=True, fastmath=_FAST)
def pi_forward(x, r, w, z, y):  # type: ignore[no-untyped-def]
    """Weighted sum of play operators, sample by sample.

    x : (N,) input; r : (n,) thresholds; w : (n,) weights;
    z : (n,) operator states, updated in place (final state on return);
    y : (N,) output, written: ``y[k] = sum_i w[i] * z_i[k]``.
    """
    n = r.shape[0]
    for k in range(x.shape[0]):
        xk = x[k]
        acc = 0.0
        for i in range(n):
            zi = min(max(z[i], xk - r[i]), xk + r[i])
            z[i] = zi
            acc += w[i] * zi
        y[k] = acc


@njit(cache=True)
def play_states(x, r, z, out):  # type: ignore[no-untyped-def]
    """Every operator's output: ``out[k, i] = z_i[k]``; ``z`` updated in place.

    ``out`` is (M, n) with M >= len(x); rows past len(x) are left untouched.
    """
    n = r.shape[0]
    for k in range(x.shape[0]):
        xk = x[k]
        for i in range(n):
            zi = min(max(z[i], xk - r[i]), xk + r[i])
            z[i] = zi
            out[k, i] = zi


@njit(cache=True)
def running_integral(x, dt, start, out):  # type: ignore[no-untyped-def]
    """Backward-rectangle integral of the paper (eq. 13): ``y2[k] = y2[k-1] + x[k]*dt[k]``.

    ``start`` is y2 before the first sample; returns the final value.
    """
    acc = start
    for k in range(x.shape[0]):
        acc += x[k] * dt[k]
        out[k] = acc
    return acc


def warm_up() -> None:
    """Compile every kernel once (numba caches the result on disk)."""
    x = np.zeros(2)
    r = np.zeros(1)
    z = np.zeros(1)
    pi_forward(x, r, np.ones(1), z, np.empty(2))
    play_states(x, r, z, np.empty((2, 1)))
    running_integral(x, np.zeros(2), 0.0, np.empty(2))
