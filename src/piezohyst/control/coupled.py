"""The coupled compensator: desired stage positions in, one command per actuator out.

A :class:`~piezohyst.model.coupled.CoupledModel` says ``y = C h(u) + c``: each actuator's
hysteresis, then the static coupling. Its inverse runs the other way, sample by sample:
the coupling's inverse turns the desired positions into what each actuator alone must move
(``C^-1 (y - c)``), and each actuator's own :class:`~piezohyst.Compensator` inverts its
hysteresis, within its limits (voltage and slew, per actuator), counting what they held.
A target the stage cannot reach is named: the reachable set is the image of the actuators'
ranges through the coupling (a parallelogram for two, not a box), so a position inside each
axis's own range may still be out of reach.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import FloatArray
from ..errors import LimitWarning, ParameterError, ShapeError, warn
from ..model.coupled import CoupledModel
from .compensator import Compensator

__all__ = ["CoupledCompensator", "actuator_reach", "plane_slack", "stage_targets"]

#: A desired position counts as out of reach when an actuator would have to move beyond its
#: range by more than this share of the range (rounding at the range's edge is not)
REACH_SLACK = 1e-3


def _per_actuator(value: float | ArrayLike, n: int, name: str) -> FloatArray:
    given = np.asarray(value, dtype=np.float64)
    if given.ndim > 1 or given.size not in (1, n):
        msg = f"'{name}' must be a finite number or one per actuator ({n}). Got {value!r}."
        raise ParameterError(msg)
    arr = np.broadcast_to(given.reshape(-1), (n,)).copy()
    if not np.all(np.isfinite(arr)):
        msg = f"'{name}' must be a finite number or one per actuator ({n}). Got {value!r}."
        raise ParameterError(msg)
    return arr


def _counted(n: int, what: str) -> str:
    """``3 desired positions lie``, ``1 desired position lies``: a warning's count."""
    return f"{n} {what}s lie" if n != 1 else f"1 {what} lies"


def actuator_reach(comp: Compensator) -> tuple[float, float]:
    """What an actuator's hysteresis gives over its compensator's limits (both branches'
    extremes, its model's output units).

    Parameters
    ----------
    comp : Compensator

    Returns
    -------
    tuple of float
        The lowest and the highest output.
    """
    h = comp.model.hysteresis_.operator_
    path = np.array([comp.v_min, comp.v_max, comp.v_min, comp.v_max])
    q = np.asarray(h.propagate(path, h.rest_state(comp.v_min)).output)
    return float(q.min()), float(q.max())


def plane_slack(coupling: FloatArray, reach: FloatArray) -> FloatArray:
    """How far (each output's units) a desired position may lie off what the actuators move
    the stage to before it counts as out of reach: :data:`REACH_SLACK` of each output's
    extent over the actuators' ranges ``reach`` (actuators x 2).

    Parameters
    ----------
    coupling : ndarray, shape (outputs, actuators)
    reach : ndarray, shape (actuators, 2)

    Returns
    -------
    ndarray, shape (outputs,)
    """
    lo, hi = coupling * reach[:, 0], coupling * reach[:, 1]
    return np.asarray(REACH_SLACK * (np.maximum(lo, hi) - np.minimum(lo, hi)).sum(axis=1))


def stage_targets(
    tally: Any, desired: FloatArray, coupling: FloatArray, offset: FloatArray
) -> FloatArray:
    """What each actuator alone must move for the desired positions, through the coupling's
    inverse (``tally.inverse``; least squares with more outputs than actuators); the rows the
    stage cannot reach (beyond an actuator's ``tally.reach``, or off what the actuators move
    the outputs to) counted in ``tally.outside_count`` (and ``off_plane_count``) and said once
    each, naming ``tally.owner`` (the coupled compensator's and the stage's self-sensing
    loop's one rule).

    Parameters
    ----------
    tally : object
        Holds ``inverse``, ``reach``, ``owner``, the counts and whether each was said.
    desired : ndarray, shape (N, outputs)
    coupling : ndarray, shape (outputs, actuators)
    offset : ndarray, shape (outputs,)

    Returns
    -------
    ndarray, shape (N, actuators)
    """
    reach = tally.reach
    # per row, the same arithmetic for a block as for one row (a matrix product's blocking
    # would round a block otherwise): process equals step to the bit
    own = ((desired - offset)[:, None, :] * tally.inverse[None, :, :]).sum(axis=2)
    span = reach[:, 1] - reach[:, 0]
    beyond = (own < reach[:, 0] - REACH_SLACK * span) | (own > reach[:, 1] + REACH_SLACK * span)
    off = np.zeros(desired.shape[0], dtype=bool)
    if coupling.shape[0] != coupling.shape[1]:  # a position the actuators cannot give
        resid = (desired - offset) - own @ coupling.T
        off = np.any(np.abs(resid) > plane_slack(coupling, reach), axis=1)
    if off.any():  # the nearest position they reach
        tally.off_plane_count += int(off.sum())
        if not tally._off_said:
            tally._off_said = True
            k = int(np.flatnonzero(off)[0])
            warn(
                f"{tally.owner}: {_counted(int(off.sum()), 'desired position')} off what "
                f"the {own.shape[1]} actuators move the stage's {desired.shape[1]} outputs "
                f"to (first at sample {k}): the nearest position they reach, in least "
                "squares, is followed (counted in outside_count and off_plane_count)",
                LimitWarning,
            )
    tally.outside_count += int(np.count_nonzero(beyond.any(axis=1) | off))
    rows = np.flatnonzero(beyond.any(axis=1))
    if rows.size and not tally._outside_said:
        tally._outside_said = True
        k = int(rows[0])
        axes = ", ".join(
            f"actuator {i} {own[k, i]:.4g} outside [{reach[i, 0]:.4g}, {reach[i, 1]:.4g}]"
            for i in np.flatnonzero(beyond[k])
        )
        warn(
            f"{tally.owner}: {_counted(rows.size, 'desired position')} outside what the "
            f"stage reaches (first at sample {k}: {axes}); the reachable set is the "
            "actuators' ranges through the coupling, not a box; those commands sit at the "
            "limits (counted in saturated_count)",
            LimitWarning,
        )
    return np.asarray(own)


