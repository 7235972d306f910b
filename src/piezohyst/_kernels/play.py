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
from numba import njit, prange

from .._validation import frozen

# The one fastmath policy of every kernel: reassociation lets LLVM vectorise the
# weighted sums over operators; min/max and comparisons stay exact, so results
# differ from a sequential sum by rounding only. Never 'nnan'/'ninf': the
# compensators test for NaN and infinity, and those tests must survive.
FASTMATH = {"reassoc", "contract", "nsz"}


@njit(cache=True, fastmath=FASTMATH)
def pi_forward(x, r, w, z, y):  # type: ignore[no-untyped-def]
    """Weighted sum of play operators, sample by sample.

    x : (N,) input; r : (n,) thresholds; w : (n,) weights;
    z : (n,) operator states, updated in place (final state on return);
    y : (N,) output, written: ``y[k] = sum_i w[i] * z_i[k]``.
    """
    for k in range(x.shape[0]):
        y[k] = play_sum(x[k], r, w, z)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def play_sum(xk, r, w, z):  # type: ignore[no-untyped-def]
    """The play operators' states ``z`` moved by one input ``xk`` (in place); their weighted sum."""
    acc = 0.0
    for i in range(r.shape[0]):
        zi = min(max(z[i], xk - r[i]), xk + r[i])
        z[i] = zi
        acc += w[i] * zi
    return acc


# Fast prediction: the play operators plus at most one running integral, from the model's
# initial state. Inputs are checked here, not in Python (a bad one returns its index and
# the caller takes the checked path, which names the problem). No fastmath on the sums
# added here: they round exactly as the general path (output + column * coefficient).
FAST_NONE = 0  # no growth term
FAST_INTEGRAL = 1  # + c * sum x dt
FAST_TIME = 2  # + c * (t - t0)


@njit(cache=True, fastmath=FASTMATH)
def fast_predict(x, t, timed, r, w, z0, offset, kind, coef, out):  # type: ignore[no-untyped-def]
    """``out`` = the model's output for ``x`` (and ``t``) from ``z0``; -1, or the first bad index.

    Bad: a non-finite input, or (``timed``) a time not finite or not after the
    previous one. One pass computes the operators, the offset and the running
    integral per sample; the result equals the general path's to rounding.
    """
    m = x.shape[0]
    for k in range(m):
        if not math.isfinite(x[k]):
            return k
    if timed:
        for k in range(m):
            if not math.isfinite(t[k]) or (k > 0 and not t[k] > t[k - 1]):
                return k
    z = z0.copy()
    if kind == FAST_NONE:
        pi_forward(x, r, w, z, out)
        if offset != 0.0:
            for k in range(m):
                out[k] += offset
        return -1
    integral = 0.0
    t_prev = t[0]
    for k in range(m):
        xk = x[k]
        acc = play_sum(xk, r, w, z)
        tk = t[k]
        integral += (xk if kind == FAST_INTEGRAL else 1.0) * (tk - t_prev)
        t_prev = tk
        out[k] = (acc + offset) + integral * coef
    return -1


@njit(cache=True, fastmath=FASTMATH)
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


@njit(cache=True, fastmath=FASTMATH)
def play_states_rows(x, r, z, rows, out):  # type: ignore[no-untyped-def]
    """``play_states`` that runs through every sample but writes only ``rows`` (sorted).

    ``out[j, i]`` is operator i after sample ``rows[j]``: an outer search that
    sums a few rows of a long record does not pay for writing all of them.
    """
    n = r.shape[0]
    j = 0
    m = rows.shape[0]
    for k in range(x.shape[0]):
        xk = x[k]
        for i in range(n):
            z[i] = min(max(z[i], xk - r[i]), xk + r[i])
        if j < m and rows[j] == k:
            for i in range(n):
                out[j, i] = z[i]
            j += 1


# ---------------------------------------------------------------------------
# Compensator kernels. One layout for both inversion paths, named here and
# built by piezohyst.control.compensator; nothing else reads these arrays.
#
# tables (5, n), one row per operator quantity:
TAB_R = 0  # thresholds r_i (V)
TAB_W = 1  # weights w_i (output/V)
TAB_S = 2  # loading slopes S_i = sum_{j<=i} w_j (analytic path)
TAB_RI = 3  # inverse thresholds r'_i (output units, analytic path)
TAB_WI = 4  # inverse weights w'_i (V/output, analytic path)
# config (9,), scalars:
CFG_OFFSET = 0  # output offset c
CFG_INV_OFFSET = 1  # inverse offset c' (analytic path)
CFG_V_MIN = 2  # command limits (V)
CFG_V_MAX = 3
CFG_MAX_STEP = 4  # largest change per sample (V; inf = no slew limit)
CFG_INV_GAIN = 5  # model output units per desired unit (1/gain; 1 for charge)
CFG_REFERENCE = 6  # model output meaning desired 0 (displacement domain)
CFG_BOUND = 7  # |y - c| <= bound for every state and command within the limits (analytic)
CFG_STATIC_SCALE = 8  # scale s of the static shape (numeric path)
CONFIG_SIZE = 9
# state (n + k + 3,): forward operator states z (V, n), then k auxiliary states
# (analytic: inverse operator states zeta, k = n; numeric: creep lag states, V),
# then the status slots, addressed from the end:
ST_LAST = -3  # last command sent (V)
ST_NONFINITE = -2  # non-finite desired values (the last command was held)
ST_SATURATED = -1  # commands clipped to the limits
# static (3, K): knots, rising and falling coefficients. lags (3, m): time
# constants (s), gains, a = 1 - exp(-dt / tau) for the loop's dt.


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _inverse_states_at(c, tables, config, state):  # type: ignore[no-untyped-def]
    """``inverse_states`` of channel ``c`` of stacked arrays (no views: see ``_step_at``)."""
    n = tables.shape[2]
    tail = 0.0
    for i in range(n - 1, -1, -1):
        state[c, n + i] = config[c, CFG_OFFSET] + tables[c, TAB_S, i] * state[c, i] + tail
        tail += tables[c, TAB_W, i] * state[c, i]


