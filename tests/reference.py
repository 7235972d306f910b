"""Slow, obviously correct pure-Python references the kernels are compared against.

Written straight from the paper's equations, one sample and one operator at a
time, with no NumPy in the recursions.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence


def play(x: Sequence[float], r: float, y0: float) -> list[float]:
    """Eq. 9-10: H_r[x, y0](t) = max(x(t) - r, min(x(t) + r, y(t - T)))."""
    out = []
    prev = y0
    for xk in x:
        prev = max(xk - r, min(xk + r, prev))
        out.append(prev)
    return out


def classical_pi(
    x: Sequence[float],
    r: Sequence[float],
    w: Sequence[float],
    y0: Sequence[float],
    offset: float = 0.0,
) -> list[float]:
    """Eq. 11: y = offset + sum_i w_i H_{r_i}[x, y0_i]."""
    columns = [play(x, ri, y0i) for ri, y0i in zip(r, y0, strict=True)]
    return [
        offset + sum(wi * col[k] for wi, col in zip(w, columns, strict=True)) for k in range(len(x))
    ]


def integrator(x: Sequence[float], t: Sequence[float]) -> list[float]:
    """Eq. 13/19: y2(t) = x(t) T + y2(t - T), y2(0) = 0, with T = t_k - t_{k-1}."""
    out = [0.0]
    for k in range(1, len(x)):
        out.append(out[-1] + x[k] * (t[k] - t[k - 1]))
    return out


def active_pi(
    x: Sequence[float],
    t: Sequence[float],
    r: Sequence[float],
    w: Sequence[float],
    y0: Sequence[float],
    offset: float,
    growth_rate: float,
) -> list[float]:
    """Eq. 15: classical PI plus R * y2."""
    hyst = classical_pi(x, r, w, y0, offset)
    return [h + growth_rate * g for h, g in zip(hyst, integrator(x, t), strict=True)]


def inverse_parameters(r: Sequence[float], w: Sequence[float]) -> tuple[list[float], list[float]]:
    """Eq. 18 with w' (the paper prints w): inverse thresholds and weights."""
    sums = [sum(w[: i + 1]) for i in range(len(w))]
    r_inv = [sum(w[j] * (r[i] - r[j]) for j in range(i + 1)) for i in range(len(r))]
    w_inv = [1.0 / w[0]] + [-w[i] / (sums[i] * sums[i - 1]) for i in range(1, len(w))]
    return r_inv, w_inv


