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
from typing import Any

import numpy as np

from ...errors import ParameterError
from ...io import atomic_write_text
from ..c_text import CText, Precision
from ..compensator import Compensator
from ..coupled import REACH_SLACK, CoupledCompensator, plane_slack
from ..coupled_selfsensing import CoupledSelfSensingController
from ..selfsensing import SelfSensingController
from .c_code import c_paths, export_c

__all__ = [
    "StageCode",
    "export_stage_c",
    "stage_paths",
    "write_stage_c",
    "write_stage_fmu",
    "write_stage_mex",
    "write_stage_shared",
]


def _counts(n: int) -> list[str]:
    """The stage state's counts, as every host numbers them: ``outside``, then per actuator
    k its ``aK.nonfinite``, ``aK.saturated``, ``aK.slewed`` (1 + 3k ...)."""
    fields = ("nonfinite", "saturated", "slewed")
    return ["outside", *(f"a{k}.{field}" for k in range(n) for field in fields)]


def stage_paths(path: str | os.PathLike[str], actuators: int, *, mex: bool = False) -> list[Path]:
    """The files the stage's writers write for ``path``, the stage's ``.c`` first (with
    ``mex``: the gateway first, the stage's files named after it without ``_mex``).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.c`` file asked for (the stage's, or with ``mex`` the gateway's).
    actuators : int
    mex : bool

    Returns
    -------
    list of Path
    """
    c_path, _, prefix = c_paths(path)
    gate = [c_path] if mex else []
    if mex:
        prefix = prefix[: -len("_mex")] if prefix.endswith("_mex") else f"{prefix}_step"
    names = [f"{prefix}.c", f"{prefix}.h"] + [
        f"{prefix}_a{k}{ext}" for k in range(actuators) for ext in (".c", ".h")
    ]
    return gate + [c_path.with_name(name) for name in names]


@dataclass(frozen=True)
class _Stage:
    """What a stage's export needs of a coupled compensator or a stage's self-sensing loop."""

    steps: list[Any]  # each actuator's Compensator or SelfSensingController
    coupling: np.ndarray
    offset: np.ndarray
    inverse: np.ndarray
    reach: np.ndarray
    plane: np.ndarray
    reads: bool  # each step also takes its actuator's measured charge
    unit: str


def _stage(obj: CoupledCompensator | CoupledSelfSensingController) -> _Stage:
    if isinstance(obj, CoupledSelfSensingController):
        st = obj.stage
        return _Stage(list(obj.loops), st.coupling, st.offset, obj.inverse, obj.reach,
                      plane_slack(st.coupling, obj.reach), True, st.output_unit)  # fmt: skip
    if not isinstance(obj, CoupledCompensator):
        msg = (
            "a stage's export takes a CoupledCompensator or a CoupledSelfSensingController. "
            f"Got {type(obj).__name__}."
        )
        raise ParameterError(msg)
    model = obj.model
    return _Stage(list(obj.compensators), model.coupling_, model.offset_, obj.inverse, obj.reach,
                  obj.plane_slack, False, model.channels_[0].output_unit)  # fmt: skip


