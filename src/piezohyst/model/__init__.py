"""Models: terms, dynamics, the cores (``cores/``, one module per core), the estimator
contract, state, the fit, the model class and its presets, files and banks, and the
calibrations beside them (the subpackage ``calibrations``: the leakage from holds, the
charge -> displacement map from a sensor).
May import: the foundation, ``_kernels``, ``io``.

The model (``model``: the one class; ``presets``: its presets; ``state``: runs from a state;
``inverse_spec``: what a compensator inverts)
    HysteresisModel, ModelState, History, InverseSpec
    ClassicalPI, ActivePI, GeneralizedPI, PIModel, PreisachModel, DuhemModel, BoucWenModel
What a model holds besides its core
    Term, growth_kinds (``terms``); InputDynamics, OutputDynamics (``dynamics``, their
    search in ``fit_dynamics``)
The calibrations, side by side (``calibrations``: ``leakage`` and ``from_holds``,
``output_map`` and ``from_sensor``, ``stage_map``)
    Leakage, calibrate_leakage, OutputMap, calibrate_gain, StageMap, calibrate_stage
Several actuators moving one structure (``coupled``; ``structure``, its identification in
``structure_fit``)
    CoupledModel, StructureModel
Files and banks (``persistence``, ``bank``)
    load_model, save_model, model_names, model_class, register; ModelBank, load_bank
The estimator contract (``estimator``) and the fit (``fit_record``: a record in, the core
identified and scored; ``fit_state``: what a fit found, stored by its one writer;
``fit_dynamics``: the input and output dynamics searched)
    Estimator
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

# each name loaded from its module at first use (PEP 562): importing the package stays light
__getattr__, __dir__ = attach(
    __name__,
    {
        "ModelBank": ".bank",
        "CoupledModel": ".coupled",
        "StructureModel": ".structure",
        "load_bank": ".bank",
        "InputDynamics": ".dynamics",
        "OutputDynamics": ".dynamics",
        "Estimator": ".estimator",
        "Leakage": ".calibrations",
        "calibrate_leakage": ".calibrations",
        "OutputMap": ".calibrations",
        "calibrate_gain": ".calibrations",
        "StageMap": ".calibrations",
        "calibrate_stage": ".calibrations",
        "History": ".model",
        "HysteresisModel": ".model",
        "InverseSpec": ".inverse_spec",
        "ModelState": ".model",
        "ActivePI": ".presets",
        "BoucWenModel": ".presets",
        "ClassicalPI": ".presets",
        "DuhemModel": ".presets",
        "GeneralizedPI": ".presets",
        "PIModel": ".presets",
        "PreisachModel": ".presets",
        "load_model": ".persistence",
        "model_class": ".persistence",
        "model_names": ".persistence",
        "register": ".persistence",
        "save_model": ".persistence",
        "Term": ".terms",
        "growth_kinds": ".terms",
    },
)

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from .bank import ModelBank, load_bank
    from .calibrations import (
        Leakage,
        OutputMap,
        StageMap,
        calibrate_gain,
        calibrate_leakage,
        calibrate_stage,
    )
    from .coupled import CoupledModel
    from .dynamics import InputDynamics, OutputDynamics
    from .estimator import Estimator
    from .inverse_spec import InverseSpec
    from .model import History, HysteresisModel, ModelState
    from .persistence import load_model, model_class, model_names, register, save_model
    from .presets import (
        ActivePI,
        BoucWenModel,
        ClassicalPI,
        DuhemModel,
        GeneralizedPI,
        PIModel,
        PreisachModel,
    )
    from .structure import StructureModel
    from .terms import Term, growth_kinds

__all__ = [
    "ActivePI",
    "BoucWenModel",
    "ClassicalPI",
    "CoupledModel",
    "DuhemModel",
    "Estimator",
    "GeneralizedPI",
    "History",
    "HysteresisModel",
    "InputDynamics",
    "InverseSpec",
    "Leakage",
    "ModelBank",
    "ModelState",
    "OutputDynamics",
    "OutputMap",
    "PIModel",
    "PreisachModel",
    "StageMap",
    "StructureModel",
    "Term",
    "calibrate_gain",
    "calibrate_leakage",
    "calibrate_stage",
    "growth_kinds",
    "load_bank",
    "load_model",
    "model_class",
    "model_names",
    "register",
    "save_model",
]
