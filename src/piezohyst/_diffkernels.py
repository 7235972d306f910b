"""Numba kernels of the differential hysteresis cores: Duhem and Bouc-Wen.

Both cores carry a two-value state ``[v, x]``: the last input ``v`` (V) and one
internal variable ``x`` — the hysteresis output ``q`` itself for Duhem, the
Bouc-Wen variable ``h`` (V) for Bouc-Wen. A core's parameters are one packed
array ``p`` whose first slot names its kind; nothing outside
:mod:`piezohyst.differential` and the compensator builds one.

Duhem (rate independent, explicit Euler in the voltage, sub-steps of at most
``dv_max``)::

    q[k+1] = q[k] + f±(v[k], q[k]) * (v[k+1] - v[k])      (+ rising, - falling)

with ``f±`` bilinear on a (voltage, output) grid, clamped at its edges. Both
slopes are positive, so a step is strictly increasing in ``v[k+1]``; a step
within ``dv_max`` (every step of a sampled trajectory, in practice) inverts
explicitly, ``v[k+1] = v[k] + (q* - q[k]) / f±``, a larger one by the same
safeguarded Newton solve as Bouc-Wen.

Bouc-Wen (rate independent, classical Runge-Kutta in the voltage, sub-steps
of at most ``dv_max``)::

    dh/dv = 1 - |h|^n (beta sign(h dv) + gamma),    y = c0 v + alpha h + offset

With ``beta > 0`` and ``|gamma| <= beta``, ``dh/dv`` lies in ``[0, g_max]``,
``g_max = 2 beta / (beta + gamma)`` (clamped there), so with ``c0 > 0`` and
``c0 + alpha g_max > 0`` the slope ``dy/dv`` is at least
``s_min = c0 + min(alpha, 0) g_max > 0`` and a step is strictly increasing in
``v[k+1]``; its inverse is a safeguarded Newton solve (bisection when a Newton
step leaves the bracket), at most ``NEWTON_MAX`` iterations.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _kernels as K
from ._kernels import FASTMATH

KIND_DUHEM = 0.0  # slopes over (voltage, output): the classical Duhem form
KIND_BOUC_WEN = 1.0
KIND_DUHEM_REV = 2.0  # slopes over (voltage, excursion since the last reversal)
# Duhem: p = [kind, nv, nq, v_lo, v_step, q_lo, q_step, dv_max, f_min, up (nv*nq),
# down (nv*nq)], the slopes row-major in (voltage node, output node)
DU_NV = 1
DU_NQ = 2
DU_V_LO = 3
DU_V_STEP = 4
DU_Q_LO = 5
DU_Q_STEP = 6
DU_DV_MAX = 7  # largest Euler sub-step (V)
DU_F_MIN = 8  # the smallest slope (bounds the inverse's bracket)
DU_UP = 9
# Bouc-Wen: p = [kind, c0, alpha, beta, gamma, n, offset, dv_max, g_max, s_min]
BW_C0 = 1
BW_ALPHA = 2
BW_BETA = 3
BW_GAMMA = 4
BW_N = 5
BW_OFFSET = 6
BW_DV_MAX = 7
BW_G_MAX = 8  # dh/dv never exceeds it (2 beta / (beta + gamma)): clamped there
BW_S_MIN = 9  # the smallest slope dy/dv, c0 + min(alpha, 0) g_max > 0
BW_SIZE = 10
REGION_BISECTIONS = 40  # halvings to find the region's edge along a refused move
NEWTON_MAX = 40  # iterations of the Bouc-Wen inverse (bisection halves the bracket each time)


# --------------------------------------------------------------------- Duhem
@njit(cache=True, fastmath=FASTMATH, inline="always")
def _cell(u, lo, step, nodes):  # type: ignore[no-untyped-def]
    """Cell index and fraction of coordinate ``u`` on a grid, clamped; inside flag."""
    a = (u - lo) / step
    inside = True
    if a < 0.0:
        a = 0.0
        inside = False
    elif a > nodes - 1.0:
        a = nodes - 1.0
        inside = False
    i = int(a)
    if i > nodes - 2:
        i = int(nodes) - 2
    return i, a - i, inside


@njit(cache=True, fastmath=FASTMATH)
def duhem_slope(p, v, q, up):  # type: ignore[no-untyped-def]
    """f+ (``up``) or f- at (v, q), and its derivative in q (0 outside the grid)."""
    nv = p[DU_NV]
    nq = p[DU_NQ]
    i, fa, _ = _cell(v, p[DU_V_LO], p[DU_V_STEP], nv)
    j, fb, inside_q = _cell(q, p[DU_Q_LO], p[DU_Q_STEP], nq)
    base = DU_UP + (0 if up else int(nv * nq))
    m = int(nq)
    c00 = p[base + i * m + j]
    c01 = p[base + i * m + j + 1]
    c10 = p[base + (i + 1) * m + j]
    c11 = p[base + (i + 1) * m + j + 1]
    f = (1.0 - fa) * ((1.0 - fb) * c00 + fb * c01) + fa * ((1.0 - fb) * c10 + fb * c11)
    dfdq = 0.0
    if inside_q:
        dfdq = ((1.0 - fa) * (c01 - c00) + fa * (c11 - c10)) / p[DU_Q_STEP]
    return f, dfdq


# ----------------------------------------------------------------- Bouc-Wen
@njit(cache=True, fastmath=FASTMATH, inline="always")
def _bw_g(p, h, s):  # type: ignore[no-untyped-def]
    """dh/dv for direction s (+1 rising, -1 falling), floored at 0."""
    ah = abs(h)
    n = p[BW_N]
    if n == 1.0:
        hn = ah
    elif n == 2.0:
        hn = ah * ah
    else:
        hn = ah**n
    sh = 1.0 if h >= 0.0 else -1.0
    g = 1.0 - hn * (p[BW_BETA] * sh * s + p[BW_GAMMA])
    return min(max(g, 0.0), p[BW_G_MAX])


@njit(cache=True, fastmath=FASTMATH)
def bw_next(p, v0, h0, v1):  # type: ignore[no-untyped-def]
    """h after the input moves from v0 to v1 (RK4 sub-steps of at most dv_max)."""
    dv = v1 - v0
    if dv == 0.0:
        return h0
    s = 1.0 if dv > 0.0 else -1.0
    m = math.ceil(abs(dv) / p[BW_DV_MAX])
    if m < 1:
        m = 1
    d = dv / m
    h = h0
    for _ in range(m):
        k1 = _bw_g(p, h, s)
        k2 = _bw_g(p, h + 0.5 * d * k1, s)
        k3 = _bw_g(p, h + 0.5 * d * k2, s)
        k4 = _bw_g(p, h + d * k3, s)
        h += d * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
    return h


@njit(cache=True, fastmath=FASTMATH)
def duhem_next(p, v0, q0, v1):  # type: ignore[no-untyped-def]
    """q after the input moves from v0 to v1 (Euler sub-steps of at most dv_max)."""
    dv = v1 - v0
    up = dv > 0.0
    if abs(dv) <= p[DU_DV_MAX]:
        f, _ = duhem_slope(p, v0, q0, up)
        return q0 + f * dv
    m = math.ceil(abs(dv) / p[DU_DV_MAX])
    d = dv / m
    q = q0
    v = v0
    for _ in range(m):
        f, _ = duhem_slope(p, v, q, up)
        q += f * d
        v += d
    return q


# ------------------------------------------------- Duhem on reversal memory
# The slope depends on the voltage and the excursion since the branch's
# reversal point, d = |v - v_r|; the reversal points form a stack with the
# wiping-out rule of Preisach models (passing the previous extremum of the
# same direction removes the inner loop's pair). Every step integrates the
# slope by Simpson's rule over sub-steps of at most dv_max, and the same walk,
# given an accumulator, adds up the basis functions instead: the fit's
# regressors are the simulation's own arithmetic.
# state: [v, q, direction (0 none, +-1), k (points on the stack), R[0..STACK-1]]
STACK = 32
RV_DIR = 2
RV_K = 3
RV_R = 4
RV_SIZE = RV_R + STACK


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _basis_add(p, acc, base, w, d, weight):  # type: ignore[no-untyped-def]
    """acc[base + cell] += weight * bilinear weights at (w, d)."""
    nv = p[DU_NV]
    nq = p[DU_NQ]
    m = int(nq)
    i, fa, _ = _cell(w, p[DU_V_LO], p[DU_V_STEP], nv)
    j, fb, _ = _cell(d, p[DU_Q_LO], p[DU_Q_STEP], nq)
    acc[base + i * m + j] += (1.0 - fa) * (1.0 - fb) * weight
    acc[base + i * m + j + 1] += (1.0 - fa) * fb * weight
    acc[base + (i + 1) * m + j] += fa * (1.0 - fb) * weight
    acc[base + (i + 1) * m + j + 1] += fa * fb * weight


@njit(cache=True, fastmath=FASTMATH)
def _rev_integral(p, u0, u1, top, up, acc):  # type: ignore[no-untyped-def]
    """The integral of f(w, |w - top|) dw from u0 to u1 (Simpson on sub-steps); with an
    accumulator (size > 0), the basis functions' integrals are added to it as well."""
    du = u1 - u0
    if du == 0.0:
        return 0.0
    n = math.ceil(abs(du) / p[DU_DV_MAX])
    if n < 1:
        n = 1
    h = du / n
    cells = int(p[DU_NV] * p[DU_NQ])
    base = 0 if up else cells
    total = 0.0
    track = acc.shape[0] > 0
    for m in range(n):
        a = u0 + m * h
        b = a + h if m < n - 1 else u1
        c = 0.5 * (a + b)
        fa_, _ = duhem_slope(p, a, abs(a - top), up)
        fc, _ = duhem_slope(p, c, abs(c - top), up)
        fb_, _ = duhem_slope(p, b, abs(b - top), up)
        w = b - a
        total += w * (fa_ + 4.0 * fc + fb_) / 6.0
        if track:
            _basis_add(p, acc, base, a, abs(a - top), w / 6.0)
            _basis_add(p, acc, base, c, abs(c - top), 4.0 * w / 6.0)
            _basis_add(p, acc, base, b, abs(b - top), w / 6.0)
    return total


