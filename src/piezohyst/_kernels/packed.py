"""Numba kernels of the cores beyond play operators: Duhem, Bouc-Wen and Preisach.

A core's state starts ``[v, x]``: the last input ``v`` (V) and one internal
variable ``x`` — the output ``q`` itself for Duhem and Preisach, the
Bouc-Wen variable ``h`` (V) for Bouc-Wen; Preisach adds its stack of
reversal points. A core's parameters are one packed array ``p`` whose first
slot names its kind; nothing outside :mod:`piezohyst.model.cores` and the
compensator builds one. Every core's step is strictly increasing in the new
input, so the compensator inverts it by Newton's method in a bracket (or
explicitly, for a Duhem step within ``dv_max``).

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

Preisach: see the section below; its output is an Everett function's
differences (no integration), linear in the Everett function's node values.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from .._validation import FloatArray
from . import play as K
from .play import FASTMATH

KIND_DUHEM = 0.0  # slopes over (voltage, output): the classical Duhem form
KIND_BOUC_WEN = 1.0
KIND_PREISACH = 2.0  # an Everett function over pairs of reversal points
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
PR_S_OUT = 5  # Preisach: the smallest reversible slope (kept in the layout; not used now)
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
    """h after the input moves from v0 to v1 (RK4 steps of dv_max, then the rest)."""
    dv = v1 - v0
    if dv == 0.0:
        return h0
    s = 1.0 if dv > 0.0 else -1.0
    full, rest = _steps(abs(dv), p[BW_DV_MAX])
    h = h0
    for i in range(full + (1 if rest > 0.0 else 0)):
        d = s * (p[BW_DV_MAX] if i < full else rest)
        k1 = _bw_g(p, h, s)
        k2 = _bw_g(p, h + 0.5 * d * k1, s)
        k3 = _bw_g(p, h + 0.5 * d * k2, s)
        k4 = _bw_g(p, h + d * k3, s)
        h += d * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
    return h


@njit(cache=True, fastmath=FASTMATH)
def duhem_next(p, v0, q0, v1):  # type: ignore[no-untyped-def]
    """q after the input moves from v0 to v1 (Euler steps of dv_max, then the rest)."""
    dv = v1 - v0
    up = dv > 0.0
    n, full, rest = _euler_plan(dv, p[DU_DV_MAX])
    q = q0
    v = v0
    for i in range(n):
        d = _euler_step(i, full, rest, dv, p[DU_DV_MAX])
        f, _ = duhem_slope(p, v, q, up)
        q += f * d
        v += d
    return q


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _euler_plan(dv, dv_max):  # type: ignore[no-untyped-def]
    """(steps, full steps, rest) of a Duhem move: one step within dv_max, else full steps
    of dv_max then the rest. The simulation and both fit kernels follow this plan."""
    if abs(dv) <= dv_max:
        return 1, 0, abs(dv)
    full, rest = _steps(abs(dv), dv_max)
    return full + (1 if rest > 0.0 else 0), full, rest


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _euler_step(i, full, rest, dv, dv_max):  # type: ignore[no-untyped-def]
    """The signed length of step ``i`` of ``_euler_plan``."""
    return (dv_max if i < full else rest) * (1.0 if dv > 0.0 else -1.0)


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _steps(distance, step):  # type: ignore[no-untyped-def]
    """(full steps, rest): ``distance`` covered by steps of ``step`` and a last shorter one.

    A step's outcome is continuous in its end point: when the distance grows
    past a multiple of ``step``, a vanishing rest becomes a full step. (Equal
    sub-steps, ``ceil(distance / step)`` of them, would jump there, and an
    inverse could not meet every target.)
    """
    full = int(distance / step)
    rest = distance - full * step
    if rest < 0.0:  # rounding
        rest = 0.0
    return full, rest


# --------------------------------------------------------------- Preisach
# The Everett function E(a, b) (a <= b) on a square grid of n nodes, bilinear,
# extended by E(b, a) = -E(a, b) below the diagonal (so E(v, v) = 0 inside the
# diagonal cells too) and by the smallest slope beyond the grid. Rising from a
# reversal point (minimum) a, q(v) = q(a) + E(a, v); falling from a maximum b,
# q(v) = q(b) - E(v, b): every minor loop closes by construction. The reversal
# points form a stack with Preisach's wiping-out rule (passing the previous
# extremum of the same direction removes the inner loop's pair).
# p = [kind, n, n, v_lo, h, 0, 0, 0, s_min, E (n*n, row-major, lower half unused)]
# state: [v, q, direction (0 none, +-1), k (points on the stack), R[0..STACK-1]]
STACK = 32
RV_DIR = 2
RV_K = 3
RV_R = 4
RV_SIZE = RV_R + STACK


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _node(p, i, j):  # type: ignore[no-untyped-def]
    """E at nodes (i, j), antisymmetric below the diagonal."""
    n = int(p[DU_NV])
    if i <= j:
        return p[DU_UP + i * n + j]
    return -p[DU_UP + j * n + i]


@njit(cache=True, fastmath=FASTMATH)
def everett(p, a, b):  # type: ignore[no-untyped-def]
    """(E(a, b), dE/da, dE/db): bilinear inside the grid, and beyond it each branch continued
    at its slope at the edge: ``E(a, b) = E(a', b') + (b - b') E_b(a', b') + (a - a') E_a(a',
    b')`` with ``a', b'`` the ends clamped into the grid. So E(v, v) = 0 everywhere (a loop
    beyond the grid closes, a turn there does not jump), a branch rising past the edge keeps
    its own slope there, and one turning beyond it falls at the edge's reversible slope."""
    n = p[DU_NV]
    lo = p[DU_V_LO]
    h = p[DU_V_STEP]
    hi = lo + h * (n - 1.0)
    ca = min(max(a, lo), hi)
    cb = min(max(b, lo), hi)
    i, fa, _ = _cell(ca, lo, h, n)
    j, fb, _ = _cell(cb, lo, h, n)
    e00 = _node(p, i, j)
    e01 = _node(p, i, j + 1)
    e10 = _node(p, i + 1, j)
    e11 = _node(p, i + 1, j + 1)
    e = (1.0 - fa) * ((1.0 - fb) * e00 + fb * e01) + fa * ((1.0 - fb) * e10 + fb * e11)
    dea = ((1.0 - fb) * (e10 - e00) + fb * (e11 - e01)) / h
    deb = ((1.0 - fa) * (e01 - e00) + fa * (e11 - e10)) / h
    cross = (e11 - e10 - e01 + e00) / (h * h)  # d2E/da db inside the cell
    da, db = a - ca, b - cb  # how far each end lies beyond the grid (0 inside)
    out_a = dea + (db * cross if da == 0.0 else 0.0)  # an end inside moves E_b's point
    out_b = deb + (da * cross if db == 0.0 else 0.0)
    return e + db * deb + da * dea, out_a, out_b


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _everett_add(p, acc, a, b, weight):  # type: ignore[no-untyped-def]
    """acc += weight * dE(a, b)/d(nodes): the bilinear weights, antisymmetry applied."""
    n = p[DU_NV]
    m = int(n)
    i, fa, _ = _cell(a, p[DU_V_LO], p[DU_V_STEP], n)
    j, fb, _ = _cell(b, p[DU_V_LO], p[DU_V_STEP], n)
    for di in range(2):
        for dj in range(2):
            w = (fa if di else 1.0 - fa) * (fb if dj else 1.0 - fb) * weight
            r = i + di
            c = j + dj
            if r <= c:
                acc[r * m + c] += w
            else:
                acc[c * m + r] -= w


