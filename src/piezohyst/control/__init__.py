"""Control: the inverse engines, the compensator, the self-sensing controller,
learning from repetition, channel banks and the C export.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``analysis``).

The one contract every controller answers, ``step(desired, measured=None)``, ``process``,
``reads`` (``contract``)
    Controller
Feedforward (``compensator``, its arguments checked in ``arguments``; its engines in the
subpackage ``engines``)
    Compensator, CompensatorSettings, CompensatorState
A coupled stage: the coupling's inverse, then each actuator's compensator (``coupled``)
    CoupledCompensator
A structure's shared modes: the tracker with preview of a ``StructureModel`` (``structure``)
    StructureCompensator
Feedback on the measured charge (``selfsensing``)
    SelfSensingController, ControllerState, LoopSettings
A coupled stage on its actuators' charges: the coupling's inverse, then each actuator's
self-sensing loop (``coupled_selfsensing``; the stage's map, ``StageMap`` and
``calibrate_stage``, is a calibration)
    CoupledSelfSensingController
Learning a repeated scan (the subpackage ``learning``: the compensator in
``learning.compensator``, the harmonic law's design in ``learning.design``, the Jacobian law in
``learning.jacobian``, the lead-in's probe in ``learning.probe``, a trial's trajectory and limits
in ``learning.trial``, the laws behind one interface in ``learning.laws``)
    LearningCompensator, Trial, LearningDesign, design_learning
A repeated scan on a coupled stage: the coupling's inverse, one learner per actuator
(``learning.coupled``)
    CoupledLearningCompensator, CoupledTrial
Desired displacements as charges through the calibrated map (``charges``; the map itself,
``OutputMap`` and ``calibrate_gain``, is a calibration: ``piezohyst.model.calibrations``)
    Charges
Many channels in one kernel (``channels``)
    BankCompensator, BankController
The compensator outside Python (the subpackage ``export``: C in ``export.c_code``; a shared
library and a MEX gateway in ``export.shared``; an FMI 2.0 co-simulation FMU in ``export.fmu``;
their C templates in ``export/c/``)
    export_c, write_c, CCode, write_shared, write_mex, write_fmu
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

# each name loaded from its module at first use (PEP 562): importing the package stays light
__getattr__, __dir__ = attach(
    __name__,
    {
        "Charges": ".charges",
        "BankCompensator": ".channels",
        "BankController": ".channels",
        "Controller": ".contract",
        "Compensator": ".compensator",
        "CoupledCompensator": ".coupled",
        "CoupledSelfSensingController": ".coupled_selfsensing",
        "StructureCompensator": ".structure",
        "CompensatorSettings": ".compensator",
        "CompensatorState": ".compensator",
        "CCode": ".export",
        "export_c": ".export",
        "write_c": ".export",
        "write_fmu": ".export",
        "LearningCompensator": ".learning",
        "CoupledLearningCompensator": ".learning",
        "CoupledTrial": ".learning",
        "Trial": ".learning",
        "LearningDesign": ".learning",
        "design_learning": ".learning",
        "ControllerState": ".selfsensing",
        "LoopSettings": ".selfsensing",
        "SelfSensingController": ".selfsensing",
        "write_mex": ".export",
        "write_shared": ".export",
    },
)

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from .channels import BankCompensator, BankController
    from .charges import Charges
    from .compensator import Compensator, CompensatorSettings, CompensatorState
    from .contract import Controller
    from .coupled import CoupledCompensator
    from .coupled_selfsensing import CoupledSelfSensingController
    from .export import CCode, export_c, write_c, write_fmu, write_mex, write_shared
    from .learning import (
        CoupledLearningCompensator,
        CoupledTrial,
        LearningCompensator,
        LearningDesign,
        Trial,
        design_learning,
    )
    from .selfsensing import ControllerState, LoopSettings, SelfSensingController
    from .structure import StructureCompensator

__all__ = [
    "BankCompensator",
    "BankController",
    "CCode",
    "Charges",
    "Compensator",
    "CompensatorSettings",
    "CompensatorState",
    "Controller",
    "ControllerState",
    "CoupledCompensator",
    "CoupledLearningCompensator",
    "CoupledSelfSensingController",
    "CoupledTrial",
    "LearningCompensator",
    "LearningDesign",
    "LoopSettings",
    "SelfSensingController",
    "StructureCompensator",
    "Trial",
    "design_learning",
    "export_c",
    "write_c",
    "write_fmu",
    "write_mex",
    "write_shared",
]