@njit(cache=True, fastmath=FASTMATH)
def rev_move(p, st, v1, commit, acc):  # type: ignore[no-untyped-def]
    """Output after the input moves from st[0] to v1, and the slope there; st updated if
    ``commit``. A reversal at st[0] is pushed; extrema passed are wiped out."""
    v0 = st[0]
    q = st[1]
    dv = v1 - v0
    k = int(st[RV_K])
    top = st[RV_R + k - 1]
    if dv == 0.0:
        up0 = st[RV_DIR] >= 0.0
        f, _ = duhem_slope(p, v0, abs(v0 - top), up0)
        return q, f
    sd = 1.0 if dv > 0.0 else -1.0
    up = sd > 0.0
    push = st[RV_DIR] != 0.0 and sd != st[RV_DIR]
    kk = k + 1 if push else k
    if push:
        top = v0
    u = v0
    while True:
        end = v1
        popped = False
        if kk >= 3:  # the previous extremum of this direction (R[0], the rest point, stays)
            prev = v0 if (push and kk - 2 == k) else st[RV_R + kk - 2]
            if (up and prev < v1 and prev >= u) or (not up and prev > v1 and prev <= u):
                end = prev
                popped = True
        q += _rev_integral(p, u, end, top, up, acc)
        if not popped:
            break
        kk -= 2
        top = v0 if (push and kk - 1 == k) else st[RV_R + kk - 1]
        u = end
    f, _ = duhem_slope(p, v1, abs(v1 - top), up)
    if commit:
        if push and kk == k + 1:
            if k >= STACK:  # full: forget the oldest pair after the rest point
                for i in range(1, STACK - 2):
                    st[RV_R + i] = st[RV_R + i + 2]
                kk -= 2
                k -= 2
            st[RV_R + k] = v0
        st[RV_K] = kk
        st[RV_DIR] = sd
        st[0] = v1
        st[1] = q
    return q, f


