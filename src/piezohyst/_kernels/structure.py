"""Numba kernel of a structure moved by several actuators: coupled linear dynamics in state
space with each actuator's hysteresis inside the loop (:class:`piezohyst.StructureModel`).
A plain function over arrays and explicit state, the fastmath policy of
:mod:`piezohyst._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import play as P
from .play import FASTMATH


@njit(cache=True, fastmath=FASTMATH, inline="always")
def read_out(c, d, off, x, v, k, out):  # type: ignore[no-untyped-def]
    """``out[k] = c x + d v[k] + off``."""
    for o in range(c.shape[0]):
        acc = off[o]
        for s in range(x.shape[0]):
            acc += c[o, s] * x[s]
        for i in range(v.shape[1]):
            acc += d[o, i] * v[k, i]
        out[k, o] = acc


@njit(cache=True, fastmath=FASTMATH, inline="always")
def advance(a, b, e, x, v, k, p, xn):  # type: ignore[no-untyped-def]
    """``x <- a x + b v[k] + e p`` (``xn`` the scratch)."""
    n = x.shape[0]
    for s in range(n):
        acc = 0.0
        for u in range(n):
            acc += a[s, u] * x[u]
        for i in range(v.shape[1]):
            acc += b[s, i] * v[k, i]
        for f in range(p.shape[0]):
            acc += e[s, f] * p[f]
        xn[s] = acc
    for s in range(n):
        x[s] = xn[s]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def advance_scheduled(a, b, e, a1, b1, e1, rk, x, v, k, p, xn):  # type: ignore[no-untyped-def]
    """``x <- a x + b v[k] + e p + rk (a1 x + b1 v[k] + e1 p)``: the dynamics at the drive's
    level ``rk`` (``a1`` with no rows: :func:`advance`)."""
    if a1.shape[0] == 0:
        advance(a, b, e, x, v, k, p, xn)
        return
    n = x.shape[0]
    for s in range(n):
        acc = 0.0
        acc1 = 0.0
        for u in range(n):
            acc += a[s, u] * x[u]
            acc1 += a1[s, u] * x[u]
        for i in range(v.shape[1]):
            acc += b[s, i] * v[k, i]
            acc1 += b1[s, i] * v[k, i]
        for f in range(p.shape[0]):
            acc += e[s, f] * p[f]
            acc1 += e1[s, f] * p[f]
        xn[s] = acc + rk * acc1
    for s in range(n):
        x[s] = xn[s]


@njit(cache=True, fastmath=FASTMATH, inline="always")
def stroke(t, out, k, q):  # type: ignore[no-untyped-def]
    """Actuator ``q``'s stroke ``t[q] . out[k]``."""
    sq = 0.0
    for o in range(out.shape[1]):
        sq += t[q, o] * out[k, o]
    return sq


@njit(cache=True, fastmath=FASTMATH, inline="always")
def lags(t, r, out, k, z, p):  # type: ignore[no-untyped-def]
    """Each actuator's operators ``z`` moved by its stroke ``t out[k]``; their lags behind it
    written into ``p`` (actuator by actuator, ``r.shape[1]`` each)."""
    nk = r.shape[1]
    for q in range(r.shape[0]):
        sq = stroke(t, out, k, q)
        for j in range(nk):
            zj = min(max(z[q, j], sq - r[q, j]), sq + r[q, j])
            z[q, j] = zj
            p[q * nk + j] = zj - sq


@njit(cache=True, fastmath=FASTMATH)
def structure_run(a, b, c, d, e, t, r, off, rho, a1, b1, e1, x, z, v, out):  # type: ignore[no-untyped-def]
    """Run the structure over the inputs ``v`` (N, inputs), sample by sample::

        out[k] = c x[k] + d v[k] + off
        s[k]   = t out[k]                    (each actuator's stroke, from the outputs)
        p[k]   = play_r(s[k]) - s[k]         (each actuator's play operators, their lag)
        x[k+1] = a x[k] + b v[k] + e p[k] + rho[k] (a1 x[k] + b1 v[k] + e1 p[k])

    a (n, n), b (n, inputs), c (outputs, n), d (outputs, inputs), e (n, actuators * K),
    t (actuators, outputs), r (actuators, K) the operators' widths, off (outputs,); rho (N,)
    the drive's level and a1, b1, e1 the dynamics it schedules (a1 with no rows: none);
    x (n,) and z (actuators, K), the state and the operators' states, updated in place;
    out (N, outputs), written. The operators read this sample's output and act on the next
    state: no algebraic loop.
    """
    na = r.shape[0]
    nk = r.shape[1]
    xn = np.empty(a.shape[0])
    p = np.empty(na * nk)
    for k in range(v.shape[0]):
        read_out(c, d, off, x, v, k, out)
        lags(t, r, out, k, z, p)
        advance_scheduled(a, b, e, a1, b1, e1, rho[k] if rho.size else 0.0, x, v, k, p, xn)


@njit(cache=True, fastmath=FASTMATH)
def structure_trace(a, b, c, d, e, t, r, off, rho, a1, b1, e1, x, z, v, out, xs, ps, moved):  # type: ignore[no-untyped-def]
    """:func:`structure_run` keeping what its adjoint needs: the state before each sample
    ``xs`` (N, n), the operators' lags ``ps`` (N, actuators * K) and whether each operator
    moved ``moved`` (N, actuators * K), all written."""
    na = r.shape[0]
    nk = r.shape[1]
    xn = np.empty(a.shape[0])
    for k in range(v.shape[0]):
        for s in range(x.shape[0]):
            xs[k, s] = x[s]
        read_out(c, d, off, x, v, k, out)
        for q in range(na):
            sq = stroke(t, out, k, q)
            for j in range(nk):
                old = z[q, j]
                zj = min(max(old, sq - r[q, j]), sq + r[q, j])
                z[q, j] = zj
                moved[k, q * nk + j] = zj != old
                ps[k, q * nk + j] = zj - sq
        advance_scheduled(a, b, e, a1, b1, e1, rho[k] if rho.size else 0.0, x, v, k, ps[k], xn)


