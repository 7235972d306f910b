"""The identification of :class:`~piezohyst.model.structure.StructureModel`, in steps.

1. **The best linear approximation**: the frequency response from every input to every
   output, by least squares over the records at each frequency (a periodic record's own
   lines; a record from rest by Welch's averaged cross-spectra), each record and output
   weighted by the inverse of that output's spread (what an error relative to the output's
   spread, the benchmark's NRMSE, weighs).
2. **A realization**: its impulse response realized in state space of the order asked by
   the eigensystem realization algorithm (python-control's ``eigensys_realization``): the
   poles ``A`` and the read-out ``C``.
3. **Everything else by least squares** given ``A`` and ``C``: the input matrix ``B``, the
   feed-through ``D``, the offsets, and the matrix ``E`` through which each actuator's play
   operators (on its stroke, the outputs mapped back by the inverse of the static gain)
   act on the next state. The outputs are linear in all of them once the operators read the
   measured outputs (equation error); the regressors are each input filtered by each mode.
4. **Output error**: all of them, the poles too, refined from there on the simulated
   outputs' error, its gradient by the adjoint of the recursion (:func:`refine`).

Plain functions over arrays; the class checks inputs and keeps the result.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import signal as sps

from .._kernels import play as P
from .._kernels import structure as S
from .._validation import FloatArray
from ..errors import IdentifiabilityWarning, ParameterError, warn

#: Input lines whose energy is below this share of the strongest are not excited
EXCITED = 1e-6
#: A line whose inputs' cross-spectrum is this ill-conditioned cannot separate the inputs
LINE_COND = 1e8
#: Periodic records that excite less than this share of the band are warned about
BAND = 0.8
#: The output-error refinement's iterations, at most (L-BFGS; it stops earlier where the
#: error no longer falls)
REFINE_ITERATIONS = 2000
#: The least squares' rows are built this many samples at a time (memory, not results)
CHUNK = 4096
#: Eigenvalues at or beyond this modulus are reflected into the unit circle (stable)
STABLE = 0.9999
#: The refinement keeps the loop's poles, where every operator sticks, within this modulus
#: (a structure at rest is stable; its own modes lie within, the mirror's at about 0.994) ...
STUCK_RADIUS = 0.9995
#: ... by a penalty of this weight on their squared excess (the error it is added to is
#: about 0.5 NRMSE^2 per output: 0.002 at 6 %)
STUCK_WEIGHT = 1000.0
#: The drive's level (:class:`Schedule`) is the inputs' RMS over this time constant (s): long
#: beside a structure's modes, short beside a record
LEVEL_TIME = 0.1
#: The dynamics are scheduled by the level only where the records' levels differ by this
#: factor at least (max over min of their RMS) ...
LEVEL_SPREAD = 1.2
#: ... and the scheduled refinement lowers the squared error by this share at least
LEVEL_GAIN = 0.05


@dataclass
class Schedule:
    """The dynamics the drive's level schedules: ``x+ = ... + rho (a1 x + b1 v + e1 p)``, with
    ``rho`` the inputs' RMS over ``tau`` samples (a first-order running mean of their squared
    norm) over ``ref``, less 1, held within ``[lo, hi]`` (the levels the records held: beyond
    them the schedule is not known)."""

    a1: FloatArray
    b1: FloatArray
    e1: FloatArray
    ref: float
    tau: float
    lo: float
    hi: float

    def levels(self, u: FloatArray, periodic: bool) -> FloatArray:
        """``rho`` at each sample of the inputs ``u`` (N, inputs): from their mean square
        (a record's start), or in the periodic steady state (one period run first)."""
        return levels(u, periodic, self.ref, self.tau, self.lo, self.hi)


def levels(
    u: FloatArray, periodic: bool, ref: float, tau: float, lo: float = -1.0, hi: float = np.inf
) -> FloatArray:
    """The drive's level ``rho`` at each sample (:class:`Schedule`)."""
    power = np.sum(u**2, axis=1)
    alpha = 1.0 / max(tau, 1.0)
    start = float(np.mean(power)) if power.size else 0.0
    if periodic:  # the period before, to its steady state: the running mean at its end
        start = float(
            sps.lfilter([alpha], [1.0, alpha - 1.0], power, zi=[(1 - alpha) * start])[0][-1]
        )
    run = sps.lfilter([alpha], [1.0, alpha - 1.0], power, zi=[(1 - alpha) * start])[0]
    return np.asarray(np.clip(np.sqrt(np.maximum(run, 0.0)) / ref - 1.0, lo, hi), dtype=np.float64)


@dataclass
class Record:
    """One record, checked: inputs (N, n), outputs (N, m), and whether it is one period of
    a periodic steady state (else it starts at rest)."""

    u: FloatArray
    y: FloatArray
    periodic: bool

    @cached_property
    def weights(self) -> FloatArray:
        """Per output: the inverse of its spread (1 where it does not move); once per record."""
        sd = np.std(self.y, axis=0)
        return np.where(sd > 0, 1.0 / np.where(sd > 0, sd, 1.0), 1.0)


@dataclass
class Structure:
    """A fitted structure: ``x+ = a x + b v + e p``, ``y = c x + d v + off``, ``p`` the play
    operators of widths ``r`` on the strokes ``t y`` (their lag behind the stroke)."""

    a: FloatArray
    b: FloatArray
    c: FloatArray
    d: FloatArray
    e: FloatArray
    t: FloatArray
    r: FloatArray
    off: FloatArray
    schedule: Schedule | None = None

    @property
    def order(self) -> int:
        return int(self.a.shape[0])

    def at(self, rho: float) -> Structure:
        """The structure at one level of the drive (itself where it holds no schedule)."""
        sc = self.schedule
        if sc is None:
            return self
        rho = float(np.clip(rho, sc.lo, sc.hi))
        return Structure(self.a + rho * sc.a1, self.b + rho * sc.b1, self.c, self.d,
                         self.e + rho * sc.e1, self.t, self.r, self.off)  # fmt: skip

    def scheduled(
        self, u: FloatArray, periodic: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The kernels' schedule arguments for the inputs ``u``: ``rho``, ``a1``, ``b1``,
        ``e1`` (empty where the structure holds no schedule)."""
        sc = self.schedule
        if sc is None:
            return np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0))
        return sc.levels(u, periodic), sc.a1, sc.b1, sc.e1

    def linear(self, stuck: bool = False) -> tuple[FloatArray, FloatArray]:
        """``a`` and ``b`` of the linear structure the loop is at either end of its
        amplitudes: every operator sliding (its lag its width, a constant: the loop open), or
        every one ``stuck`` (its output constant, so its lag ``-s`` feeds each stroke back
        through the sum of its actuator's columns of ``e``)."""
        na, nk = self.r.shape
        if not stuck or not nk:
            return self.a, self.b
        e_sum = self.e.reshape(self.order, na, nk).sum(axis=2)
        return self.a - e_sum @ self.t @ self.c, self.b - e_sum @ self.t @ self.d

    def radius(self) -> float:
        """The largest pole modulus of the two linear ends (:meth:`linear`), at both ends of
        the drive's levels where the structure holds a schedule: below 1, the structure is
        stable at every amplitude's end."""
        if self.schedule is not None:
            return max(self.at(rho).radius() for rho in (self.schedule.lo, self.schedule.hi))
        return max(float(np.max(np.abs(np.linalg.eigvals(self.linear(stuck)[0]))))
                   for stuck in (False, True))  # fmt: skip

    def dc_gain(self) -> FloatArray:
        """The static gain ``d + c (I - a)^-1 b`` (outputs, inputs)."""
        eye = np.eye(self.order)
        return np.asarray(self.d + self.c @ np.linalg.solve(eye - self.a, self.b))

    def run(self, u: FloatArray, periodic: bool) -> FloatArray:
        """The outputs for the inputs ``u`` (N, n): from rest, or in the periodic steady
        state (one period run first, its end the start)."""
        x = np.zeros(self.order)
        z = np.repeat((self.t @ self.off)[:, None], self.r.shape[1], axis=1)
        out = np.empty((u.shape[0], self.c.shape[0]))
        ua = np.ascontiguousarray(u)
        rho, a1, b1, e1 = self.scheduled(ua, periodic)
        args = (self.a, self.b, self.c, self.d, self.e, self.t, self.r, self.off, rho, a1, b1, e1)
        if periodic:
            S.structure_run(*args, x, z, ua, out)
        S.structure_run(*args, x, z, ua, out)
        return out


def impulse_response(records: list[Record]) -> FloatArray:
    """The structure's impulse response (outputs, inputs, lags), its first lag the
    feed-through: from periodic records, the inverse transform of their frequency response
    (weighted least squares at each excited line, lines not excited 0); from records at
    rest, a finite impulse response of a quarter of the shortest record's length (at most
    1024 lags) by weighted least squares (the normal equations from the records'
    correlations)."""
    if records[0].periodic:
        nfft = records[0].u.shape[0]
        if any(r.u.shape[0] != nfft for r in records):
            msg = "periodic records must all hold one period of the same length"
            raise ParameterError(msg)
        g = _lines(records)
        return np.asarray(np.fft.irfft(g, n=nfft, axis=0).transpose(1, 2, 0))
    return _fir(records, min(min(r.u.shape[0] for r in records) // 4, 1024))


def _lines(records: list[Record]) -> np.ndarray:
    """The frequency response at each line of periodic records (lines, outputs, inputs)."""
    n, m = records[0].u.shape[1], records[0].y.shape[1]
    lines = records[0].u.shape[0] // 2 + 1
    suu = np.zeros((m, lines, n, n), dtype=complex)
    suy = np.zeros((m, lines, n), dtype=complex)
    energy = np.zeros(lines)
    for rec in records:
        uf, yf = np.fft.rfft(rec.u, axis=0), np.fft.rfft(rec.y, axis=0)
        w2 = rec.weights**2
        cross = np.einsum("li,lj->lij", uf.conj(), uf)
        suu += w2[:, None, None, None] * cross[None]
        suy += w2[:, None, None] * np.einsum("li,lo->oli", uf.conj(), yf)
        energy += np.real(np.einsum("lii->l", cross))
    g = np.zeros((lines, m, n), dtype=complex)
    excited = np.flatnonzero(energy > EXCITED * energy.max())
    good = excited[np.linalg.cond(suu[0, excited]) < LINE_COND]
    if good.size < max(excited.size // 2, 1):
        msg = (
            f"the records cannot separate the {n} inputs' responses (at {excited.size - good.size} "
            f"of {excited.size} excited frequencies): record at least {n} realizations whose "
            "inputs differ (other phases), or drive each input with its own signal"
        )
        raise ParameterError(msg)
    for o in range(m):
        g[good, o, :] = np.linalg.solve(suu[o, good], suy[o, good][..., None])[..., 0]
    # the band's ends, 0 and half the sample rate, are real lines a multisine leaves out:
    # held at the nearest excited line's real part (else the impulse response would lack
    # the structure's static gain, a constant error of G(0) / N at every lag)
    if good.size and good[0] > 0:
        g[: good[0]] = g[good[0]].real
    if good.size and good[-1] < lines - 1:
        g[good[-1] + 1 :] = g[good[-1]].real
    share = good.size / max(lines - 2, 1)  # of the lines between 0 and the Nyquist frequency
    if share < BAND:
        warn(
            f"the periodic records excite {100 * share:.0f} % of the band up to half the "
            "sample rate: the structure's response elsewhere is taken as zero, which bends "
            "the realization; excite the whole band (a multisine on every line)",
            IdentifiabilityWarning,
        )
    return g


def _fir(records: list[Record], lags: int) -> FloatArray:
    """A finite impulse response of ``lags`` lags from records at rest (inputs 0 before
    the first sample) and an offset per output: weighted least squares, the normal
    equations from the records' correlations (exact: each sum stops at the record's end)."""
    n, m = records[0].u.shape[1], records[0].y.shape[1]
    size = n * lags + 1  # the last unknown: the output's offset
    normal = np.zeros((m, size, size))
    rhs = np.zeros((m, size))
    idx = np.arange(lags)
    shift = idx[:, None] - idx[None, :]  # [j, j'] -> j - j'
    for rec in records:
        nn = rec.u.shape[0]
        pad = int(2 ** np.ceil(np.log2(2 * nn)))
        uf = np.fft.rfft(rec.u, n=pad, axis=0)
        yf = np.fft.rfft(rec.y, n=pad, axis=0)
        # cuu[l, i, i'] = sum_k u_i[k] u_i'[k + l]; cuy[l, i, o] = sum_k u_i[k] y_o[k + l]
        cuu = np.fft.irfft(np.einsum("li,lj->lij", uf.conj(), uf), n=pad, axis=0)
        cuy = np.fft.irfft(np.einsum("li,lo->lio", uf.conj(), yf), n=pad, axis=0)
        block = np.empty((size, size))
        tail = rec.u[::-1][:lags]  # tail[j - 1] = u[N - j]
        for i in range(n):
            for j in range(n):
                # the sums stop at the record's end: take off what runs past it
                past = np.zeros((lags, lags))
                for d in range(1, min(lags, nn + 1)):
                    past[d, 1:] = past[d - 1, :-1] + tail[d - 1, i] * tail[: lags - 1, j]
                full = cuu[shift % pad, i, j] - past
                block[i * lags : (i + 1) * lags, j * lags : (j + 1) * lags] = full
        # the offset's column: sum_k u_i[k - j] = the sum of u_i over its first N - j samples
        sums = np.cumsum(rec.u, axis=0)[::-1][:lags]  # sums[j] = sum of u[:N - j]
        block[:-1, -1] = block[-1, :-1] = sums.T.reshape(-1)
        block[-1, -1] = nn
        w2 = rec.weights**2
        for o in range(m):
            normal[o] += w2[o] * block
            rhs[o, :-1] += w2[o] * cuy[:lags, :, o].T.reshape(-1)
            rhs[o, -1] += w2[o] * rec.y[:, o].sum()
    h = np.empty((m, n, lags))
    for o in range(m):
        ridge = 1e-9 * np.trace(normal[o]) / size
        h[o] = np.linalg.solve(normal[o] + ridge * np.eye(size), rhs[o])[:-1].reshape(n, lags)
    return h


def realize(h: FloatArray, order: int) -> tuple[FloatArray, FloatArray]:
    """``A`` and ``C`` of a realization of the impulse response ``h`` (outputs, inputs,
    lags) of the given order (the eigensystem realization algorithm), every pole inside the
    unit circle (one outside is reflected in it: the least squares that follow refit the
    rest)."""
    import control  # well kept, heavier than the rest: loaded only here

    size = min((h.shape[2] - 3) // 2, max(4 * order, 64))
    m, n = h.shape[0], h.shape[1]
    if order > min(m, n) * size:
        msg = f"order {order} is more than the records can hold (at most {min(m, n) * size})"
        raise ParameterError(msg)
    sysd, _ = control.eigensys_realization(h[:, :, : 2 * size + 2], order, m=size, n=size)
    a, c = np.asarray(sysd.A, dtype=np.float64), np.asarray(sysd.C, dtype=np.float64)
    lam, vec = np.linalg.eig(a)
    big = np.abs(lam) >= STABLE
    if np.any(big):
        lam = np.where(big, STABLE**2 / np.conj(lam), lam)
        a = np.real(vec @ np.diag(lam) @ np.linalg.inv(vec))
    return a, c


def _modes(a: FloatArray) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """The eigenvalues, eigenvectors, and each real eigenvalue (index, -1) or complex pair
    (index with positive imaginary part, its conjugate's index)."""
    lam, vec = np.linalg.eig(a)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(lam))))
    reps: list[tuple[int, int]] = []
    taken: set[int] = set()
    for k in np.argsort(-lam.imag):
        k = int(k)
        if k in taken:
            continue
        if abs(lam[k].imag) <= tol:
            reps.append((k, -1))
            taken.add(k)
            continue
        rest = [j for j in range(lam.size) if j not in taken and j != k]
        partner = rest[int(np.argmin(np.abs(lam[rest] - np.conj(lam[k]))))]
        reps.append((k, partner))
        taken.update((k, partner))
    return lam, vec, reps


def features(rec: Record, t: FloatArray, r: FloatArray) -> FloatArray:
    """The play operators' lag behind each actuator's measured stroke ``t y``: (N, actuators
    * K), a periodic record's in its steady state (run twice, the second kept)."""
    s = rec.y @ t.T  # (N, actuators)
    na, nk = r.shape
    out = np.empty((rec.y.shape[0], na * nk))
    for q in range(na):
        sq = np.ascontiguousarray(s[:, q])
        z = np.full(nk, sq[0])
        cols = np.empty((sq.size, nk))
        if rec.periodic:
            P.play_states(sq, np.ascontiguousarray(r[q]), z, cols)
        P.play_states(sq, np.ascontiguousarray(r[q]), z, cols)
        out[:, q * nk : (q + 1) * nk] = cols - sq[:, None]
    return out


def _regressors(
    filt: np.ndarray, cv_o: np.ndarray, reps: list[tuple[int, int]], size: int
) -> FloatArray:
    """One output's rows: each mode's filtered columns read out (a real mode's one column,
    a complex pair's real and imaginary parts), the feed-through and offset left 0."""
    z = filt * np.array([cv_o[k] for k, _ in reps])[None, :, None]
    blocks = []
    for p, (_, partner) in enumerate(reps):
        if partner < 0:
            blocks.append(z[:, p].real[:, None])
        else:
            blocks.append(np.stack([2 * z[:, p].real, -2 * z[:, p].imag], axis=1))
    modal = np.concatenate(blocks, axis=1).reshape(filt.shape[0], -1)
    reg = np.zeros((filt.shape[0], size))
    reg[:, : modal.shape[1]] = modal
    return reg


def least_squares(
    records: list[Record], a: FloatArray, c: FloatArray, t: FloatArray, r: FloatArray
) -> Structure:
    """``B``, ``D``, ``E`` and the offsets given the poles and read-out: one weighted
    least-squares problem over every record, output and sample."""
    lam, vec, reps = _modes(a)
    cv = c @ vec  # (outputs, n)
    n, m = records[0].u.shape[1], records[0].y.shape[1]
    nf = r.size
    cols = n + nf
    order = a.shape[0]
    size = order * cols + m * n + m
    normal = np.zeros((size, size))
    rhs = np.zeros(size)
    ones = [0.0, 1.0]
    for rec in records:
        w = np.column_stack([rec.u, features(rec, t, r)]) if nf else rec.u
        states = [np.zeros((1, cols), dtype=complex) for _ in reps]
        if rec.periodic:  # the period before: each mode's state at its end
            for p, (k, _) in enumerate(reps):
                states[p] = sps.lfilter(ones, [1.0, -lam[k]], w, axis=0, zi=states[p])[1]
        for start in range(0, rec.u.shape[0], CHUNK):  # rows a few at a time: any length
            rows = slice(start, min(start + CHUNK, rec.u.shape[0]))
            filt = np.empty((rows.stop - start, len(reps), cols), dtype=complex)
            for p, (k, _) in enumerate(reps):
                filt[:, p], states[p] = sps.lfilter(
                    ones, [1.0, -lam[k]], w[rows], axis=0, zi=states[p]
                )
            for o in range(m):
                reg = _regressors(filt, cv[o], reps, size)
                reg[:, order * cols + o * n : order * cols + (o + 1) * n] = rec.u[rows]
                reg[:, order * cols + m * n + o] = 1.0
                wo = rec.weights[o] ** 2
                normal += wo * (reg.T @ reg)
                rhs += wo * (reg.T @ rec.y[rows, o])
    ridge = 1e-10 * np.trace(normal) / size
    theta = np.linalg.solve(normal + ridge * np.eye(size), rhs)
    modal = theta[: order * cols].reshape(order, cols)
    bt = np.zeros((order, cols), dtype=complex)
    p = 0
    for k, partner in reps:
        if partner < 0:
            bt[k] = modal[p]
            p += 1
        else:
            bt[k] = modal[p] + 1j * modal[p + 1]
            bt[partner] = np.conj(bt[k])
            p += 2
    be = np.real(vec @ bt)
    d = theta[order * cols : order * cols + m * n].reshape(m, n)
    off = theta[order * cols + m * n :]
    parts = (a, be[:, :n], c, d, be[:, n:], t, r, off)
    a_, b_, c_, d_, e_, t_, r_, off_ = (np.ascontiguousarray(x, dtype=np.float64) for x in parts)
    return Structure(a_, b_, c_, d_, e_, t_, r_, off_)


def nrmse(structure: Structure, records: list[Record], tail: float = 0.0) -> float:
    """The mean over records and outputs of RMS(error) / std(measured) (%), on each
    record's last ``1 - tail`` part (all of it for 0)."""
    scores = []
    for rec in records:
        err = structure.run(rec.u, rec.periodic) - rec.y
        start = int(tail * rec.u.shape[0])
        sd = np.std(rec.y[start:], axis=0)
        rms = np.sqrt(np.mean(err[start:] ** 2, axis=0))
        scores.append(np.where(sd > 0, rms / np.where(sd > 0, sd, 1.0), rms))
    value = 100.0 * float(np.mean(scores))
    return value if np.isfinite(value) else float("inf")


def _built(blocks: list[np.ndarray], r: FloatArray, schedule: Schedule | None) -> Structure:
    """The refinement's blocks ``a, b, c, d, e, off, t`` (and ``a1, b1, e1`` where the
    dynamics are scheduled) as a :class:`Structure`."""
    a, b, c, d, e, off, t, *rest = blocks
    sched = None
    if schedule is not None:
        a1, b1, e1 = rest
        sched = Schedule(a1, b1, e1, schedule.ref, schedule.tau, schedule.lo, schedule.hi)
    return Structure(a, b, c, d, e, t, r, off, sched)


def stuck_penalty(
    a: FloatArray, c: FloatArray, e: FloatArray, t: FloatArray, nk: int, grads: list[FloatArray]
) -> float:
    """The refinement's penalty on the loop's poles past :data:`STUCK_RADIUS` where every
    operator sticks (``a - E' t c``, :meth:`Structure.linear`): :data:`STUCK_WEIGHT` times
    the sum of each one's squared excess, its gradient added to ``grads`` (``a, b, c, d, e,
    off, t``) by the eigenvalues' first-order perturbation (``d lam = w dM v``)."""
    order, na = a.shape[0], t.shape[0]
    e_sum = e.reshape(order, na, nk).sum(axis=2)
    lam, vec = np.linalg.eig(a - e_sum @ t @ c)
    excess = np.abs(lam) - STUCK_RADIUS
    over = np.flatnonzero(excess > 0)
    if not over.size:
        return 0.0
    left = np.linalg.inv(vec)  # rows: left eigenvectors, left @ vec = I
    g = np.zeros_like(a)
    for i in over:
        phase = np.conj(lam[i]) / abs(lam[i])
        g += 2 * STUCK_WEIGHT * excess[i] * np.real(phase * np.outer(left[i], vec[:, i]))
    ga, _, gc, _, ge, _, gt = grads
    ga += g
    g_sum = -g @ c.T @ t.T  # d/dE' of -E' t c
    ge += np.repeat(g_sum, nk, axis=1)
    gt += -e_sum.T @ g @ c.T
    gc += -(e_sum @ t).T @ g
    return float(STUCK_WEIGHT * np.sum(excess[over] ** 2))


@dataclass(frozen=True)
class Refinement:
    """What the output-error refinement did: the weighted squared error before and after,
    the iterations, and whether the result was kept (stable and lower)."""

    before: float
    after: float
    iterations: int
    kept: bool


def refine(
    records: list[Record],
    structure: Structure,
    maxiter: int = REFINE_ITERATIONS,
    schedule: Schedule | None = None,
) -> tuple[Structure, Refinement]:
    """Every matrix (the stroke map too) and the offsets refined by **output error**: the
    squared error of the simulated outputs (each record and output weighted by the inverse
    of its variance), its gradient by the adjoint of the recursion (reverse mode through the
    play operators), minimised by L-BFGS from the least squares' solution. The equation
    error the least squares minimise reads the measured outputs in the loop, and is biased
    where the loop matters; this is the structure's own error. With operators in the loop,
    where the refined loop is unstable with every operator stuck, the operators' action on
    the state is scaled down until it is stable, and it is refined again from there with
    its poles held within :data:`STUCK_RADIUS` (:func:`stuck_penalty`). Kept
    only if stable (with the operators sliding and stuck: :meth:`Structure.radius`) and
    lower, or stable where the start was not.

    With a ``schedule`` (its levels; its matrices the start, or the structure's own), the
    dynamics the drive's level schedules are refined with the rest, from a stable start,
    with the stuck loop's penalty at both ends of the levels from the first step."""
    from scipy.optimize import minimize

    st = structure
    sched = schedule if schedule is not None else st.schedule
    blocks = [st.a, st.b, st.c, st.d, st.e, st.off, st.t]
    if sched is not None:
        blocks += [sched.a1, sched.b1, sched.e1]
    shapes = [blk.shape for blk in blocks]
    cuts = np.cumsum([blk.size for blk in blocks])[:-1]
    theta0 = np.concatenate([blk.ravel() for blk in blocks])
    # each block in units of 1 % of its mean size: L-BFGS's first step has length 1, which
    # must not move the loop far (a unit step on the matrices themselves can make it run away);
    # a scheduled block in its unscheduled twin's units (it may start at 0)
    sizes = [0.01 * np.mean(np.abs(blk)) + 1e-300 if blk.size else 1.0 for blk in blocks]
    if sched is not None:
        sizes[7:] = [sizes[0], sizes[1], sizes[4]]
    scale = np.concatenate(
        [np.full(blk.size, size) for blk, size in zip(blocks, sizes, strict=True)]
    )
    nk = st.r.shape[1]
    weights = [
        1.0 / (np.maximum(np.var(rec.y, axis=0), 1e-300) * rec.y.shape[0] * len(records))
        for rec in records
    ]
    rhos = [np.zeros(0) if sched is None else sched.levels(rec.u, rec.periodic) for rec in records]

    def unpack(delta: np.ndarray) -> list[np.ndarray]:
        parts = np.split(theta0 + scale * delta, cuts)
        return [np.ascontiguousarray(p.reshape(s)) for p, s in zip(parts, shapes, strict=True)]

    start_error = [np.inf]  # the start's, once known: the height of the runaway wall

    def loss(delta: np.ndarray, penalized: bool = True) -> tuple[float, np.ndarray]:
        parts = unpack(delta)
        a, b, c, d, e, off, t = parts[:7]
        empty = np.zeros((0, 0))
        a1, b1, e1 = parts[7:] if sched is not None else (empty, empty, empty)
        grads = [np.zeros(s) for s in shapes]
        total = _penalty(parts, sched, nk, grads) if penalized and nk else 0.0
        ga1, gb1, ge1 = grads[7:] if sched is not None else (empty, empty, empty)
        for rec, w, rho in zip(records, weights, rhos, strict=True):
            n_s = rec.u.shape[0]
            x = np.zeros(st.order)
            z = np.repeat((t @ off)[:, None], nk, axis=1)
            out = np.empty((n_s, c.shape[0]))
            run = (a, b, c, d, e, t, st.r, off, rho, a1, b1, e1)
            if rec.periodic:  # the period before, to its steady state
                S.structure_run(*run, x, z, rec.u, out)
            xs, ps = np.empty((n_s, st.order)), np.empty((n_s, st.r.size))
            moved = np.zeros((n_s, st.r.size), dtype=np.bool_)
            S.structure_trace(*run, x, z, rec.u, out, xs, ps, moved)
            res = out - rec.y
            if not np.all(np.isfinite(res)) or np.max(np.abs(res)) > 1e6 * np.ptp(rec.y):
                # the loop ran away: a step too far. A wall rising away from the start, ten
                # times the start's error, so that the line search steps back part of the way
                # (1e30 and a zero gradient there collapsed the step to nothing and ended it)
                wall = 10.0 * start_error[0]
                return wall, 2 * wall * delta / max(float(delta @ delta), 1e-300)
            total += 0.5 * float(np.sum(w * res**2))
            gy = np.ascontiguousarray(w * res)
            ga, gb, gc, gd, ge, goff, gt = grads[:7]
            S.structure_adjoint(a, c, e, t, nk, rho, a1, e1, xs, ps, moved, rec.u, out, gy, ga,
                                gb, gc, gd, ge, goff, gt, ga1, gb1, ge1)  # fmt: skip
        if not np.isfinite(start_error[0]):
            start_error[0] = total
        return total, np.concatenate([g.ravel() for g in grads]) * scale

    # the output error first; where its loop is unstable with every operator stuck, again
    # from there with the penalty on those poles (from a start far from stable, the penalty
    # alone holds the refinement back from the fit); a schedule from a stable start: with it
    options = {"maxiter": maxiter, "gtol": 0.0}
    opt = minimize(lambda x: loss(x, penalized=schedule is not None), np.zeros_like(theta0),
                   jac=True, method="L-BFGS-B", options=options)  # fmt: skip
    iterations = int(opt.nit)
    if nk and _built(unpack(opt.x), st.r, sched).radius() >= 1.0:
        # back inside first: the operators' action on the state scaled down until the stuck
        # loop is stable (a bisection on the scale), then refined with the penalty from there
        parts = unpack(opt.x)
        lo_s, hi_s = 0.0, 1.0
        for _ in range(30):
            mid = 0.5 * (lo_s + hi_s)
            trial = [*parts[:4], mid * parts[4], *parts[5:]]
            if sched is not None:
                trial[9] = mid * parts[9]
            inside = _stuck_radius(_built(trial, st.r, sched)) < STUCK_RADIUS
            lo_s, hi_s = (mid, hi_s) if inside else (lo_s, mid)
        parts[4] = lo_s * parts[4]
        if sched is not None:
            parts[9] = lo_s * parts[9]
        start = (np.concatenate([blk.ravel() for blk in parts]) - theta0) / scale
        opt = minimize(loss, start, jac=True, method="L-BFGS-B", options=options)
        iterations += int(opt.nit)
    refined = _built(unpack(opt.x), st.r, sched)
    before = loss(np.zeros_like(theta0), penalized=False)[0]
    after = loss(opt.x, penalized=False)[0]
    # kept where stable at both linear ends and lower, or stable where the start was not
    kept = refined.radius() < 1.0 and (after < before or structure.radius() >= 1.0)
    info = Refinement(before, after, iterations, kept)
    return (refined if kept else st), info


def _stuck_radius(structure: Structure) -> float:
    """The largest pole modulus of the loop with every operator stuck (at both ends of the
    drive's levels where the dynamics are scheduled)."""
    sc = structure.schedule
    ends = (0.0,) if sc is None else (sc.lo, sc.hi)
    return max(float(np.max(np.abs(np.linalg.eigvals(structure.at(rho).linear(stuck=True)[0]))))
               for rho in ends)  # fmt: skip


def _penalty(
    parts: list[np.ndarray], sched: Schedule | None, nk: int, grads: list[np.ndarray]
) -> float:
    """:func:`stuck_penalty` on the refinement's blocks, at both ends of the drive's levels
    where the dynamics are scheduled (its gradient carried to the scheduled blocks)."""
    a, _, c, _, e, _, t = parts[:7]
    if sched is None:
        return stuck_penalty(a, c, e, t, nk, grads)
    a1, _, e1 = parts[7:]
    total = 0.0
    for rho in (sched.lo, sched.hi):
        g = [np.zeros_like(x) for x in grads[:7]]
        total += stuck_penalty(a + rho * a1, c, e + rho * e1, t, nk, g)
        for i in range(7):
            grads[i] += g[i]
        grads[7] += rho * g[0]
        grads[9] += rho * g[4]
    return total