# --------------------------------------------------------------- both cores
@njit(cache=True, fastmath=FASTMATH)
def state_size(p):  # type: ignore[no-untyped-def]
    """Values in a core's state."""
    return RV_SIZE if p[0] == KIND_DUHEM_REV else 2


@njit(cache=True, fastmath=FASTMATH)
def core_output(p, st):  # type: ignore[no-untyped-def]
    """The core's output at state st."""
    if p[0] == KIND_BOUC_WEN:
        return p[BW_C0] * st[0] + p[BW_ALPHA] * st[1] + p[BW_OFFSET]
    return st[1]


@njit(cache=True, fastmath=FASTMATH)
def core_move(p, st, v1, commit):  # type: ignore[no-untyped-def]
    """(output, slope dy/dv) after the input moves from st[0] to v1; st updated if ``commit``."""
    if p[0] == KIND_DUHEM_REV:
        return rev_move(p, st, v1, commit, np.empty(0))
    v0 = st[0]
    x0 = st[1]
    s = 1.0 if v1 >= v0 else -1.0
    if p[0] == KIND_DUHEM:
        x1 = duhem_next(p, v0, x0, v1)
        f, _ = duhem_slope(p, v1, x1, s > 0.0)
        y = x1
    else:
        x1 = bw_next(p, v0, x0, v1)
        f = p[BW_C0] + p[BW_ALPHA] * _bw_g(p, x1, s)
        y = p[BW_C0] * v1 + p[BW_ALPHA] * x1 + p[BW_OFFSET]
    if commit:
        st[0] = v1
        st[1] = x1
    return y, f


