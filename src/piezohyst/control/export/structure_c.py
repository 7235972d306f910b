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

__all__ = [
    "export_structure_c",
    "write_structure_c",
    "write_structure_fmu",
    "write_structure_mex",
    "write_structure_shared",
]


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
    st, g = compensator._st, compensator._g  # at the level it inverts at
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
    """The structure's C files and its shared library, built with the system C compiler.

    Its functions, on doubles, row by row:

    * ``NAME_new``, ``NAME_free``, ``NAME_reset``: a handle at rest;
    * ``int NAME_process(NAME_t *s, const double *target, double *volts, long n)``: n rows
      of one value per output in ``target``, each the target ``NAME_preview()`` samples ahead
      of the command row written at its place in ``volts`` (one command per actuator);
    * ``int NAME_counts(const NAME_t *s, unsigned long *counts)``: the targets out of reach,
      the non-finite ones, then per actuator its voltage-limit and slew counts;
    * ``int NAME_preview(void)`` and ``NAME_version``.

    Parameters
    ----------
    compensator : StructureCompensator
    path : str or os.PathLike
        The ``.c`` file (NAME from it); its header and the library are written next to it.
    precision : {"double", "float"}
        The step's C reals; the library's functions pass doubles either way.

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


def write_structure_mex(
    compensator: StructureCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> list[Path]:
    """A MEX gateway ``NAME.c`` for MATLAB and Octave, and the structure's C beside it.

    ``NAME`` comes from ``path`` (``ph_st_mex.c``: the function ``ph_st_mex``); the step's
    files are named after it without ``_mex`` (``ph_st.c``, ``ph_st.h``). Build with
    ``mkoctfile --mex`` (or ``mex``) on the gateway and the step's ``.c``. ``v = NAME(target)``
    takes one row per sample (each the preview ahead of its command row), ``[v, counts]``
    the counts as :func:`write_structure_shared`'s, ``NAME('preview')`` the preview.

    Parameters
    ----------
    compensator : StructureCompensator
    path : str or os.PathLike
        Where the gateway goes (``NAME.c``); the step's two files are written beside it.
    precision : {"double", "float"}
        The step's C reals (MATLAB's arrays are doubles either way).

    Returns
    -------
    list of Path
        The gateway, the step's source and header.
    """
    from .shared import _version_text, mex_commands

    gate, _, name = c_paths(path)
    prefix = name[: -len("_mex")] if name.endswith("_mex") else f"{name}_step"
    files = write_structure_c(compensator, gate.with_name(f"{prefix}.c"), precision=precision)
    n, m = compensator.model.n_inputs_, compensator.model.n_outputs_
    version = _version_text(f"{name}, the compensator of a structure of {n} actuators")
    text = _template("structure_mex.c").substitute(
        name=name, prefix=prefix, upper=prefix.upper(), n=n, m=m, n_counts=2 + 2 * n,
        preview=compensator.preview, version=version,
        run_command=mex_commands(name, prefix, version),
    )  # fmt: skip
    atomic_write_text(gate, text)
    return [gate, *files]


def write_structure_fmu(
    compensator: StructureCompensator,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> Path:
    """An FMI 2.0 Co-Simulation FMU of a structure's compensator.

    Real inputs ``ahead_0`` ... (one per output, value references 0 ...: the target
    ``preview`` steps ahead of the commands this step returns; start: the rest outputs), real
    outputs ``voltage_0`` ... (one per actuator, after the inputs), integer outputs
    ``outside`` (0), ``nonfinite`` (1), then per actuator k ``saturated_k``, ``slewed_k``
    (2 + 2k, 3 + 2k). One ``fmi2DoStep`` is one sample at the rate the model was identified
    at.

    Parameters
    ----------
    compensator : StructureCompensator
    path : str or os.PathLike
        Where the FMU goes; the file's stem is the model identifier (a C identifier).
    precision : {"double", "float"}
        The step's C reals (the FMI variables are doubles either way).

    Returns
    -------
    Path
        Where the FMU was written.

    Raises
    ------
    ParameterError
        A file name that is not a C identifier, or no C compiler to build the FMU with.
    """
    from .fmu import fmi2_wrapper, package_fmu, stamp_guid

    out = Path(path).with_suffix(".fmu")
    name = out.stem
    if not name.isidentifier() or not name.isascii():
        msg = f"the FMU's name {name!r} (its file name) must be a C identifier"
        raise ParameterError(msg)
    n, m = compensator.model.n_inputs_, compensator.model.n_outputs_
    rate, preview = compensator.sample_rate, compensator.preview
    period = 1.0 / float(rate)
    what = (f"{name}: the compensator of a structure of {n} actuators and {m} outputs, "
            f"{rate:g} Hz, targets {preview} steps ahead")  # fmt: skip
    files = export_structure_c(compensator, precision=precision, prefix=name)
    counts = ["c->s.outside", "c->s.nonfinite"]
    counts += [f"c->s.{f}[{k}]" for k in range(n) for f in ("saturated", "slewed")]
    rest = compensator.model.structure_.off
    files[f"{name}.c"] += fmi2_wrapper(
        name, period, what, n_real=m + n,
        layout=f"0-{m - 1} the targets ahead, {m}-{m + n - 1} the voltages",
        not_input=f"vr[i] >= {m}", inputs="the targets ahead", counts=tuple(counts),
        counts_said="0 targets out of reach, 1 non-finite targets, then per actuator k:\n * "
        "2 + 2k commands at a voltage limit, 3 + 2k cut by the slew limit",
        step_statement=f"{name}_step_doubles(&c->s, c->r, c->r + {m})",
        start_outputs="\n    ".join([*(f"c->r[{i}] = {float(rest[i])!r};" for i in range(m)),
                                      *(f"c->r[{m + k}] = (fmi2Real)c->s.last[{k}];"
                                        for k in range(n))]),
    )  # fmt: skip
    guid = stamp_guid(name, files)
    xml = _fmu_description(name, guid, n, m, period, what, rest, preview)
    return package_fmu(out, name, files, xml, what)


def _fmu_description(
    name: str, guid: str, n: int, m: int, period: float, what: str, rest: np.ndarray,
    preview: int,
) -> str:  # fmt: skip
    """The structure FMU's ``modelDescription.xml``."""
    from .fmu import cosim_description, scalar

    rows = [scalar(f"ahead_{i}", i, "input", "Real", f"output {i}'s target {preview} steps "
                   "ahead of this step's commands (start: at rest)", repr(float(rest[i])))
            for i in range(m)]  # fmt: skip
    rows += [scalar(f"voltage_{k}", m + k, "output", "Real", f"actuator {k}'s command (V)")
             for k in range(n)]  # fmt: skip
    rows.append(scalar("outside", 0, "output", "Integer", "targets out of reach"))
    rows.append(scalar("nonfinite", 1, "output", "Integer", "non-finite targets (held)"))
    for k in range(n):
        for j, field in enumerate(("saturated", "slewed")):
            rows.append(scalar(f"{field}_{k}", 2 + 2 * k + j, "output", "Integer",
                               f"actuator {k}: {field} commands since the last reset"))  # fmt: skip
    outputs = range(m + 1, m + n + 2 + 2 * n + 1)  # 1-based: every one after the inputs
    return cosim_description(name, guid, what, period, [f"{name}.c"], rows, outputs)
