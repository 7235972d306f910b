"""C99 export of a :class:`~piezohyst.Compensator` for microcontrollers.

The C is C: the algorithms are files shipped with the package
(``piezohyst/model/cores/c``: ``play.c`` and its controller and dynamics steps,
``packed.c`` with the Preisach, Duhem and Bouc-Wen cores, ``ieee.c``,
``mode.c``), compiled on their own in the tests. An export writes a header
from ``play.h`` or ``packed.h`` and a source that is a preamble of the
identified parameters (constants and tables, feature switches, the names
under the chosen prefix) followed by the files the compensator needs.

The generated code has no dependency beyond ``<stdint.h>`` (the NaN/inf guard
reads the IEEE-754 exponent bits, so it survives ``-ffast-math``, which lets a
compiler drop ``isfinite``), bakes the identified parameters in, and follows the
same arithmetic, in the same order, as the Python kernel, with the same safety
behaviour: commands always finite and inside the limits, NaN/inf desired
values hold the last command, unreachable values saturate, optional slew limit.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from string import Template
from typing import cast

import numpy as np

from ...errors import ParameterError
from ...io import atomic_write_text
from ..c_text import CText, Precision, init_extra
from ..compensator import Compensator
from ..selfsensing import SelfSensingController

__all__ = ["CCode", "c_paths", "export_c", "write_c"]


@dataclass(frozen=True)
class CCode:
    """Generated header and source text, and the header's file name.

    Attributes
    ----------
    header, source : str
        The ``.h`` and ``.c`` texts.
    header_name : str
        The file name the source includes.
    """

    header: str
    source: str
    header_name: str


def export_c(
    compensator: Compensator | SelfSensingController,
    *,
    precision: Precision = "double",
    prefix: str = "ph_comp",
) -> CCode:
    """C99 header and source implementing ``compensator`` from its current state.

    The API: ``ph_comp_t`` (state), ``void ph_comp_init(ph_comp_t *s)``, and
    ``ph_real ph_comp_step(ph_comp_t *s, ph_real desired)`` where ``ph_real``
    is ``double`` (default) or ``float``. ``prefix`` renames ``ph_comp``. A
    :class:`~piezohyst.control.selfsensing.SelfSensingController` exports the same
    with ``ph_comp_step(ph_comp_t *s, ph_real desired, ph_real measured)``
    and the feedback state in the struct.

    Parameters
    ----------
    compensator : Compensator or SelfSensingController
        An analytic compensator (play operators and growth terms only), or a
        self-sensing controller (its feedback state is exported as it is now).
    precision : {"double", "float"}
        The C type of every real.
    prefix : str
        A C identifier for the generated names.

    Returns
    -------
    CCode
    """
    comp = cast(Compensator, getattr(compensator, "compensator", compensator))  # a controller's
    controller = cast("SelfSensingController", compensator) if comp is not compensator else None
    if controller is not None and comp.delay_samples:
        msg = (
            "C export of the self-sensing controller inverts a lag and a fraction of a "
            f"sample's delay, not a delay of {comp.delay_samples} whole samples (the step "
            "would need the preview): run it in Python, or fit the model without the delay"
        )
        raise ParameterError(msg)
    if comp.mode.active and comp.delay_samples:
        msg = (
            "C export inverts an output mode only without an integer input delay (the mode "
            "would need the preview of several samples): pass the pre-inverted target "
            "(OutputDynamics.invert) or fit without the mode"
        )
        raise ParameterError(msg)
    if precision not in ("double", "float"):
        msg = f"precision must be 'double' or 'float'. Got {precision!r}."
        raise ParameterError(msg)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        msg = f"prefix must be a C identifier. Got {prefix!r}."
        raise ParameterError(msg)
    taken = _taken_prefixes()
    if prefix in taken:
        msg = (
            f"the name {prefix!r} (from the file name) clashes with the exported step's own C "
            f"names ({prefix}_step, {prefix}_init or {prefix}_t): name the file otherwise, "
            "e.g. ph_comp.c"
        )
        raise ParameterError(msg)
    om = comp.output_map
    if om is not None and not om.monotone:
        msg = (
            "C export takes an output map that is monotone over its calibrated charges; this "
            "one turns (the butterfly of bipolar drive), so a displacement has two charges and "
            "the step would need the branch the actuator is on: compensate in Python "
            "(output_map=), or export in charge and choose the branch before the step"
        )
        raise ParameterError(msg)
    c = CText(precision, prefix)
    fold = None
    if om is not None and om.order == 1 and not comp.mode.active:  # folded into the scale
        fold = (1.0 / om.gain, om.center - om.coefficients[0] / om.gain)
    loop = None if controller is None else (controller.config, controller.ctl, controller.feedback)
    parts = comp.inverse.c_parts(c, fold, loop)  # the engine's own arrays, files and fields
    lines, init, files = list(parts.lines), list(parts.init), list(parts.files)
    lines += _mode(comp, c, init, files)
    lines.append(init_extra(init))
    spec = comp.spec
    header = Template(_c_file(parts.header) + _c_file("step.h")).substitute(
        _names(prefix, precision), **parts.fields, model=type(comp.model).__name__,
        input_unit=spec.input_unit, output_unit=spec.output_unit,
        desired_unit="m" if comp.domain == "displacement" else spec.output_unit,
        v_min=repr(comp.v_min), v_max=repr(comp.v_max), notes=_notes(comp),
        dynamic=int(comp.dynamic), mode=int(comp.mode.active),
    )  # fmt: skip
    return CCode(header, _source(prefix, precision, lines, files, comp), f"{prefix}.h")


def _names(prefix: str, precision: Precision) -> dict[str, str]:
    """The header template's names: the prefix, its upper case, the guard and the real type."""
    upper = prefix.upper()
    return {"prefix": prefix, "upper": upper, "guard": f"{upper}_H",
            "real": f"{prefix}_real", "precision": precision}  # fmt: skip