@njit(cache=True, fastmath=FASTMATH)
def inverse_states(tables, config, state):  # type: ignore[no-untyped-def]
    """zeta_i = c + S_i z_i + sum_{j>i} w_j z_j (eq. 18's state map), from the forward states."""
    _inverse_states_at(0, tables[np.newaxis], config[np.newaxis], state[np.newaxis])


@njit(cache=True, fastmath=FASTMATH, inline="always")
def clamp(v, last, lo, hi, step):  # type: ignore[no-untyped-def]
    """A command inside the voltage limits ``[lo, hi]``, then within ``step`` of ``last``.

    Returns ``(sent, slewed, over)``: ``slewed`` when the slew limit cut it, ``over`` when it
    overshot a voltage limit (a real overshoot, not a limit reached exactly but for
    rounding). A voltage limit held the command where ``over and not slewed``: sent at the
    limit, not where the slew limit held it first. Inlined where it is called (a call
    returning the tuple cost a third of ``compensator_process``, measured).
    """
    over = False
    if v < lo or v > hi:
        tol = 1e-12 * (hi - lo)
        over = v < lo - tol or v > hi + tol
        v = min(max(v, lo), hi)
    slewed = True
    if v > last + step:
        v = last + step
    elif v < last - step:
        v = last - step
    else:
        slewed = False
    return v, slewed, over


@njit(cache=True, fastmath=FASTMATH)
def _limit(v, last, config, state):  # type: ignore[no-untyped-def]
    """A command clamped to the limits (real overshoots counted) and slew; True if they acted."""
    sent, slewed, over = clamp(v, last, config[CFG_V_MIN], config[CFG_V_MAX], config[CFG_MAX_STEP])
    if over and not slewed:
        state[state.shape[0] + ST_SATURATED] += 1.0
    return sent, sent != v


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _step_at(c, desired, tables, config, state):  # type: ignore[no-untyped-def]
    """``compensator_step`` for channel ``c`` of stacked arrays: tables (C, 5, n), config (C, 9),
    state (C, m).

    Indexed, never sliced: a view per channel and call costs an atomic reference count on
    the shared array, and in a parallel bank every thread fought over that one count (the
    bank step ran 1.5x slower for it).
    """
    n = tables.shape[2]
    end = state.shape[1]
    last = state[c, end + ST_LAST]
    if not math.isfinite(desired):  # NaN or +-inf: hold the last safe command
        state[c, end + ST_NONFINITE] += 1.0
        return last
    q = config[c, CFG_REFERENCE] + desired * config[c, CFG_INV_GAIN]
    # beyond +-bound nothing is reachable: clamping keeps huge values from overflowing the
    # inverse sums (inf - inf = NaN) while they still saturate on the correct side
    off = config[c, CFG_OFFSET]
    q = min(max(q, off - config[c, CFG_BOUND]), off + config[c, CFG_BOUND])
    x = config[c, CFG_INV_OFFSET]
    for i in range(n):
        zeta = min(max(state[c, n + i], q - tables[c, TAB_RI, i]), q + tables[c, TAB_RI, i])
        state[c, n + i] = zeta
        x += tables[c, TAB_WI, i] * zeta
    if not math.isfinite(x):  # belt and braces: never emit a non-finite command
        state[c, end + ST_NONFINITE] += 1.0
        _inverse_states_at(c, tables, config, state)
        return last
    v, slewed, over = clamp(x, last, config[c, CFG_V_MIN], config[c, CFG_V_MAX],
                            config[c, CFG_MAX_STEP])  # fmt: skip
    if over and not slewed:
        state[c, end + ST_SATURATED] += 1.0
    limited = v != x
    for i in range(n):
        state[c, i] = min(max(state[c, i], v - tables[c, TAB_R, i]), v + tables[c, TAB_R, i])
    if limited:
        _inverse_states_at(c, tables, config, state)
    state[c, end + ST_LAST] = v
    return v


@njit(cache=True, fastmath=FASTMATH)
def compensator_step(desired, tables, config, state):  # type: ignore[no-untyped-def]
    """One feedforward command (V) for one desired value, analytic inverse; updates ``state``.

    The inverse states run their own play recursion (eq. 18); the forward
    states follow the command actually sent. Only when a limit acts do the two
    part, and then the inverse states are rebuilt from the forward ones, so the
    next inversion starts from the actuator's real state.
    """
    return _step_at(0, desired, tables[np.newaxis], config[np.newaxis], state[np.newaxis])


# A compensator's tally of the commands the slew limit held: [last command, the limit per
# sample less rounding (inf: none), commands held, commands given, arrived, every command].
# Counting starts when the commands first arrive on the trajectory (a command the limit did
# not hold): the ramp from rest, or from the end of a precondition cycle, is the limit doing
# its job. Every command from the reset on (what the voltage limits' count is of), and of
# those, the commands at each voltage limit (``TALLY_LOW``/``TALLY_HIGH`` hold v_min, v_max):
# which side a target out of reach is on. ``TALLY_APPROACH``: the commands the limit held
# before they arrived (an approach that does not arrive is the limit biting: warned of).
TALLY_PREV = 0
TALLY_TOL = 1
TALLY_HELD = 2
TALLY_GIVEN = 3
TALLY_ARRIVED = 4
TALLY_ALL = 5
TALLY_LOW = 6
TALLY_HIGH = 7
TALLY_AT_LOW = 8
TALLY_AT_HIGH = 9
TALLY_APPROACH = 10
TALLY_SIZE = 11