@njit(cache=True, fastmath=FASTMATH)
def core_propagate(p, x, st, out):  # type: ignore[no-untyped-def]
    """``out[k]`` = output after input ``x[k]``; ``st`` updated in place."""
    for k in range(x.shape[0]):
        y, _ = core_move(p, st, x[k], True)
        out[k] = y


@njit(cache=True, fastmath=FASTMATH)
def core_inverse(p, st, y, lo, hi):  # type: ignore[no-untyped-def]
    """The input v in [lo, hi] whose step from st gives output y, or the nearer end.

    Returns (v, clamped): ``clamped`` is True when y is out of reach inside [lo, hi].
    A step's output is strictly increasing in v with slope at least ``s_min``
    (c0 for Bouc-Wen, the smallest slope for Duhem), so the root lies between
    v0 and v0 + dy / s_min: Newton's method inside that bracket, bisecting
    whenever a step would leave it. A Duhem step on charge memory within
    dv_max is one Euler step: its explicit inverse is exact.
    """
    v0 = st[0]
    dy = y - core_output(p, st)
    if dy == 0.0:
        return min(max(v0, lo), hi), v0 < lo or v0 > hi
    s = 1.0 if dy > 0.0 else -1.0
    if p[0] == KIND_BOUC_WEN:
        s_min = p[BW_S_MIN]
        slope0 = p[BW_C0] + p[BW_ALPHA] * _bw_g(p, st[1], s)
    else:
        s_min = p[DU_F_MIN]
        if p[0] == KIND_DUHEM:
            slope0, _ = duhem_slope(p, v0, st[1], s > 0.0)
        else:  # a reversal here starts the new branch at excursion 0
            reverse = st[RV_DIR] != 0.0 and s != st[RV_DIR]
            top = v0 if reverse else st[RV_R + int(st[RV_K]) - 1]
            slope0, _ = duhem_slope(p, v0, abs(v0 - top), s > 0.0)
    v = v0 + dy / slope0
    if p[0] == KIND_DUHEM and abs(v - v0) <= p[DU_DV_MAX] and lo <= v <= hi:
        return v, False
    far = v0 + dy / s_min
    a = min(v0, far)
    b = max(v0, far)
    if b > hi:  # the root may lie beyond the upper limit
        yh, _ = core_move(p, st, hi, False)
        if yh <= y:
            return hi, True
        b = hi
    if a < lo:
        yl, _ = core_move(p, st, lo, False)
        if yl >= y:
            return lo, True
        a = lo
    if a >= b:
        return a, True
    if not a < v < b:
        v = 0.5 * (a + b)
    eps = 1e-13 * (abs(a) + abs(b) + 1.0)
    for _ in range(NEWTON_MAX):
        y1, f1 = core_move(p, st, v, False)
        res = y1 - y
        if res == 0.0:
            return v, False
        if res < 0.0:
            a = v
        else:
            b = v
        vn = v - res / f1 if f1 > 0.0 else 0.5 * (a + b)
        if not a < vn < b:
            vn = 0.5 * (a + b)
        if abs(vn - v) <= eps or b - a <= eps:
            return vn, False
        v = vn
    return v, False


