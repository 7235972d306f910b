"""Exception types raised by piezohyst.

Every error subclasses :class:`PiezohystError` *and* a built-in (mostly
:class:`ValueError`), so ``except ValueError`` keeps working in user code.
Messages say what was expected and what came.
"""

from __future__ import annotations

import sys
import warnings

__all__ = [
    "DataFileError",
    "ExtrapolationWarning",
    "IdentifiabilityWarning",
    "InsufficientDataError",
    "ModelFileError",
    "NonFiniteError",
    "NotFittedError",
    "NotInvertibleError",
    "NumericRangeError",
    "OutputError",
    "OverwriteError",
    "ParameterError",
    "PiezohystError",
    "RecordWarning",
    "ShapeError",
    "TimeAxisError",
]


class PiezohystError(Exception):
    """Base class of every error raised on purpose by piezohyst."""


class ParameterError(PiezohystError, ValueError):
    """A constructor or function parameter has the wrong type or value."""


class ShapeError(PiezohystError, ValueError):
    """Arrays have the wrong dimension or mismatched lengths."""


class NonFiniteError(PiezohystError, ValueError):
    """An input array holds NaN or infinity."""


class TimeAxisError(PiezohystError, ValueError):
    """A time vector is missing, not strictly increasing, or inconsistent."""


class InsufficientDataError(PiezohystError, ValueError):
    """Too few samples to identify the requested parameters."""


class NumericRangeError(PiezohystError, ValueError):
    """Data so large or small that the model's parameters leave double precision."""


class NotFittedError(PiezohystError, ValueError, AttributeError):
    """An estimator was used before :meth:`fit` was called."""


class NotInvertibleError(PiezohystError, ValueError):
    """A hysteresis model violates the conditions of the analytic inverse (eq. 18)."""


class ModelFileError(PiezohystError, ValueError):
    """A model file is malformed, of an unknown version, or was modified."""


class DataFileError(PiezohystError, ValueError):
    """A data file cannot be read: missing, empty, unknown column, bad value."""


class OverwriteError(DataFileError):
    """An output would replace an input, or a file piezohyst did not write.

    ``replaceable`` is True when forcing would be allowed (never for an input).
    """

    def __init__(self, message: str, *, replaceable: bool) -> None:
        super().__init__(message)
        self.replaceable = replaceable


class OutputError(PiezohystError, OSError):
    """A file or folder cannot be written where asked (a read-only folder, a full disk)."""


class ExtrapolationWarning(UserWarning):
    """A model ran outside the (input, output) region its training data covered."""


class IdentifiabilityWarning(UserWarning):
    """The record cannot determine a fitted quantity (e.g. a lag apart from hysteresis)."""


class LimitWarning(UserWarning):
    """A voltage or slew limit held back more than a small share of the commands."""


class RecordWarning(UserWarning):
    """A record holds something not to be trusted blindly: an isolated outlier, a hole in time."""


class LearningWarning(UserWarning):
    """A learning trial was undone (its error grew) or not learned from (too few readings)."""


def warn(message: str, category: type[Warning] = UserWarning) -> None:
    """Issue a warning attributed to the first caller outside piezohyst: the line of the
    user's script (or test) that called into the library, however deep the call that found
    it (a fixed ``stacklevel`` pointed at the library's own modules from a longer chain).

    Parameters
    ----------
    message : str
    category : type of Warning, default UserWarning
    """
    frame = sys._getframe(1)
    level = 2  # the caller of this function
    while frame.f_back is not None and frame.f_globals.get("__name__", "").startswith("piezohyst"):
        frame = frame.f_back
        level += 1
    warnings.warn(message, category, stacklevel=level)