@njit(cache=True, fastmath=FASTMATH)
def tally_command(c, tally):  # type: ignore[no-untyped-def]
    """Count command ``c`` in ``tally`` (see ``TALLY_PREV``); returns ``c``."""
    held = abs(c - tally[TALLY_PREV]) >= tally[TALLY_TOL]
    tally[TALLY_PREV] = c
    tally[TALLY_ALL] += 1.0
    if c <= tally[TALLY_LOW]:
        tally[TALLY_AT_LOW] += 1.0
    elif c >= tally[TALLY_HIGH]:
        tally[TALLY_AT_HIGH] += 1.0
    if tally[TALLY_ARRIVED] == 0.0:
        if held:
            tally[TALLY_APPROACH] += 1.0
            return c
        tally[TALLY_ARRIVED] = 1.0
    if held:
        tally[TALLY_HELD] += 1.0
    tally[TALLY_GIVEN] += 1.0
    return c


@njit(cache=True)
def tally_block(commands, tally):  # type: ignore[no-untyped-def]
    """:func:`tally_command` over a block of commands."""
    for k in range(commands.shape[0]):
        tally_command(commands[k], tally)


@njit(cache=True, fastmath=FASTMATH)
def compensator_step_tallied(desired, tables, config, state, tally):  # type: ignore[no-untyped-def]
    """:func:`compensator_step`, the command counted in ``tally`` (one call from Python)."""
    c = _step_at(0, desired, tables[np.newaxis], config[np.newaxis], state[np.newaxis])
    return tally_command(c, tally)


# Input dynamics of a compensator (analytic path): command -> [fraction f of a sample's delay,
# interpolated: w = (1 - f) x + f x_prev] -> [lag B] -> piezo voltage.
# ``dyn`` = [f, gain B] (0: absent; gain = 1 - exp(-dt/tau)), ``dstate`` = [after the
# fraction, after B]. An integer delay is handled by the caller (preview). The compensator
# keeps f in [-1/2, 1/2]: a model's fraction above half a sample is one more sample of preview
# and f - 1 < 0 (the same delay at low frequency; the filters differ by O(w^2) at w rad/sample).
# A fraction f > 0 is inverted as ``x = (1 + f) w_target - f w_prev``: exact on ramps, poles at
# radius f <= 1/2 (the interpolation's own inverse has its pole at -f / (1 - f), outside the
# unit circle for f > 1/2, and a pole at radius f near 1 rings at a quarter of the sample rate).
# A fraction f < 0 (an extrapolation) is inverted exactly: x = (w_target - f x_prev) / (1 - f),
# its pole at -f / (1 - f) in (0, 1/3].
DYN_FRACTION = 0
DYN_GAIN_B = 1


@njit(cache=True, fastmath=FASTMATH, inline="always")
def delay_fraction(x, last, f):  # type: ignore[no-untyped-def]
    """Command ``x`` after a delay of a fraction ``f`` of a sample (``last``: the one before)."""
    return (1.0 - f) * x + f * last if f != 0.0 else x


@njit(cache=True, fastmath=FASTMATH, inline="always")
def undo_fraction(w_target, w_prev, last, f):  # type: ignore[no-untyped-def]
    """The command whose delayed value heads for ``w_target`` (see ``DYN_FRACTION``)."""
    if f > 0.0:
        return (1.0 + f) * w_target - f * w_prev
    if f < 0.0:
        return (w_target - f * last) / (1.0 - f)
    return w_target


@njit(cache=True, fastmath=FASTMATH)
def advance_dynamics(x, last, dyn, dstate):  # type: ignore[no-untyped-def]
    """The piezo voltage after command ``x`` (after ``last``) is held for one sample."""
    w = delay_fraction(x, last, dyn[DYN_FRACTION])
    u = dstate[1] + dyn[DYN_GAIN_B] * (w - dstate[1]) if dyn[DYN_GAIN_B] > 0.0 else w
    dstate[0] = w
    dstate[1] = u
    return u


@njit(cache=True, fastmath=FASTMATH)
def dynamic_step(desired, tables, config, state, dyn, dstate):  # type: ignore[no-untyped-def]
    """``compensator_step`` with lags between the command and the piezo, inverted exactly.

    The inverse operators give the piezo voltage that yields ``desired``; the
    lags are inverted one sample at a time (exact for a command held over the
    sample); the command is limited; the piezo voltage it really produces
    drives the forward states, and the inverse states are rebuilt when it
    differs from the target (a limit acted).
    """
    n = tables.shape[1]
    end = state.shape[0]
    last = state[end + ST_LAST]
    lo = config[CFG_V_MIN]
    hi = config[CFG_V_MAX]
    if not math.isfinite(desired):  # hold the last command: the piezo keeps settling on it
        state[end + ST_NONFINITE] += 1.0
        u = advance_dynamics(last, last, dyn, dstate)
        for i in range(n):
            state[i] = min(max(state[i], u - tables[TAB_R, i]), u + tables[TAB_R, i])
        inverse_states(tables, config, state)
        return last
    q = config[CFG_REFERENCE] + desired * config[CFG_INV_GAIN]
    c = config[CFG_OFFSET]
    q = min(max(q, c - config[CFG_BOUND]), c + config[CFG_BOUND])
    target = config[CFG_INV_OFFSET]
    for i in range(n):
        zeta = min(max(state[n + i], q - tables[TAB_RI, i]), q + tables[TAB_RI, i])
        state[n + i] = zeta
        target += tables[TAB_WI, i] * zeta
    w_target = target
    if dyn[DYN_GAIN_B] > 0.0:
        w_target = dstate[1] + (target - dstate[1]) / dyn[DYN_GAIN_B]
    x = undo_fraction(w_target, dstate[0], last, dyn[DYN_FRACTION])
    if not math.isfinite(x):
        state[end + ST_NONFINITE] += 1.0
        inverse_states(tables, config, state)
        return last
    x, _ = _limit(x, last, config, state)
    u = advance_dynamics(x, last, dyn, dstate)
    for i in range(n):
        state[i] = min(max(state[i], u - tables[TAB_R, i]), u + tables[TAB_R, i])
    if abs(u - target) > 1e-12 * (hi - lo):
        inverse_states(tables, config, state)
    state[end + ST_LAST] = x
    return x