class CoupledCompensator:
    """Feedforward compensation of a coupled stage (the controllers' one contract).

    Parameters
    ----------
    model : CoupledModel
        Fitted.
    v_min, v_max : float or array_like
        Each actuator's voltage limits (V): one number for all, or one per actuator.
    sample_rate : float, optional
        Hz, of the loop (needed by models with creep or input dynamics, and by a slew rate).
    slew_rate : float, "trained" or None, default "trained"
        As for :class:`~piezohyst.Compensator`, per actuator.
    allow_extrapolation : bool, default False
        As for :class:`~piezohyst.Compensator`.

    Attributes
    ----------
    compensators : list of Compensator
        One per actuator, in its own axis's units.
    reach : ndarray, shape (actuators, 2)
        What each actuator alone moves over its limits (its axis's units).

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import make_signal, simulate_stage
    >>> t, a = make_signal("decaying", duration=8.0)
    >>> _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    >>> rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t)
    >>> model = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
    >>> comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
    ...                              slew_rate=None)
    >>> comp.step(model.predict([[70.0, 70.0]], t=[0.0])[0]).shape   # one command per actuator
    (2,)
    """

    #: False: the commands do not depend on readings (the controllers' one contract)
    reads = False
    #: Who its warnings name (a learner built on it names itself)
    owner = "CoupledCompensator"

    def __init__(
        self,
        model: CoupledModel,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        sample_rate: float | None = None,
        slew_rate: float | Literal["trained"] | None = "trained",
        allow_extrapolation: bool = False,
    ) -> None:
        if not isinstance(model, CoupledModel) or not hasattr(model, "coupling_"):
            msg = (
                "CoupledCompensator takes a fitted ph.CoupledModel "
                f"(got {type(model).__name__}); a single actuator has ph.Compensator."
            )
            raise ParameterError(msg)
        n = len(model.channels_)
        lo, hi = _per_actuator(v_min, n, "v_min"), _per_actuator(v_max, n, "v_max")
        self.model = model
        self.compensators = [
            Compensator(ch, v_min=float(lo[i]), v_max=float(hi[i]), sample_rate=sample_rate,
                        slew_rate=slew_rate, allow_extrapolation=allow_extrapolation)
            for i, ch in enumerate(model.channels_)
        ]  # fmt: skip
        for i, comp in enumerate(self.compensators):  # its warnings name the actuator
            comp.owner = f"CoupledCompensator, actuator {i}"
        cond = float(np.linalg.cond(model.coupling_))
        if not math.isfinite(cond) or cond > 1e6:
            msg = f"the coupling cannot be inverted (condition number {cond:.3g})"
            raise ParameterError(msg)
        c = model.coupling_
        # more outputs than actuators: the least squares (what each actuator moves for the
        # nearest position they reach); a target off it is counted (actuator_targets)
        self._inverse = np.linalg.inv(c) if c.shape[0] == c.shape[1] else np.linalg.pinv(c)
        self.reach = np.array([actuator_reach(c) for c in self.compensators])
        self.outside_count = 0  # desired positions out of the stage's reach since the reset
        self.off_plane_count = 0  # of them, off what the actuators move the outputs to
        self._outside_said = self._off_said = False

    @property
    def plane_slack(self) -> FloatArray:
        """How far (each output's units) a desired position may lie off what the actuators
        move the stage to before it counts as out of reach: :data:`REACH_SLACK` of the
        output's extent over the actuators' ranges."""
        return plane_slack(self.model.coupling_, self.reach)

    # ------------------------------------------------------------------ counts
    @property
    def last_command(self) -> FloatArray:
        """The last commands sent, one per actuator (V)."""
        return np.array([c.last_command for c in self.compensators])

    @property
    def saturated_count(self) -> NDArray[np.int64]:
        """Per actuator, commands sent at a voltage limit because the target was beyond it."""
        return np.array([c.saturated_count for c in self.compensators], dtype=np.int64)

    @property
    def slew_limited_count(self) -> NDArray[np.int64]:
        """Per actuator, commands the slew limit held back."""
        return np.array([c.slew_limited_count for c in self.compensators], dtype=np.int64)

    @property
    def nonfinite_count(self) -> NDArray[np.int64]:
        """Per actuator, samples held because a desired value was NaN or infinite."""
        return np.array([c.nonfinite_count for c in self.compensators], dtype=np.int64)

    def reset(self, *, voltage: float | ArrayLike | None = None) -> None:
        """Every actuator back to its initial state (or ``voltage``), the counts to zero.

        Parameters
        ----------
        voltage : float or array_like, optional
            Where the actuators sit now (V).
        """
        n = len(self.compensators)
        v = None if voltage is None else _per_actuator(voltage, n, "voltage")
        for i, comp in enumerate(self.compensators):
            comp.reset(voltage=None if v is None else float(v[i]))
        self.outside_count = self.off_plane_count = 0
        self._outside_said = self._off_said = False

    # ---------------------------------------------------------------- commands
    @property
    def inverse(self) -> FloatArray:
        """The coupling's inverse: what each actuator moved, ``inverse @ (y - offset)``."""
        return np.array(self._inverse)

    def actuator_targets(self, desired: FloatArray) -> FloatArray:
        """What each actuator alone must move for the desired positions (its axis's units),
        the targets out of the stage's reach counted in :attr:`outside_count` and said once.

        Parameters
        ----------
        desired : ndarray, shape (N, outputs)

        Returns
        -------
        ndarray, shape (N, actuators)
        """
        return stage_targets(self, desired, self.model.coupling_, self.model.offset_)

    def step(
        self, desired: ArrayLike, measured: Any = None, preview: ArrayLike | None = None
    ) -> FloatArray:
        """One command per actuator for one desired position.

        Parameters
        ----------
        desired : array_like, shape (outputs,)
            The stage's desired position (the model's output units); NaN holds.
        measured : optional
            A reading: ignored (feedforward; the controllers' one contract).
        preview : array_like, shape (k, outputs) or (outputs,), optional
            The desired positions of the next samples, for actuators whose models look ahead
            (an output mode, an input delay): each actuator's compensator gets what it alone
            must move there (:meth:`~piezohyst.Compensator.step`'s ``preview``). Without it
            they extrapolate, so ``process`` of a block equals ``step`` on each row with the
            rows after it as the preview.

        Returns
        -------
        ndarray, shape (actuators,)
            Commands (V), each inside its actuator's limits.
        """
        m = self.model.coupling_.shape[0]
        d = np.asarray(desired, dtype=np.float64).reshape(1, -1)
        if d.shape[1] != m:
            msg = f"'desired' must hold {m} positions. Got {d.size}."
            raise ShapeError(msg)
        own = self.actuator_targets(d)[0]
        if preview is None:
            return np.array([c.step(float(own[i])) for i, c in enumerate(self.compensators)])
        ahead = np.atleast_2d(np.asarray(preview, dtype=np.float64))
        if ahead.ndim != 2 or ahead.shape[1] != m:
            msg = f"'preview' must be (samples, {m}) desired positions. Got shape {ahead.shape}."
            raise ShapeError(msg)
        own_ahead = (ahead - self.model.offset_) @ self._inverse.T  # not counted: not yet due
        return np.array([c.step(float(own[i]), preview=own_ahead[:, i])
                         for i, c in enumerate(self.compensators)])  # fmt: skip

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for a block of desired positions; equal to :meth:`step` on each row with
        the rows after it as its preview (the block's last row: extrapolated).

        Parameters
        ----------
        desired : array_like, shape (N, outputs)
        measured : optional
            Ignored (feedforward).

        Returns
        -------
        ndarray, shape (N, actuators)
        """
        d = np.asarray(desired, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != self.model.coupling_.shape[0]:
            msg = (
                f"'desired' must be (samples, {self.model.coupling_.shape[0]}). "
                f"Got shape {d.shape}."
            )
            raise ShapeError(msg)
        own = self.actuator_targets(d)
        return np.column_stack(
            [c.process(np.ascontiguousarray(own[:, i])) for i, c in enumerate(self.compensators)]
        )