# ------------------------------------------------------------ compensator
# config (CC_SIZE,):
CC_V_MIN = 0
CC_V_MAX = 1
CC_MAX_STEP = 2  # largest change per sample (V; inf: none)
CC_INV_GAIN = 3  # model output units per desired unit
CC_REF = 4  # model output meaning desired 0
CC_REFUSE = 5  # 1: hold the last command rather than leave the region
CC_TOL = 6  # how far outside the region's output band counts (output units; inf: no region)
CC_RV_LO = 7  # the region's voltage range (its bins split it evenly)
CC_RV_HI = 8
CC_SIZE = 9
# state: the core's state first, then four status slots addressed from the end:
DS_LAST = -4  # the last command (V)
DS_NONFINITE = -3
DS_SATURATED = -2
DS_OUTSIDE = -1  # commands that left the region (sent, or held when refusing)
DS_STATUS = 4
# input dynamics: dyn = [gain A, gain B] as in _kernels (0: absent), dstate = [after A, after B]


@njit(cache=True, fastmath=FASTMATH)
def region_distance(region, cfg, v, y):  # type: ignore[no-untyped-def]
    """How far output y lies outside the band recorded at voltage v (0 inside)."""
    m = region.shape[1]
    if m == 0:
        return 0.0
    lo = cfg[CC_RV_LO]
    hi = cfg[CC_RV_HI]
    b = int((v - lo) / (hi - lo) * m) if hi > lo else 0
    b = min(max(b, 0), m - 1)
    return max(region[0, b] - y, y - region[1, b], 0.0)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _advance(x, dyn, dstate):  # type: ignore[no-untyped-def]
    """The piezo voltage after command x is held one sample (as ``_kernels._advance_dynamics``)."""
    w = dstate[0] + dyn[0] * (x - dstate[0]) if dyn[0] > 0.0 else x
    u = dstate[1] + dyn[1] * (w - dstate[1]) if dyn[1] > 0.0 else w
    dstate[0] = w
    dstate[1] = u
    return u


@njit(cache=True, fastmath=FASTMATH)
def core_step(desired, p, cfg, st, region, dyn, dstate):  # type: ignore[no-untyped-def]
    """One feedforward command (V) for one desired value; ``st`` updated."""
    end = st.shape[0]
    last = st[end + DS_LAST]
    lo = cfg[CC_V_MIN]
    hi = cfg[CC_V_MAX]
    dynamic = dyn[0] > 0.0 or dyn[1] > 0.0
    if not math.isfinite(desired):  # hold the last command (the piezo keeps settling on it)
        st[end + DS_NONFINITE] += 1.0
        if dynamic:
            core_move(p, st, _advance(last, dyn, dstate), True)
        return last
    y = cfg[CC_REF] + desired * cfg[CC_INV_GAIN]
    step = cfg[CC_MAX_STEP]
    a, b = lo, hi
    if not dynamic:  # the slew limit bounds the inverse itself
        a = max(lo, last - step)
        b = min(hi, last + step)
    u, clamped = core_inverse(p, st, y, a, b)
    if clamped and (u <= lo or u >= hi):  # out of reach inside the limits (not the slew)
        st[end + DS_SATURATED] += 1.0
    x = u
    saved0 = dstate[0]
    saved1 = dstate[1]
    if dynamic:  # invert the lags one sample at a time, then limit the command
        w = u
        if dyn[1] > 0.0:
            w = dstate[1] + (u - dstate[1]) / dyn[1]
        x = w
        if dyn[0] > 0.0:
            x = dstate[0] + (w - dstate[0]) / dyn[0]
        if not math.isfinite(x):
            x = last
        x = min(max(x, lo), hi)
        x = min(max(x, last - step), last + step)
        u = _advance(x, dyn, dstate)
    if cfg[CC_TOL] < math.inf:  # leaving the region (moves back towards it always pass)
        y1, _ = core_move(p, st, u, False)
        d1 = region_distance(region, cfg, u, y1)
        d0 = region_distance(region, cfg, st[0], core_output(p, st))
        if d1 > cfg[CC_TOL] and d1 > d0:
            st[end + DS_OUTSIDE] += 1.0
            if cfg[CC_REFUSE] > 0.0:
                if dynamic:  # hold the last command instead
                    dstate[0] = saved0
                    dstate[1] = saved1
                    core_move(p, st, _advance(last, dyn, dstate), True)
                    return last
                # stop at the region's edge: the largest move towards u that stays inside
                edge = max(cfg[CC_TOL], d0)
                a = st[0]
                b = u
                for _ in range(REGION_BISECTIONS):
                    mid = 0.5 * (a + b)
                    ym, _ = core_move(p, st, mid, False)
                    if region_distance(region, cfg, mid, ym) <= edge:
                        a = mid
                    else:
                        b = mid
                u = a
                x = a
    core_move(p, st, u, True)
    st[end + DS_LAST] = x
    return x