@njit(cache=True, fastmath=FASTMATH, inline="always")
def preview_target(desired, k, delay):  # type: ignore[no-untyped-def]
    """The value the command at k must reach: ``desired[k + delay]``, extrapolated linearly
    from the block's last two values beyond its end."""
    m = desired.shape[0]
    j = k + delay
    if j < m:
        return desired[j]
    if m >= 2:
        return desired[m - 1] + (j - m + 1) * (desired[m - 1] - desired[m - 2])
    return desired[m - 1]


@njit(cache=True, fastmath=FASTMATH)
def dynamic_process(desired, delay, tables, config, state, dyn, dstate, out):  # type: ignore[no-untyped-def]
    """``dynamic_step`` over a block; the command at k targets ``desired[k + delay]``: the
    block is its own preview, its last ``delay`` targets extrapolated (``preview_target``)."""
    for k in range(desired.shape[0]):
        out[k] = dynamic_step(preview_target(desired, k, delay), tables, config, state, dyn, dstate)


@njit(cache=True, fastmath=FASTMATH)
def compensator_process(desired, tables, config, state, out):  # type: ignore[no-untyped-def]
    """``compensator_step`` over a block: the same arithmetic, fused.

    The settings, the last command and the counters live in locals and the
    tables in contiguous rows for the whole block (``compensator_step`` reads
    them from the arrays at every sample); the results are identical.
    """
    n = tables.shape[1]
    end = state.shape[0]
    r = tables[TAB_R].copy()
    w = tables[TAB_W].copy()
    s_ = tables[TAB_S].copy()
    ri = tables[TAB_RI].copy()
    wi = tables[TAB_WI].copy()
    c = config[CFG_OFFSET]
    c_inv = config[CFG_INV_OFFSET]
    lo = config[CFG_V_MIN]
    hi = config[CFG_V_MAX]
    step = config[CFG_MAX_STEP]
    ref = config[CFG_REFERENCE]
    inv_gain = config[CFG_INV_GAIN]
    bound = config[CFG_BOUND]
    last = state[end + ST_LAST]
    nonfinite = state[end + ST_NONFINITE]
    saturated = state[end + ST_SATURATED]
    for k in range(desired.shape[0]):
        d = desired[k]
        if not math.isfinite(d):
            nonfinite += 1.0
            out[k] = last
            continue
        q = min(max(ref + d * inv_gain, c - bound), c + bound)
        x = c_inv
        for i in range(n):
            zeta = min(max(state[n + i], q - ri[i]), q + ri[i])
            state[n + i] = zeta
            x += wi[i] * zeta
        if not math.isfinite(x):
            nonfinite += 1.0
            tail = 0.0
            for i in range(n - 1, -1, -1):
                state[n + i] = c + s_[i] * state[i] + tail
                tail += w[i] * state[i]
            out[k] = last
            continue
        v, slewed, over = clamp(x, last, lo, hi, step)
        if over and not slewed:  # sent at the voltage limit
            saturated += 1.0
        limited = v != x
        for i in range(n):
            state[i] = min(max(state[i], v - r[i]), v + r[i])
        if limited:
            tail = 0.0
            for i in range(n - 1, -1, -1):
                state[n + i] = c + s_[i] * state[i] + tail
                tail += w[i] * state[i]
        last = v
        out[k] = v
    state[end + ST_LAST] = last
    state[end + ST_NONFINITE] = nonfinite
    state[end + ST_SATURATED] = saturated


@njit(cache=True, fastmath=FASTMATH)
def hysteresis_output(v, tables, static, lags, config, state):  # type: ignore[no-untyped-def]
    """Hysteresis-part output for command v from the current state, and its slope in v."""
    n = tables.shape[1]
    y = config[CFG_OFFSET]
    slope = 0.0
    for i in range(n):
        zi = state[i]
        lo = v - tables[TAB_R, i]
        hi = v + tables[TAB_R, i]
        w = tables[TAB_W, i]
        if zi < lo:
            y += w * lo
            slope += w
        elif zi > hi:
            y += w * hi
            slope += w
        else:
            y += w * zi
    s = config[CFG_STATIC_SCALE]
    for j in range(static.shape[1]):
        d = v - static[0, j]
        if d > 0:
            y += static[1, j] * d * d / s
            slope += 2.0 * static[1, j] * d / s
        else:
            y -= static[2, j] * d * d / s
            slope -= 2.0 * static[2, j] * d / s
    for k in range(lags.shape[1]):
        lag = state[n + k]
        y += lags[1, k] * (lag + lags[2, k] * (v - lag))
        slope += lags[1, k] * lags[2, k]
    return y, slope


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _follow(u, tables, lags, state):  # type: ignore[no-untyped-def]
    """The operators and creep lags after the piezo voltage ``u`` is held one sample."""
    n = tables.shape[1]
    for i in range(n):
        state[i] = min(max(state[i], u - tables[TAB_R, i]), u + tables[TAB_R, i])
    for k in range(lags.shape[1]):
        state[n + k] += lags[2, k] * (u - state[n + k])


