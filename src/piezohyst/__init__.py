"""piezohyst: model and cancel hysteresis in piezoelectric actuators.

Active Prandtl-Ishlinskii models identified from voltage-to-charge data
(sensorless), their analytic inverse, and the tools around them.

Models (the scikit-learn estimator contract: ``fit``, ``predict``, ``score``)
    ClassicalPI, ActivePI, GeneralizedPI, PIModel -- play operators plus terms
    PreisachModel, DuhemModel, BoucWenModel -- the other cores, same terms
    HysteresisModel -- the one model class: a core, terms, input/output dynamics
    ModelState, History, InverseSpec -- explicit state; what a compensator inverts
    load_model, ModelBank, load_bank -- model files; one model per channel
    CoupledModel -- several actuators moving one structure: a model each, the coupling
    StructureModel -- a structure's coupled dynamics (state space), hysteresis in the loop
    default_thresholds -- play thresholds spread over an input range

Cores and terms (for people who write their own; ``piezohyst.testing.check_core``)
    Core, Propagation, Region -- the core contract
    PIHysteresis, PreisachHysteresis, DuhemHysteresis, BoucWenHysteresis
    Term, terms -- growth and shape terms (``terms.growth_kinds()``)

Compensation and control
    Compensator, CompensatorState -- streaming feedforward, safe by default
    SelfSensingController, ControllerState -- feedback on the measured charge
    Leakage, calibrate_leakage -- the leakage from constant-voltage holds
    OutputMap, calibrate_gain -- charge to displacement, from a sensor once (eq. 6-7)
    LearningCompensator -- learning a repeated scan from the charge
    CoupledLearningCompensator -- learning a repeated scan on a coupled stage
    BankCompensator, BankController -- many channels in one kernel
    CoupledCompensator -- a coupled stage: the coupling's inverse, then each actuator's
    StageMap, calibrate_stage -- a stage's positions from its actuators' charges
    CoupledSelfSensingController -- a coupled stage on its charges, without sensors
    StructureCompensator -- a structure's inverse through its shared modes, with preview

Choosing and checking a model
    compare_models, Comparison, ComparisonRow -- held-out scores of several models
    select_model, Selection -- the choice inside one record, with how sure it is
    metrics -- NRMSE, loop width and the other error measures

Records
    io, read_recording, read_table, write_table -- CSV, Parquet, MAT, TDMS, HDF5...
    simulate -- the simulated bench and plants (``piezohyst.simulation``)

Errors and warnings (``piezohyst.errors``; every error is a ``ValueError`` too)
    PiezohystError, ParameterError, ShapeError, NonFiniteError, TimeAxisError,
    InsufficientDataError, NumericRangeError, NotFittedError, NotInvertibleError,
    ModelFileError, DataFileError, OutputError
    ExtrapolationWarning, LimitWarning, RecordWarning

Modules not imported here: ``piezohyst.io.screening`` (a record's check),
``piezohyst.testing`` (the core contract as a check), ``piezohyst.analysis.selection``,
``piezohyst.workflows`` (file to file), ``piezohyst.cli`` (the command line).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import attach
from ._version import __version__
from .errors import (
    DataFileError,
    ExtrapolationWarning,
    InsufficientDataError,
    LimitWarning,
    ModelFileError,
    NonFiniteError,
    NotFittedError,
    NotInvertibleError,
    NumericRangeError,
    OutputError,
    ParameterError,
    PiezohystError,
    RecordWarning,
    ShapeError,
    TimeAxisError,
)

# Every other public name is imported from its module at first use (PEP 562), so
# ``import piezohyst`` loads neither the readers nor the models until a program asks for them.
__getattr__, __dir__ = attach(
    __name__,
    {
        "io": ".io:module",
        "metrics": ".metrics:module",
        "selection": ".analysis.selection:module",  # ph.selection, as before the packages
        "terms": ".model.terms:module",
        "Comparison": ".analysis.comparison",
        "ComparisonRow": ".analysis.comparison",
        "compare_models": ".analysis.comparison",
        "Selection": ".analysis.selection",
        "select_model": ".analysis.selection",
        "OutputMap": ".model.calibrations",
        "calibrate_gain": ".model.calibrations",
        "StageMap": ".model.calibrations",
        "calibrate_stage": ".model.calibrations",
        "CoupledSelfSensingController": ".control.coupled_selfsensing",
        "BankCompensator": ".control.channels",
        "BankController": ".control.channels",
        "CoupledCompensator": ".control.coupled",
        "CoupledModel": ".model.coupled",
        "StructureModel": ".model.structure",
        "StructureCompensator": ".control.structure",
        "Compensator": ".control.compensator",
        "CompensatorState": ".control.compensator",
        "LearningCompensator": ".control.learning",
        "CoupledLearningCompensator": ".control.learning",
        "ControllerState": ".control.selfsensing",
        "SelfSensingController": ".control.selfsensing",
        "read_recording": ".io",
        "read_table": ".io",
        "write_table": ".io",
        "ModelBank": ".model.bank",
        "load_bank": ".model.bank",
        "Core": ".model.cores.base",
        "Propagation": ".model.cores.base",
        "Region": ".model.cores.base",
        "BoucWenHysteresis": ".model.cores.boucwen",
        "DuhemHysteresis": ".model.cores.duhem",
        "PIHysteresis": ".model.cores.play",
        "default_thresholds": ".model.cores.play",
        "PreisachHysteresis": ".model.cores.preisach",
        "Leakage": ".model.calibrations",
        "calibrate_leakage": ".model.calibrations",
        "History": ".model.model",
        "HysteresisModel": ".model.model",
        "InverseSpec": ".model.inverse_spec",
        "ModelState": ".model.model",
        "ActivePI": ".model.presets",
        "BoucWenModel": ".model.presets",
        "ClassicalPI": ".model.presets",
        "DuhemModel": ".model.presets",
        "GeneralizedPI": ".model.presets",
        "PIModel": ".model.presets",
        "PreisachModel": ".model.presets",
        "load_model": ".model.persistence",
        "Term": ".model.terms",
        "simulate": ".simulation",
    },
)

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from . import io, metrics
    from .analysis import selection as selection
    from .analysis.comparison import Comparison, ComparisonRow, compare_models
    from .analysis.selection import Selection, select_model
    from .control.channels import BankCompensator, BankController
    from .control.compensator import Compensator, CompensatorState
    from .control.coupled import CoupledCompensator
    from .control.coupled_selfsensing import CoupledSelfSensingController
    from .control.learning import CoupledLearningCompensator, LearningCompensator
    from .control.selfsensing import ControllerState, SelfSensingController
    from .control.structure import StructureCompensator
    from .io import read_recording, read_table, write_table
    from .model import (  # the model package's face: one name each, as it exports them
        ActivePI,
        BoucWenModel,
        ClassicalPI,
        CoupledModel,
        DuhemModel,
        GeneralizedPI,
        History,
        HysteresisModel,
        InverseSpec,
        Leakage,
        ModelBank,
        ModelState,
        OutputMap,
        PIModel,
        PreisachModel,
        StageMap,
        StructureModel,
        Term,
        calibrate_gain,
        calibrate_leakage,
        calibrate_stage,
        load_bank,
        load_model,
        terms,
    )
    from .model.cores.base import Core, Propagation, Region
    from .model.cores.boucwen import BoucWenHysteresis
    from .model.cores.duhem import DuhemHysteresis
    from .model.cores.play import PIHysteresis, default_thresholds
    from .model.cores.preisach import PreisachHysteresis
    from .simulation import simulate

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
    "CoupledCompensator",
    "CoupledLearningCompensator",
    "CoupledModel",
    "CoupledSelfSensingController",
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
    "LimitWarning",
    "ModelBank",
    "ModelFileError",
    "ModelState",
    "NonFiniteError",
    "NotFittedError",
    "NotInvertibleError",
    "NumericRangeError",
    "OutputError",
    "OutputMap",
    "PIHysteresis",
    "PIModel",
    "ParameterError",
    "PiezohystError",
    "PreisachHysteresis",
    "PreisachModel",
    "Propagation",
    "RecordWarning",
    "Region",
    "Selection",
    "SelfSensingController",
    "ShapeError",
    "StageMap",
    "StructureCompensator",
    "StructureModel",
    "Term",
    "TimeAxisError",
    "__version__",
    "calibrate_gain",
    "calibrate_leakage",
    "calibrate_stage",
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