def _compensator(step: Any) -> Compensator:
    """An actuator's compensator (a loop's own)."""
    return step.compensator if isinstance(step, SelfSensingController) else step


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
    compensator: CoupledCompensator | CoupledSelfSensingController,
    *,
    precision: Precision = "double",
    prefix: str = "ph_stage",
) -> StageCode:
    """C99 files implementing ``compensator`` from its current state.

    The API: ``ph_stage_t`` (every actuator's state and the out-of-reach count),
    ``void ph_stage_init(ph_stage_t *s)`` and
    ``void ph_stage_step(ph_stage_t *s, const ph_stage_real *desired, ph_stage_real *command)``;
    each actuator's own counts (``s->a0.saturated``, ...) are those of :func:`export_c`. A
    stage's self-sensing loop (:class:`~piezohyst.CoupledSelfSensingController`) exports
    ``ph_stage_step(s, desired, measured, command)``: ``measured`` each actuator's charge
    read before this step (NaN: that loop runs on feedforward this sample).

    Parameters
    ----------
    compensator : CoupledCompensator or CoupledSelfSensingController
        Its actuators' compensators (or loops) each exportable by :func:`export_c`.
    precision : {"double", "float"}
        The C type of every real.
    prefix : str
        A C identifier; the actuators' files take ``PREFIX_a0``, ``PREFIX_a1``, ...

    Returns
    -------
    StageCode
    """
    c = CText(precision, prefix)
    st = _stage(compensator)
    comps = [_compensator(step) for step in st.steps]
    n, m = len(comps), st.coupling.shape[0]
    files: dict[str, str] = {}
    for k, step in enumerate(st.steps):
        code = export_c(step, precision=precision, prefix=f"{prefix}_a{k}")
        files[f"{prefix}_a{k}.h"] = code.header
        files[f"{prefix}_a{k}.c"] = code.source
    span = st.reach[:, 1] - st.reach[:, 0]

    def matrix(a: np.ndarray) -> str:
        return ",\n    ".join("{" + ", ".join(c.literal(x) for x in row) + "}" for row in a)

    plane, planes = "", []
    if m > n:  # a position off what the actuators move the outputs to is out of reach too
        planes = [
            f"static const {prefix}_real COUPLING[{m}][{n}] = {{\n    {matrix(st.coupling)}\n}};",
            f"static const {prefix}_real PLANE[{m}] = {{"
            + ", ".join(c.literal(float(x)) for x in st.plane)
            + "};",
        ]
        plane = (
            f"    for (j = 0; j < {m}; ++j) {{ /* off what the actuators move it to */\n"
            f"        {prefix}_real r = desired[j] - OFFSET[j];\n"
            f"        for (i = 0; i < {n}; ++i) {{\n"
            "            r -= COUPLING[j][i] * own[i];\n"
            "        }\n"
            "        if (r < -PLANE[j] || r > PLANE[j]) {\n"
            "            beyond = 1;\n"
            "        }\n"
            "    }\n"
        )
    tables = "\n".join([
        f"static const {prefix}_real INVERSE[{n}][{m}] = {{\n    {matrix(st.inverse)}\n}};",
        *planes,
        *(f"static const {prefix}_real {name}[{len(values)}] = {{"
          + ", ".join(c.literal(float(x)) for x in values) + "};"
          for name, values in (("OFFSET", st.offset),
                               ("REACH_LO", st.reach[:, 0]),
                               ("REACH_HI", st.reach[:, 1]),
                               ("SLACK", REACH_SLACK * span))),
    ])  # fmt: skip
    looks = {**_next_fields(comps, prefix, n, m), **_measured_fields(st.reads, prefix, n)}
    read = ", measured[{k}]" if st.reads else ""
    files[f"{prefix}.h"] = _template("stage.h").substitute(
        **looks, prefix=prefix, upper=prefix.upper(), n=n, m=m, precision=precision,
        parts=", ".join(f"{prefix}_a{k}.c" for k in range(n)),
        includes="\n".join(f'#include "{prefix}_a{k}.h"' for k in range(n)),
        members="\n".join(f"    {prefix}_a{k}_t a{k};" for k in range(n)),
        what="self-sensing loop" if st.reads else "compensator",
    )  # fmt: skip
    files[f"{prefix}.c"] = _template("stage.c").substitute(
        **looks, prefix=prefix, n=n, m=m, tables=tables, plane=plane,
        inits="\n".join(f"    {prefix}_a{k}_init(&s->a{k});" for k in range(n)),
        steps="\n".join(f"    command[{k}] = {prefix}_a{k}_step(&s->a{k}, own[{k}]"
                        + read.format(k=k)
                        + (f", own_next[{k}]" if comp.mode.active else "") + ");"
                        for k, comp in enumerate(comps)),
    )  # fmt: skip
    return StageCode(files)