@njit(cache=True, fastmath=FASTMATH)
def numeric_step(desired, tables, static, lags, config, state):  # type: ignore[no-untyped-def]
    """One command (V): solve output(v) = desired in [v_min, v_max] (output strictly increasing).

    A safeguarded Newton iteration keeps the root bracketed (``_numeric_piezo``); creep lags
    advance with the command sent (also when a NaN holds the last one).
    """
    n = tables.shape[1]
    m = lags.shape[1]
    end = state.shape[0]
    last = state[end + ST_LAST]
    if not math.isfinite(desired):
        state[end + ST_NONFINITE] += 1.0
        for k in range(m):
            state[n + k] += lags[2, k] * (last - state[n + k])
        return last
    q = config[CFG_REFERENCE] + desired * config[CFG_INV_GAIN]
    v, out_of_reach = _numeric_piezo(q, last, tables, static, lags, config, state)
    step = config[CFG_MAX_STEP]
    if v > last + step:
        v = last + step
    elif v < last - step:
        v = last - step
    elif out_of_reach:  # sent at the voltage limit (see _limit)
        state[end + ST_SATURATED] += 1.0
    _follow(v, tables, lags, state)
    state[end + ST_LAST] = v
    return v


@njit(cache=True, fastmath=FASTMATH)
def numeric_process(desired, tables, static, lags, config, state, out):  # type: ignore[no-untyped-def]
    """``numeric_step`` over a block."""
    for k in range(desired.shape[0]):
        out[k] = numeric_step(desired[k], tables, static, lags, config, state)


@njit(cache=True, fastmath=FASTMATH)
def _numeric_piezo(q, start, tables, static, lags, config, state):  # type: ignore[no-untyped-def]
    """The piezo voltage in [v_min, v_max] whose output from the current state is ``q`` (the
    nearer limit when out of reach), and whether it was out of reach (beyond rounding).

    A safeguarded Newton iteration from ``start`` (clamped into the limits): the bracket
    always holds the root.
    """
    lo = config[CFG_V_MIN]
    hi = config[CFG_V_MAX]
    y_lo, _ = hysteresis_output(lo, tables, static, lags, config, state)
    y_hi, _ = hysteresis_output(hi, tables, static, lags, config, state)
    tol = 1e-12 * (y_hi - y_lo)
    if q <= y_lo:
        return lo, q < y_lo - tol
    if q >= y_hi:
        return hi, q > y_hi + tol
    v = min(max(start, lo), hi)
    for _ in range(200):
        y, slope = hysteresis_output(v, tables, static, lags, config, state)
        err = y - q
        if err == 0.0:
            break
        if err > 0:
            hi = v
        else:
            lo = v
        if hi - lo <= 1e-15 * (abs(lo) + abs(hi) + 1e-300):
            break
        trial = v - err / slope if slope > 0 else 0.5 * (lo + hi)
        v = trial if lo < trial < hi else 0.5 * (lo + hi)
    return v, False


@njit(cache=True, fastmath=FASTMATH)
def numeric_dynamic_step(desired, tables, static, lags, config, state, dyn, dstate):  # type: ignore[no-untyped-def]
    """``numeric_step`` behind input dynamics: the piezo voltage that gives ``desired`` is
    solved as there, the lags are inverted one sample at a time (as ``dynamic_step``), the
    command limited, and the operators and creep lags follow the piezo voltage it produces."""
    end = state.shape[0]
    last = state[end + ST_LAST]
    if not math.isfinite(desired):  # hold the last command: the piezo keeps settling on it
        state[end + ST_NONFINITE] += 1.0
        u = advance_dynamics(last, last, dyn, dstate)
    else:
        q = config[CFG_REFERENCE] + desired * config[CFG_INV_GAIN]
        target, held = _numeric_piezo(q, dstate[1], tables, static, lags, config, state)
        w_target = target
        if dyn[DYN_GAIN_B] > 0.0:
            w_target = dstate[1] + (target - dstate[1]) / dyn[DYN_GAIN_B]
        x = undo_fraction(w_target, dstate[0], last, dyn[DYN_FRACTION])
        if not math.isfinite(x):
            x = last
        lo = config[CFG_V_MIN]
        hi = config[CFG_V_MAX]
        sent, slewed, over = clamp(x, last, lo, hi, config[CFG_MAX_STEP])
        held = held or over  # out of reach, or the lags' inverse asks beyond a limit
        if held and not slewed and (sent <= lo or sent >= hi):  # held by it, sent at it
            state[end + ST_SATURATED] += 1.0
        u = advance_dynamics(sent, last, dyn, dstate)
        last = sent
    _follow(u, tables, lags, state)
    state[end + ST_LAST] = last
    return last


@njit(cache=True, fastmath=FASTMATH)
def numeric_dynamic_process(desired, delay, tables, static, lags, config, state, dyn, dstate, out):  # type: ignore[no-untyped-def]
    """``numeric_dynamic_step`` over a block; the command at k targets ``desired[k + delay]``."""
    for k in range(desired.shape[0]):
        target = preview_target(desired, k, delay)
        out[k] = numeric_dynamic_step(target, tables, static, lags, config, state, dyn, dstate)


