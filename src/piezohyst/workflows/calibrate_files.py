"""``piezohyst calibrate-leakage`` and ``calibrate-gain``: the leakage from holds, the charge to
displacement map from a sensor's record.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..errors import DataFileError
from ..io import (
    DataSpec,
)
from ..model.calibrations import Leakage, OutputMap, calibrate_gain, calibrate_leakage
from ..model.calibrations.leakage import LEAKAGE_TERMS
from ._base import (
    PathLike,
    _default_unit,
    _load,
    guard_outputs,
    warn_assumed_span,
)

__all__ = ["calibrate_gain_file", "calibrate_leakage_file"]


def calibrate_leakage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    data_spec: DataSpec | None = None,
    terms: Sequence[str] = LEAKAGE_TERMS,
    min_duration: float = 1.0,
    settle: float | str = "auto",
    force: bool = False,
) -> Leakage:
    """Calibrate the leakage from the holds of a record and save it (JSON) to ``out``.

    Parameters
    ----------
    data : str or os.PathLike
        A record with constant-voltage holds (voltage, charge, time).
    out : str or os.PathLike, optional
        Where to save the leakage.
    data_spec : DataSpec, optional
        Columns, units and window.
    terms : sequence of str
        Leakage terms to fit (see :func:`~piezohyst.calibrate_leakage`).
    min_duration, settle
        Hold detection and trim (see :func:`~piezohyst.calibrate_leakage`).
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    Leakage
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    rec = (data_spec or DataSpec()).read(data)
    assert rec.y is not None
    w = rec.window
    x_unit, y_unit = rec.units
    leak = calibrate_leakage(
        rec.t[w],
        rec.x[w],
        rec.y[w],
        terms=terms,
        min_duration=min_duration,
        settle=settle,
        input_unit=x_unit or "V",
        output_unit=y_unit or _default_unit(rec.names[1]),
    )
    if out is not None:
        leak.save(out)
    return leak


def _sensor_spec(
    spec: DataSpec, column: str, unit: str | None, scale: str | float | None
) -> DataSpec:
    """``spec`` reading the displacement sensor's column as its output: its own unit and
    scale (never the charge channel's)."""
    return dataclasses.replace(spec, output_column=column, output_unit=unit, output_scale=scale)


def calibrate_gain_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike | None = None,
    *,
    displacement_column: str = "displacement",
    displacement_unit: str | None = None,
    displacement_scale: str | float | None = None,
    data_spec: DataSpec | None = None,
    force: bool = False,
    output_dynamics: str = "auto",
) -> OutputMap:
    """Calibrate the charge -> displacement map from a record with a displacement sensor
    (voltage, charge and displacement sampled together) and save it (JSON) to ``out``.

    Parameters
    ----------
    model_path : str or os.PathLike
        A model fitted on voltage -> charge.
    data : str or os.PathLike
        The record: its voltage, charge and time columns as ``data_spec`` names them,
        and the displacement column.
    out : str or os.PathLike, optional
        Where to save the map.
    displacement_column : str, default "displacement"
    displacement_unit : str, optional
        Its unit if its header does not say (um, nm, m...); converted to m.
    displacement_scale : str or float, optional
        What one unit of it is worth, for a sensor logged in V (``"10 um/V"``).
    data_spec : DataSpec, optional
        Columns, units, scales and window of the voltage and charge.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    output_dynamics : {"auto", "none", "second-order"}, default "auto"
        A mode between the charge and the displacement (:func:`~piezohyst.calibrate_gain`).

    Returns
    -------
    OutputMap
    """
    if out is not None:
        guard_outputs([out], [data, model_path], force=force)
    model = _load(model_path)
    spec = data_spec or DataSpec()
    rec = spec.read(data)
    sensor = _sensor_spec(spec, displacement_column, displacement_unit, displacement_scale).read(
        data
    )
    if rec.t is None:
        msg = f"{data}: calibrate-gain needs the time column (or --sample-rate)"
        raise DataFileError(msg)
    assert rec.y is not None and sensor.y is not None
    w = rec.window
    unit = sensor.units[1] or "m"
    if sensor.units[1] is None:
        span = float(np.ptp(sensor.y[w]))
        warn_assumed_span(span, "m", displacement_column, data, "--displacement-unit")
    om = calibrate_gain(model, rec.x[w], rec.y[w], sensor.y[w], rec.t[w], output_unit=unit,
                        output_dynamics=output_dynamics)  # fmt: skip
    if out is not None:
        om.save(out)
    return om
