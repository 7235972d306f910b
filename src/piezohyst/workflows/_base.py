"""What every file workflow shares: the output guard, the units check, loading a model."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..control.compensator import CompensatorSettings
from ..errors import DataFileError, OverwriteError, ParameterError, warn
from ..io import (
    Table,
    is_piezohyst_output,
)
from ..metrics import clipped
from ..model.model import HysteresisModel
from ..model.persistence import load_model
from ..units import Role, scaled, to_standard

PathLike = str | os.PathLike[str]


Progress = Callable[[int], None] | None  # told the rows read so far


def guard_outputs(
    outputs: Sequence[PathLike], inputs: Sequence[PathLike], *, force: bool = False
) -> None:
    """Refuse to write where data would be lost, before any work is done.

    An output that is one of the inputs is always refused; an existing file
    (or report folder) that piezohyst did not write is refused unless
    ``force`` (see :func:`~piezohyst.io.is_piezohyst_output`).

    Parameters
    ----------
    outputs, inputs : sequence of path
    force : bool, default False
        Replace existing files piezohyst did not write.

    Raises
    ------
    OverwriteError
    """
    # inputs by resolved path and by file identity (hard links), each looked up once
    by_path: dict[Path, Path] = {}
    by_inode: dict[tuple[int, int], Path] = {}
    for src in map(Path, inputs):
        by_path.setdefault(src.resolve(), src)
        try:
            st = src.stat()
        except OSError:
            continue
        by_inode.setdefault((st.st_dev, st.st_ino), src)
    for out in map(Path, outputs):
        same = by_path.get(out.resolve())
        if same is None and out.exists():
            st = out.stat()
            same = by_inode.get((st.st_dev, st.st_ino))
        if same is not None:
            msg = (
                f"{out}: that is an input of this command ({same}); piezohyst never writes "
                "over its input: choose another output name"
            )
            raise OverwriteError(msg, replaceable=False)
        if out.exists() and not force and not is_piezohyst_output(out):
            kind = "folder" if out.is_dir() else "file"
            msg = f"{out}: an existing {kind} that piezohyst did not write; not replacing it"
            raise OverwriteError(msg, replaceable=True)


#: Suffixes of files piezohyst reads or writes: a folder output named so is a slip
FILE_SUFFIXES = frozenset({".csv", ".tsv", ".txt", ".json", ".npz", ".parquet", ".mat", ".tdms",
                           ".h5", ".hdf5", ".html", ".md", ".png", ".pdf", ".svg", ".c", ".h",
                           ".fmu", ".zip", ".xlsx"})  # fmt: skip


def check_folder(out: PathLike, what: str) -> Path:
    """The folder ``out`` a command writes ``what`` into, refused where its name is a file's
    (``-o fleet.csv`` made a folder named so, the models and the summary inside it).

    Parameters
    ----------
    out : path
    what : str
        What goes into it, for the message.

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    ParameterError
        ``out`` names a file (a table's suffix), not a folder.
    """
    p = Path(out)
    if not p.is_dir() and p.suffix.lower() in FILE_SUFFIXES:
        msg = (
            f"{p}: the name of a {p.suffix} file, but {what} go into a folder: give a folder "
            f"name (such as {p.with_suffix('')})"
        )
        raise ParameterError(msg)
    return p


_DEFAULT_SETTINGS = CompensatorSettings()  # frozen: safe as a shared default


def desired_unit(settings: CompensatorSettings, model: HysteresisModel) -> str:
    """The unit a desired trajectory is in: m in the displacement domain or through an output
    map, else the model's output unit."""
    metres = settings.domain == "displacement" or settings.output_map is not None
    return "m" if metres else model.output_unit


def command_gain(scale: str | float | None) -> float:
    """Piezo volts per volt written: the amplifier's gain that ``--command-scale`` gives (a
    DAQ plays 0-10 V into an amplifier of gain 14: ``14``; an inverting one: ``-14``). Commands
    and excitations are written divided by it, in the volts the DAQ plays; 1 without one."""
    return 1.0 if scale is None else scaled(scale, "V", "input", "--command-scale")[0]


def standard_column(
    table: Table,
    name: str,
    what: str,
    role: Role,
    expected: str | None,
    scale: tuple[str, str | float | None] | None = None,
) -> Any:
    """A column in the unit piezohyst works in (its header's: um, uC, ms, as ``compensate``
    reads a target), refused where that is not of ``expected``'s kind (None: any).

    ``scale``: the option's name and what one unit of the column is worth (a DAQ's volts,
    :func:`piezohyst.units.scaled`)."""
    found = table.find(name)
    if found is None:
        columns = ", ".join(table.columns)
        msg = f"{table.path}: no column {name!r} for the {what} (columns: {columns})"
        raise DataFileError(msg)
    where = f"{table.path}: column {found!r}"
    values, unit = table.get(found, finite=False), table.unit(found)
    if scale is not None and scale[1] is not None and role != "time":
        factor, unit = scaled(scale[1], unit, role, scale[0])
        values = values * factor
    values, unit = to_standard(values, unit, role, where)
    if expected is not None and unit is not None and unit != expected:
        msg = f"{where}: the {what} is in {unit!r}, where {expected!r} is expected"
        raise DataFileError(msg)
    return values


#: Spans of an output no piezo reaches in the unit assumed from the column's name: 1 cm
#: (amplified stages move up to a few mm), 10 mC (a large stack at full voltage holds a few)
IMPLAUSIBLE = {"m": 0.01, "C": 0.01}


def warn_assumed_span(
    span: float, assumed: str, column: str | None, data: PathLike, option: str = "--output-unit"
) -> None:
    """Warn when an output that states no unit, taken in ``assumed`` (m or C), spans more
    than any piezo's does in it (:data:`IMPLAUSIBLE`): micrometres or nanocoulombs, most
    likely; ``option`` is the one that says the unit."""
    if assumed in IMPLAUSIBLE and span > IMPLAUSIBLE[assumed]:
        name = {"m": "metres", "C": "coulombs"}[assumed]
        usual = {"m": "um or nm", "C": "uC or nC"}[assumed]
        warn(
            f"{data}: column {column!r} states no unit and spans {span:.4g}, read as {name}; "
            f"no piezo's does: if it is in {usual}, give the unit ({option} "
            f"{usual.split()[0]}, or a header '{column} [{usual.split()[0]}]')",
            UserWarning,
        )


def time_rate(t: FloatArray) -> float | None:
    """The sample rate (Hz) of a time column (s): one over its median step, rounded to 12
    digits (1000.0, not 999.9999999999991 from times written in ms); None where it does not
    increase."""
    steps = np.diff(t)
    if not (steps.size and np.all(steps > 0)):
        return None
    return float(f"{1.0 / float(np.median(steps)):.12g}")


#: what a sample rate given beside a time column it contradicts would do
ONE_RATE = (
    "the values would be computed at one rate and written at the other's times; give the "
    "rate of the file's time column, or leave it out"
)


def check_rate(where: PathLike, timed: float | None, rate: float, against: str) -> None:
    """Refuse a file whose time column steps at another rate than ``rate`` (Hz), the one its
    values will be computed or played at: ``against`` (after the file's rate) says whose
    rate it is and what would follow."""
    if timed is not None and abs(timed - rate) > 1e-3 * rate:
        msg = f"{where}: the time column steps at {timed:.6g} Hz{against}"
        raise DataFileError(msg)


#: An input span (V) no piezo amplifier drives: a column in mV read as volts
VOLTS_IMPLAUSIBLE = 2e4


def warn_assumed_volts(span: float, unit: str | None, column: str | None, data: PathLike) -> None:
    """Warn when an input that states no unit (taken in V) spans more than any piezo
    amplifier drives (:data:`VOLTS_IMPLAUSIBLE`): millivolts, most likely."""
    if unit is None and span > VOLTS_IMPLAUSIBLE:
        warn(
            f"{data}: column {column!r} states no unit and spans {span:.4g}, read as volts; "
            "no piezo amplifier drives that: if it is in mV, give the unit (--input-unit mV, "
            f"or a header '{column} [mV]')",
            UserWarning,
        )


def _default_unit(column: str | None) -> str:
    """The unit of an output column that names none: piezohyst's own names (a grouped file's
    too: ``run 1/charge``), else arbitrary."""
    short = (column or "").rpartition("/")[2].casefold()
    return {"charge": "C", "displacement": "m"}.get(short, "a.u.")


def _check_measured_unit(unit: str | None, model: HysteresisModel, data: PathLike) -> None:
    """The recorded output must be in the model's unit; a unit the file omits is assumed."""
    if unit is None:
        warn(
            f"{data}: the output column states no unit; taken to be in the model's unit "
            f"{model.output_unit!r} (give the output unit if it is not)",
            UserWarning,
        )
    elif unit != model.output_unit:
        msg = f"{data}: the output column is in {unit!r}, the model predicts {model.output_unit!r}"
        raise DataFileError(msg)


def _load(model_path: PathLike) -> HysteresisModel:
    model: HysteresisModel = load_model(model_path)
    return model


#: A measured channel flat at its extreme on this share of the samples or more is reported
CLIP_SHARE = 0.01


def warn_clipped(
    chunks: Iterable[FloatArray], column: str | None, unit: str | None, data: PathLike
) -> None:
    """Warn when a measured channel sits at its top or bottom in flat runs (clipped), and
    when a column whose unit piezohyst assumes from its name (:func:`_default_unit`) spans
    more than any piezo's does in that unit (:data:`IMPLAUSIBLE`)."""
    extremes = [math.inf, -math.inf]

    def seen() -> Iterator[FloatArray]:
        for chunk in chunks:
            if chunk.size:
                extremes[:] = (
                    min(extremes[0], float(chunk.min())),
                    max(extremes[1], float(chunk.max())),
                )
            yield chunk

    count, which, level, first, n = clipped(seen())
    if unit is None:
        warn_assumed_span(extremes[1] - extremes[0], _default_unit(column), column, data)
    if n and count >= CLIP_SHARE * n:
        warn(
            f"{data}: column {column!r} sits at its {which} ({level:.6g} {unit or ''}) on "
            f"{count} of {n} samples ({100 * count / n:.1f} %, the first at sample {first} of "
            "the window) in flat runs: the recording clipped there (a sensor or an ADC at "
            "its full scale) and those samples say nothing of the actuator; record with a "
            "wider range, or use a window that does not clip",
            UserWarning,
        )


def _desired_column(table: Table, column: str | None, target: PathLike) -> str:
    """The desired trajectory's column: as named, else ``desired``, else the only one but time."""
    if column is None:
        others = [c for c in table.columns if c != "time"]
        column = "desired" if "desired" in table else (others[0] if len(others) == 1 else None)
        if column is None:
            msg = (
                f"{target}: which column is the desired trajectory? Name it 'desired' or name "
                f"the column (columns: {', '.join(map(repr, table.columns))})"
            )
            raise DataFileError(msg)
    return table.resolve(column)