# Self-sensing controller (analytic inverse only): settings ``ctl``, state ``cs``.
CTL_KP = 0  # proportional gain on the charge error (model units per model unit)
CTL_KI = 1  # integral gain per sample
CTL_G0 = 2  # leakage conductance (model units per V*s)
CTL_G1 = 3  # voltage-dependent conductance, times v|v| / scale
CTL_INV_SCALE = 4  # 1 / scale (1/V)
CTL_DT = 5  # sample interval (s)
CTL_REF = 6  # model output meaning desired 0 (displacement domain)
CTL_INV_GAIN = 7  # model units per desired unit
CTL_TOL = 8  # |achieved - asked| below this counts as delivered (model units)
CTL_HOLD_TOL = 9  # a desired value within this of the hold's start is still the hold
CTL_HOLD_SAMPLES = 10  # samples per leakage refresh window
CTL_REFRESH = 11  # fraction of the bias error corrected per window; 0 = off
CTL_DISCHARGE = 12  # the measuring circuit's loss rate 1/tau (1/s), times the measured charge
CTL_SIZE = 13

CS_INTEGRAL = 0  # integral action (model units)
CS_LEAK = 1  # leaked charge since the frame was set (model units)
CS_FRAME = 2  # measured frame -> model frame
CS_D_PREV = 3  # the previous sample's desired output (model units; NaN: none)
CS_STARTED = 4  # 1 once a measurement set the frame
CS_FAULTS = 5  # non-finite measurements (feedforward used)
CS_ERROR = 6  # the last charge error (model units)
CS_BIAS = 7  # bias current in use (model units per s)
CS_HOLD_REF = 8  # desired value at the start of the current hold
CS_HOLD_N = 9  # samples into the current refresh window
CS_SX = 10  # regression sums of the integral over the window
CS_SY = 11
CS_SXX = 12
CS_SXY = 13
CS_SM = 14
CS_REFRESHES = 15  # leakage refreshes done
CS_Q_LAST = 16  # the last finite measured charge (for the discharge term)
CS_Y0 = 17  # the integral where the window's regression starts (sums relative to it)
CS_SIZE = 18


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _hold_window_reset_at(c, cs):  # type: ignore[no-untyped-def]
    cs[c, CS_HOLD_N] = 0.0
    cs[c, CS_SX] = 0.0
    cs[c, CS_SY] = 0.0
    cs[c, CS_SXX] = 0.0
    cs[c, CS_SXY] = 0.0
    cs[c, CS_SM] = 0.0


@njit(cache=True, fastmath=FASTMATH, inline="always")
def feedback_measure_at(c, measured, last, ctl, cs):  # type: ignore[no-untyped-def]
    """The leakage over the last sample, then the measured charge minus it (NaN if none).

    The first of the controller's three steps, shared by every model: measure,
    then ``feedback_error_at`` once the caller has set the frame, then
    ``feedback_command_at`` and, after the model's inverse, ``feedback_close_at``.
    """
    if math.isfinite(measured):
        cs[c, CS_Q_LAST] = measured
    if cs[c, CS_STARTED] > 0.0:  # leakage over the sample the last command was held
        current = ctl[c, CTL_G0] * last + ctl[c, CTL_G1] * last * abs(last) * ctl[c, CTL_INV_SCALE]
        current += cs[c, CS_BIAS] - ctl[c, CTL_DISCHARGE] * cs[c, CS_Q_LAST]
        cs[c, CS_LEAK] += current * ctl[c, CTL_DT]
    if math.isfinite(measured):
        return measured - cs[c, CS_LEAK]
    cs[c, CS_FAULTS] += 1.0
    return math.nan


@njit(cache=True, fastmath=FASTMATH, inline="always")
def feedback_error_at(c, qc, cs):  # type: ignore[no-untyped-def]
    """The charge error against the previous sample's desired value (0 without one)."""
    e = 0.0
    if math.isfinite(qc):
        qc += cs[c, CS_FRAME]
        if math.isfinite(cs[c, CS_D_PREV]):
            e = cs[c, CS_D_PREV] - qc
    cs[c, CS_ERROR] = e
    return e


@njit(cache=True, fastmath=FASTMATH, inline="always")
def feedback_command_at(c, desired, e, ctl, cs):  # type: ignore[no-untyped-def]
    """(d, integral, u): the desired output in model units, the integral if delivered, and
    what the inverse is asked for; NaN d for a non-finite desired value (the caller holds)."""
    if not math.isfinite(desired):
        cs[c, CS_D_PREV] = math.nan
        _hold_window_reset_at(c, cs)
        return math.nan, 0.0, math.nan
    d = ctl[c, CTL_REF] + desired * ctl[c, CTL_INV_GAIN]
    integral = cs[c, CS_INTEGRAL] + ctl[c, CTL_KI] * e
    return d, integral, d + ctl[c, CTL_KP] * e + integral


