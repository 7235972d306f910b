"""A coupled stage's compensator as C: each actuator's step (:func:`export_c`, one pair of
files per actuator, its own prefix) and the stage's step around them, the coupling's inverse.

The stage's step is :meth:`CoupledCompensator.step <piezohyst.CoupledCompensator.step>` in
C, in the same order: what each actuator alone must move (the coupling's inverse times the
desired position less the offset), a desired position out of the stage's reach counted, then
each actuator's compensator step on its own share.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from string import Template

import numpy as np

from ...io import atomic_write_text
from ..c_text import CText, Precision
from ..coupled import REACH_SLACK, CoupledCompensator
from .c_code import c_paths, export_c

__all__ = ["StageCode", "export_stage_c", "write_stage_c", "write_stage_shared"]


def _template(name: str) -> Template:
    """A C template shipped with the package (``piezohyst/control/export/c``), without its
    first two lines (the note that it is one)."""
    text = (resources.files("piezohyst.control.export") / "c" / name).read_text("utf-8")
    return Template(text.split("\n", 2)[2])


@dataclass(frozen=True)
class StageCode:
    """Generated C files of a coupled stage's compensator, by file name.

    Attributes
    ----------
    files : dict of str to str
        ``PREFIX.h``, ``PREFIX.c``, and ``PREFIX_aK.h``, ``PREFIX_aK.c`` per actuator K.
    """

    files: dict[str, str]


def export_stage_c(
    compensator: CoupledCompensator, *, precision: Precision = "double", prefix: str = "ph_stage"
) -> StageCode:
    """C99 files implementing ``compensator`` from its current state.

    The API: ``ph_stage_t`` (every actuator's state and the out-of-reach count),
    ``void ph_stage_init(ph_stage_t *s)`` and
    ``void ph_stage_step(ph_stage_t *s, const ph_stage_real *desired, ph_stage_real *command)``;
    each actuator's own counts (``s->a0.saturated``, ...) are those of :func:`export_c`.

    Parameters
    ----------
    compensator : CoupledCompensator
        Its actuators' compensators each exportable by :func:`export_c`.
    precision : {"double", "float"}
        The C type of every real.
    prefix : str
        A C identifier; the actuators' files take ``PREFIX_a0``, ``PREFIX_a1``, ...

    Returns
    -------
    StageCode
    """
    c = CText(precision, prefix)
    comps = compensator.compensators
    n, m = len(comps), compensator.model.coupling_.shape[0]
    files: dict[str, str] = {}
    for k, comp in enumerate(comps):
        code = export_c(comp, precision=precision, prefix=f"{prefix}_a{k}")
        files[f"{prefix}_a{k}.h"] = code.header
        files[f"{prefix}_a{k}.c"] = code.source
    inverse = np.linalg.inv(compensator.model.coupling_)
    span = compensator.reach[:, 1] - compensator.reach[:, 0]
    rows = ",\n    ".join("{" + ", ".join(c.literal(x) for x in row) + "}" for row in inverse)
    tables = "\n".join([
        f"static const {prefix}_real INVERSE[{n}][{m}] = {{\n    {rows}\n}};",
        *(f"static const {prefix}_real {name}[{len(values)}] = {{"
          + ", ".join(c.literal(float(x)) for x in values) + "};"
          for name, values in (("OFFSET", compensator.model.offset_),
                               ("REACH_LO", compensator.reach[:, 0]),
                               ("REACH_HI", compensator.reach[:, 1]),
                               ("SLACK", REACH_SLACK * span))),
    ])  # fmt: skip
    files[f"{prefix}.h"] = _template("stage.h").substitute(
        prefix=prefix, upper=prefix.upper(), n=n, m=m, precision=precision,
        parts=", ".join(f"{prefix}_a{k}.c" for k in range(n)),
        includes="\n".join(f'#include "{prefix}_a{k}.h"' for k in range(n)),
        members="\n".join(f"    {prefix}_a{k}_t a{k};" for k in range(n)),
    )  # fmt: skip
    files[f"{prefix}.c"] = _template("stage.c").substitute(
        prefix=prefix, n=n, m=m, tables=tables,
        inits="\n".join(f"    {prefix}_a{k}_init(&s->a{k});" for k in range(n)),
        steps="\n".join(f"    command[{k}] = {prefix}_a{k}_step(&s->a{k}, own[{k}]);"
                        for k in range(n)),
    )  # fmt: skip
    return StageCode(files)


def write_stage_c(
    compensator: CoupledCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> list[Path]:
    """Write a coupled stage's C files beside ``path`` (``NAME.c``, ``NAME.h``, and the
    actuators' ``NAME_aK.c``, ``NAME_aK.h``), each atomically.

    Parameters
    ----------
    compensator : CoupledCompensator
    path : str or os.PathLike
        The stage's ``.c`` file; NAME, the C prefix, from it.
    precision : {"double", "float"}

    Returns
    -------
    list of Path
        Every file written, the stage's ``.c`` first.
    """
    c_path, _, prefix = c_paths(path)
    code = export_stage_c(compensator, precision=precision, prefix=prefix)
    written = []
    for name in sorted(code.files, key=lambda f: (f != f"{prefix}.c", f)):
        out = c_path.with_name(name)
        atomic_write_text(out, code.files[name])
        written.append(out)
    return written


def write_stage_shared(
    compensator: CoupledCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> tuple[list[Path], Path]:
    """The stage's C files (:func:`write_stage_c`) with a shared-library API, and the library.

    The API (doubles, row by row): ``NAME_new``, ``NAME_free``, ``NAME_reset``,
    ``int NAME_process(NAME_t *s, const double *target, double *volts, long n)`` (``target``
    n rows of one position per axis, ``volts`` n rows of one command per actuator),
    ``int NAME_counts(const NAME_t *s, unsigned long *counts)`` (the out-of-reach count,
    then per actuator its non-finite targets, voltage-limit and slew counts),
    ``NAME_version``.

    Parameters
    ----------
    compensator : CoupledCompensator
    path : str or os.PathLike
        The stage's ``.c`` file; the other files and the library go beside it.
    precision : {"double", "float"}
        The C type of the steps' reals (the API takes and returns doubles).

    Returns
    -------
    tuple
        The files written (the stage's ``.c`` first), and the library.

    Raises
    ------
    ParameterError
        No C compiler, or a build that fails (its first error named).
    """
    from .shared import _version_text, build_library, library_path

    c_path, _, prefix = c_paths(path)
    files = write_stage_c(compensator, c_path, precision=precision)
    n, m = len(compensator.compensators), compensator.model.coupling_.shape[0]
    count_lines = "\n".join(
        f"    counts[{1 + 3 * k + j}] = s->a{k}.{field};"
        for k in range(n) for j, field in enumerate(("nonfinite", "saturated", "slewed"))
    )  # fmt: skip
    api = _template("handle.c").substitute(prefix=prefix) + _template("stage_api.c").substitute(
        prefix=prefix, n=n, m=m, counts=1 + 3 * n, count_lines=count_lines,
        version=_version_text(f"{prefix}, the compensator of a stage of {n} actuators"),
    )  # fmt: skip
    atomic_write_text(c_path, c_path.read_text() + api)
    lib = library_path(c_path, prefix)
    build_library([p for p in files if p.suffix == ".c"], lib)
    return files, lib
