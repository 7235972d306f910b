"""The compensator as an FMI 2.0 Co-Simulation FMU, for Simulink, dSPACE and any FMI host.

Simulink's FMU Import block, dSPACE VEOS and SCALEXIO, OpenModelica and FMPy load an FMU
through one C API. :func:`write_fmu` writes the exported step
(:mod:`piezohyst.control.export`) with an FMI 2.0 Co-Simulation wrapper, builds it for the
machine it runs on with the system C compiler, and zips ``modelDescription.xml``,
``binaries/<platform>/NAME.so`` and ``sources/`` (to build for another platform):

* input ``target`` (Real; the desired value in the model's output unit, or m), with
  ``--controller`` a second input ``charge``, and where a mode is inverted (the model's, or
  a controller's output map's) then ``next``, the next step's target; output ``voltage``
  (Real, V);
* one ``fmi2DoStep`` of ``1/sample_rate`` is one compensator step: a step of another size
  is refused with ``fmi2Error`` and a log message, as is any call out of the standard's
  order (a step before initialization, after terminate...), never a crash;
* ``fmi2Reset`` goes back to the exported state: the same run again reproduces the first;
* a NaN target holds the last command, inside the limits, as in Python;
* Integer outputs ``nonfinite``, ``saturated``, ``slewed`` and ``extrapolated`` count what
  the limits held since the last reset (non-finite targets, targets out of reach, commands
  cut by the slew limit, targets beyond the output map's calibrated range), so the host
  sees when they bite;
* the limits, slew and gain are baked into the step at export (constants of the C source),
  so they are not FMU parameters: changing them means exporting again.

The FMI 2.0 types are declared in the wrapper itself (the standard's ``fmi2Functions.h``
names and signatures, with C linkage and default visibility), so the sources build with any
C99 compiler and nothing else.
"""

from __future__ import annotations

import hashlib
import os
import platform
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast
from xml.sax.saxutils import escape

from ..._version import __version__
from ...errors import ParameterError
from ..c_text import Precision
from ..compensator import Compensator
from .c_code import export_c
from .shared import _c_template, compiler

if TYPE_CHECKING:
    from ..selfsensing import SelfSensingController

__all__ = ["fmu_platform", "write_fmu"]

#: Relative tolerance on the communication step size (the host's time arithmetic)
STEP_TOLERANCE = 1e-6


def fmu_platform() -> str:
    """The FMI 2.0 platform folder for this machine (``linux64``, ``win64``, ``darwin64``).

    Returns
    -------
    str
    """
    bits = "64" if sys.maxsize > 2**32 else "32"
    name = {"win32": "win", "darwin": "darwin"}.get(sys.platform, "linux")
    return f"{name}{bits}"


def _wrapper(prefix: str, extras: tuple[str, ...], period: float, what: str) -> str:
    """The FMI 2.0 Co-Simulation functions around the step; ``extras`` names the step's
    further inputs, value references 2, 3 ("charge" for the controller, then "next" for a
    mode: the next target, its inverse's preview; none for a plain compensator)."""
    n_real = 2 + len(extras)
    args = "".join(f", ({prefix}_real)c->r[{2 + k}]" for k in range(len(extras)))
    step_call = f"{prefix}_step(&c->s, ({prefix}_real)c->r[0]{args})"
    starts = "".join(f"\n    c->r[{2 + k}] = {'NAN' if x == 'next' else '0.0'};"
                     for k, x in enumerate(extras))  # fmt: skip
    layout = ", ".join(["0 target", "1 voltage"] + [f"{2 + k} {x}" for k, x in enumerate(extras)])
    return fmi2_wrapper(
        prefix, period, what, n_real=n_real,
        layout=layout, not_input="vr[i] == 1",
        inputs=", ".join(["target", *extras]),
        counts=("c->s.nonfinite", "c->s.saturated", "c->s.slewed", "c->s.extrapolated"),
        counts_said="0 non-finite targets, 1 targets out of reach,\n * 2 commands cut by the "
        "slew limit, 3 targets beyond the output map's calibrated range",
        step_statement=f"c->r[1] = (fmi2Real){step_call}",
        start_outputs="c->r[0] = 0.0;\n    c->r[1] = (fmi2Real)c->s.last;" + starts,
    )  # fmt: skip