@njit(cache=True, fastmath=FASTMATH)
def structure_adjoint(  # type: ignore[no-untyped-def]
    a,
    c,
    e,
    t,
    nk,
    rho,
    a1,
    e1,
    xs,
    ps,
    moved,
    v,
    out,
    gy,
    ga,
    gb,
    gc,
    gd,
    ge,
    goff,
    gt,
    ga1,
    gb1,
    ge1,
):
    """The gradient of a loss through a traced run (its outputs ``out``): given ``gy``
    (N, outputs), the loss's derivative by each output, accumulate its derivatives by ``a``,
    ``b``, ``c``, ``d``, ``e``, ``off``, the stroke map ``t`` and the scheduled ``a1``,
    ``b1``, ``e1`` (none where ``a1`` has no rows) into ``ga`` ... ``ge1`` (reverse mode over
    the samples; the run's start taken as given). ``nk`` operators per actuator."""
    n = a.shape[0]
    m = c.shape[0]
    ni = v.shape[1]
    nf = ps.shape[1]
    na = t.shape[0]
    lam = np.zeros(n)  # the loss's derivative by the state after the sample
    mu = np.zeros(nf)  # ... by each operator's state, through the samples after it
    lam_new = np.empty(n)
    gp = np.empty(nf)
    gs = np.empty(na)
    gyk = np.empty(m)
    sched = a1.shape[0] > 0
    for k in range(v.shape[0] - 1, -1, -1):
        rk = rho[k] if sched else 0.0
        for s in range(n):
            ls = lam[s]
            for u in range(n):
                ga[s, u] += ls * xs[k, u]
            for i in range(ni):
                gb[s, i] += ls * v[k, i]
            for f in range(nf):
                ge[s, f] += ls * ps[k, f]
            if sched:
                lr = ls * rk
                for u in range(n):
                    ga1[s, u] += lr * xs[k, u]
                for i in range(ni):
                    gb1[s, i] += lr * v[k, i]
                for f in range(nf):
                    ge1[s, f] += lr * ps[k, f]
        for f in range(nf):
            acc = 0.0
            for s in range(n):
                acc += e[s, f] * lam[s]
                if sched:
                    acc += rk * e1[s, f] * lam[s]
            gp[f] = acc
        for q in range(na):
            gs[q] = 0.0
            for j in range(nk):
                f = q * nk + j
                muz = mu[f] + gp[f]
                gs[q] -= gp[f]  # the lag is the operator's state less the stroke
                if moved[k, f]:  # dragged: its state follows the stroke
                    gs[q] += muz
                    mu[f] = 0.0
                else:
                    mu[f] = muz
        for q in range(na):
            for o in range(m):
                gt[q, o] += gs[q] * out[k, o]
        for o in range(m):
            acc = gy[k, o]
            for q in range(na):
                acc += t[q, o] * gs[q]
            gyk[o] = acc
            goff[o] += acc
            for i in range(ni):
                gd[o, i] += acc * v[k, i]
            for s in range(n):
                gc[o, s] += acc * xs[k, s]
        for s in range(n):
            acc = 0.0
            for u in range(n):
                acc += a[u, s] * lam[u]
                if sched:
                    acc += rk * a1[u, s] * lam[u]
            for o in range(m):
                acc += c[o, s] * gyk[o]
            lam_new[s] = acc
        for s in range(n):
            lam[s] = lam_new[s]


@njit(cache=True, fastmath=FASTMATH)
def structure_compensate(  # type: ignore[no-untyped-def]
    a, b, c, d, e, t, r, off, gain, ff, hold, lo, hi, step, slack, x, z, last, tally, cmd, beyond
):
    """The structure's inverse with preview, sample by sample: each command the state
    feedback ``ff[k] - gain x`` (``ff`` (N, inputs) the preview's feed-forward, from the
    desired outputs ahead), then each actuator's slew limit ``step`` and voltage limits
    ``lo``, ``hi`` (inputs,) applied and the command counted in ``tally[i]``
    (:func:`~piezohyst._kernels.play.tally_command`); a row with ``hold[k]`` sends ``last``
    again; ``beyond[k]`` says whether the tracker asked an actuator for more than ``slack``
    (V, per input) past a voltage limit there (the target out of the structure's reach). The
    structure then runs on the commands sent, as :func:`structure_run` (its operators on the
    strokes it moves): ``x``, ``z`` and ``last`` updated in place, ``cmd`` (N, inputs) and
    ``beyond`` (N,) written."""
    na = r.shape[0]
    nk = r.shape[1]
    n = a.shape[0]
    xn = np.empty(n)
    p = np.empty(na * nk)
    out = np.empty((1, c.shape[0]))
    for k in range(ff.shape[0]):
        beyond[k] = False
        for i in range(ff.shape[1]):
            ci = last[i]
            if not hold[k]:
                acc = ff[k, i]
                for s in range(n):
                    acc -= gain[i, s] * x[s]
                ci = min(max(acc, last[i] - step[i]), last[i] + step[i])
                if ci < lo[i] - slack[i] or ci > hi[i] + slack[i]:
                    beyond[k] = True
                ci = min(max(ci, lo[i]), hi[i])
            last[i] = ci
            cmd[k, i] = ci
            P.tally_command(ci, tally[i])
        read_out(c, d, off, x, cmd[k : k + 1], 0, out)
        lags(t, r, out, 0, z, p)
        advance(a, b, e, x, cmd, k, p, xn)
