r"""The inverse of a structure moved by several actuators: desired outputs in, one command
per actuator out, through the structure's shared modes.

A :class:`~piezohyst.StructureModel` says

.. math::

    x_{k+1} = A x_k + B u_k + E p_k, \qquad y_k = C x_k + D u_k + c,

with :math:`p_k` each actuator's play operators on its stroke :math:`T y_k`. Tracking the
desired outputs :math:`r_k` makes :math:`y_k = r_k`, so the operators' lags are known ahead
from the targets alone: :math:`p_k = \Gamma(T r_k) - T r_k` is a known input, and what is
left is a linear tracking problem. Its inverse is the linear-quadratic tracker with
preview (the optimal stable inverse: the structure's zeros outside the unit circle, which a
plain inverse would turn into unstable poles, are met by looking ahead instead):

.. math::

    \min_u \sum_k (y_k - r_k)^\top Q (y_k - r_k) + (u_k - \bar u_k)^\top R (u_k - \bar u_k)

with :math:`\bar u_k` the static inverse of the target (what holds it at rest) and
:math:`Q`, :math:`R` the outputs' and the commands' spans (``effort`` the commands' weight).
Its solution is a state feedback on the model's own state (the compensator runs the model
on the commands it sends) plus a feed-forward of the targets ahead,

.. math::

    u_k = -K x_k + F_0 z_k + \sum_{j=0}^{N-1} L_j z_{k+1+j}, \qquad
    z_i = [r_i - c;\ p_i],

the gains from the discrete Riccati equation, :math:`L_j` decaying as the closed loop's
poles: the preview :math:`N` is where they have fallen below :data:`PREVIEW_TOL` of the
largest. Each command then meets its actuator's slew and voltage limits, counted and said
as every compensator's are; the model's state follows the commands actually sent, so the
feedback makes up for a command a limit held.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg, signal

from .._kernels import play as K
from .._kernels import structure as S
from .._validation import FloatArray
from ..errors import LimitWarning, ParameterError, ShapeError, warn
from ..model.structure import StructureModel
from .coupled import REACH_SLACK, _counted, _per_actuator
from .tally import LIMIT_CHECK_FIRST, limit_parts

__all__ = ["EFFORT", "MAX_PREVIEW", "PREVIEW_TOL", "StructureCompensator"]

#: The commands' weight against the outputs', each in its span (small: track closely; the
#: static inverse is what the commands are drawn to, so it costs no offset at rest)
EFFORT = 1e-6
#: Rounds of correcting a stated position's voltages for the operators' lags (each one a
#: settling run; the correction falls by the lags' share each round)
SETTLE_ROUNDS = 8
#: The preview ends where the feed-forward's gains have fallen below this share of the largest
PREVIEW_TOL = 1e-6
#: Samples of preview at most (a closed loop slower than that is truncated, and said)
MAX_PREVIEW = 8192
#: Blocks at least this large (samples x preview) compute the preview's sum by FFT
FFT_FROM = 2_000_000


def _design(
    a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray, w: FloatArray,
    q: FloatArray, rn: FloatArray, mz: FloatArray,
) -> dict[str, Any]:  # fmt: skip
    """The tracker for ``x+ = a x + b u + w z``, ``y = c x + d u + c0``, with ``z = [s; p]``
    known ahead (``s`` the targets less the offsets, ``p`` the operators' lags) and ``mz z``
    the static inverse the commands are drawn to."""
    m = c.shape[0]
    pick = np.hstack([np.eye(m), np.zeros((m, mz.shape[1] - m))])  # z -> s
    ru = d.T @ q @ d + rn
    try:
        p = linalg.solve_discrete_are(a, b, c.T @ q @ c, ru, s=c.T @ q @ d)
    except (ValueError, np.linalg.LinAlgError) as exc:
        msg = f"the structure's tracking problem has no stabilising solution ({exc})"
        raise ParameterError(msg) from None
    g = ru + b.T @ p @ b
    gain = np.linalg.solve(g, d.T @ q @ c + b.T @ p @ a)
    acl, ccl = a - b @ gain, c - d @ gain
    f0 = np.linalg.solve(g, d.T @ q @ pick + rn @ mz - b.T @ p @ w)
    hz = -ccl.T @ q @ pick + gain.T @ rn @ mz + acl.T @ p @ w
    ahead, bj, top, size = [], b.copy(), 0.0, 0.0
    for _ in range(MAX_PREVIEW):
        lj = -np.linalg.solve(g, bj.T @ hz)
        size = float(np.max(np.abs(lj)))
        top = max(top, size)
        ahead.append(lj)
        if size <= PREVIEW_TOL * top:
            break
        bj = acl @ bj
    return {
        "gain": np.ascontiguousarray(gain),
        "f0": f0,
        "ahead": np.array(ahead),
        "truncated": size / top if top > 0 else 0.0,
    }


def _gains(st: Any, lo: FloatArray, hi: FloatArray, effort: float) -> dict[str, Any]:
    """The tracker's gains for the structure ``st`` within the limits ``lo``, ``hi``: the
    operators' lags along the tracked trajectory known ahead from the targets (a deviation
    from it moves the lags of the operators that stick: the state follows the model, so the
    feedback sees it)."""
    a, b, c, d, e = st.a, st.b, st.c, st.d, st.e
    nx, m = a.shape[0], c.shape[0]
    eye = np.eye(nx)
    g0 = d + c @ np.linalg.solve(eye - a, b)  # static gain (outputs, inputs)
    h0 = c @ np.linalg.solve(eye - a, e)  # the operators' lags at rest (outputs, lags)
    half = (hi - lo) / 2
    span = np.abs(g0) @ half  # each output's span over the limits
    if not np.all(span > 0):
        msg = "the structure's static gain moves an output by nothing over the limits"
        raise ParameterError(msg)
    q = np.diag(1.0 / span**2)
    rn = effort * np.diag(1.0 / half**2)
    qh = np.diag(1.0 / span)
    ms = np.linalg.pinv(qh @ g0) @ qh  # the static inverse, weighted least squares
    mz = np.hstack([ms, -ms @ h0])
    best = _design(a, b, c, d, np.hstack([np.zeros((nx, m)), e]), q, rn, mz)
    best["static"], best["span"] = (ms, -ms @ h0), span
    best["poles"] = float(np.abs(np.linalg.eigvals(a - b @ best["gain"])).max())
    return best


class StructureCompensator:
    """Feedforward compensation of a structure moved by several actuators (the
    controllers' one contract): the tracker with preview of the module's equations.

    Parameters
    ----------
    model : StructureModel
        Fitted; it sets the sample rate.
    v_min, v_max : float or array_like
        Each actuator's voltage limits (V): one number for all, or one per actuator.
    slew_rate : float, array_like or None, default None
        Each actuator's largest command change (V/s); None: no slew limit.
    effort : float, default :data:`EFFORT`
        The commands' weight against the tracking error, each relative to its span.
    level : float, optional
        Where the model's dynamics are scheduled by the drive's level
        (``StructureModel(scheduled=True)``): the commands' RMS (V, over all actuators) the
        structure is inverted at; default the identification records' mean. Held within the
        levels the records held; ignored by a model without a schedule.

    Attributes
    ----------
    preview : int
        Samples of the targets ahead the commands depend on: :meth:`step` with that many
        rows of ``preview`` (and :meth:`process` of a block, for all but its last rows)
        sends the tracker's commands exactly; beyond them the target is taken to hold.
    static_inverse : ndarray, shape (inputs, outputs)
        The commands that hold the outputs at rest, without the operators' lags (V per
        output unit; weighted least squares where there are more outputs than inputs).
    outside_count : int
        Targets out of the structure's reach since the reset: where the tracker asked an
        actuator for more than :data:`~piezohyst.control.coupled.REACH_SLACK` of its range
        past a voltage limit (through the dynamics: a fast target may be out of reach where
        a slow one is not); the first named in a :class:`~piezohyst.errors.LimitWarning`.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> rng = np.random.default_rng(0)
    >>> u = [rng.uniform(0, 100, (400, 2)) for _ in range(3)]
    >>> a = np.array([[1.2, -0.5], [1.0, 0.0]])                     # one shared mode
    >>> def structure(v):
    ...     x, y = np.zeros(2), []
    ...     for vk in v:
    ...         y.append([x[0], 0.5 * x[0] + 0.1 * vk[1]])
    ...         x = a @ x + np.array([0.1, 0.0]) * (vk[0] + 0.3 * vk[1])
    ...     return np.array(y)
    >>> model = ph.StructureModel(order=2, operators=0).fit(
    ...     u, [structure(v) for v in u], sample_rate=1000.0)
    >>> comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    >>> end = model.predict(np.full((500, 2), [40.0, 60.0]))[-1]     # where 40 V, 60 V settle
    >>> target = np.clip(np.linspace(0.0, 2.0, 400), 0, 1)[:, None] * end   # ramp, hold
    >>> np.round(comp.process(target)[-1], 3)                         # the commands found
    array([40., 60.])
    """

    #: False: the commands do not depend on readings (the controllers' one contract)
    reads = False

    def __init__(
        self,
        model: StructureModel,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        slew_rate: float | ArrayLike | None = None,
        effort: float = EFFORT,
        level: float | None = None,
    ) -> None:
        fitted = isinstance(model, StructureModel) and hasattr(model, "structure_")
        if not fitted:
            kind = type(model).__name__
            msg = (f"StructureCompensator takes a fitted ph.StructureModel (got {kind}); a "
                   "CoupledModel has ph.CoupledCompensator.")  # fmt: skip
            raise ParameterError(msg)
        n, m = model.n_inputs_, model.n_outputs_
        lo, hi = _per_actuator(v_min, n, "v_min"), _per_actuator(v_max, n, "v_max")
        if not np.all(lo < hi):
            msg = f"each actuator's 'v_min' must be below its 'v_max' (got {v_min!r}, {v_max!r})"
            raise ParameterError(msg)
        if not (isinstance(effort, (int, float)) and math.isfinite(effort) and effort > 0):
            msg = f"'effort' must be a positive number. Got {effort!r}."
            raise ParameterError(msg)
        rate = model.sample_rate_
        if slew_rate is None:
            step = np.full(n, np.inf)
        else:
            per_s = _per_actuator(slew_rate, n, "slew_rate")
            if not np.all(per_s > 0):
                msg = f"'slew_rate' must be positive (V/s). Got {slew_rate!r}."
                raise ParameterError(msg)
            step = per_s / rate
        self.model, self.v_min, self.v_max, self.sample_rate = model, lo, hi, rate
        self.max_step, self.effort = step, float(effort)
        sc = model.structure_.schedule
        if level is not None and not (isinstance(level, (int, float)) and level > 0):
            msg = f"'level' must be a positive RMS (V). Got {level!r}."
            raise ParameterError(msg)
        rho = 0.0 if sc is None or level is None else float(level) / sc.ref - 1.0
        self._st = model.structure_.at(rho)  # the structure at that level (itself: unscheduled)
        self._g = _gains(self._st, lo, hi, self.effort)
        self.preview = int(self._g["ahead"].shape[0])
        self.static_inverse = np.asarray(self._g["static"][0])
        self.least_squares = m > n
        if self._g["truncated"] > 1e-3:
            warn(
                f"StructureCompensator: the tracker's closed loop is slow (pole radius "
                f"{self._g['poles']:.6f}): its preview is cut at {MAX_PREVIEW} samples, where "
                f"the gains are still {self._g['truncated']:.2g} of their largest; raise "
                "'effort'",
                LimitWarning,
            )
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(
        self, *, voltage: float | ArrayLike | None = None, position: ArrayLike | None = None
    ) -> None:
        """The model back at rest (or settled at ``voltage``, or at ``position``), the counts
        to zero.

        Parameters
        ----------
        voltage : float or array_like, optional
            Where the actuators sit now (V): the model is run to rest there (a ramp from
            0 V, then a hold).
        position : array_like, optional
            Where the outputs sit now (the model's units; one per output), instead: the
            voltages that settle there are found (the static inverse, then corrected for the
            operators' lags, a few rounds) and the model run to rest at them. A position
            whose voltages are past a limit is refused; with more outputs than inputs the
            nearest in the least-squares sense is taken.
        """
        st, n = self._st, self.model.n_inputs_
        if voltage is not None and position is not None:
            msg = "give where the structure sits as 'voltage' or as 'position', not both"
            raise ParameterError(msg)
        if position is not None:
            voltage = self._voltage_at(position)
        self._x = np.zeros(st.order)
        self._z = np.repeat((st.t @ st.off)[:, None], st.r.shape[1], axis=1)
        self._last = np.zeros(n)
        if voltage is not None:
            v = _per_actuator(voltage, n, "voltage")
            self._x, self._z = self._settled(v)
            self._last = v.copy()
        y_now = st.c @ self._x + st.d @ self._last + st.off
        self._target = y_now  # the last finite target (a NaN holds it)
        self._zd = self._z.copy()  # the operators on the targets' strokes
        self._tally = np.zeros((n, K.TALLY_SIZE))
        tol = np.where(np.isfinite(self.max_step), self.max_step * (1.0 - 1e-9), np.inf)
        self._tally[:, K.TALLY_PREV], self._tally[:, K.TALLY_TOL] = self._last, tol
        self._tally[:, K.TALLY_LOW], self._tally[:, K.TALLY_HIGH] = self.v_min, self.v_max
        self.nonfinite_count = 0
        self.outside_count = 0
        self._said: set[str] = set()
        self._until_check = LIMIT_CHECK_FIRST

    def _settled(self, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The model's state and operators at rest at the voltages ``v``: a ramp from 0 V
        over the longer of four previews and 1000 samples, then as long a hold."""
        st = self._st
        x = np.zeros(st.order)
        z = np.repeat((st.t @ st.off)[:, None], st.r.shape[1], axis=1)
        settle = max(4 * self.preview, 1000)
        ramp = np.vstack([np.linspace(0.0, 1.0, settle)[:, None] * v, np.tile(v, (settle, 1))])
        out = np.empty((ramp.shape[0], st.c.shape[0]))
        ramp = np.ascontiguousarray(ramp)
        rho, a1, b1, e1 = st.scheduled(ramp, False)  # none: the structure at one level
        S.structure_run(st.a, st.b, st.c, st.d, st.e, st.t, st.r, st.off, rho, a1, b1, e1, x, z,
                        ramp, out)  # fmt: skip
        return x, z

    def _voltage_at(self, position: ArrayLike) -> FloatArray:
        """The voltages at whose rest the outputs sit at ``position``: the static inverse,
        corrected by it for what the operators' lags leave (:data:`SETTLE_ROUNDS`)."""
        st, m = self._st, self.model.n_outputs_
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.size != m or not np.all(np.isfinite(p)):
            msg = f"'position' must be {m} finite numbers, one per output. Got {position!r}."
            raise ParameterError(msg)
        ms = self.static_inverse
        v = ms @ (p - st.off)  # the operators' lags taken as none, at first
        for _ in range(SETTLE_ROUNDS):
            if np.any(v < self.v_min) or np.any(v > self.v_max):
                break
            x, _ = self._settled(v)
            step = ms @ (p - (st.c @ x + st.d @ v + st.off))
            v = v + step
            if np.all(np.abs(step) <= 1e-9 * (self.v_max - self.v_min)):
                break
        # the settling rounds' last correction (1e-9 of the range) and rounding
        slack = 1e-6 * (self.v_max - self.v_min)
        beyond = (v < self.v_min - slack) | (v > self.v_max + slack)
        if np.any(beyond):
            past = [f"actuator {q}: {v[q]:.6g} V" for q in np.flatnonzero(beyond)]
            msg = (f"the position {np.array2string(p, precision=6)} is out of reach: it needs "
                   f"{', '.join(past)}, past the limits")  # fmt: skip
            raise ParameterError(msg)
        return np.asarray(np.clip(v, self.v_min, self.v_max))

    @property
    def output(self) -> FloatArray:
        """The model's outputs now: where the commands sent have moved it (its units)."""
        st = self._st
        return np.asarray(st.c @ self._x + st.d @ self._last + st.off)

    @property
    def last_command(self) -> FloatArray:
        """The last commands sent, one per actuator (V)."""
        return self._last.copy()

    @property
    def saturated_count(self) -> NDArray[np.int64]:
        """Per actuator, commands sent at a voltage limit."""
        t = self._tally
        return (t[:, K.TALLY_AT_LOW] + t[:, K.TALLY_AT_HIGH]).astype(np.int64)

    @property
    def slew_limited_count(self) -> NDArray[np.int64]:
        """Per actuator, commands the slew limit held back (on the trajectory)."""
        return self._tally[:, K.TALLY_HELD].astype(np.int64)

    @property
    def command_count(self) -> int:
        """Commands sent per actuator since the reset."""
        return int(self._tally[0, K.TALLY_ALL])

    # ---------------------------------------------------------------- commands
    def _check(self, desired: ArrayLike, name: str, row: bool = False) -> FloatArray:
        d = np.asarray(desired, dtype=np.float64)
        m = self.model.n_outputs_
        if d.ndim == 1 and row:
            d = d.reshape(1, -1)
        if d.ndim != 2 or d.shape[1] != m:
            msg = f"'{name}' must be (samples, {m}) desired outputs. Got shape {d.shape}."
            raise ShapeError(msg)
        return d

    def _run(self, rows: FloatArray, ahead: FloatArray) -> FloatArray:
        """Send the commands for ``rows``, with ``ahead`` the targets after them."""
        st, g = self._st, self._g
        every = np.vstack([rows, ahead]) if ahead.size else rows
        finite = np.all(np.isfinite(every), axis=1)
        hold = ~finite[: rows.shape[0]]
        if not finite.all():  # a NaN target holds the last finite one
            idx = np.where(finite, np.arange(every.shape[0]), -1)
            idx = np.maximum.accumulate(idx)
            filled = np.where((idx >= 0)[:, None], every[np.maximum(idx, 0)], self._target)
            every = filled
        s = every - st.off
        nk = st.r.shape[1]
        lags = np.empty((every.shape[0], st.r.shape[0] * nk))
        zd = self._zd.copy()
        for q in range(st.r.shape[0]):  # each actuator's operators on the targets' stroke
            sq = np.ascontiguousarray(every @ st.t[q])
            out = np.empty((every.shape[0], nk))
            K.play_states(sq, np.ascontiguousarray(st.r[q]), zd[q], out)
            lags[:, q * nk : (q + 1) * nk] = out - sq[:, None]
            if rows.shape[0] < every.shape[0]:  # the state after the rows sent only
                keep = self._zd[q].copy()
                K.play_states(sq[: rows.shape[0]], np.ascontiguousarray(st.r[q]), keep,
                              np.empty((rows.shape[0], nk)))  # fmt: skip
                self._zd[q] = keep
            else:
                self._zd[q] = zd[q]
        z = np.hstack([s, lags])
        n_rows, ahead_gains = rows.shape[0], g["ahead"]
        npv = ahead_gains.shape[0]
        tail = np.repeat(z[-1:], max(n_rows + npv - z.shape[0], 0), axis=0)
        zf = np.vstack([z, tail])[1 : n_rows + npv]  # z[k+1+j] for k < rows, j < preview
        ff = z[:n_rows] @ g["f0"].T
        if n_rows * npv < FFT_FROM:
            for j in range(npv):
                ff += zf[j : j + n_rows] @ ahead_gains[j].T
        else:
            ff += signal.fftconvolve(zf[:, None, :], ahead_gains[::-1], mode="valid", axes=0).sum(
                axis=2
            )
        cmd = np.empty((n_rows, self.model.n_inputs_))
        beyond = np.empty(n_rows, dtype=np.bool_)
        S.structure_compensate(
            st.a, st.b, st.c, st.d, st.e, st.t, st.r, st.off, g["gain"],
            np.ascontiguousarray(ff), hold, self.v_min, self.v_max, self.max_step,
            REACH_SLACK * (self.v_max - self.v_min), self._x, self._z, self._last,
            self._tally, cmd, beyond,
        )  # fmt: skip
        self._reach(beyond, self.command_count - n_rows)
        self.nonfinite_count += int(hold.sum())
        self._target = every[n_rows - 1].copy()
        self._until_check -= n_rows
        if self._until_check <= 0 or n_rows > 1:
            self._say()
        return cmd

    def _reach(self, beyond: NDArray[np.bool_], first: int) -> None:
        """Count (and name once) the targets the tracker asked more than the limits for."""
        rows = np.flatnonzero(beyond)
        if not rows.size:
            return
        self.outside_count += int(rows.size)
        if "reach" not in self._said:
            self._said.add("reach")
            warn(
                f"StructureCompensator: {_counted(rows.size, 'desired position')} outside what "
                "the structure "
                f"reaches within the limits (first at sample {first + int(rows[0])} since the "
                "reset: an actuator asked for more than its range allows, through the "
                "structure's dynamics; what it reaches is not a box); their commands are held "
                "at the limits (counted in saturated_count)",
                LimitWarning,
            )

    def _say(self) -> None:
        """Warn once per limit and actuator that held more than the share of commands."""
        given = self.command_count
        self._until_check = max(given, LIMIT_CHECK_FIRST)
        if given < LIMIT_CHECK_FIRST:
            return
        rate = self.sample_rate
        for i in range(self.model.n_inputs_):
            t = self._tally[i]
            parts = limit_parts(
                int(t[K.TALLY_GIVEN]), int(t[K.TALLY_AT_LOW] + t[K.TALLY_AT_HIGH]),
                int(t[K.TALLY_HELD]), (float(self.v_min[i]), float(self.v_max[i])),
                float(self.max_step[i]), rate, given=given,
                sides=(int(t[K.TALLY_AT_LOW]), int(t[K.TALLY_AT_HIGH])), trained=False,
            )  # fmt: skip
            new = {k: v for k, v in parts.items() if f"{k}{i}" not in self._said}
            if new:
                self._said.update(f"{k}{i}" for k in new)
                warn(f"StructureCompensator, actuator {i}: {'; '.join(new.values())}",
                     LimitWarning)  # fmt: skip

    def step(
        self, desired: ArrayLike, measured: Any = None, preview: ArrayLike | None = None
    ) -> FloatArray:
        """The commands for one target: one per actuator.

        Parameters
        ----------
        desired : array_like of one value per output
            The target (the model's units); NaN holds the last commands.
        measured : optional
            A reading: ignored (feedforward; the controllers' one contract).
        preview : array_like, shape (k, outputs), optional
            The targets of the next samples (up to :attr:`preview` of them count); beyond
            them the last one holds.

        Returns
        -------
        ndarray, shape (actuators,)
            Commands (V), each inside its actuator's limits.
        """
        d = self._check(desired, "desired", row=True)
        if d.shape[0] != 1:
            msg = f"'desired' must hold {self.model.n_outputs_} outputs. Got shape {d.shape}."
            raise ShapeError(msg)
        ahead = np.empty((0, d.shape[1])) if preview is None else self._check(preview, "preview")
        return np.asarray(self._run(d, ahead[: self.preview])[0])

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for a block of desired outputs; equal to :meth:`step` on each row with
        the rows after it as its preview (after the block's last row: held).

        Parameters
        ----------
        desired : array_like, shape (N, outputs)
            The targets, one row per sample (the model's units; a NaN row holds).
        measured : optional
            A reading: not used (the commands are feedforward).

        Returns
        -------
        ndarray, shape (N, actuators)
            Commands (V), each inside its actuator's limits.
        """
        d = self._check(desired, "desired")
        if d.shape[0] == 0:
            return np.empty((0, self.model.n_inputs_))
        return self._run(d, np.empty((0, d.shape[1])))