@njit(cache=True, fastmath=FASTMATH)
def _branch(p, u0, u1, top, up, acc, track):  # type: ignore[no-untyped-def]
    """The output change along a branch from u0 to u1 whose reversal point is ``top``;
    with ``track``, its derivative in the Everett nodes is added to ``acc``."""
    if up:
        e1, _, _ = everett(p, top, u1)
        e0, _, _ = everett(p, top, u0)
        if track:
            _everett_add(p, acc, top, u1, 1.0)
            _everett_add(p, acc, top, u0, -1.0)
        return e1 - e0
    e1, _, _ = everett(p, u1, top)
    e0, _, _ = everett(p, u0, top)
    if track:
        _everett_add(p, acc, u1, top, -1.0)
        _everett_add(p, acc, u0, top, 1.0)
    return e0 - e1


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _branch_slope(p, v, top, up):  # type: ignore[no-untyped-def]
    """dq/dv at v on a branch from reversal point ``top``."""
    if up:
        _, _, deb = everett(p, top, v)
        return deb
    _, dea, _ = everett(p, v, top)
    return -dea


@njit(cache=True, fastmath=FASTMATH)
def rev_move(p, st, v1, commit, acc, track):  # type: ignore[no-untyped-def]
    """Output after the input moves from st[0] to v1, and the slope there; st updated if
    ``commit``. A reversal at st[0] is pushed; extrema passed are wiped out."""
    v0 = st[0]
    q = st[1]
    dv = v1 - v0
    k = int(st[RV_K])
    top = st[RV_R + k - 1]
    if dv == 0.0:
        return q, _branch_slope(p, v0, top, st[RV_DIR] >= 0.0)
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
            if (up and prev <= v1 and prev >= u) or (not up and prev >= v1 and prev <= u):
                end = prev
                popped = True
        q += _branch(p, u, end, top, up, acc, track)
        if not popped:
            break
        kk -= 2
        top = v0 if (push and kk - 1 == k) else st[RV_R + kk - 1]
        u = end
    f = _branch_slope(p, v1, top, up)
    if commit:
        if push and kk == k + 1:
            if k >= STACK:  # full: forget the innermost pair before this reversal, the
                # smallest loop the stack remembers (the outer ones matter most)
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
    return RV_SIZE if p[0] == KIND_PREISACH else 2