@njit(cache=True, fastmath=FASTMATH)
def core_process(desired, delay, p, cfg, st, region, dyn, dstate, out):  # type: ignore[no-untyped-def]
    """``core_step`` over a block; with an integer delay the command at k targets k + delay."""
    m = desired.shape[0]
    for k in range(m):
        j = k + delay
        if j < m:
            target = desired[j]
        elif m >= 2:
            target = desired[m - 1] + (j - m + 1) * (desired[m - 1] - desired[m - 2])
        else:
            target = desired[m - 1]
        out[k] = core_step(target, p, cfg, st, region, dyn, dstate)


# ------------------------------------------------------------ identification
@njit(cache=True)
def duhem_normal_equations(p, v, q, dy, dg, gram, rhs):  # type: ignore[no-untyped-def]
    """Accumulate the increment regression: dy[k] ~ f±(v[k], q[k]) dv[k] + dg[k] @ g.

    Columns: the up coefficients, the down coefficients, then the growth
    increments ``dg`` (N-1, m). ``gram``/``rhs`` are added to.
    """
    nv = p[DU_NV]
    nq = p[DU_NQ]
    m = int(nq)
    cells = int(nv * nq)
    ng = dg.shape[1]
    idx = np.empty(4, dtype=np.int64)
    val = np.empty(4)
    for k in range(v.shape[0] - 1):
        dv = v[k + 1] - v[k]
        i, fa, _ = _cell(v[k], p[DU_V_LO], p[DU_V_STEP], nv)
        j, fb, _ = _cell(q[k], p[DU_Q_LO], p[DU_Q_STEP], nq)
        base = 0 if dv > 0.0 else cells
        nz = 0
        if dv != 0.0:
            idx[0] = base + i * m + j
            idx[1] = base + i * m + j + 1
            idx[2] = base + (i + 1) * m + j
            idx[3] = base + (i + 1) * m + j + 1
            val[0] = (1.0 - fa) * (1.0 - fb) * dv
            val[1] = (1.0 - fa) * fb * dv
            val[2] = fa * (1.0 - fb) * dv
            val[3] = fa * fb * dv
            nz = 4
        for a in range(nz):
            rhs[idx[a]] += val[a] * dy[k]
            for b in range(nz):
                gram[idx[a], idx[b]] += val[a] * val[b]
            for g in range(ng):
                gram[idx[a], 2 * cells + g] += val[a] * dg[k, g]
                gram[2 * cells + g, idx[a]] += val[a] * dg[k, g]
        for g in range(ng):
            rhs[2 * cells + g] += dg[k, g] * dy[k]
            for h in range(ng):
                gram[2 * cells + g, 2 * cells + h] += dg[k, g] * dg[k, h]


@njit(cache=True)
def duhem_jacobian(p, v, q0, rows, qsim, jac):  # type: ignore[no-untyped-def]
    """Simulate q from q0 (qsim, every sample) and d q / d(up, down, q0) at ``rows``.

    ``jac`` (len(rows), 2 nv nq + 1) is written; rows must be increasing.
    """
    nv = p[DU_NV]
    nq = p[DU_NQ]
    m = int(nq)
    cells = int(nv * nq)
    s = np.zeros(2 * cells + 1)
    s[2 * cells] = 1.0
    q = q0
    r = 0
    nr = rows.shape[0]
    for k in range(v.shape[0]):
        if k > 0:
            dv = v[k] - v[k - 1]
            if dv != 0.0:
                up = dv > 0.0
                f, dfdq = duhem_slope(p, v[k - 1], q, up)
                i, fa, _ = _cell(v[k - 1], p[DU_V_LO], p[DU_V_STEP], nv)
                j, fb, _ = _cell(q, p[DU_Q_LO], p[DU_Q_STEP], nq)
                scale = 1.0 + dfdq * dv
                if scale != 1.0:
                    for a in range(s.shape[0]):
                        s[a] *= scale
                base = 0 if up else cells
                s[base + i * m + j] += (1.0 - fa) * (1.0 - fb) * dv
                s[base + i * m + j + 1] += (1.0 - fa) * fb * dv
                s[base + (i + 1) * m + j] += fa * (1.0 - fb) * dv
                s[base + (i + 1) * m + j + 1] += fa * fb * dv
                q = q + f * dv
        qsim[k] = q
        if r < nr and rows[r] == k:
            for a in range(s.shape[0]):
                jac[r, a] = s[a]
            r += 1


