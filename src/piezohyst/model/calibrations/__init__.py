"""The calibrations, side by side: what a record tells beside the hysteresis, each saved as a
JSON file with a schema and a checksum (one save and load: :class:`~piezohyst.io.JsonFile`).

================  ==========================================================================
module            what it holds
================  ==========================================================================
``leakage``       :class:`Leakage` (the capacitor's leakage current: conductance, bias,
                  the amplifier's discharge), :class:`Hold`
``from_holds``    :func:`calibrate_leakage` and :func:`find_holds`: the leakage from a
                  record's constant-voltage holds
``output_map``    :class:`OutputMap`: charge -> displacement (eq. 6-7), its uncertainty,
                  its calibrated range
``from_sensor``   :func:`calibrate_gain`: the map from one record with a displacement sensor
``stage_map``     :class:`StageMap` and :func:`calibrate_stage`: a coupled stage's positions
                  from its actuators' charges (each actuator's map and the coupling)
================  ==========================================================================
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..._lazy import attach

# each name loaded from its module at first use (PEP 562): a fit that needs the leakage's
# fit does not load the output map's
__getattr__, __dir__ = attach(
    __name__,
    {
        "calibrate_leakage": ".from_holds",
        "find_holds": ".from_holds",
        "calibrate_gain": ".from_sensor",
        "Hold": ".leakage",
        "Leakage": ".leakage",
        "OutputMap": ".output_map",
        "StageMap": ".stage_map",
        "calibrate_stage": ".stage_map",
    },
)

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from .from_holds import calibrate_leakage, find_holds
    from .from_sensor import calibrate_gain
    from .leakage import Hold, Leakage
    from .output_map import OutputMap
    from .stage_map import StageMap, calibrate_stage

__all__ = [
    "Hold",
    "Leakage",
    "OutputMap",
    "StageMap",
    "calibrate_gain",
    "calibrate_leakage",
    "calibrate_stage",
    "find_holds",
]