def fmi2_wrapper(
    prefix: str, period: float, what: str, *, n_real: int, layout: str, not_input: str,
    inputs: str, counts: tuple[str, ...], counts_said: str, step_statement: str,
    start_outputs: str,
) -> str:  # fmt: skip
    """The FMI 2.0 Co-Simulation functions (``c/fmi2_cs.c``) around a step: its real
    variables (``n_real``, the inputs where ``not_input`` is false), its integer counts (C
    expressions on the state ``c->s``, value references 0, 1, ...), and the statement a step
    runs (it reads the inputs from ``c->r`` and writes the outputs there).

    Parameters
    ----------
    prefix : str
    period : float
        The step (s).
    what : str
        One line naming what the FMU holds.
    n_real : int
    layout : str
        The real variables, said in a comment.
    not_input : str
        A C expression of ``vr[i]``: true for a real that is an output.
    inputs : str
        The inputs' names, for a refusal.
    counts : tuple of str
    counts_said : str
        The counts, said in a comment.
    step_statement : str
    start_outputs : str
        The statements that set every real variable at the start (the outputs: the commands
        of the exported state).

    Returns
    -------
    str
    """
    chain = counts[-1]
    for k in range(len(counts) - 2, -1, -1):
        chain = f"vr[i] == {k} ? {counts[k]} : {chain}"
    return _c_template("fmi2_cs.c").substitute(
        what=what, prefix=prefix, period=repr(period), n_real=n_real,
        STEP_TOLERANCE=repr(STEP_TOLERANCE), layout=layout, not_input=not_input,
        inputs=inputs, last_count=len(counts) - 1, count_of=chain, counts_said=counts_said,
        step_statement=step_statement, start_outputs=start_outputs,
    )  # fmt: skip


def stamp_guid(name: str, files: dict[str, str]) -> str:
    """Put the FMU's GUID (a digest of its sources) in place of ``{NAME-GUID}`` in its
    ``NAME.c``, and return it.

    Parameters
    ----------
    name : str
        The model identifier.
    files : dict of str to str
        The sources by file name; ``NAME.c`` is changed in place.

    Returns
    -------
    str
    """
    guid = "{" + hashlib.sha256("".join(files.values()).encode()).hexdigest()[:32] + "}"
    files[f"{name}.c"] = files[f"{name}.c"].replace(f'"{{{name}-GUID}}"', f'"{guid}"')
    return guid


def scalar(label: str, ref: int, causality: str, kind: str, said: str, start: str = "0") -> str:
    """One ``ScalarVariable`` of a model description: an input (continuous, with its start)
    or an output (discrete, calculated).

    Parameters
    ----------
    label : str
    ref : int
        Its value reference.
    causality : {"input", "output"}
    kind : {"Real", "Integer"}
    said : str
        Its description.
    start : str
        An input's start value.

    Returns
    -------
    str
    """
    extra = ' variability="continuous"' if causality == "input" else (
        ' variability="discrete" initial="calculated"')  # fmt: skip
    begin = f' start="{start}"' if causality == "input" else ""
    return (f'    <ScalarVariable name="{label}" valueReference="{ref}" causality="{causality}"'
            f'{extra} description="{escape(said)}">\n      <{kind}{begin}/>\n'
            "    </ScalarVariable>")  # fmt: skip


def cosim_description(
    name: str, guid: str, what: str, period: float, sources: list[str], rows: list[str],
    outputs: Sequence[int],
) -> str:  # fmt: skip
    """An FMI 2.0 Co-Simulation ``modelDescription.xml``: its variables (:func:`scalar`),
    the C sources it is built from, and the outputs by index (1-based).

    Parameters
    ----------
    name, guid, what : str
        The model identifier, its GUID, one line naming what it holds.
    period : float
        Its step (s).
    sources : list of str
        The C files.
    rows : list of str
        The variables, in order.
    outputs : sequence of int
        The outputs' indices.

    Returns
    -------
    str
    """
    files = "".join(f'      <File name="{f}"/>\n' for f in sources)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{guid}"
  description="{escape(what)}" generationTool="piezohyst {__version__}"
  variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" needsExecutionTool="false"
    canHandleVariableCommunicationStepSize="false" canInterpolateInputs="false"
    canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false"
    canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="false"
    canSerializeFMUstate="false" providesDirectionalDerivative="false">
    <SourceFiles>
{files}    </SourceFiles>
  </CoSimulation>
  <DefaultExperiment startTime="0" stepSize="{period!r}"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{chr(10).join(f'      <Unknown index="{i}"/>' for i in outputs)}
    </Outputs>
    <InitialUnknowns>
{chr(10).join(f'      <Unknown index="{i}" dependencies=""/>' for i in outputs)}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def _model_description(
    name: str, guid: str, extras: tuple[str, ...], period: float, desired_unit: str, what: str
) -> str:
    said = {
        "charge": ("0", "the charge read at this step (model output units)"),
        "next": ("NaN", f"the next step's desired value ({desired_unit}; NaN: extrapolated), "
                        "for the mechanical mode (the model's or its output map's)"),
    }  # fmt: skip
    rows = [
        scalar("target", 0, "input", "Real", f"the desired value ({desired_unit})"),
        scalar("voltage", 1, "output", "Real", "the command (V), inside the limits"),
    ]
    for k, extra in enumerate(extras):
        rows.append(scalar(extra, 2 + k, "input", "Real", said[extra][1], said[extra][0]))
    rows += [
        scalar("nonfinite", 0, "output", "Integer",
               "non-finite targets since the last reset (the last command held)"),
        scalar("saturated", 1, "output", "Integer",
               "targets out of reach since the last reset (the nearer voltage limit sent)"),
        scalar("slewed", 2, "output", "Integer",
               "commands cut by the slew limit since the last reset"),
        scalar("extrapolated", 3, "output", "Integer",
               "targets beyond the output map's calibrated range since the last reset (the "
               "map extended linearly; 0 without a map)"),
    ]  # fmt: skip
    first = 3 + len(extras)  # the counts follow target, voltage (and charge, next)
    outputs = [2, *range(first, first + 4)]
    return cosim_description(name, guid, what, period, [f"{name}.c"], rows, outputs)