def _mode(comp: Compensator, c: CText, init: list[str], files: list[str]) -> list[str]:
    """The output mode's constants and state, and ``mode.c`` after the step."""
    if not comp.mode.active:
        return []
    mode = comp.mode
    w = 2.0 * math.pi * mode.f0
    for name, value in zip(("e2", "e1"), comp.mode_history, strict=True):
        v = c.literal(float(value)) if np.isfinite(value) else "not_a_number()"
        init.append(f"s->{name} = {v};")
    files.append("mode.c")
    return c.constants(MODE_DT=mode.sample_interval, MODE_K1=2.0 * mode.zeta / w, MODE_W2=w * w)


def _notes(comp: Compensator) -> str:
    """The header's notes on an input delay and an output mode (how to call the step)."""
    notes = ""
    if comp.delay_samples:
        notes += (
            f"\n * With the model's input delay of {comp.delay_samples} samples, pass the "
            f"value\n * desired {comp.delay_samples} samples from now (the command acts then)."
        )
    if comp.mode.active:
        notes += (
            f"\n * With the mechanical mode ({comp.mode.f0:.6g} Hz: the model's or its output"
            "\n * map's), also pass the desired value of the next sample (NaN: extrapolated"
            "\n * from the last two);"
            f"\n * the loop must run at {1.0 / comp.mode.sample_interval:.6g} Hz."
        )
    return notes


def _c_file(name: str) -> str:
    """A C file shipped with the package (``piezohyst/model/cores/c``)."""
    return (resources.files("piezohyst.model.cores") / "c" / name).read_text(encoding="utf-8")