@njit(cache=True)
def rev_design(p, v, st, rows, out):  # type: ignore[no-untyped-def]
    """The reversal-memory Duhem's regressors: ``out[r]`` = the basis functions' integrals
    from the record's start to sample rows[r] (the walk of ``rev_move``, st from its start)."""
    acc = np.zeros(out.shape[1])
    r = 0
    nr = rows.shape[0]
    for k in range(v.shape[0]):
        if k > 0:
            rev_move(p, st, v[k], True, acc)
        if r < nr and rows[r] == k:
            for a in range(acc.shape[0]):
                out[r, a] = acc[a]
            r += 1


@njit(cache=True)
def bw_trace(p, v, h0, out):  # type: ignore[no-untyped-def]
    """The Bouc-Wen variable h at every sample of v, from h0 at v[0]; returns the last h."""
    h = h0
    out[0] = h
    for k in range(1, v.shape[0]):
        h = bw_next(p, v[k - 1], h, v[k])
        out[k] = h
    return h


@njit(cache=True)
def duhem_cumulative(p, v, q, rows, out):  # type: ignore[no-untyped-def]
    """Integrated regressors of the charge-memory Duhem: ``out[r]`` = the sum over
    k < rows[r] of d(f±(v[k], q[k]) dv[k]) / d(up, down).

    The output is then ``q[0] + out @ (up, down)`` with the slopes evaluated
    on the measured path: linear in the slopes, and noise enters only through
    the path, not through differences of the output.
    """
    nv = p[DU_NV]
    nq = p[DU_NQ]
    m = int(nq)
    cells = int(nv * nq)
    s = np.zeros(2 * cells)
    r = 0
    nr = rows.shape[0]
    for k in range(v.shape[0]):
        if k > 0:
            dv = v[k] - v[k - 1]
            if dv != 0.0:
                i, fa, _ = _cell(v[k - 1], p[DU_V_LO], p[DU_V_STEP], nv)
                j, fb, _ = _cell(q[k - 1], p[DU_Q_LO], p[DU_Q_STEP], nq)
                base = 0 if dv > 0.0 else cells
                s[base + i * m + j] += (1.0 - fa) * (1.0 - fb) * dv
                s[base + i * m + j + 1] += (1.0 - fa) * fb * dv
                s[base + (i + 1) * m + j] += fa * (1.0 - fb) * dv
                s[base + (i + 1) * m + j + 1] += fa * fb * dv
        if r < nr and rows[r] == k:
            for a in range(2 * cells):
                out[r, a] = s[a]
            r += 1


# ---------------------------------------------------------- self-sensing loop
@njit(cache=True, fastmath=FASTMATH)
def core_controller_step(desired, measured, p, cfg, st, region, dyn, dstate, ctl, cs):  # type: ignore[no-untyped-def]
    """``_kernels.controller_step`` on a differential core: the same feedback arithmetic
    (shared helpers), the core's inverse in place of eq. 18. ``cfg`` takes model units."""
    c2 = ctl[np.newaxis]
    cs2 = cs[np.newaxis]
    end = st.shape[0]
    last = st[end + DS_LAST]
    qc = K.feedback_measure_at(0, measured, last, c2, cs2)
    if math.isfinite(qc) and cs[K.CS_STARTED] == 0.0:  # the first measurement sets the frame
        cs[K.CS_FRAME] = core_output(p, st) - qc
        cs[K.CS_STARTED] = 1.0
    e = K.feedback_error_at(0, qc, cs2)
    d, integral, u = K.feedback_command_at(0, desired, e, c2, cs2)
    if not math.isfinite(d):  # hold the last safe command
        st[end + DS_NONFINITE] += 1.0
        return last
    v = core_step(u, p, cfg, st, region, dyn, dstate)
    K.feedback_close_at(0, d, u, core_output(p, st), integral, c2, cs2)
    return v


@njit(cache=True, fastmath=FASTMATH)
def core_controller_process(desired, measured, p, cfg, st, region, dyn, dstate, ctl, cs, out):  # type: ignore[no-untyped-def]
    """``core_controller_step`` over a block of recorded samples."""
    for k in range(desired.shape[0]):
        out[k] = core_controller_step(
            desired[k], measured[k], p, cfg, st, region, dyn, dstate, ctl, cs
        )
