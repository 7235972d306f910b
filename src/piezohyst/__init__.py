"""piezohyst: model and cancel hysteresis in piezoelectric actuators.

Active Prandtl-Ishlinskii models identified from voltage-to-charge data
(sensorless), their analytic inverse, and the tools around them.
"""

from __future__ import annotations

from . import io, metrics, terms
from ._version import __version__
from .bank import ModelBank, load_bank
from .channels import BankCompensator, BankController
from .comparison import Comparison, ComparisonRow, compare_models
from .compensator import Compensator, CompensatorState
from .cores.base import Core, Propagation, Region
from .cores.boucwen import BoucWenHysteresis
from .cores.duhem import DuhemHysteresis
from .cores.play import PIHysteresis
from .cores.preisach import PreisachHysteresis
from .errors import (
    DataFileError,
    ExtrapolationWarning,
    InsufficientDataError,
    ModelFileError,
    NonFiniteError,
    NotFittedError,
    NotInvertibleError,
    NumericRangeError,
    OutputError,
    ParameterError,
    PiezohystError,
    ShapeError,
    TimeAxisError,
)
from .identification import default_thresholds
from .io import read_recording, read_table, write_table
from .leakage import Leakage, calibrate_leakage
from .learning import LearningCompensator
from .model import History, HysteresisModel, InverseSpec, ModelState
from .models import (
    ActivePI,
    BoucWenModel,
    ClassicalPI,
    DuhemModel,
    GeneralizedPI,
    PIModel,
    PreisachModel,
)
from .persistence import load_model
from .selection import Selection, select_model
from .selfsensing import ControllerState, SelfSensingController
from .simulation import simulate
from .terms import Term

__all__ = [
    "ActivePI",
    "BankCompensator",
    "BankController",
    "BoucWenHysteresis",
    "BoucWenModel",
    "ClassicalPI",
    "Comparison",
    "ComparisonRow",
    "Compensator",
    "CompensatorState",
    "ControllerState",
    "Core",
    "DataFileError",
    "DuhemHysteresis",
    "DuhemModel",
    "ExtrapolationWarning",
    "GeneralizedPI",
    "History",
    "HysteresisModel",
    "InsufficientDataError",
    "InverseSpec",
    "Leakage",
    "LearningCompensator",
    "ModelBank",
    "ModelFileError",
    "ModelState",
    "NonFiniteError",
    "NotFittedError",
    "NotInvertibleError",
    "NumericRangeError",
    "OutputError",
    "PIHysteresis",
    "PIModel",
    "ParameterError",
    "PiezohystError",
    "PreisachHysteresis",
    "PreisachModel",
    "Propagation",
    "Region",
    "Selection",
    "SelfSensingController",
    "ShapeError",
    "Term",
    "TimeAxisError",
    "__version__",
    "calibrate_leakage",
    "compare_models",
    "default_thresholds",
    "io",
    "load_bank",
    "load_model",
    "metrics",
    "read_recording",
    "read_table",
    "select_model",
    "simulate",
    "terms",
    "write_table",
]
