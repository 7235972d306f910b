"""Reading DAQ recordings and writing results.

Readers: CSV/TSV/text (delimiter sniffing, header detection), NumPy ``.npz``,
MATLAB ``.mat`` (v4-v7 through :mod:`scipy.io`, v7.3 through h5py), NI TDMS
(npTDMS; group/channel selection, time from ``wf_increment``) and HDF5.
Every problem with a file becomes one :class:`~piezohyst.errors.DataFileError`
whose message names the file and, where it applies, the row and column.
Writers (CSV, NPZ) write to a temporary file and rename it into place, so a
failure never leaves a half-written file.

This package defines nothing itself; its modules:

================  ===================================================================
module            public names
================  ===================================================================
``tables``        :func:`read_table`, :func:`open_table` (a file's columns, by format)
``recording``     :func:`read_recording`, :func:`open_recording`, :class:`DataSpec`,
                  :class:`RecordingStream`, :class:`Block`, :func:`collect`,
                  :func:`check_finite`, :func:`check_increasing` (input, output and
                  time, in units, whole or block by block)
``_formats``      :class:`Table`, :class:`Recording`, ``BATCH_ROWS``, ``MD_MARKER``: what
                  every reader builds
``_text``         the text readers (CSV, TSV, text, aixACCT), :func:`estimated_rows`
``_containers``   the container readers (``.npz``, Parquet, ``.mat``, HDF5, TDMS)
``_writers``      :func:`write_table`, :func:`write_rows`, :func:`write_blocks`,
                  :func:`write_json`, :func:`read_json`, :class:`JsonFile`,
                  :func:`atomic_write`, :func:`atomic_write_text`, :func:`atomic_folder`,
                  :func:`is_piezohyst_output`
``blocks``        block summaries of a record too long to hold
``screening``     glitches and gaps named (the record's screen)
``_isolate``      :func:`parse_isolated`: a file parsed in a child process
================  ===================================================================
"""

from __future__ import annotations

from ._formats import BATCH_ROWS, MD_MARKER, Recording, Table
from ._isolate import parse_isolated
from ._text import estimated_rows
from ._writers import (
    JsonFile,
    atomic_folder,
    atomic_write,
    atomic_write_text,
    is_piezohyst_output,
    read_json,
    write_blocks,
    write_json,
    write_rows,
    write_table,
)
from .recording import (
    Block,
    DataSpec,
    RecordingStream,
    check_finite,
    check_increasing,
    collect,
    open_recording,
    read_recording,
)
from .tables import open_table, read_table

__all__ = [
    "BATCH_ROWS",
    "MD_MARKER",
    "Block",
    "DataSpec",
    "JsonFile",
    "Recording",
    "RecordingStream",
    "Table",
    "atomic_folder",
    "atomic_write",
    "atomic_write_text",
    "check_finite",
    "check_increasing",
    "collect",
    "estimated_rows",
    "is_piezohyst_output",
    "open_recording",
    "open_table",
    "parse_isolated",
    "read_json",
    "read_recording",
    "read_table",
    "write_blocks",
    "write_json",
    "write_rows",
    "write_table",
]