@njit(cache=True, fastmath=FASTMATH)
def core_output(p, st):  # type: ignore[no-untyped-def]
    """The core's output at state st."""
    if p[0] == KIND_BOUC_WEN:
        return p[BW_C0] * st[0] + p[BW_ALPHA] * st[1] + p[BW_OFFSET]
    return st[1]


@njit(cache=True, fastmath=FASTMATH)
def core_move(p, st, v1, commit):  # type: ignore[no-untyped-def]
    """(output, slope dy/dv) after the input moves from st[0] to v1; st updated if ``commit``."""
    if p[0] == KIND_PREISACH:
        return rev_move(p, st, v1, commit, st, False)
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


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _trial(p, st, trial, v):  # type: ignore[no-untyped-def]
    """``trial`` = the state after moving from ``st`` to ``v``; (output, slope) there."""
    for i in range(trial.shape[0]):
        trial[i] = st[i]
    return core_move(p, trial, v, True)


@njit(cache=True, fastmath=FASTMATH)
def _slow_move(p, cfg, st, trial, v):  # type: ignore[no-untyped-def]
    """The slow core's part of ``trial`` after the piezo voltage moves to ``v`` (its input
    moves along its lag from the state in ``st``); its (output, slope in v)."""
    ns = int(cfg[CC_NS])
    for i in range(ns, trial.shape[0]):
        trial[i] = st[i]
    a = cfg[CC_SLOW_A]
    c = st[ns]
    ys, fs = rev_move(p[int(cfg[CC_SLOW_AT]) :], trial[ns:], c + a * (v - c), True, trial[:0],
                      False)  # fmt: skip
    return ys, a * fs


@njit(cache=True, fastmath=FASTMATH)
def _move_all(p, cfg, st, trial, v, lin):  # type: ignore[no-untyped-def]
    """``trial`` = the state after the piezo voltage moves from ``st`` to ``v``: the core,
    and a slow core (if any) whose input moves along its lag; (output, slope) of the core
    plus ``lin * v`` plus the slow core's output. The slow core adds a slope >= 0."""
    y, f = _trial(p, st, trial, v)
    y += lin * v
    f += lin
    if cfg[CC_SLOW_AT] > 0.0:
        ys, fs = _slow_move(p, cfg, st, trial, v)
        y += ys
        f += fs
    return y, f


#: Resolution of the inverse's solve, relative to the voltage (plus one unit): a move this
#: small is a hold; Newton's bracket stops at the same width
HOLD_RES = 1e-13


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _hold(p, cfg, st, trial, v0, lo, hi, lin):  # type: ignore[no-untyped-def]
    """``core_inverse``'s answer when the command stays at v0 (inside [lo, hi])."""
    v = min(max(v0, lo), hi)
    _move_all(p, cfg, st, trial, v, lin)
    return v, v0 < lo or v0 > hi


