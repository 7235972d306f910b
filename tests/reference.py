"""Slow, obviously correct pure-Python references the kernels are compared against.

Written straight from the paper's equations, one sample and one operator at a
time, with no NumPy in the recursions.
"""

from __future__ import annotations

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