def _measured_fields(reads: bool, prefix: str, n: int) -> dict[str, str]:
    """The template's fields for a step that also takes each actuator's measured charge (a
    stage's self-sensing loop; empty fields otherwise)."""
    if not reads:
        return {"measured_param": "", "measured_double": "", "measured_copy_decl": "",
                "measured_copy": "", "measured_arg": "", "measured_said": ""}  # fmt: skip
    return {
        "measured_param": f", const {prefix}_real *measured",
        "measured_double": ", const double *measured",
        "measured_copy_decl": f" {prefix}_real q[{n}];",
        "measured_copy": (f"\n    for (i = 0; i < {n}; ++i) {{\n"
                          f"        q[i] = ({prefix}_real)measured[i];\n    }}"),
        "measured_arg": ", q",
        "measured_said": (f"\n * Each actuator's loop reads its charge (measured[{n}], read before "
                          "this step;\n * NaN: that loop runs on feedforward this sample)."),
    }  # fmt: skip


def _looks_ahead(comps: list[Compensator]) -> bool:
    """Whether an actuator's model holds an output mode: the stage's step then takes the next
    desired position too (its inverse's preview)."""
    return any(comp.mode.active for comp in comps)


NEXT_FIELDS = ("next_param", "next_decl", "next_own", "next_double", "next_copy_decl",
               "next_copy", "next_arg", "next_said")  # fmt: skip


def _next_fields(comps: list[Compensator], prefix: str, n: int, m: int) -> dict[str, str]:
    """The template's fields for a step that also takes the next desired position: where an
    actuator's model holds an output mode, whose inverse needs it (empty fields otherwise)."""
    if not _looks_ahead(comps):
        return dict.fromkeys(NEXT_FIELDS, "")
    return {
        "next_param": f", const {prefix}_real *next",
        "next_decl": f"\n    {prefix}_real own_next[{n}];",
        "next_own": (f"    for (i = 0; i < {n}; ++i) {{ /* the same for the next position */\n"
                     "        own_next[i] = 0;\n"
                     f"        for (j = 0; j < {m}; ++j) {{\n"
                     "            own_next[i] += INVERSE[i][j] * (next[j] - OFFSET[j]);\n"
                     "        }\n    }\n"),
        "next_double": ", const double *next",
        "next_copy_decl": f" {prefix}_real e[{m}];",
        "next_copy": "\n        e[i] = (" + prefix + "_real)next[i];",
        "next_arg": ", e",
        "next_said": (f"\n * An actuator's mechanical mode is inverted from the trajectory: also "
                      f"pass the next\n * desired position (next[{m}]; NaN: extrapolated)."),
    }  # fmt: skip


def _block_fields(comps: list[Compensator], prefix: str, n: int, m: int) -> dict[str, str]:
    """The shared library's and the MEX's fields: a block is its own preview, as Python's
    ``process`` (each row's next position is the row after it; the block's last row's is
    unknown, NaN: extrapolated), where an actuator's model holds a mode."""
    if not _looks_ahead(comps):
        step = f"{prefix}_step_doubles(s, target + k * {m}, volts + k * {n});"
        return {"process_decl": "", "process_said": "", "mex_next_decl": "", "mex_next": "",
                "mex_next_arg": "", "process_step": step}  # fmt: skip
    return {
        "process_decl": (f"\n    double unknown[{m}];\n    long j;\n"
                         f"    for (j = 0; j < {m}; ++j) {{\n        unknown[j] = NAN;\n    }}"),
        "process_said": ("\n * An actuator's mode is inverted from the trajectory: each row's next "
                         "position is\n * the row after it (the block's last: extrapolated)."),
        "process_step": (f"{prefix}_step_doubles(s, target + k * {m}, k + 1 < n ? target + "
                         f"(k + 1) * {m} : unknown, volts + k * {n});"),
        "mex_next_decl": f", e[{m}]",
        "mex_next": "\n            e[i] = k + 1 < rows ? target[k + 1 + i * rows] : NAN;",
        "mex_next_arg": ", e",
    }  # fmt: skip