@njit(cache=True, fastmath=FASTMATH, inline="always")
def feedback_close_at(c, d, u, y, integral, ctl, cs):  # type: ignore[no-untyped-def]
    """After the inverse: integrate only what was delivered (anti-windup), and refresh the
    bias current from the integral's drift on holds of the desired value."""
    delivered = abs(y - u) <= ctl[c, CTL_TOL]
    if delivered:
        cs[c, CS_INTEGRAL] = integral
    cs[c, CS_D_PREV] = d
    if ctl[c, CTL_REFRESH] > 0.0:  # the integral's drift on a hold is the leakage error
        if delivered and abs(d - cs[c, CS_HOLD_REF]) <= ctl[c, CTL_HOLD_TOL]:
            cs[c, CS_HOLD_N] += 1.0
            k = cs[c, CS_HOLD_N]
            if k > 0.25 * ctl[c, CTL_HOLD_SAMPLES]:  # after the loop settled on the hold
                if cs[c, CS_SM] == 0.0:
                    cs[c, CS_Y0] = cs[c, CS_INTEGRAL]
                yi = cs[c, CS_INTEGRAL] - cs[c, CS_Y0]  # small numbers: no cancellation in the sums
                cs[c, CS_SM] += 1.0
                cs[c, CS_SX] += k
                cs[c, CS_SY] += yi
                cs[c, CS_SXX] += k * k
                cs[c, CS_SXY] += k * yi
            if k >= ctl[c, CTL_HOLD_SAMPLES]:
                m = cs[c, CS_SM]
                den = m * cs[c, CS_SXX] - cs[c, CS_SX] * cs[c, CS_SX]
                if m > 2.0 and den > 0.0:
                    slope = (m * cs[c, CS_SXY] - cs[c, CS_SX] * cs[c, CS_SY]) / den  # per sample
                    cs[c, CS_BIAS] -= ctl[c, CTL_REFRESH] * slope / ctl[c, CTL_DT]
                    cs[c, CS_REFRESHES] += 1.0
                _hold_window_reset_at(c, cs)
        else:
            cs[c, CS_HOLD_REF] = d
            _hold_window_reset_at(c, cs)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _output_at(c, tables, config, state):  # type: ignore[no-untyped-def]
    """The play operators' output now (forward states)."""
    n = tables.shape[2]
    y = config[c, CFG_OFFSET]
    for i in range(n):
        y += tables[c, TAB_W, i] * state[c, i]
    return y


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _controller_step_at(c, desired, measured, tables, config, state, ctl, cs):  # type: ignore[no-untyped-def]
    """``controller_step`` for channel ``c`` of stacked arrays (indexed: see ``_step_at``)."""
    end = state.shape[1]
    last = state[c, end + ST_LAST]
    qc = feedback_measure_at(c, measured, last, ctl, cs)
    if math.isfinite(qc) and cs[c, CS_STARTED] == 0.0:  # the first measurement sets the frame
        cs[c, CS_FRAME] = _output_at(c, tables, config, state) - qc
        cs[c, CS_STARTED] = 1.0
    e = feedback_error_at(c, qc, cs)
    d, integral, u = feedback_command_at(c, desired, e, ctl, cs)
    if not math.isfinite(d):  # hold the last safe command
        state[c, end + ST_NONFINITE] += 1.0
        return last
    v = _step_at(c, u, tables, config, state)
    feedback_close_at(c, d, u, _output_at(c, tables, config, state), integral, ctl, cs)
    return v


@njit(cache=True, fastmath=FASTMATH)
def controller_step(desired, measured, tables, config, state, ctl, cs):  # type: ignore[no-untyped-def]
    """One command (V): feedforward inverse of ``desired`` plus PI feedback on the charge.

    ``measured`` is the charge read at this sample, the response to the
    commands before it; the leakage estimate integrated over the last
    command's sample is subtracted, and the first measurement after a reset
    sets the frame (measured charge -> model output). The feedback acts in the
    charge domain before the inverse, so the inverse linearises the loop.
    The integral only moves when the command delivered what was asked (not
    at a limit or the slew limit): anti-windup by conditional integration.
    """
    return _controller_step_at(
        0,
        desired,
        measured,
        tables[np.newaxis],
        config[np.newaxis],
        state[np.newaxis],
        ctl[np.newaxis],
        cs[np.newaxis],
    )


@njit(cache=True, fastmath=FASTMATH)
def controller_process(desired, measured, tables, config, state, ctl, cs, out):  # type: ignore[no-untyped-def]
    """``controller_step`` over a block of recorded samples."""
    t3, c2, s2 = tables[np.newaxis], config[np.newaxis], state[np.newaxis]  # once, not per sample
    ctl2, cs2 = ctl[np.newaxis], cs[np.newaxis]
    for k in range(desired.shape[0]):
        out[k] = _controller_step_at(0, desired[k], measured[k], t3, c2, s2, ctl2, cs2)


@njit(cache=True, fastmath=FASTMATH)
def dynamic_controller_step(reach, target, measured, tables, config, state, ctl, cs, dyn, dstate):  # type: ignore[no-untyped-def]
    """``controller_step`` through ``dynamic_step``: the reading compared with ``reach`` (the
    output wanted now), the command computed for ``target`` (``reach``, or an input delay's
    preview); the leakage flows at the piezo's voltage (the lag's output), not the command's."""
    t3, c2, s2, ctl2, cs2 = tables[None], config[None], state[None], ctl[None], cs[None]
    qc = feedback_measure_at(0, measured, dstate[1], ctl2, cs2)
    if math.isfinite(qc) and cs[CS_STARTED] == 0.0:  # the first measurement sets the frame
        cs[CS_FRAME] = _output_at(0, t3, c2, s2) - qc
        cs[CS_STARTED] = 1.0
    d, integral, u = feedback_command_at(0, reach, feedback_error_at(0, qc, cs2), ctl2, cs2)
    if not math.isfinite(d):  # hold the last safe command (the piezo keeps settling on it)
        return dynamic_step(math.nan, tables, config, state, dyn, dstate)
    u += (target - reach) * ctl[CTL_INV_GAIN]
    v = dynamic_step(u, tables, config, state, dyn, dstate)
    feedback_close_at(0, d, u, _output_at(0, t3, c2, s2), integral, ctl2, cs2)
    return v


