"""``piezohyst fit`` with several input and output columns: a coupled stage identified from
one file (:class:`~piezohyst.CoupledModel`), saved as a coupled model file."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..errors import DataFileError, ParameterError
from ..io import DataSpec
from ..model.coupled import CoupledModel
from ..model.persistence import model_class
from ._base import PathLike, guard_outputs

__all__ = ["fit_stage_file", "stage_columns"]


def stage_columns(spec: str | None, what: str) -> list[str]:
    """Column names from ``--input vx,vy`` (several: a stage), checked.

    Parameters
    ----------
    spec : str or None
        The option's value.
    what : str
        The option, for the error.

    Returns
    -------
    list of str
        One name per channel (one: not a stage).
    """
    names = [c.strip() for c in (spec or "").split(",")]
    if any(not c for c in names):
        msg = f"{what} {spec!r}: a column name is empty (write them as vx,vy)"
        raise ParameterError(msg)
    return names


def fit_stage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    inputs: Sequence[str],
    outputs: Sequence[str],
    model: str = "classical-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    force: bool = False,
) -> CoupledModel:
    """Fit a coupled stage (one model per actuator and the coupling) to a file and save it.

    Each actuator's voltage column and each axis's position column are read as the single
    channel's are (units, scales, window, the record's check), pair by pair, on the same
    time axis.

    Parameters
    ----------
    data : str or os.PathLike
        The recording.
    out : str or os.PathLike, optional
        Where to save the coupled model (JSON).
    inputs, outputs : sequence of str
        The actuators' voltage columns and the axes' position columns, as many of each.
    model : str
        Each actuator's model (a name from :func:`~piezohyst.model.persistence.model_names`).
    operators : int
        Play operators, for the models that have them.
    data_spec : DataSpec, optional
        Time column, rate, group, window, units and scales (its input and output columns
        are replaced by each pair).
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    CoupledModel

    Raises
    ------
    ParameterError
        Not as many outputs as inputs, fewer than two, or a setting the model lacks.
    DataFileError
        The pairs' time axes differ (a column read with another window).
    """
    if len(inputs) != len(outputs) or len(inputs) < 2:
        msg = (
            f"a stage pairs each actuator's voltage with one axis's position: got "
            f"{len(inputs)} input and {len(outputs)} output columns (two or more of each)"
        )
        raise ParameterError(msg)
    if out is not None:
        guard_outputs([out], [data], force=force)
    spec = data_spec or DataSpec()
    recs = [
        dataclasses.replace(spec, input_column=i, output_column=o).read(data)
        for i, o in zip(inputs, outputs, strict=True)
    ]
    w = recs[0].window
    t = recs[0].t[w]
    for rec in recs[1:]:
        if rec.t[rec.window].shape != t.shape or not np.array_equal(rec.t[rec.window], t):
            msg = f"{data}: the columns' time axes differ (rows dropped from one, not another?)"
            raise DataFileError(msg)
    u = np.column_stack([rec.x[rec.window] for rec in recs])
    y = np.column_stack([rec.y[rec.window] for rec in recs if rec.y is not None])
    cls = model_class(model)
    accepted = cls().get_params()
    settings: dict[str, object] = {"output_unit": recs[0].units[1] or "m"}
    if "n_operators" in accepted:
        settings["n_operators"] = operators
    elif operators != 10:
        msg = f"the 'operators' setting does not apply to {model} (it has no play operators)"
        raise ParameterError(msg)
    stage = CoupledModel(cls(**settings)).fit(u, y, t=t)
    if out is not None:
        stage.save(out)
    return stage
