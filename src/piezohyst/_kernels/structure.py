"""Numba kernel of a structure moved by several actuators: coupled linear dynamics in state
space with each actuator's hysteresis inside the loop (:class:`piezohyst.StructureModel`).
A plain function over arrays and explicit state, the fastmath policy of
:mod:`piezohyst._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .play import FASTMATH


@njit(cache=True, fastmath=FASTMATH)
def structure_run(a, b, c, d, e, t, r, off, x, z, v, out):  # type: ignore[no-untyped-def]
    """Run the structure over the inputs ``v`` (N, inputs), sample by sample::

        out[k] = c x[k] + d v[k] + off
        s[k]   = t out[k]                    (each actuator's stroke, from the outputs)
        p[k]   = play_r(s[k]) - s[k]         (each actuator's play operators, their lag)
        x[k+1] = a x[k] + b v[k] + e p[k]

    a (n, n), b (n, inputs), c (outputs, n), d (outputs, inputs), e (n, actuators * K),
    t (actuators, outputs), r (actuators, K) the operators' widths, off (outputs,);
    x (n,) and z (actuators, K), the state and the operators' states, updated in place;
    out (N, outputs), written. The operators read this sample's output and act on the next
    state: no algebraic loop.
    """
    n = a.shape[0]
    m = c.shape[0]
    ni = b.shape[1]
    na = r.shape[0]
    nk = r.shape[1]
    xn = np.empty(n)
    p = np.empty(na * nk)
    for k in range(v.shape[0]):
        for o in range(m):
            acc = off[o]
            for s in range(n):
                acc += c[o, s] * x[s]
            for i in range(ni):
                acc += d[o, i] * v[k, i]
            out[k, o] = acc
        for q in range(na):
            sq = 0.0
            for o in range(m):
                sq += t[q, o] * out[k, o]
            for j in range(nk):
                zj = min(max(z[q, j], sq - r[q, j]), sq + r[q, j])
                z[q, j] = zj
                p[q * nk + j] = zj - sq
        for s in range(n):
            acc = 0.0
            for u in range(n):
                acc += a[s, u] * x[u]
            for i in range(ni):
                acc += b[s, i] * v[k, i]
            for f in range(na * nk):
                acc += e[s, f] * p[f]
            xn[s] = acc
        for s in range(n):
            x[s] = xn[s]
