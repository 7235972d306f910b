"""Numba kernels: plain functions over arrays and explicit state.

No validation and no allocation of results the caller can provide: the public
layers check inputs once and call these. The play (backlash) operator of
threshold ``r`` is (paper eq. 9, with the recursion on the *unweighted* state)::

    z[k] = max(x[k] - r, min(x[k] + r, z[k-1]))

written here as ``min(max(z, x - r), x + r)``, which is the same for ``r >= 0``.
"""

from __future__ import annotations

import math

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


@njit(cache=True)
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


def warm_up() -> None:
    """Compile every kernel once (numba caches the result on disk)."""
    x = np.zeros(2)
    r = np.zeros(1)
    z = np.zeros(1)
    pi_forward(x, r, np.ones(1), z, np.empty(2))
    play_states(x, r, z, np.empty((2, 1)))
    running_integral(x, np.zeros(2), 0.0, np.empty(2))
    params = np.zeros((6, 1))
    config = np.array([0.0, 0.0, -1.0, 1.0, np.inf, 1.0, 0.0, 1.0])
    state = np.zeros(5)
    inverse_states(params, config, state)
    compensator_step(0.0, params, config, state)
    compensator_process(x, params, config, state, np.empty(2))


# Compensator layout (see piezohyst.compensator):
#   params (6, n): thresholds r, weights w, loading slopes S, inverse thresholds r',
#                  inverse weights w', (unused row kept zero)
#   config (8,):   offset c, inverse offset c', v_min, v_max, max step per sample (inf = none),
#                  1/gain (1 for the charge domain), reference output q_ref, output bound B
#                  (|y - c| <= B for every state and command within the limits)
#   state (2n + 3,): forward operator states z (V), inverse operator states zeta (output
#                  units), last command (V), non-finite count, saturated count
@njit(cache=True)
def inverse_states(params, config, state):  # type: ignore[no-untyped-def]
    """zeta_i = c + S_i z_i + sum_{j>i} w_j z_j (eq. 18's state map), from the forward states."""
    n = params.shape[1]
    tail = 0.0
    for i in range(n - 1, -1, -1):
        state[n + i] = config[0] + params[2, i] * state[i] + tail
        tail += params[1, i] * state[i]


@njit(cache=True, fastmath=_FAST)
def compensator_step(desired, params, config, state):  # type: ignore[no-untyped-def]
    """One feedforward command (V) for one desired value; updates ``state``.

    The inverse states run their own play recursion (the analytic inverse);
    the forward states follow the command actually sent. Only when a limit
    acts do the two part, and then the inverse states are rebuilt from the
    forward ones, so the next inversion starts from the actuator's real state.
    """
    n = params.shape[1]
    last = state[2 * n]
    if not math.isfinite(desired):  # NaN or +-inf: hold the last safe command
        state[2 * n + 1] += 1.0
        return last
    q = config[6] + desired * config[5]
    # beyond +-B nothing is reachable: clamping keeps huge values from overflowing the
    # inverse sums (inf - inf = NaN) while they still saturate on the correct side
    q = min(max(q, config[0] - config[7]), config[0] + config[7])
    x = config[1]
    for i in range(n):
        zeta = min(max(state[n + i], q - params[3, i]), q + params[3, i])
        state[n + i] = zeta
        x += params[4, i] * zeta
    v = x
    limited = False
    if not math.isfinite(v):  # belt and braces: never emit a non-finite command
        state[2 * n + 1] += 1.0
        inverse_states(params, config, state)
        return last
    if v < config[2] or v > config[3]:
        # count real overshoots, not a limit reached exactly but for rounding
        tol = 1e-12 * (config[3] - config[2])
        if v < config[2] - tol or v > config[3] + tol:
            state[2 * n + 2] += 1.0
        v = min(max(v, config[2]), config[3])
        limited = True
    step = config[4]
    if v > last + step:
        v = last + step
        limited = True
    elif v < last - step:
        v = last - step
        limited = True
    for i in range(n):
        state[i] = min(max(state[i], v - params[0, i]), v + params[0, i])
    if limited:
        inverse_states(params, config, state)
    state[2 * n] = v
    return v