def _target_map(comp: Compensator, precision: Precision) -> list[str]:
    """The constants of ``map.c``: any output map's calibrated displacements (beyond them a
    desired value is counted), and a curved map's coefficients and edges (a linear one is
    folded into the step's REFERENCE and SCALE by its engine, but before an output mode,
    whose inverse runs on the map's charges: there its coefficients and edges too)."""
    om = comp.output_map
    if om is None:
        return ["#define HAS_MAP 0", "#define CURVED_MAP 0", "#define LINEAR_MAP 0"]
    text = CText(precision)
    lo, hi, s_lo, s_hi, d_lo, d_hi = om.edges()
    rising = s_hi > s_lo
    low_end, high_end = (s_lo, s_hi) if rising else (s_hi, s_lo)
    ends = text.constants(MAP_LOW_END=low_end, MAP_HIGH_END=high_end)
    edges = text.constants(MAP_CENTER=om.center, MAP_SCALE=om.scale, MAP_LO=lo, MAP_HI=hi,
                           MAP_S_LO=s_lo, MAP_S_HI=s_hi, MAP_D_LO=d_lo, MAP_D_HI=d_hi)  # fmt: skip
    if om.order == 1 and comp.mode.active:  # before the mode's inverse, as Python inverts it
        c0, c1 = om.coefficients
        return ["#define HAS_MAP 1", "#define CURVED_MAP 0", "#define LINEAR_MAP 1", *ends,
                f"#define MAP_RISING {int(rising)}", *edges,
                *text.constants(MAP_C0=c0, MAP_C1=c1)]  # fmt: skip
    if om.order == 1:
        return ["#define HAS_MAP 1", "#define CURVED_MAP 0", "#define LINEAR_MAP 0", *ends]
    c = np.array(om.coefficients, dtype=np.float64)
    tol = (1e-13 if precision == "double" else 1e-6) * max(abs(high_end - low_end), 1e-300)
    return [
        "#define HAS_MAP 1",
        "#define CURVED_MAP 1",
        "#define LINEAR_MAP 0",
        *ends,
        f"#define MAP_ORDER {om.order}",
        f"#define MAP_RISING {int(rising)}",
        text.table("MAP_C", str(c.size), c),
        text.table("MAP_DC", str(c.size - 1), np.polynomial.polynomial.polyder(c)),
        *edges,
        *text.constants(MAP_TOL=tol),
    ]  # fmt: skip


def _source(
    prefix: str, precision: Precision, lines: list[str], files: list[str], comp: Compensator
) -> str:
    """The generated ``.c``: the preamble of parameters and names, the desired value's map
    (``map.c``), then the shipped files."""
    lines = lines + _target_map(comp, precision)
    files = [files[0], "map.c", *files[1:]]  # after ieee.c, before the step that uses it
    libm = "#include <math.h>\n" if "boucwen.c" in files else ""
    names = "\n".join(f"#define PREFIX_{n} {prefix}_{n}" for n in ("t", "init", "step"))
    preamble = (
        f"/* {prefix}.c: generated by piezohyst; do not edit (re-export instead). */\n"
        f'#include "{prefix}.h"\n#include <stdint.h>\n{libm}\n'
        f"typedef {prefix}_real real_t;\n{names}\n"
        f"#define REAL_IS_DOUBLE {int(precision == 'double')}\n"
    )
    body = "\n".join(_c_file(name) for name in files)
    return preamble + "\n".join(lines) + "\n\n" + body


def c_paths(path: str | os.PathLike[str]) -> tuple[Path, Path, str]:
    """The ``.c`` and ``.h`` files :func:`write_c` writes for ``path``, and their C prefix.

    Parameters
    ----------
    path : str or os.PathLike
        The requested ``.c`` file (another suffix is replaced).

    Returns
    -------
    tuple
        Source path, header path, prefix (a C identifier from the file name).
    """
    c_path = Path(path)
    if c_path.suffix != ".c":
        c_path = c_path.with_suffix(".c")
    prefix = re.sub(r"\W", "_", c_path.stem)
    if prefix[:1].isdigit():
        prefix = "_" + prefix
    return c_path, c_path.with_name(f"{prefix}.h"), prefix


def write_c(
    compensator: Compensator | SelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> tuple[Path, Path]:
    """Write ``NAME.c`` and ``NAME.h`` (NAME from ``path``) atomically.

    Parameters
    ----------
    compensator : Compensator or SelfSensingController
        An analytic compensator, or a self-sensing controller.
    path : str or os.PathLike
        The ``.c`` file; the header goes beside it.
    precision : {"double", "float"}
        The C type of every real.

    Returns
    -------
    tuple of Path
        The source and the header.
    """
    c_path, h_path, prefix = c_paths(path)
    code = export_c(compensator, precision=precision, prefix=prefix)
    atomic_write_text(h_path, code.header)
    atomic_write_text(c_path, code.source)
    return c_path, h_path


def _taken_prefixes() -> set[str]:
    """Prefixes whose ``_step``, ``_init`` or ``_t`` names the C sources already use."""
    folder = resources.files("piezohyst.model.cores") / "c"
    text = "".join(
        f.read_text(encoding="utf-8") for f in folder.iterdir() if f.name[-2:] in (".c", ".h")
    )
    found = re.findall(r"\b([A-Za-z_][A-Za-z0-9_]*?)_(?:step|init|t)\b", text)
    return {name for name in found if name != "PREFIX"}
