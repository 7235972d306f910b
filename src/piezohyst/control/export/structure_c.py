"""A structure's compensator as C: :class:`~piezohyst.StructureCompensator`'s tracker with
preview, one step per sample, and its shared library.

The step takes the target the tracker's preview ahead of the command it returns (a ring of
the targets ahead, each with its operators' lags, sits in the state), then computes the
command as Python does (the feed-forward of the targets ahead less the feedback on the
model's state; the slew and voltage limits; the counts), and runs the model on it. So a run
of targets comes out ``preview`` samples later: the first ``preview`` commands are those of
the rest the compensator starts at, already moving towards the first targets (the tracker
acts ahead, as it does in Python on a block that starts at rest).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from string import Template

import numpy as np

from ...errors import ParameterError
from ...io import atomic_write_text
from ..c_text import CText, Precision
from ..coupled import REACH_SLACK
from ..structure import StructureCompensator
from .c_code import c_paths

__all__ = ["export_structure_c", "write_structure_c", "write_structure_shared"]


def _template(name: str) -> Template:
    """A shipped C template without its first two lines (the note that it is one)."""
    text = (resources.files("piezohyst.control.export") / "c" / name).read_text("utf-8")
    return Template(text.split("\n", 2)[2])


def export_structure_c(
    compensator: StructureCompensator, *, precision: Precision = "double", prefix: str = "ph_st"
) -> dict[str, str]:
    """The C source and header of a structure's compensator, in the state of its reset.

    Parameters
    ----------
    compensator : StructureCompensator
    precision : {"double", "float"}
        The C type of every real.
    prefix : str
        The C names' prefix.

    Returns
    -------
    dict
        File name: text (``PREFIX.c``, ``PREFIX.h``).

    Raises
    ------
    ParameterError
        Not a StructureCompensator.
    """
    if not isinstance(compensator, StructureCompensator):
        msg = (
            f"export_structure_c takes a ph.StructureCompensator (got "
            f"{type(compensator).__name__}); a coupled stage has write_stage_c"
        )
        raise ParameterError(msg)
    st, g = compensator.model.structure_, compensator._g
    n, m, nx = st.b.shape[1], st.c.shape[0], st.order
    na, nk = st.r.shape
    r, e = st.r, st.e
    f0, ahead = g["f0"], g["ahead"]
    if nk == 0:  # no operators: one of width 0 per actuator, acting on nothing (C has no
        nk = 1  # empty arrays); its lag is always 0
        r, e = np.zeros((na, 1)), np.zeros((nx, na))
        f0 = np.hstack([f0, np.zeros((n, na))])
        ahead = np.concatenate([ahead, np.zeros((ahead.shape[0], n, na))], axis=2)
    q = m + na * nk
    preview = ahead.shape[0]
    text = CText(precision, prefix)
    step = compensator.max_step
    # no slew limit: a step no command reaches (C literals hold no infinity in double)
    tol = np.where(np.isfinite(step), step * (1.0 - 1e-9), 1e300)
    big = np.where(np.isfinite(step), step, 1e300)
    tables = [
        text.table("A", f"{nx}][{nx}", st.a.ravel()),
        text.table("B", f"{nx}][{n}", st.b.ravel()),
        text.table("C", f"{m}][{nx}", st.c.ravel()),
        text.table("D", f"{m}][{n}", st.d.ravel()),
        text.table("E", f"{nx}][{na * nk}", e.ravel()),
        text.table("T", f"{na}][{m}", st.t.ravel()),
        text.table("R", f"{na}][{nk}", r.ravel()),
        text.table("OFF", f"{m}", st.off),
        text.table("GAIN", f"{n}][{nx}", g["gain"].ravel()),
        text.table("F0", f"{n}][{q}", f0.ravel()),
        text.table("L", f"{preview}][{n}][{q}", ahead.ravel()),
        text.table("LO", f"{n}", compensator.v_min),
        text.table("HI", f"{n}", compensator.v_max),
        text.table("STEP", f"{n}", big),
        text.table("TOL", f"{n}", tol),
        text.table("SLACK", f"{n}", REACH_SLACK * (compensator.v_max - compensator.v_min)),
    ]
    fields = {
        "prefix": prefix, "upper": text.upper, "precision": precision, "n": n, "m": m,
        "nx": nx, "na": na, "nk": nk, "q": q, "preview": preview, "slots": preview + 1,
        "tables": "\n".join(tables),
    }  # fmt: skip
    return {
        f"{prefix}.c": _template("structure.c").substitute(fields),
        f"{prefix}.h": _template("structure.h").substitute(fields),
    }


def write_structure_c(
    compensator: StructureCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> list[Path]:
    """Write a structure's compensator as ``NAME.c`` and ``NAME.h`` beside ``path``.

    Parameters
    ----------
    compensator : StructureCompensator
    path : str or os.PathLike
        The ``.c`` file; NAME, the C prefix, from it.
    precision : {"double", "float"}

    Returns
    -------
    list of Path
        The source and the header.
    """
    c_path, h_path, prefix = c_paths(path)
    files = export_structure_c(compensator, precision=precision, prefix=prefix)
    atomic_write_text(c_path, files[c_path.name])
    atomic_write_text(h_path, files[h_path.name])
    return [c_path, h_path]


def write_structure_shared(
    compensator: StructureCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> tuple[list[Path], Path]:
    """The structure's C files with a shared-library API, and the library.

    The API (doubles, row by row): ``NAME_new``, ``NAME_free``, ``NAME_reset``,
    ``int NAME_process(NAME_t *s, const double *target, double *volts, long n)`` (``target``
    n rows of one value per output, each the target ``NAME_preview()`` samples ahead of the
    command row written at its place in ``volts``, n rows of one command per actuator),
    ``int NAME_counts(const NAME_t *s, unsigned long *counts)`` (the targets out of reach,
    the non-finite ones, then per actuator its voltage-limit and slew counts),
    ``int NAME_preview(void)``, ``NAME_version``.

    Parameters
    ----------
    compensator : StructureCompensator
    path : str or os.PathLike
        The ``.c`` file; the header and the library go beside it.
    precision : {"double", "float"}
        The C type of the step's reals (the API takes and returns doubles).

    Returns
    -------
    tuple
        The source and header, and the library.

    Raises
    ------
    ParameterError
        No C compiler, or a build that fails (its first error named).
    """
    from .shared import _version_text, build_library, library_path

    c_path, h_path, prefix = c_paths(path)
    files = export_structure_c(compensator, precision=precision, prefix=prefix)
    n, m = compensator.model.n_inputs_, compensator.model.n_outputs_
    count_lines = "\n".join(
        f"    counts[{2 + 2 * i}] = s->saturated[{i}];\n    counts[{3 + 2 * i}] = s->slewed[{i}];"
        for i in range(n)
    )
    what = f"{prefix}, the compensator of a structure of {n} actuators and {m} outputs"
    files[c_path.name] += _template("handle.c").substitute(prefix=prefix) + _template(
        "structure_api.c"
    ).substitute(
        prefix=prefix, n=n, m=m, counts=2 + 2 * n, count_lines=count_lines,
        preview=compensator.preview, version=_version_text(what),
    )  # fmt: skip
    atomic_write_text(c_path, files[c_path.name])
    atomic_write_text(h_path, files[h_path.name])
    lib = library_path(c_path, prefix)
    build_library([c_path], lib)
    return [c_path, h_path], lib