@njit(cache=True, fastmath=FASTMATH)
def core_inverse(p, cfg, st, y, lo, hi, trial, lin):  # type: ignore[no-untyped-def]
    """The input v in [lo, hi] whose step from st gives output y, or the nearer end.

    The output solved for is the core's plus ``lin * v`` (``lin >= 0``: the part
    of kept creep lags that moves with this sample's voltage; 0 without creep).
    Returns (v, clamped): ``clamped`` is True when y is out of reach inside [lo, hi];
    ``trial`` holds the state after the step to v. A step's output is strictly
    increasing in v with slope at least ``s_min + lin`` (s_min: c0 + min(alpha, 0)
    g_max for Bouc-Wen, the smallest slope for Duhem), so the root lies between
    v0 and v0 + dy / (s_min + lin): Newton's method inside that bracket,
    bisecting whenever a step would leave it, until the output is within 1e-12
    of the step's change. A Duhem step on charge memory within dv_max is one
    Euler step: its explicit inverse is exact (the lags' part is linear too).
    A slow core (``cfg[CC_SLOW_AT]``) adds its output, nondecreasing in v: the
    bracket holds, Newton runs on the sum.
    """
    v0 = st[0]
    slow = cfg[CC_SLOW_AT] > 0.0
    slow_slope = 0.0
    dy = y - core_output(p, st) - lin * v0
    if slow:  # the slow core moves along its lag even if the voltage stays
        ys, slow_slope = _slow_move(p, cfg, st, trial, v0)
        dy -= ys
    if dy == 0.0:
        return _hold(p, cfg, st, trial, v0, lo, hi, lin)
    s = 1.0 if dy > 0.0 else -1.0
    if p[0] == KIND_BOUC_WEN:
        s_min = p[BW_S_MIN]
        g0 = _bw_g(p, st[1], s)
        # Heun's guess: the slope averaged with the one an Euler step would end on (one
        # Newton iteration fewer on a smooth step)
        g1 = _bw_g(p, st[1] + g0 * dy / (p[BW_C0] + p[BW_ALPHA] * g0), s)
        slope0 = p[BW_C0] + p[BW_ALPHA] * 0.5 * (g0 + g1)
    else:
        s_min = p[DU_F_MIN]
        if p[0] == KIND_DUHEM:
            slope0, _ = duhem_slope(p, v0, st[1], s > 0.0)
        else:  # a reversal here starts a new branch at v0
            reverse = st[RV_DIR] != 0.0 and s != st[RV_DIR]
            top = v0 if reverse else st[RV_R + int(st[RV_K]) - 1]
            slope0 = _branch_slope(p, v0, top, s > 0.0)
    slope0 += lin + slow_slope
    s_min += lin
    # (a zero slope heads for the bracket's end, as the C step's IEEE division does)
    v = v0 + dy / slope0 if slope0 != 0.0 else v0 + s * math.inf
    if abs(v - v0) <= HOLD_RES * (2.0 * abs(v0) + 1.0):
        # a move below the solve's own resolution (the output's rounding on a held
        # target): hold, or rounding dithers the command and a Preisach core's stack fills
        # with reversals a few ulp wide, forgetting the memory that matters
        return _hold(p, cfg, st, trial, v0, lo, hi, lin)
    if p[0] == KIND_DUHEM and not slow and abs(v - v0) <= p[DU_DV_MAX] and lo <= v <= hi:
        _trial(p, st, trial, v)
        return v, False
    far = v0 + 1.000001 * dy / s_min  # a branch as flat as s_min puts the root at its end
    a = max(min(v0, far), lo)
    b = min(max(v0, far), hi)
    if a >= b:  # at or beyond a limit and asked to go further out
        v = b if dy > 0.0 else a
        _move_all(p, cfg, st, trial, v, lin)
        return v, True
    at_hi = max(v0, far) > hi  # the bracket ends at a limit: try it only if Newton heads there
    at_lo = min(v0, far) < lo
    if not a < v < b:
        if v >= b:
            v = b if at_hi else 0.5 * (a + b)
        else:
            v = a if at_lo else 0.5 * (a + b)
    tol = 1e-12 * abs(dy) + 4e-16 * abs(y)  # a residual below rounding ends it too
    eps = HOLD_RES * (abs(a) + abs(b) + 1.0)
    for _ in range(NEWTON_MAX):
        if slow:
            y1, f1 = _move_all(p, cfg, st, trial, v, lin)
        else:
            y1, f1 = _trial(p, st, trial, v)
            y1 += lin * v
            f1 += lin
        res = y1 - y
        if abs(res) <= tol:
            return v, False
        if res < 0.0:
            if v >= b:  # at the upper limit and still short: out of reach
                return v, True
            a = v
        else:
            if v <= a:  # at the lower limit and still above
                return v, True
            b = v
        vn = v - res / f1 if f1 > 0.0 else 0.5 * (a + b)
        if not a < vn < b:
            if vn >= b and at_hi and b >= hi:
                vn = b
            elif vn <= a and at_lo and a <= lo:
                vn = a
            else:
                vn = 0.5 * (a + b)
        if abs(vn - v) <= eps or b - a <= eps:
            return v, False
        v = vn
    _move_all(p, cfg, st, trial, v, lin)  # the iterations ran out: the state at v returned
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
CC_NS = 9  # values in the core's state (a slow core's state follows it in st)
CC_SLOW_AT = 10  # where a slow (relaxing) Preisach core's packed params start in p; 0: none
CC_SLOW_A = 11  # its lag's 1 - exp(-dt / tau)
CC_SIZE = 12
# state: the core's state first, then four status slots addressed from the end:
DS_LAST = -4  # the last command (V)
DS_NONFINITE = -3
DS_SATURATED = -2
DS_OUTSIDE = -1  # commands that left the region (sent, or held when refusing)
DS_STATUS = 4
# between the command and the output, beside the core: dyn = [gain A, gain B] as in _kernels
# (the input dynamics; 0: absent), then (g_k, a_k) for each kept creep lag (its gain and
# 1 - exp(-dt / tau_k)); dstate = [after A, after B], then each lag's state c_k (V).
# A lag's output at this sample, c_k + a_k (u - c_k), is affine in the piezo voltage u.
DYN_LAGS = 2


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
def _advance(x, last, dyn, dstate):  # type: ignore[no-untyped-def]
    """The piezo voltage after command x (after ``last``) is held one sample (as
    ``_kernels.advance_dynamics``)."""
    w = K.delay_fraction(x, last, dyn[0])
    u = dstate[1] + dyn[1] * (w - dstate[1]) if dyn[1] > 0.0 else w
    dstate[0] = w
    dstate[1] = u
    return u


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _commit(st, trial):  # type: ignore[no-untyped-def]
    for i in range(trial.shape[0]):
        st[i] = trial[i]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _lags_affine(dyn, dstate):  # type: ignore[no-untyped-def]
    """(slope, offset): the kept lags' output at this sample is slope * u + offset."""
    lin = 0.0
    base = 0.0
    for k in range((dyn.shape[0] - DYN_LAGS) // 2):
        g = dyn[DYN_LAGS + 2 * k]
        a = dyn[DYN_LAGS + 2 * k + 1]
        lin += g * a
        base += g * (1.0 - a) * dstate[DYN_LAGS + k]
    return lin, base


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _lags_output(dyn, dstate):  # type: ignore[no-untyped-def]
    """The kept lags' part of the model's output in their current state."""
    y = 0.0
    for k in range((dyn.shape[0] - DYN_LAGS) // 2):
        y += dyn[DYN_LAGS + 2 * k] * dstate[DYN_LAGS + k]
    return y


@njit(cache=True, fastmath=FASTMATH, inline="always")
def _lags_advance(dyn, dstate, u):  # type: ignore[no-untyped-def]
    """Every kept lag after the piezo voltage u is held one sample."""
    for k in range((dyn.shape[0] - DYN_LAGS) // 2):
        c = dstate[DYN_LAGS + k]
        dstate[DYN_LAGS + k] = c + dyn[DYN_LAGS + 2 * k + 1] * (u - c)


@njit(cache=True, fastmath=FASTMATH)
def core_step(desired, p, cfg, st, region, dyn, dstate, trial):  # type: ignore[no-untyped-def]
    """One feedforward command (V) for one desired value; ``st`` updated.

    ``trial`` is scratch of the core state's size (no allocation per sample).
    """
    end = st.shape[0]
    last = st[end + DS_LAST]
    lo = cfg[CC_V_MIN]
    hi = cfg[CC_V_MAX]
    dynamic = dyn[0] != 0.0 or dyn[1] > 0.0
    if not math.isfinite(desired):  # hold the last command (the piezo keeps settling on it)
        st[end + DS_NONFINITE] += 1.0
        if dynamic or cfg[CC_SLOW_AT] > 0.0:
            held = _advance(last, last, dyn, dstate) if dynamic else st[0]
            _move_all(p, cfg, st, trial, held, 0.0)
            _commit(st, trial)
        _lags_advance(dyn, dstate, st[0])
        return last
    lin, base = _lags_affine(dyn, dstate)
    y = cfg[CC_REF] + desired * cfg[CC_INV_GAIN] - base
    step = cfg[CC_MAX_STEP]
    a, b = lo, hi
    if not dynamic:  # the slew limit bounds the inverse itself
        a = max(lo, last - step)
        b = min(hi, last + step)
    u, clamped = core_inverse(p, cfg, st, y, a, b, trial, lin)
    held = clamped and (u <= lo or u >= hi)  # out of reach inside the limits (not the slew)
    x = u
    saved0 = dstate[0]
    saved1 = dstate[1]
    if dynamic:  # invert the lags one sample at a time, then limit the command
        w = u
        if dyn[1] > 0.0:
            w = dstate[1] + (u - dstate[1]) / dyn[1]
        x = K.undo_fraction(w, dstate[0], last, dyn[0])
        if not math.isfinite(x):
            x = last
        # the lags' inverse asks beyond a voltage limit: held there, counted where the slew
        # limit did not hold it first (as the play engine's _limit)
        x, slewed, over = K.clamp(x, last, lo, hi, step)
        held = (held or over) and not slewed
    if dynamic:
        u = _advance(x, last, dyn, dstate)
        if trial[0] != u:
            _move_all(p, cfg, st, trial, u, 0.0)
    if cfg[CC_TOL] < math.inf:  # leaving the region (moves back towards it always pass)
        d1 = region_distance(region, cfg, u, core_output(p, trial))
        d0 = region_distance(region, cfg, st[0], core_output(p, st))
        if d1 > cfg[CC_TOL] and d1 > d0:
            st[end + DS_OUTSIDE] += 1.0
            if cfg[CC_REFUSE] > 0.0:
                if dynamic:  # hold the last command instead
                    dstate[0] = saved0
                    dstate[1] = saved1
                    _move_all(p, cfg, st, trial, _advance(last, last, dyn, dstate), 0.0)
                    _commit(st, trial)
                    _lags_advance(dyn, dstate, st[0])
                    return last
                # stop at the region's edge: the largest move towards u that stays inside
                edge = max(cfg[CC_TOL], d0)
                a = st[0]
                b = u
                for _ in range(REGION_BISECTIONS):
                    mid = 0.5 * (a + b)
                    ym, _ = _trial(p, st, trial, mid)
                    if region_distance(region, cfg, mid, ym) <= edge:
                        a = mid
                    else:
                        b = mid
                u = a
                x = a
                _move_all(p, cfg, st, trial, u, 0.0)
    if held and (x <= lo or x >= hi):  # sent at the voltage limit that held it
        st[end + DS_SATURATED] += 1.0
    _commit(st, trial)
    _lags_advance(dyn, dstate, st[0])
    st[end + DS_LAST] = x
    return x


@njit(cache=True, fastmath=FASTMATH)
def core_process(desired, delay, p, cfg, st, region, dyn, dstate, trial, out):  # type: ignore[no-untyped-def]
    """``core_step`` over a block; with an integer delay the command at k targets k + delay."""
    for k in range(desired.shape[0]):
        target = K.preview_target(desired, k, delay)
        out[k] = core_step(target, p, cfg, st, region, dyn, dstate, trial)


# ------------------------------------------------------------ identification
@njit(cache=True, inline="always")
def _basis_step(p, s, v, q, d, up):  # type: ignore[no-untyped-def]
    """s += d * d f±(v, q) / d(up, down) (the 4 bilinear weights of the step's cell)."""
    nv = p[DU_NV]
    nq = p[DU_NQ]
    m = int(nq)
    base = 0 if up else int(nv * nq)
    i, fa, _ = _cell(v, p[DU_V_LO], p[DU_V_STEP], nv)
    j, fb, _ = _cell(q, p[DU_Q_LO], p[DU_Q_STEP], nq)
    s[base + i * m + j] += (1.0 - fa) * (1.0 - fb) * d
    s[base + i * m + j + 1] += (1.0 - fa) * fb * d
    s[base + (i + 1) * m + j] += fa * (1.0 - fb) * d
    s[base + (i + 1) * m + j + 1] += fa * fb * d


@njit(cache=True)
def duhem_jacobian(p, v, q0, rows, qsim, jac):  # type: ignore[no-untyped-def]
    """Simulate q from q0 (qsim, every sample) and d q / d(up, down, q0) at ``rows``.

    The same Euler steps as ``duhem_next`` (a long move in steps of dv_max,
    then the rest). ``jac`` (len(rows), 2 nv nq + 1) is written; rows must be
    increasing.
    """
    cells = int(p[DU_NV] * p[DU_NQ])
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
                n, full, rest = _euler_plan(dv, p[DU_DV_MAX])
                u = v[k - 1]
                for step in range(n):
                    d = _euler_step(step, full, rest, dv, p[DU_DV_MAX])
                    f, dfdq = duhem_slope(p, u, q, up)
                    scale = 1.0 + dfdq * d
                    if scale != 1.0:
                        s *= scale
                    _basis_step(p, s, u, q, d, up)
                    q = q + f * d
                    u += d
        qsim[k] = q
        if r < nr and rows[r] == k:
            jac[r, :] = s
            r += 1


@njit(cache=True)
def rev_design(p, v, st, rows, acc, first, nmap, tmp, out):  # type: ignore[no-untyped-def]
    """The Preisach core's regressors in parameter space: ``out[r]`` = d(q[rows[r]] - q[0])
    / d(parameters), where ``nmap`` maps parameters to Everett nodes (E = nmap @ params).

    The walk of ``rev_move`` from st, which touches a few nodes per step (``tmp``, zeros
    of the nodes' size, collects them); ``acc`` carries the derivative since the record's
    start. st and acc are updated, so a record can be walked in pieces; with ``first``,
    v[0] is where st already is."""
    r = 0
    nr = rows.shape[0]
    for k in range(v.shape[0]):
        if k > 0 or not first:
            rev_move(p, st, v[k], True, tmp, True)
            for i in np.flatnonzero(tmp):  # a few nodes (array operations: fast uncompiled too)
                acc += tmp[i] * nmap[i]
                tmp[i] = 0.0
        if r < nr and rows[r] == k:
            out[r, :] = acc
            r += 1


@njit(cache=True)
def rev_columns(p, v, st, acc, out):  # type: ignore[no-untyped-def]
    """Preisach regressors along v, continuing from st: ``out[k]`` = ``acc`` after the
    move to v[k], where ``acc`` carries d q / d(Everett nodes) since the rest state
    (st and acc updated: the walk goes on in the next block)."""
    for k in range(v.shape[0]):
        rev_move(p, st, v[k], True, acc, True)
        out[k, :] = acc


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
    """Integrated regressors of the Duhem core: ``out[r]`` = the sum, over the steps before
    sample rows[r], of d(f±(v, q) dv) / d(up, down) on the measured path.

    The output is then ``q[0] + out @ (up, down)`` with the slopes evaluated
    on the measured path: linear in the slopes, and noise enters only through
    the path, not through differences of the output. A long move takes the
    Euler steps of ``duhem_next``, the output between samples interpolated.
    """
    cells = int(p[DU_NV] * p[DU_NQ])
    s = np.zeros(2 * cells)
    r = 0
    nr = rows.shape[0]
    for k in range(v.shape[0]):
        if k > 0:
            dv = v[k] - v[k - 1]
            if dv != 0.0:
                up = dv > 0.0
                n, full, rest = _euler_plan(dv, p[DU_DV_MAX])
                u = v[k - 1]
                for step in range(n):
                    d = _euler_step(step, full, rest, dv, p[DU_DV_MAX])
                    qu = q[k - 1] + (q[k] - q[k - 1]) * (u - v[k - 1]) / dv
                    _basis_step(p, s, u, qu, d, up)
                    u += d
        if r < nr and rows[r] == k:
            out[r, :] = s
            r += 1


# ---------------------------------------------------------- self-sensing loop
@njit(cache=True, fastmath=FASTMATH, inline="always")
def _model_output(p, cfg, st, dyn, dstate):  # type: ignore[no-untyped-def]
    """The hysteresis part's output in the current state: core, slow core, creep lags."""
    y = core_output(p, st) + _lags_output(dyn, dstate)
    if cfg[CC_SLOW_AT] > 0.0:
        y += st[int(cfg[CC_NS]) + 1]
    return y


@njit(cache=True, fastmath=FASTMATH)
def core_controller_step(  # type: ignore[no-untyped-def]
    desired, target, measured, p, cfg, st, region, dyn, dstate, trial, ctl, cs
):
    """``_kernels.controller_step`` on a packed core: the same feedback arithmetic
    (shared helpers), the core's inverse in place of eq. 18. ``cfg`` takes model units.
    ``target`` is what the command must bring (``desired``, or an input delay's preview);
    with input dynamics the leakage flows at the piezo's voltage (the lag's output)."""
    c2 = ctl[np.newaxis]
    cs2 = cs[np.newaxis]
    end = st.shape[0]
    last = st[end + DS_LAST]
    piezo = dstate[1] if dyn[0] != 0.0 or dyn[1] > 0.0 else last
    qc = K.feedback_measure_at(0, measured, piezo, c2, cs2)
    if math.isfinite(qc) and cs[K.CS_STARTED] == 0.0:  # the first measurement sets the frame
        cs[K.CS_FRAME] = _model_output(p, cfg, st, dyn, dstate) - qc
        cs[K.CS_STARTED] = 1.0
    e = K.feedback_error_at(0, qc, cs2)
    d, integral, u = K.feedback_command_at(0, desired, e, c2, cs2)
    if not math.isfinite(d):  # hold the last safe command (the piezo and lags settle on it)
        return core_step(math.nan, p, cfg, st, region, dyn, dstate, trial)
    u += (target - desired) * ctl[K.CTL_INV_GAIN]
    v = core_step(u, p, cfg, st, region, dyn, dstate, trial)
    K.feedback_close_at(0, d, u, _model_output(p, cfg, st, dyn, dstate), integral, c2, cs2)
    return v


@njit(cache=True, fastmath=FASTMATH)
def core_controller_process(des, delay, meas, p, cfg, st, region, dyn, dstate, trial, ctl, cs, out):  # type: ignore[no-untyped-def]
    """``core_controller_step`` over a block; the command at k for ``des[k + delay]``."""
    for k in range(des.shape[0]):
        out[k] = core_controller_step(des[k], K.preview_target(des, k, delay), meas[k], p, cfg,
                                      st, region, dyn, dstate, trial, ctl, cs)  # fmt: skip


# ------------------------------------------- Everett maps (plain NumPy, cached)
def everett_nodes(density: FloatArray) -> FloatArray:
    """Everett values at the nodes from a density on the cells: E[i, j] = sum of mu[k, l]
    over i <= k <= l < j (0 on and below the diagonal).

    Parameters
    ----------
    density : ndarray, shape (n - 1, n - 1)

    Returns
    -------
    ndarray, shape (n, n)
    """
    mu = np.triu(density)
    m = mu.shape[0]
    e = np.zeros((m + 1, m + 1))
    # E[i, j] = sum over k >= i, l < j of mu[k, l] (mu is upper triangular)
    tail = np.cumsum(mu[::-1], axis=0)[::-1]  # rows k >= i
    e[:m, 1:] = np.cumsum(tail, axis=1)
    return np.triu(e, 1)


def everett_map(n: int) -> FloatArray:
    """The matrix T with E.ravel() = T @ mu.ravel() (n nodes, (n-1)^2 cells).

    Parameters
    ----------
    n : int

    Returns
    -------
    ndarray, shape (n * n, (n - 1) ** 2)
        Read-only (one copy per grid size is kept).
    """
    return _everett_map(int(n))


@functools.lru_cache(maxsize=8)
def _everett_map(n: int) -> FloatArray:
    m = n - 1
    t = np.zeros((n * n, m * m))
    for k in range(m):
        for c in range(k, m):
            unit = np.zeros((m, m))
            unit[k, c] = 1.0
            t[:, k * m + c] = everett_nodes(unit).ravel()
    t.flags.writeable = False
    return t