@njit(cache=True, fastmath=_FAST)
def compensator_process(desired, params, config, state, out):  # type: ignore[no-untyped-def]
    """``compensator_step`` over a block (same arithmetic, one call)."""
    for k in range(desired.shape[0]):
        out[k] = compensator_step(desired[k], params, config, state)


# Generalized compensator (numerical inverse). Layout:
#   pi (2, n): thresholds r, weights w        static (3, K): knots, up, down coefficients
#   creep (3, m): time constant, gain, a = 1 - exp(-dt / tau) for the loop's dt
#   config (8,): offset c, v_min, v_max, max step, 1/gain, reference, static scale, unused
#   state (n + m + 3,): play states z, lag states, last command, non-finite, saturated
@njit(cache=True)
def _generalized_output(v, pi, static, creep, config, state):  # type: ignore[no-untyped-def]
    """Hysteresis-part output for command v from the current state, and its slope in v."""
    n = pi.shape[1]
    y = config[0]
    slope = 0.0
    for i in range(n):
        zi = state[i]
        lo = v - pi[0, i]
        hi = v + pi[0, i]
        if zi < lo:
            y += pi[1, i] * lo
            slope += pi[1, i]
        elif zi > hi:
            y += pi[1, i] * hi
            slope += pi[1, i]
        else:
            y += pi[1, i] * zi
    s = config[6]
    for j in range(static.shape[1]):
        d = v - static[0, j]
        if d > 0:
            y += static[1, j] * d * d / s
            slope += 2.0 * static[1, j] * d / s
        else:
            y -= static[2, j] * d * d / s
            slope -= 2.0 * static[2, j] * d / s
    for k in range(creep.shape[1]):
        lag = state[n + k]
        y += creep[1, k] * (lag + creep[2, k] * (v - lag))
        slope += creep[1, k] * creep[2, k]
    return y, slope


@njit(cache=True)
def generalized_step(desired, pi, static, creep, config, state):  # type: ignore[no-untyped-def]
    """One command (V): solve output(v) = desired in [v_min, v_max] (output strictly increasing)."""
    n = pi.shape[1]
    m = creep.shape[1]
    last = state[n + m]
    if not math.isfinite(desired):
        state[n + m + 1] += 1.0
        # the held command is still applied for this sample: creep keeps evolving
        for k in range(m):
            state[n + k] += creep[2, k] * (last - state[n + k])
        return last
    q = config[5] + desired * config[4]
    lo, hi = config[1], config[2]
    y_lo, _ = _generalized_output(lo, pi, static, creep, config, state)
    y_hi, _ = _generalized_output(hi, pi, static, creep, config, state)
    tol = 1e-12 * (y_hi - y_lo)  # count real overshoots, not rounding at a limit
    if q <= y_lo:
        v = lo
        if q < y_lo - tol:
            state[n + m + 2] += 1.0
    elif q >= y_hi:
        v = hi
        if q > y_hi + tol:
            state[n + m + 2] += 1.0
    else:  # safeguarded Newton: the bracket always holds the root
        v = min(max(last, lo), hi)
        for _ in range(200):
            y, slope = _generalized_output(v, pi, static, creep, config, state)
            err = y - q
            if err == 0.0:
                break
            if err > 0:
                hi = v
            else:
                lo = v
            if hi - lo <= 1e-15 * (abs(lo) + abs(hi) + 1e-300):
                break
            step = v - err / slope if slope > 0 else 0.5 * (lo + hi)
            v = step if lo < step < hi else 0.5 * (lo + hi)
    mx = config[3]
    if v > last + mx:
        v = last + mx
    elif v < last - mx:
        v = last - mx
    for i in range(n):
        state[i] = min(max(state[i], v - pi[0, i]), v + pi[0, i])
    for k in range(m):
        state[n + k] += creep[2, k] * (v - state[n + k])
    state[n + m] = v
    return v


@njit(cache=True)
def generalized_process(desired, pi, static, creep, config, state, out):  # type: ignore[no-untyped-def]
    for k in range(desired.shape[0]):
        out[k] = generalized_step(desired[k], pi, static, creep, config, state)
