"""Numba kernels of the signals around the hysteresis: the growth terms' running integral,
creep lags, the input dynamics (delay and lag) and the output mode, reversal counting for
the cross-validation folds, the constant runs of leakage holds, and the slew limit's hulls
of a known command sequence. Plain functions over
arrays and explicit state, the fastmath policy of :mod:`piezohyst._kernels`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._validation import frozen
from .play import FASTMATH


@njit(cache=True, fastmath=FASTMATH)
def running_integral(x, dt, start, out):  # type: ignore[no-untyped-def]
    """Backward-rectangle integral of the paper (eq. 13): ``y2[k] = y2[k-1] + x[k]*dt[k]``.

    ``start`` is y2 before the first sample; returns the final value.
    """
    acc = start
    for k in range(x.shape[0]):
        acc += x[k] * dt[k]
        out[k] = acc
    return acc


@njit(cache=True)  # no fastmath: its ring and block loops must round alike (chunks == one call)
def input_filter(x, dt, d_int, d_frac, tau, nominal, state, out):  # type: ignore[no-untyped-def]
    """Delay (``d_int + d_frac`` samples, linear interpolation) then a first-order lag ``tau``.

    ``state`` = [unused, lag, head, ring buffer of the last ``d_int + 2``
    inputs]; the lag is exact for an input held over each sample
    (``u = e u + (1 - e) v``, ``e = exp(-dt/tau)``); ``tau = 0`` means no lag.
    An interval within 1 ppm of ``nominal`` (the record's sample interval; 0:
    none) is taken as ``nominal``: time stamps' rounding makes a uniform
    record's intervals differ in their last digits, and one ``exp`` serves
    the record. A function of each interval alone, so chunks equal one call.
    """
    size = state.shape[0] - 3
    head = int(state[2])
    lag = state[1]
    dt_seen = -1.0
    gain = 0.0
    keep = 1.0
    keep0 = math.exp(-nominal / tau) if tau > 0.0 and nominal > 0.0 else 1.0
    gain0 = 1.0 - keep0
    near = 1e-6 * nominal
    n = x.shape[0]
    first = min(n, d_int + 1)  # samples whose delayed inputs reach back into the ring
    for k in range(first):  # those delayed inputs first, into ``out``
        head = (head + 1) % size
        state[3 + head] = x[k]
        a = state[3 + (head - d_int) % size]
        out[k] = a + d_frac * (state[3 + (head - d_int - 1) % size] - a)
    if tau > 0.0:
        for k in range(n):  # the lag, the rest of the delayed inputs read from the block itself
            if k < first:
                v = out[k]
            else:
                a = x[k - d_int]
                v = a + d_frac * (x[k - d_int - 1] - a)
            if abs(dt[k] - nominal) <= near:  # the chain through ``lag``: one multiply, one add
                lag = keep0 * lag + gain0 * v
            else:
                if dt[k] != dt_seen:
                    dt_seen = dt[k]
                    keep = math.exp(-dt_seen / tau)
                    gain = 1.0 - keep
                lag = keep * lag + gain * v
            out[k] = lag
    else:
        for k in range(first, n):
            a = x[k - d_int]
            out[k] = a + d_frac * (x[k - d_int - 1] - a)
        if n > 0:
            lag = out[n - 1]
    for k in range(max(first, n - size), n):  # the ring ends holding the last inputs
        head = (head + 1) % size
        state[3 + head] = x[k]
    state[1] = lag
    state[2] = float(head)


@njit(cache=True, fastmath=FASTMATH)
def mode_filter(u, ad, bd, state, out):  # type: ignore[no-untyped-def]
    """A second-order mode of unit DC gain on every column of ``u`` (m x p), state carried.

    ``state`` (2 x p): position and velocity per column. Each row's input is
    held over the sample that ends at it (exact discretisation ``ad``, ``bd``);
    the output is the position at the sample's end.
    """
    for j in range(u.shape[1]):
        x1 = state[0, j]
        x2 = state[1, j]
        for k in range(u.shape[0]):
            n1 = ad[0, 0] * x1 + ad[0, 1] * x2 + bd[0] * u[k, j]
            n2 = ad[1, 0] * x1 + ad[1, 1] * x2 + bd[1] * u[k, j]
            x1 = n1
            x2 = n2
            out[k, j] = x1
        state[0, j] = x1
        state[1, j] = x2


@njit(cache=True, fastmath=FASTMATH)
def mode_unfilter(y, ad, bd, u):  # type: ignore[no-untyped-def]
    """The inputs that :func:`mode_filter` turns into ``y`` (1-D), from rest at ``y[0]``.

    Row ``k``'s input moves the position from ``y[k-1]`` to ``y[k]`` (``bd[0] > 0``: a
    held input always moves the position); the velocity follows from it.
    """
    u[0] = y[0]
    x2 = 0.0
    for k in range(1, y.shape[0]):
        x1 = y[k - 1]
        u[k] = (y[k] - ad[0, 0] * x1 - ad[0, 1] * x2) / bd[0]
        x2 = ad[1, 0] * x1 + ad[1, 1] * x2 + bd[1] * u[k]


@njit(cache=True)
def turn_points(x, band, state, out):  # type: ignore[no-untyped-def]
    """The input's turns: reversals of at least ``band`` back from the last extreme. Writes
    the index of each turn's extreme (in this block; -1 where it lay in an earlier block)
    to ``out`` (as long as ``x``) and returns how many.

    ``state`` = [direction (+1 rising, -1 falling, 0 not yet known), the
    running extreme (the start while the direction is unknown), started];
    updated, so the blocks of one record count like one call.
    """
    direction = state[0]
    extreme = state[1]
    at = -1
    if state[2] == 0.0 and x.shape[0]:
        extreme = x[0]
        at = 0
        state[2] = 1.0
    count = 0
    for k in range(x.shape[0]):
        v = x[k]
        if direction == 0.0:
            if v - extreme >= band:
                direction = 1.0
                extreme, at = v, k
            elif extreme - v >= band:
                direction = -1.0
                extreme, at = v, k
        elif direction > 0.0:
            if v > extreme:
                extreme, at = v, k
            elif extreme - v >= band:
                out[count] = at
                count += 1
                direction = -1.0
                extreme, at = v, k
        elif v < extreme:
            extreme, at = v, k
        elif v - extreme >= band:
            out[count] = at
            count += 1
            direction = 1.0
            extreme, at = v, k
    state[0] = direction
    state[1] = extreme
    return count


@njit(cache=True)
def reversals(x, band, state):  # type: ignore[no-untyped-def]
    """Count the input's reversals (:func:`turn_points`, with its ``state``)."""
    return turn_points(x, band, state, np.empty(x.shape[0], np.int64))


