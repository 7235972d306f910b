"""One contract for every controller, so that a loop runs any of them.

python-control runs every block of a system through one update; here every controller --
:class:`~piezohyst.Compensator`, :class:`~piezohyst.SelfSensingController`,
:class:`~piezohyst.LearningCompensator` and their banks -- answers

* ``step(desired, measured=None)``: the command for one sample, given the reading taken
  after the command before (``None``: no reading this sample);
* ``process(desired, measured=None)``: the commands for a block, equal to ``step`` on each
  sample (for a controller that reads, the block's readings must be known beforehand: a
  record played back);
* ``reads``: whether the commands depend on the readings. A loop need not wait for a
  reading before the next command where it is False: it may send a whole block at once.

A feedforward compensator reads nothing (``measured`` is accepted and ignored); the
self-sensing controller runs on its feedforward alone for a sample without a reading (and
counts it); the learning compensator keeps each reading for the trial's update.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ParameterError

FloatArray = np.ndarray

__all__ = ["Controller", "reading"]


@runtime_checkable
class Controller(Protocol):
    """What every controller answers (see the module's docstring); ``isinstance(x,
    Controller)`` checks that ``x`` has it.

    Attributes
    ----------
    reads : bool
        True where a command depends on the readings before it.
    last_command : float or ndarray
        The last command sent (V; one per channel for a bank).

    Methods
    -------
    step(desired, measured=None)
        The command for one sample.
    process(desired, measured=None)
        The commands for a block, equal to ``step`` on each sample.
    """

    @property
    def reads(self) -> bool:
        """True where a command depends on the readings before it."""
        ...

    @property
    def last_command(self) -> Any:
        """The last command sent (V)."""
        ...

    def step(self, desired: Any, measured: Any = None) -> Any:
        """The command for one sample.

        Parameters
        ----------
        desired : float or ndarray
            The desired output now (one per channel for a bank).
        measured : float or ndarray, optional
            The reading taken after the command before (None: none this sample).

        Returns
        -------
        float or ndarray
            The command (V).
        """
        ...

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """The commands for a block, equal to :meth:`step` on each sample.

        Parameters
        ----------
        desired : array_like
            One row per sample.
        measured : array_like, optional
            The readings, known beforehand (a record played back).

        Returns
        -------
        ndarray
            The commands (V).
        """
        ...


def reading(measured: object, owner: str) -> float:
    """One reading as a float: ``None`` (none this sample) as NaN.

    Parameters
    ----------
    measured : float or None
    owner : str
        The controller, for the error.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        Not a number (an array where one reading belongs, say).
    """
    if measured is None:
        return float("nan")
    try:
        return float(measured)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        msg = f"{owner}.step takes one reading (a number, or None). Got {measured!r} instead."
        raise ParameterError(msg) from None