def ilc_update(
    correction: Sequence[float],
    error: Sequence[float],
    gain: float,
    cutoff: float,
    lag: float,
    dt: float,
    learn_mean: bool,
) -> list[float]:
    """One trial of the learning law, written out: c' = Q (c + gain L e) over the periodic
    trial, by a plain discrete Fourier sum. Q = 1 / (1 + (f/cutoff)^8) (zero phase); L inverts
    a held-input first-order lag y[k] = a y[k-1] + (1 - a) x[k], a = exp(-dt/lag)."""
    n = len(error)
    a = math.exp(-dt / lag) if lag > 0 else 0.0
    out = [0.0] * n
    for k in range(n // 2 + 1):
        f = k / (n * dt)
        q = 1.0 / (1.0 + (f / cutoff) ** 8)
        z = cmath.exp(-2j * math.pi * k / n)  # z^-1 at this harmonic
        lag_response = (1 - a) / (1 - a * z)
        c_k = sum(correction[i] * cmath.exp(-2j * math.pi * k * i / n) for i in range(n))
        e_k = sum(error[i] * cmath.exp(-2j * math.pi * k * i / n) for i in range(n))
        new = c_k + (gain * e_k / lag_response if (k > 0 or learn_mean) else 0.0)
        new *= q
        weight = 1.0 if k == 0 or (n % 2 == 0 and k == n // 2) else 2.0  # the real signal's pair
        for i in range(n):
            out[i] += weight * (new * cmath.exp(2j * math.pi * k * i / n)).real / n
    return out


def slew_hulls(u: Sequence[float], step: float) -> tuple[list[float], list[float]]:
    """The smallest sequence moving at most ``step`` per sample at or above ``u`` and the
    largest at or below, over ``u`` repeated periodically: max_j / min_j over three periods of
    ``u[j] -/+ step |k - j|`` (O(N^2) by definition)."""
    n = len(u)
    tiled = list(u) * 3
    upper = [max(tiled[j] - step * abs(k - j) for j in range(3 * n)) for k in range(n, 2 * n)]
    lower = [min(tiled[j] + step * abs(k - j) for j in range(3 * n)) for k in range(n, 2 * n)]
    return upper, lower


def _structure_sample(
    mats: Sequence[Sequence[Sequence[float]]],
    off: Sequence[float],
    x: list[float],
    z: list[list[float]],
    vk: Sequence[float],
) -> tuple[list[float], list[float]]:
    """One sample of a structure: its outputs ``y = c x + d v + off``, each actuator's
    operators (eq. 9-10) moved by its stroke ``t y`` (``z`` updated in place), and the next
    state ``a x + b v + e p`` with ``p`` their lags. ``mats`` = a, b, c, d, e, t, r."""
    a, b, c, d, e, t, r = mats
    n, m = len(a), len(c)
    y = [
        off[o]
        + sum(c[o][s] * x[s] for s in range(n))
        + sum(d[o][i] * vk[i] for i in range(len(vk)))
        for o in range(m)
    ]
    p = []
    for q in range(len(r)):
        sq = sum(t[q][o] * y[o] for o in range(m))
        for j in range(len(r[q])):
            z[q][j] = max(sq - r[q][j], min(sq + r[q][j], z[q][j]))
            p.append(z[q][j] - sq)
    nxt = [
        sum(a[s][u] * x[u] for u in range(n))
        + sum(b[s][i] * vk[i] for i in range(len(vk)))
        + sum(e[s][f] * p[f] for f in range(len(p)))
        for s in range(n)
    ]
    return y, nxt


def _at_rest(
    mats: Sequence[Sequence[Sequence[float]]], off: Sequence[float]
) -> tuple[list[float], list[list[float]]]:
    """A structure's state at rest and its operators at the rest stroke ``t off``."""
    a, _, c, _, _, t, r = mats
    return [0.0] * len(a), [
        [sum(t[q][o] * off[o] for o in range(len(c)))] * len(r[q]) for q in range(len(r))
    ]


def structure(
    a: Sequence[Sequence[float]],
    b: Sequence[Sequence[float]],
    c: Sequence[Sequence[float]],
    d: Sequence[Sequence[float]],
    e: Sequence[Sequence[float]],
    t: Sequence[Sequence[float]],
    r: Sequence[Sequence[float]],
    off: Sequence[float],
    v: Sequence[Sequence[float]],
) -> list[list[float]]:
    """A structure from rest (StructureModel): y = c x + d v + off; each actuator's stroke
    s = t y; its play operators (eq. 9-10, states starting at the rest stroke) lag it by
    p = play - s; x <- a x + b v + e p."""
    mats = (a, b, c, d, e, t, r)
    x, z = _at_rest(mats, off)
    out = []
    for vk in v:
        y, x = _structure_sample(mats, off, x, z, vk)
        out.append(y)
    return out


def structure_compensate(
    mats: Sequence[Sequence[Sequence[float]]],
    off: Sequence[float],
    gain: Sequence[Sequence[float]],
    ff: Sequence[Sequence[float]],
    hold: Sequence[bool],
    lo: Sequence[float],
    hi: Sequence[float],
    step: Sequence[float],
    slack: Sequence[float],
) -> tuple[list[list[float]], list[bool]]:
    """The structure's tracker from rest (StructureCompensator), its commands and whether
    each row asked more than ``slack`` past a limit: each command ``ff[k] - gain x``, moved
    at most ``step`` from the last and kept in ``[lo, hi]`` (a held row sends the last
    again); then the structure (:func:`structure`) runs on it. ``mats`` = a, b, c, d, e, t,
    r."""
    x, z = _at_rest(mats, off)
    last = [0.0] * len(gain)
    cmds, asked = [], []
    for k, fk in enumerate(ff):
        past = False
        if not hold[k]:
            for i in range(len(gain)):
                want = fk[i] - sum(gain[i][s] * x[s] for s in range(len(x)))
                slewed = min(last[i] + step[i], max(last[i] - step[i], want))
                past = past or not lo[i] - slack[i] <= slewed <= hi[i] + slack[i]
                last[i] = min(hi[i], max(lo[i], slewed))
        _, x = _structure_sample(mats, off, x, z, last)
        cmds.append(list(last))
        asked.append(past)
    return cmds, asked