@njit(cache=True, fastmath=FASTMATH)
def dynamic_controller_process(d, delay, m, tables, config, state, ctl, cs, dyn, dstate, out):  # type: ignore[no-untyped-def]
    """``dynamic_controller_step`` over a block, the command at k for ``d[k + delay]``."""
    for k in range(d.shape[0]):
        out[k] = dynamic_controller_step(d[k], preview_target(d, k, delay), m[k], tables, config,
                                         state, ctl, cs, dyn, dstate)  # fmt: skip


# ---------------------------------------------------------------------------
# Banks: C channels of one structure, the single-channel kernels run per
# channel in parallel. tables (C, 5, n), config (C, CONFIG_SIZE), state
# (C, 2n + 3): row c is exactly what a single compensator of channel c holds.


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def bank_step(desired, tables, config, state, out):  # type: ignore[no-untyped-def]
    """One command per channel: ``compensator_step`` on every row, across threads."""
    for c in prange(desired.shape[0]):
        out[c] = _step_at(c, desired[c], tables, config, state)


BANK_GROUP = 128  # channels per task of bank_process
BANK_CHUNK = 128  # samples per tile: a tile's desired values and commands stay in cache


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def bank_process(desired, tables, config, state, out):  # type: ignore[no-untyped-def]
    """``compensator_process`` of every channel over a block ``desired`` (samples, C).

    Tiles of ``BANK_GROUP`` channels × ``BANK_CHUNK`` samples are copied
    channel-major into a buffer (contiguous reads of each row of the block),
    each channel runs the fused single-channel loop on its row of the tile,
    and the commands are copied back. The arithmetic is a single compensator's.
    """
    m, channels = desired.shape
    groups = (channels + BANK_GROUP - 1) // BANK_GROUP
    for g in prange(groups):
        c0 = BANK_GROUP * g
        c1 = min(c0 + BANK_GROUP, channels)
        tile = np.empty((c1 - c0, BANK_CHUNK))
        result = np.empty((c1 - c0, BANK_CHUNK))
        for k0 in range(0, m, BANK_CHUNK):
            k1 = min(k0 + BANK_CHUNK, m)
            for k in range(k0, k1):
                for c in range(c0, c1):
                    tile[c - c0, k - k0] = desired[k, c]
            for c in range(c0, c1):
                compensator_process(
                    tile[c - c0, : k1 - k0],
                    tables[c],
                    config[c],
                    state[c],
                    result[c - c0, : k1 - k0],
                )
            for k in range(k0, k1):
                for c in range(c0, c1):
                    out[k, c] = result[c - c0, k - k0]


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def bank_controller_step(desired, measured, tables, config, state, ctl, cs, out):  # type: ignore[no-untyped-def]
    """One self-sensing command per channel: ``controller_step`` on every row, across threads."""
    for c in prange(desired.shape[0]):
        out[c] = _controller_step_at(c, desired[c], measured[c], tables, config, state, ctl, cs)


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def bank_controller_process(desired, measured, tables, config, state, ctl, cs, out):  # type: ignore[no-untyped-def]
    """``controller_step`` over blocks (samples, C): groups of channels across threads."""
    m, channels = desired.shape
    groups = (channels + BANK_GROUP - 1) // BANK_GROUP
    for g in prange(groups):
        c0 = BANK_GROUP * g
        c1 = min(c0 + BANK_GROUP, channels)
        for k in range(m):
            for c in range(c0, c1):
                out[k, c] = _controller_step_at(
                    c, desired[k, c], measured[k, c], tables, config, state, ctl, cs
                )


def warm_up() -> None:
    """Compile every kernel of this module once (numba caches the result on disk), inputs
    read-only where the library's are (:func:`~piezohyst._validation.frozen`)."""
    x, r, z, state = np.zeros(2), np.zeros(1), np.zeros(1), np.zeros(5)
    pi_forward(frozen(x), frozen(r), frozen(np.ones(1)), z, np.empty(2))
    fast_predict(frozen(x), frozen(x), True, r, np.ones(1), z, 0.0, FAST_INTEGRAL, 1.0, np.empty(2))
    play_states(x, r, z, np.empty((2, 1)))
    tables = np.zeros((5, 1))
    tables[TAB_W] = tables[TAB_S] = tables[TAB_WI] = 1.0
    config = np.zeros(CONFIG_SIZE)
    config[CFG_V_MAX] = config[CFG_INV_GAIN] = config[CFG_BOUND] = config[CFG_STATIC_SCALE] = 1.0
    config[CFG_MAX_STEP] = np.inf
    inverse_states(tables, config, state)
    compensator_step(0.0, tables, config, state)
    compensator_process(x, tables, config, state, np.empty(2))
    bank_step(x[:1], tables[None], config[None], state[None], np.empty(1))
    bank_process(x[:, None], tables[None], config[None], state[None], np.empty((2, 1)))
    dynamic_process(x, 1, tables, config, state, np.zeros(2), np.zeros(2), np.empty(2))
    empty = np.zeros((3, 0))
    numeric_process(frozen(x), tables, empty, empty, config, np.zeros(4), np.empty(2))
    ctl = np.zeros(CTL_SIZE)
    ctl[CTL_DT] = ctl[CTL_INV_GAIN] = 1.0
    controller_process(x, x, tables, config, state, ctl, np.zeros(CS_SIZE), np.empty(2))
    cs = np.zeros((1, CS_SIZE))
    bank_controller_step(
        x[:1], x[:1], tables[None], config[None], state[None], ctl[None], cs, np.empty(1)
    )
    bank_controller_process(
        x[:, None],
        x[:, None],
        tables[None],
        config[None],
        state[None],
        ctl[None],
        cs,
        np.empty((2, 1)),
    )
