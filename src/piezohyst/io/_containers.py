"""Reading container files: NumPy ``.npz``, Parquet, MATLAB ``.mat``, HDF5 and NI TDMS,
each into a :class:`~._formats.Table` (a group or a file's channels chosen by name)."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import DataFileError
from ..units import split_unit
from ._formats import Table, as_column, choose_group, field_named, table_from_arrays

__all__ = ["read_hdf5", "read_mat", "read_npz", "read_parquet", "read_tdms"]


def read_npz(path: Path) -> Table:
    # open the file ourselves: np.load(path) leaks its handle when the zip is damaged
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    return table_from_arrays(path, arrays, "NPZ")


def read_parquet(path: Path, progress: Callable[[int], None] | None = None) -> Table:
    """Numeric columns of a Parquet file, read batch by batch (``progress``: rows so far)."""
    import pyarrow.parquet as pq

    source = pq.ParquetFile(path)
    names = source.schema_arrow.names
    parts: dict[str, list[np.ndarray]] = {name: [] for name in names}
    rows = 0
    for batch in source.iter_batches(batch_size=1 << 18):
        for name, column in zip(names, batch.columns, strict=True):
            parts[name].append(column.to_numpy(zero_copy_only=False))
        rows += batch.num_rows
        if progress is not None:
            progress(rows)
    arrays: dict[str, object] = {}
    units: dict[str, str] = {}
    for name in names:
        bare, unit = split_unit(name)
        arrays[bare] = np.concatenate(parts[name]) if parts[name] else np.empty(0)
        if unit is not None:
            units[bare] = unit
    return dataclasses.replace(table_from_arrays(path, arrays, "Parquet"), units=units)


def read_mat(path: Path, group: str | None, channels: Sequence[str]) -> Table:
    from ._isolate import parse_isolated

    return _grouped(path, parse_isolated("mat_arrays", path, "MAT"), "MAT", group, channels)


def read_hdf5(path: Path, group: str | None, channels: Sequence[str]) -> Table:
    from ._isolate import parse_isolated

    return _grouped(path, parse_isolated("hdf5_arrays", path, "HDF5"), "HDF5", group, channels)


#: Names under which files state their sample rate (Hz) or sample interval (s)
RATE_NAMES = ("fs", "rate", "sample_rate", "sampling_rate", "samplerate", "sampling_frequency")


STEP_NAMES = ("dt", "ts", "sample_interval", "sampling_interval", "wf_increment")


def _grouped(
    path: Path, found: Mapping[str, object], kind: str, group: str | None, channels: Sequence[str]
) -> Table:
    """A Table of a container's 1-D arrays (HDF5 paths ``group/name``; a MAT file is one
    group), with the sample interval stated beside them (:func:`_stated_interval`).

    With ``group``, its own arrays by their short names. Without, every array by its
    path, and the interval is that of the group of the columns asked for (or of the
    only group).
    """
    columns = {k: v for k, v in found.items() if "@" not in k and as_column(v) is not None}
    groups = sorted({c.rpartition("/")[0] for c in columns})
    home: str | None
    if group is not None:
        home = group.strip("/")
        if home not in groups:
            listing = ", ".join(repr(g or "/") for g in groups)
            msg = f"{path}: no {kind} group {group!r}; available: {listing}"
            raise DataFileError(msg)
        picked = {
            k.rpartition("/")[2]: v for k, v in columns.items() if k.rpartition("/")[0] == home
        }
    else:
        picked = dict(columns)
        named = [c if c in columns else field_named(c, columns) for c in channels]
        asked = [c.rpartition("/")[0] for c in named if c is not None]
        home = asked[0] if asked else (groups[0] if len(groups) == 1 else None)
    table = table_from_arrays(path, picked, kind)
    units = {
        k[: -len("_unit")]: v
        for k, v in found.items()
        if isinstance(v, str) and k.endswith("_unit") and k[: -len("_unit")] in table
    }
    for key, value in found.items():  # an HDF5 dataset's 'units' attribute
        if not (isinstance(value, str) and key.endswith("@unit")):
            continue
        owner = key[: -len("@unit")]
        short = owner.rpartition("/")[2] if owner.rpartition("/")[0] == home else ""
        for name in (owner, short):
            if name and name in table:
                units.setdefault(name, value)
                break
    return dataclasses.replace(
        table,
        units=units,
        time_step=None if home is None else _stated_interval(found, set(columns), home),
        group=group,
        groups=tuple(g or "/" for g in groups) if len(groups) > 1 else (),
    )


def _stated_interval(found: Mapping[str, object], datasets: set[str], home: str) -> float | None:
    """The sample interval (s) a group or one of its parents states, nearest first: a
    scalar dataset or attribute named as in :data:`RATE_NAMES` (Hz) or :data:`STEP_NAMES` (s).
    Attributes come as ``owner@name``; a dataset's attributes count for its group."""
    stated: dict[str, float] = {}  # 'group/leaf' -> interval
    for key, value in found.items():
        owner, at, leaf = key.partition("@")
        if at:
            place = owner.rpartition("/")[0] if owner in datasets else owner
        else:
            place, _, leaf = key.rpartition("/")
        arr = np.asarray(value)
        if arr.size != 1 or arr.dtype.kind not in "biuf":
            continue
        v = float(arr.reshape(-1)[0])
        name = leaf.lower()
        if v > 0 and name in RATE_NAMES:
            stated.setdefault(place, 1.0 / v)
        elif v > 0 and name in STEP_NAMES:
            stated.setdefault(place, v)
    parts = home.split("/") if home else []
    for depth in range(len(parts), -1, -1):
        place = "/".join(parts[:depth])
        if place in stated:
            return stated[place]
    return None


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def read_tdms(path: Path, group: str | None, channels: Sequence[str] = ()) -> Table:
    from nptdms import TdmsFile

    # npTDMS reads what it can of a damaged file and logs a warning: for us that is
    # a damaged file, said once, not partial data behind a few lines of log
    logger = logging.getLogger("nptdms")
    collect = _Collect()
    propagate = logger.propagate
    logger.addHandler(collect)
    logger.propagate = False
    try:
        tdms = TdmsFile.read(path)
    finally:
        logger.removeHandler(collect)
        logger.propagate = propagate
    if collect.messages:
        msg = f"{path}: the TDMS file is truncated or damaged ({collect.messages[0]})"
        raise DataFileError(msg)
    groups = tdms.groups()
    if not groups:
        msg = f"{path}: the TDMS file has no groups"
        raise DataFileError(msg)
    names = [g.name for g in groups]
    chosen = tdms[
        choose_group(
            path,
            {g.name: [c.name for c in g.channels()] for g in groups},
            group,
            channels,
            "TDMS group",
        )
    ]
    arrays: dict[str, object] = {}
    units: dict[str, str] = {}
    step: float | None = None
    for channel in chosen.channels():
        values = np.asarray(channel[:])
        if str(channel.properties.get("unit_string", "")).strip():
            units[channel.name] = str(channel.properties["unit_string"]).strip()
        if values.dtype.kind == "M" and values.size:  # a channel of timestamps (LabVIEW's
            # clock): seconds from its first, as a text file's ISO timestamps are read
            values = (values - values[0]) / np.timedelta64(1, "us") * 1e-6
            units[channel.name] = "s"
        arrays[channel.name] = values
        inc = channel.properties.get("wf_increment")
        if step is None and inc is not None and float(inc) > 0:
            step = float(inc)
    table = table_from_arrays(path, arrays, "TDMS")
    units = {k: u for k, u in units.items() if k in table}
    return dataclasses.replace(
        table, time_step=step, units=units, group=chosen.name, groups=tuple(names)
    )
