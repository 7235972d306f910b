"""piezohyst: model and cancel hysteresis in piezoelectric actuators.

Active Prandtl-Ishlinskii models identified from voltage-to-charge data
(sensorless), their analytic inverse, and the tools around them.
"""

from __future__ import annotations

__version__ = "0.1.0"

from . import io, metrics
from .compensator import Compensator
from .errors import (
    DataFileError,
    InsufficientDataError,
    ModelFileError,
    NonFiniteError,
    NotFittedError,
    NotInvertibleError,
    ParameterError,
    PiezohystError,
    ShapeError,
    TimeAxisError,
)
from .generalized import GeneralizedPI
from .hysteresis import PIHysteresis, Propagation
from .identification import default_thresholds
from .io import read_recording, read_table, write_table
from .models import ActivePI, ClassicalPI, load_model
from .simulation import simulate

__all__ = [
    "ActivePI",
    "ClassicalPI",
    "Compensator",
    "DataFileError",
    "GeneralizedPI",
    "InsufficientDataError",
    "ModelFileError",
    "NonFiniteError",
    "NotFittedError",
    "NotInvertibleError",
    "PIHysteresis",
    "ParameterError",
    "PiezohystError",
    "Propagation",
    "ShapeError",
    "TimeAxisError",
    "__version__",
    "default_thresholds",
    "io",
    "load_model",
    "metrics",
    "read_recording",
    "read_table",
    "simulate",
    "write_table",
]
