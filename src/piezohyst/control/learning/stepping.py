"""The learning compensator in a loop that reads after each command (the controllers' one
contract, :mod:`~piezohyst.control.contract`): :class:`Stepping` sends the pending trial's
commands one sample at a time, keeps each reading, and learns from a trial when the reading of
its last sample arrives (with the next trial's first call). Equal to ``command`` and
``learn`` on whole trials.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ParameterError, ShapeError
from ..contract import reading

FloatArray = np.ndarray

__all__ = ["Stepping"]


class Stepping:
    """``step`` and ``process`` over repeated trials (mixed into the learning compensator,
    whose trial, trajectory and readings it walks)."""

    #: True: the trial's readings are learned from
    reads = True

    _desired: FloatArray | None
    _pending: FloatArray | None
    _cursor: int
    _seen: FloatArray
    _awaiting: int | None

    if TYPE_CHECKING:

        def command(self, desired: ArrayLike | None = None) -> FloatArray: ...

        def learn(self, charge: ArrayLike | None = None, *, displacement: Any = None) -> Any: ...

    def step(self, desired: float, measured: float | None = None) -> float:
        """One sample of the repeated trajectory, for a loop that reads after each command.

        The trial's commands are made when it begins (:meth:`command`); each call sends the
        next of them and keeps ``measured``, the reading taken after the command before, as
        that sample's. The reading of a trial's last sample arrives with the next trial's
        first call, which learns from the trial (:meth:`learn`, the charge) and begins the
        next one. Equal to :meth:`command` and :meth:`learn` on whole trials.

        Parameters
        ----------
        desired : float
            The trajectory's value at this sample (checked: the learner repeats the
            trajectory given to the first :meth:`command`).
        measured : float, optional
            The reading after the command before (model output units); None or NaN: none
            (not learned from).

        Returns
        -------
        float
            The command (V).

        Raises
        ------
        ParameterError
            No trajectory yet (give it once with :meth:`command`), or ``desired`` is not
            the trajectory's value at this point of the trial.
        """
        if self._desired is None:
            msg = (
                "step() repeats a known trajectory: give it once with command(desired), whose "
                "commands are the first trial's, which step() then sends"
            )
            raise ParameterError(msg)
        if self._awaiting is not None:
            self._seen[self._awaiting] = reading(measured, "LearningCompensator")
            self._awaiting = None
        if self._pending is not None and self._cursor == self._pending.size:
            self.learn(self._seen.copy())
        if self._pending is None:
            self.command()
        assert self._pending is not None
        k, d = self._cursor, self._desired
        if not abs(float(desired) - d[k]) <= 1e-9 * float(np.ptp(d)):
            msg = (
                f"step(): desired {float(desired)!r} at sample {k} of the trial, where the "
                f"trajectory is {d[k]!r}: the learner repeats one trajectory (reset() for another)"
            )
            raise ParameterError(msg)
        self._cursor, self._awaiting = k + 1, k
        return float(self._pending[k])

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """:meth:`step` on each sample of a block (readings known beforehand: a playback).

        Parameters
        ----------
        desired, measured : array_like, shape (N,)

        Returns
        -------
        ndarray, shape (N,)
            Commands (V).
        """
        d = np.asarray(desired, dtype=np.float64).reshape(-1)
        m = np.full(d.size, np.nan) if measured is None else np.asarray(measured, np.float64)
        if m.shape != d.shape:
            msg = f"'measured' must match 'desired' (shape {d.shape}). Got {m.shape}."
            raise ShapeError(msg)
        return np.array([self.step(float(a), float(b)) for a, b in zip(d, m, strict=True)])