@njit(cache=True)
def unturned_bounds(x, band):  # type: ignore[no-untyped-def]
    """(lowest input after the first fall of ``band`` from a maximum, highest after the first
    rise of ``band`` from a minimum); NaN for a side the input never turned on. Below the
    first (above the second) no relay the input switched up (down) ever switched back."""
    low = math.nan
    high = math.nan
    top = x[0] if x.shape[0] else 0.0
    bottom = top
    fell = False
    rose = False
    for k in range(x.shape[0]):
        v = x[k]
        if fell:
            if not v >= low:
                low = v
        elif v > top:
            top = v
        elif top - v >= band:
            fell = True
            low = v
        if rose:
            if not v <= high:
                high = v
        elif v < bottom:
            bottom = v
        elif v - bottom >= band:
            rose = True
            high = v
    return low, high


@njit(cache=True)
def constant_runs(x, tol, edges):  # type: ignore[no-untyped-def]
    """Split ``x`` into runs that stay within ``tol`` of their first sample.

    Writes the run boundaries ``0 = e_0 < e_1 < ... < e_m = len(x)`` into
    ``edges`` and returns ``m``.
    """
    n = x.shape[0]
    m = 0
    edges[0] = 0
    k = 0
    while k < n:
        j = k + 1
        while j < n and abs(x[j] - x[k]) <= tol:
            j += 1
        m += 1
        edges[m] = j
        k = j
    return m


@njit(cache=True, fastmath=FASTMATH)
def lag_filter(x, dt, tau, state, out):  # type: ignore[no-untyped-def]
    """First-order lags of unit DC gain (creep operators), exact for piecewise-constant input.

    ``c_k[n] = c_k[n-1] + (1 - exp(-dt[n] / tau_k)) (x[n] - c_k[n-1])`` for every
    time constant ``tau_k``; ``state`` (m,) holds ``c_k`` and is updated;
    ``out`` is (N, m).
    """
    m = tau.shape[0]
    for k in range(x.shape[0]):
        for j in range(m):
            a = 1.0 - math.exp(-dt[k] / tau[j])
            state[j] += a * (x[k] - state[j])
            out[k, j] = state[j]


@njit(cache=True)
def count_held(commands, prev, tol, counts, given, arrived, approach):  # type: ignore[no-untyped-def]
    """Per channel, the commands that moved by the slew limit: ``commands`` (samples, C),
    ``prev`` (C,) the commands before (updated to the last row), ``tol`` (C,) the limit
    per sample less rounding (inf: none), ``counts`` and ``given`` (C,) incremented; a
    channel counts from its first command the limit did not hold (``arrived`` (C,) set
    then: the approach to the trajectory is not counted, as ``_kernels.tally_command``, but
    ``approach`` (C,) counts the commands the limit held before the channel arrived)."""
    for k in range(commands.shape[0]):
        for c in range(commands.shape[1]):
            held = abs(commands[k, c] - prev[c]) >= tol[c]
            prev[c] = commands[k, c]
            if not arrived[c]:
                if held:
                    approach[c] += 1
                    continue
                arrived[c] = True
            if held:
                counts[c] += 1
            given[c] += 1


@njit(cache=True)
def slew_hull(u, step, upper, out):  # type: ignore[no-untyped-def]
    """The tightest sequence that moves by at most ``step`` per sample on one side of ``u``.

    ``upper``: the smallest such sequence at or above ``u``, ``out[k] = max_j (u[j] - step
    |k - j|)``; else the largest at or below, ``min_j (u[j] + step |k - j|)``. Two passes
    (forward, then backward), as a distance transform.
    """
    n = u.shape[0]
    sign = -1.0 if upper else 1.0
    for k in range(n):
        v = u[k]
        if k > 0:
            w = out[k - 1] + sign * step
            v = max(v, w) if upper else min(v, w)
        out[k] = v
    for k in range(n - 2, -1, -1):
        w = out[k + 1] + sign * step
        out[k] = max(out[k], w) if upper else min(out[k], w)


def warm_up() -> None:
    """Compile the kernels the fits use first (numba caches the result on disk), with
    read-only inputs where the library passes them so (:func:`~piezohyst._validation.frozen`)."""
    x = frozen(np.zeros(2))
    running_integral(x, np.zeros(2), 0.0, np.empty(2))
    reversals(x, 1.0, np.zeros(3))
    lag_filter(x, np.zeros(2), np.ones(1), np.zeros(1), np.empty((2, 1)))