def write_stage_c(
    compensator: CoupledCompensator | CoupledSelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> list[Path]:
    """Write a coupled stage's C files beside ``path`` (``NAME.c``, ``NAME.h``, and the
    actuators' ``NAME_aK.c``, ``NAME_aK.h``), each atomically.

    Parameters
    ----------
    compensator : CoupledCompensator or CoupledSelfSensingController
    path : str or os.PathLike
        The stage's ``.c`` file; NAME, the C prefix, from it.
    precision : {"double", "float"}

    Returns
    -------
    list of Path
        Every file written, the stage's ``.c`` first.
    """
    c_path, _, prefix = c_paths(path)
    return _write(export_stage_c(compensator, precision=precision, prefix=prefix).files, c_path)


def _write(files: dict[str, str], c_path: Path) -> list[Path]:
    """Each file beside ``c_path``, atomically; ``c_path`` first."""
    written = []
    for name in sorted(files, key=lambda f: (f != c_path.name, f)):
        out = c_path.with_name(name)
        atomic_write_text(out, files[name])
        written.append(out)
    return written


def write_stage_shared(
    compensator: CoupledCompensator | CoupledSelfSensingController,
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
    ``NAME_version``. A stage's self-sensing loop takes each row's charges too:
    ``NAME_process(s, target, measured, volts, n)``.

    Parameters
    ----------
    compensator : CoupledCompensator or CoupledSelfSensingController
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
    code = export_stage_c(compensator, precision=precision, prefix=prefix).files
    st = _stage(compensator)
    comps = [_compensator(step) for step in st.steps]
    n, m = len(comps), st.coupling.shape[0]
    count_lines = "\n".join(f"    counts[{i}] = s->{c};" for i, c in enumerate(_counts(n)) if i)
    block = _block_fields(comps, prefix, n, m)
    api = {"api_measured": "", "api_measured_null": "", "api_measured_said": ""}
    what = "compensator"
    if st.reads:  # each row also the actuators' charges read before it
        what = "self-sensing loop"
        block["process_step"] = block["process_step"].replace(
            f"target + k * {m}, ", f"target + k * {m}, measured + k * {n}, "
        )
        api = {"api_measured": ", const double *measured",
               "api_measured_null": " || measured == NULL",
               "api_measured_said": (f"\n * measured holds n rows of the {n} actuators' charges, "
                                     "each read before its row's step.")}  # fmt: skip
    code[c_path.name] += _template("handle.c").substitute(prefix=prefix) + _template(
        "stage_api.c"
    ).substitute(
        prefix=prefix, n=n, m=m, counts=1 + 3 * n, count_lines=count_lines,
        version=_version_text(f"{prefix}, the {what} of a stage of {n} actuators"),
        **block, **api,
    )  # fmt: skip
    files = _write(code, c_path)
    lib = library_path(c_path, prefix)
    build_library([p for p in files if p.suffix == ".c"], lib)
    return files, lib


def write_stage_fmu(
    compensator: CoupledCompensator | CoupledSelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> Path:
    """An FMI 2.0 Co-Simulation FMU of a coupled stage's compensator (or self-sensing loop).

    Real inputs ``target_0`` ... (one per axis, value references 0 ...), a stage's loop then
    ``charge_0`` ... (each actuator's charge read before the step; NaN: that loop runs on
    feedforward), real outputs ``voltage_0`` ... (one per actuator, after the inputs),
    integer outputs ``outside`` (0) then per actuator k ``nonfinite_k``, ``saturated_k``,
    ``slewed_k`` (1 + 3k ...). One ``fmi2DoStep`` is one sample of the compensator's rate.

    Parameters
    ----------
    compensator : CoupledCompensator or CoupledSelfSensingController
        With its ``sample_rate``.
    path, precision
        As for :func:`~piezohyst.control.export.write_fmu`.

    Returns
    -------
    Path

    Raises
    ------
    ParameterError
        No sample rate, a name that is not a C identifier, no C compiler.
    """
    from .fmu import fmi2_wrapper, package_fmu, stamp_guid

    st = _stage(compensator)
    comps = [_compensator(step) for step in st.steps]
    rate = comps[0].sample_rate
    if rate is None:
        msg = "an FMU steps at the loop's rate: give the sample rate (sample_rate=)"
        raise ParameterError(msg)
    out = Path(path).with_suffix(".fmu")
    name = out.stem
    if not name.isidentifier() or not name.isascii():
        msg = f"the FMU's name {name!r} (its file name) must be a C identifier"
        raise ParameterError(msg)
    n, m = len(comps), st.coupling.shape[0]
    # a mode's inverse needs the next position: inputs next_0 ... after the targets (NaN, the
    # start, extrapolates, as Python without a preview); a loop's charges after those
    p = m if _looks_ahead(comps) else 0
    r = n if st.reads else 0
    period = 1.0 / float(rate)
    kind = "self-sensing loop" if st.reads else "compensator"
    what = f"{name}: the {kind} of a stage of {n} actuators and {m} axes, {rate:g} Hz"
    files = export_stage_c(compensator, precision=precision, prefix=name).files
    counts = [f"c->s.{c}" for c in _counts(n)]
    ahead = f", c->r + {m}" if p else ""
    charges = f", c->r + {m + p}" if r else ""
    first = m + p + r  # the first voltage
    files[f"{name}.c"] += fmi2_wrapper(
        name, period, what, n_real=first + n,
        layout=(f"0-{m - 1} the targets, "
                + (f"{m}-{2 * m - 1} the next targets, " if p else "")
                + (f"{m + p}-{m + p + r - 1} the charges, " if r else "")
                + f"{first}-{first + n - 1} the voltages"),
        not_input=f"vr[i] >= {first}",
        inputs="the targets" + (" and the next targets" if p else "")
        + (" and the charges" if r else ""),
        counts=tuple(counts),
        counts_said="0 desired positions beyond the reach, then per actuator k: 1 + 3k\n * "
        "non-finite targets, 2 + 3k commands at a voltage limit, 3 + 3k cut by the slew limit",
        step_statement=f"{name}_step_doubles(&c->s, c->r{charges}{ahead}, c->r + {first})",
        start_outputs="\n    ".join([*(f"c->r[{i}] = 0.0;" for i in range(m)),
                                      *(f"c->r[{m + i}] = NAN;" for i in range(p + r)),
                                      *(f"c->r[{first + k}] = (fmi2Real)c->s.a{k}.last;"
                                        for k in range(n))]),
    )  # fmt: skip
    guid = stamp_guid(name, files)
    xml = _stage_description(name, guid, n, m, period, what, st.unit, ahead=bool(p),
                             reads=st.reads)  # fmt: skip
    return package_fmu(out, name, files, xml, what)


def _stage_description(
    name: str, guid: str, n: int, m: int, period: float, what: str, unit: str, *, ahead: bool,
    reads: bool = False,
) -> str:  # fmt: skip
    """The stage FMU's ``modelDescription.xml`` (``ahead``: the next targets' inputs too;
    ``reads``: each actuator's charge too, a stage's loop)."""
    from .fmu import cosim_description, scalar

    p = m if ahead else 0
    r = n if reads else 0
    rows = [scalar(f"target_{i}", i, "input", "Real", f"axis {i}'s desired position ({unit})")
            for i in range(m)]  # fmt: skip
    rows += [scalar(f"next_{i}", m + i, "input", "Real", f"axis {i}'s desired position at the "
                    f"next step ({unit}; NaN: extrapolated), for the actuators' modes", "NaN")
             for i in range(p)]  # fmt: skip
    rows += [scalar(f"charge_{k}", m + p + k, "input", "Real", f"actuator {k}'s charge read "
                    "before this step (its model's unit; NaN: none, feedforward)", "NaN")
             for k in range(r)]  # fmt: skip
    rows += [scalar(f"voltage_{k}", m + p + r + k, "output", "Real",
                    f"actuator {k}'s command (V)") for k in range(n)]  # fmt: skip
    rows.append(scalar("outside", 0, "output", "Integer", "desired positions beyond the reach"))
    for k in range(n):
        for j, field in enumerate(("nonfinite", "saturated", "slewed")):
            rows.append(scalar(f"{field}_{k}", 1 + 3 * k + j, "output", "Integer",
                               f"actuator {k}: {field} commands since the last reset"))  # fmt: skip
    outputs = range(m + p + r + 1, m + p + r + n + 1 + 1 + 3 * n)  # 1-based: after the inputs
    sources = [f"{name}{part}.c" for part in ["", *(f"_a{k}" for k in range(n))]]
    return cosim_description(name, guid, what, period, sources, rows, outputs)


def _mex_measured_fields(reads: bool, n: int) -> dict[str, str]:
    """The MEX gateway's fields for a stage's loop: a second matrix, each actuator's charges
    read before each row's step (empty fields for a compensator)."""
    if not reads:
        empty = ("mex_usage", "mex_usage_said", "mex_measured_decl", "mex_q_decl",
                 "mex_measured_check", "mex_usage_error", "mex_measured_get",
                 "mex_measured_copy", "mex_measured_arg")  # fmt: skip
        return {**dict.fromkeys(empty, ""), "mex_nrhs": "1"}
    return {
        "mex_usage": ", measured",
        "mex_usage_said": (f"\n *        measured: each actuator's charge ({n} columns, a row "
                           "per target row), read before that row's step"),
        "mex_measured_decl": "\n    const double *measured;",
        "mex_q_decl": f", q[{n}]",
        "mex_nrhs": "2",
        "mex_measured_check": ("\n        || !mxIsDouble(prhs[1]) || mxIsComplex(prhs[1]) || "
                               f"mxIsSparse(prhs[1])\n        || mxGetN(prhs[1]) != {n} || "
                               "mxGetM(prhs[1]) != mxGetM(prhs[0])"),
        "mex_usage_error": f" and measured the charges, {n} columns",
        "mex_measured_get": "\n    measured = mxGetPr(prhs[1]);",
        "mex_measured_copy": (f"\n        for (i = 0; i < {n}; ++i) {{\n"
                              "            q[i] = measured[k + i * rows];\n        }"),
        "mex_measured_arg": ", q",
    }  # fmt: skip


def write_stage_mex(
    compensator: CoupledCompensator | CoupledSelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> list[Path]:
    """A MEX gateway ``NAME.c`` for MATLAB and Octave, and the stage's C beside it.

    ``NAME`` comes from ``path`` (``ph_xy_mex.c``: the function ``ph_xy_mex``); the stage's
    files are named after it without ``_mex`` (``ph_xy.c``, ``ph_xy_a0.c``, ...). Build with
    ``mkoctfile --mex`` (or ``mex``) on the gateway and the stage's ``.c`` files. A stage's
    self-sensing loop takes each row's charges too: ``v = NAME(target, measured)``.

    Parameters
    ----------
    compensator : CoupledCompensator or CoupledSelfSensingController
    path : str or os.PathLike
        The gateway's ``.c`` file.
    precision : {"double", "float"}

    Returns
    -------
    list of Path
        The gateway first, then the stage's files.
    """
    from .shared import _version_text, mex_commands

    gate, _, name = c_paths(path)
    st = _stage(compensator)
    comps = [_compensator(step) for step in st.steps]
    n, m = len(comps), st.coupling.shape[0]
    step = stage_paths(gate, n, mex=True)[1]
    prefix = step.stem
    files = write_stage_c(compensator, step, precision=precision)
    count_lines = "\n".join(
        f"        counts[{i}] = (double)state.{c};" for i, c in enumerate(_counts(n)) if i
    )
    kind = "self-sensing loop" if st.reads else "compensator"
    version = _version_text(f"{name}, the {kind} of a stage of {n} actuators")
    text = _template("stage_mex.c").substitute(
        **_block_fields(comps, prefix, n, m), **_mex_measured_fields(st.reads, n),
        name=name, prefix=prefix, n=n, m=m, n_counts=1 + 3 * n, count_lines=count_lines,
        sources=" ".join(p.name for p in files if p.suffix == ".c"), version=version,
        run_command=mex_commands(name, prefix, version),
    )  # fmt: skip
    atomic_write_text(gate, text)
    return [gate, *files]