def write_fmu(
    compensator: Compensator | SelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> Path:
    """Write an FMI 2.0 Co-Simulation FMU of the compensator (or controller).

    Parameters
    ----------
    compensator : Compensator or SelfSensingController
        With its loop's ``sample_rate`` (one ``fmi2DoStep`` is one sample).
    path : str or os.PathLike
        The ``.fmu`` file; its stem names the model (a C identifier).
    precision : {"double", "float"}

    Returns
    -------
    Path
        The FMU written.

    Raises
    ------
    ParameterError
        No sample rate, a model the C export does not cover, no C compiler. A model (or a
        controller's output map) with a mode has a further input, ``next`` (the next step's
        target, the preview its inverse needs; start NaN: extrapolated), after a
        controller's ``charge``.
    """
    comp = cast(Compensator, getattr(compensator, "compensator", compensator))
    controller = comp is not compensator
    if comp.sample_rate is None:
        msg = "an FMU steps at the loop's rate: give the sample rate (--sample-rate)"
        raise ParameterError(msg)
    out = Path(path)
    if out.suffix != ".fmu":
        out = out.with_suffix(".fmu")
    name = out.stem
    if not name.isidentifier() or not name.isascii():
        msg = f"the FMU's name {name!r} (its file name) must be a C identifier"
        raise ParameterError(msg)
    period = 1.0 / float(comp.sample_rate)
    code = export_c(compensator, precision=precision, prefix=name)
    kind = "self-sensing controller" if controller else "compensator"
    what = f"{name}: the {kind} of a {type(comp.model).__name__}, {comp.sample_rate:g} Hz"
    extras = (("charge",) if controller else ()) + (("next",) if comp.mode.active else ())
    source = code.source + _wrapper(name, extras, period, what)
    guid = "{" + hashlib.sha256((code.header + source).encode()).hexdigest()[:32] + "}"
    source = source.replace(f'"{{{name}-GUID}}"', f'"{guid}"')
    unit = "m" if comp.domain == "displacement" else comp.spec.output_unit
    xml = _model_description(name, guid, extras, period, unit, what)
    return package_fmu(out, name, {f"{name}.c": source, code.header_name: code.header}, xml, what)


def package_fmu(out: Path, name: str, files: dict[str, str], xml: str, what: str) -> Path:
    """Build an FMU's binary from its C ``files`` (every ``.c`` a translation unit) and zip it
    with ``modelDescription.xml``, the sources and a page saying how to build them elsewhere.

    Parameters
    ----------
    out : Path
        The ``.fmu`` file, written atomically.
    name : str
        The model identifier (the binary's name).
    files : dict of str to str
        The sources and headers, by file name.
    xml : str
        The model description.
    what : str
        One line naming what the FMU holds.

    Returns
    -------
    Path
        The ``.fmu`` archive, written atomically.

    Raises
    ------
    ParameterError
        No C compiler, or a build that fails.
    """
    from ...io import atomic_write

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for file, text in files.items():
            (folder / file).write_text(text, encoding="utf-8")
        sources = [file for file in files if file.endswith(".c")]
        binary = folder / f"{name}{'.dll' if sys.platform == 'win32' else '.so'}"
        cmd = [compiler(), "-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden",
               *(str(folder / f) for f in sources), "-o", str(binary), "-lm"]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            first = next((ln for ln in done.stderr.splitlines() if "error" in ln), done.stderr)
            msg = f"building the FMU's binary failed: {first.strip()}"
            raise ParameterError(msg)
        buffer = folder / "fmu.zip"
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", xml)
            z.write(binary, f"binaries/{fmu_platform()}/{binary.name}")
            for file in files:
                z.write(folder / file, f"sources/{file}")
            z.writestr(
                "documentation/index.html",
                f"<html><body><h1>{escape(name)}</h1><p>{escape(what)}; built by piezohyst "
                f"{__version__} on {platform.system()} {platform.machine()}. Build for another "
                f"platform from sources/ (C99): cc -shared -fPIC -O2 {' '.join(sources)} -o "
                f"{name}.so -lm (Linux), cl /LD /O2 (Windows).</p></body></html>",
            )
        data = buffer.read_bytes()

        def write(target: Path) -> None:
            target.write_bytes(data)

        return atomic_write(out, write)
