"""The compensator as an FMI 2.0 Co-Simulation FMU, for Simulink, dSPACE and any FMI host.

Simulink's FMU Import block, dSPACE VEOS and SCALEXIO, OpenModelica and FMPy load an FMU
through one C API. :func:`write_fmu` writes the exported step
(:mod:`piezohyst.control.export`) with an FMI 2.0 Co-Simulation wrapper, builds it for the
machine it runs on with the system C compiler, and zips ``modelDescription.xml``,
``binaries/<platform>/NAME.so`` and ``sources/`` (to build for another platform):

* input ``target`` (Real; the desired value in the model's output unit, or m), with
  ``--controller`` a second input ``charge``; output ``voltage`` (Real, V);
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


def _wrapper(prefix: str, third: str, period: float, what: str) -> str:
    """The FMI 2.0 Co-Simulation functions around the step; ``third`` names the step's
    second input, value reference 2 ("charge" for the controller, "next" for a model with a
    mode: the next target, its inverse's preview; "" for none)."""
    n_real = 3 if third else 2
    step_call = (
        f"{prefix}_step(&c->s, ({prefix}_real)c->r[0], ({prefix}_real)c->r[2])"
        if third
        else f"{prefix}_step(&c->s, ({prefix}_real)c->r[0])"
    )
    start = "NAN" if third == "next" else "0.0"
    return fmi2_wrapper(
        prefix, period, what, n_real=n_real,
        layout=f"0 target, 1 voltage, 2 {third or 'unused'}", not_input="vr[i] == 1",
        inputs=f"target, {third}" if third else "target",
        counts=("c->s.nonfinite", "c->s.saturated", "c->s.slewed", "c->s.extrapolated"),
        counts_said="0 non-finite targets, 1 targets out of reach,\n * 2 commands cut by the "
        "slew limit, 3 targets beyond the output map's calibrated range",
        step_statement=f"c->r[1] = (fmi2Real){step_call}",
        start_outputs="c->r[0] = 0.0;\n    c->r[1] = (fmi2Real)c->s.last;"
        + (f"\n    c->r[2] = {start};" if third else ""),
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


def _model_description(
    name: str, guid: str, third: str, period: float, desired_unit: str, what: str
) -> str:
    said = {
        "charge": ("0", "the charge read at this step (model output units)"),
        "next": ("NaN", f"the next step's desired value ({desired_unit}; NaN: extrapolated), "
                        "for the model's mechanical mode"),
    }  # fmt: skip
    charge = (
        f'    <ScalarVariable name="{third}" valueReference="2" causality="input" '
        f'variability="continuous" description="{escape(said[third][1])}">\n      '
        f'<Real start="{said[third][0]}"/>\n    </ScalarVariable>\n'
        if third
        else ""
    )
    first_count = 4 if third else 3  # the counts follow target, voltage (and charge or next)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription
  fmiVersion="2.0"
  modelName="{name}"
  guid="{guid}"
  description="{escape(what)}"
  generationTool="piezohyst {__version__}"
  variableNamingConvention="flat"
  numberOfEventIndicators="0">
  <CoSimulation
    modelIdentifier="{name}"
    needsExecutionTool="false"
    canHandleVariableCommunicationStepSize="false"
    canInterpolateInputs="false"
    canRunAsynchronuously="false"
    canBeInstantiatedOnlyOncePerProcess="false"
    canNotUseMemoryManagementFunctions="true"
    canGetAndSetFMUstate="false"
    canSerializeFMUstate="false"
    providesDirectionalDerivative="false">
    <SourceFiles>
      <File name="{name}.c"/>
    </SourceFiles>
  </CoSimulation>
  <DefaultExperiment startTime="0" stepSize="{period!r}"/>
  <ModelVariables>
    <ScalarVariable name="target" valueReference="0" causality="input" variability="continuous" description="the desired value ({escape(desired_unit)})">
      <Real start="0"/>
    </ScalarVariable>
    <ScalarVariable name="voltage" valueReference="1" causality="output" variability="discrete" initial="calculated" description="the command (V), inside the limits">
      <Real/>
    </ScalarVariable>
{charge}    <ScalarVariable name="nonfinite" valueReference="0" causality="output" variability="discrete" initial="calculated" description="non-finite targets since the last reset (the last command held)">
      <Integer/>
    </ScalarVariable>
    <ScalarVariable name="saturated" valueReference="1" causality="output" variability="discrete" initial="calculated" description="targets out of reach since the last reset (the nearer voltage limit sent)">
      <Integer/>
    </ScalarVariable>
    <ScalarVariable name="slewed" valueReference="2" causality="output" variability="discrete" initial="calculated" description="commands cut by the slew limit since the last reset">
      <Integer/>
    </ScalarVariable>
    <ScalarVariable name="extrapolated" valueReference="3" causality="output" variability="discrete" initial="calculated" description="targets beyond the output map's calibrated range since the last reset (the map extended linearly; 0 without a map)">
      <Integer/>
    </ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs>
      <Unknown index="2"/>
      <Unknown index="{first_count}"/>
      <Unknown index="{first_count + 1}"/>
      <Unknown index="{first_count + 2}"/>
      <Unknown index="{first_count + 3}"/>
    </Outputs>
    <InitialUnknowns>
      <Unknown index="2" dependencies=""/>
      <Unknown index="{first_count}" dependencies=""/>
      <Unknown index="{first_count + 1}" dependencies=""/>
      <Unknown index="{first_count + 2}" dependencies=""/>
      <Unknown index="{first_count + 3}" dependencies=""/>
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""  # noqa: E501 - XML attributes on one line, as hosts write them


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
        No sample rate, a model the C export does not cover, no C compiler. A model with an
        output mode has a second input, ``next`` (the next step's target, the preview its
        inverse needs; start NaN: extrapolated).
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
    third = "charge" if controller else "next" if comp.mode.active else ""
    source = code.source + _wrapper(name, third, period, what)
    guid = "{" + hashlib.sha256((code.header + source).encode()).hexdigest()[:32] + "}"
    source = source.replace(f'"{{{name}-GUID}}"', f'"{guid}"')
    unit = "m" if comp.domain == "displacement" else comp.spec.output_unit
    xml = _model_description(name, guid, third, period, unit, what)
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
