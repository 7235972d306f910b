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
from typing import Literal, cast

import numpy as np

from ..._kernels import packed as P
from ..._kernels import play as K
from ..._validation import FloatArray
from ...errors import ParameterError
from ...io import atomic_write_text
from ..compensator import Compensator
from ..selfsensing import SelfSensingController

__all__ = ["CCode", "c_paths", "export_c", "write_c"]

Precision = Literal["double", "float"]


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


def _literal(value: float, precision: Precision) -> str:
    if precision == "float":
        return f"{float(np.float32(value))!r}f".replace("inff", "INFINITY")
    return repr(float(value))


def _array(values: np.ndarray, precision: Precision) -> str:
    items = [_literal(float(v), precision) for v in values]
    lines = []
    for k in range(0, len(items), 4):
        lines.append("    " + ", ".join(items[k : k + 4]) + ",")
    return "{\n" + "\n".join(lines) + "\n}"


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
    if controller is not None and comp.dynamic:  # pragma: no cover - the controller refuses it
        msg = "the self-sensing controller does not invert input dynamics"
        raise ParameterError(msg)
    if comp.mode.active and (controller is not None or comp.delay_samples):
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
    source = comp.spec.operator.c_source  # the core's step in C, or None
    if source == "packed.c":  # Preisach, Duhem, Bouc-Wen: the bracketed Newton step in C
        return _packed_c(comp, prefix, precision)
    if source != "play.c":
        msg = (
            f"C export covers play operators and the Preisach, Duhem and Bouc-Wen cores; a "
            f"{type(comp.spec.operator).__name__} core runs in Python (ph.Compensator) only."
        )
        raise ParameterError(msg)
    if not comp.analytic:
        return _numeric_c(comp, prefix, precision)
    tables = comp.inverse.tables
    config = _mapped(comp, comp.inverse.config, K.CFG_REFERENCE, K.CFG_INV_GAIN)
    state = comp.state
    n = comp.n_operators
    spec = comp.spec
    p = precision
    step = float(config[K.CFG_MAX_STEP])
    has_slew = int(np.isfinite(step))
    upper = prefix.upper()
    lines = [
        f"#define N {upper}_N",
        f"#define HAS_SLEW {has_slew}",
        f"#define DYNAMIC {int(comp.dynamic)}",
        f"#define MODE {int(comp.mode.active)}",
        f"#define CONTROLLER {int(controller is not None)}",
        *(f"static const real_t {name}[N] = {_array(values, p)};" for name, values in (
            ("R", tables[K.TAB_R]), ("W", tables[K.TAB_W]), ("S", tables[K.TAB_S]),
            ("RI", tables[K.TAB_RI]), ("WI", tables[K.TAB_WI]), ("Z0", state.operators))),
        *_constants(p, OFFSET=config[K.CFG_OFFSET], INV_OFFSET=config[K.CFG_INV_OFFSET],
                    V_MIN=config[K.CFG_V_MIN], V_MAX=config[K.CFG_V_MAX]),
    ]  # fmt: skip
    if has_slew:
        lines += _constants(p, MAX_STEP=step)
    lines += _constants(p, SCALE=config[K.CFG_INV_GAIN], REFERENCE=config[K.CFG_REFERENCE],
                        BOUND=config[K.CFG_BOUND], SAT_TOL=1e-12 * (comp.v_max - comp.v_min),
                        LAST0=state.command)  # fmt: skip
    init = [] if controller is None else _feedback_init(controller, p)
    files = ["ieee.c", "play.c"]
    if comp.dynamic:
        lines += _constants(
            p, FRACTION=comp.inverse.dyn[K.DYN_FRACTION], GAIN_B=comp.inverse.dyn[K.DYN_GAIN_B]
        )
        init = [
            f"s->w = {_literal(comp.inverse.dstate[0], p)};",
            f"s->u = {_literal(comp.inverse.dstate[1], p)};",
        ]
        files.append("play_dynamic.c")
    if controller is not None:
        c = controller.ctl
        lines += _constants(p, **{name: c[getattr(K, f"CTL_{name}")] for name in (
            "KP", "KI", "G0", "G1", "INV_SCALE", "DT", "TOL", "HOLD_TOL", "HOLD_SAMPLES",
            "REFRESH", "DISCHARGE")})  # fmt: skip
        files.append("play_controller.c")
    lines += _mode(comp, p, init, files)
    lines.append(_init_extra(init))
    desired_unit = "m" if comp.domain == "displacement" else spec.output_unit
    header = _template("play.h").substitute(
        _names(prefix, precision),
        title="feedforward hysteresis compensator" if controller is None
        else "self-sensing controller (feedforward + charge feedback)",
        model=type(comp.model).__name__, n=n, input_unit=spec.input_unit,
        output_unit=spec.output_unit, desired_unit=desired_unit, v_min=repr(comp.v_min),
        v_max=repr(comp.v_max), notes=_notes(comp), controller=int(controller is not None),
        dynamic=int(comp.dynamic), mode=int(comp.mode.active),
        kind="compensator" if controller is None else "controller", lag_state="",
    )  # fmt: skip
    return CCode(header, _source(prefix, precision, lines, files, comp), f"{prefix}.h")


def _numeric_c(comp: Compensator, prefix: str, precision: Precision) -> CCode:
    """C99 for play operators beside kept asymmetry or creep terms (GeneralizedPI): the
    bracketed Newton step of ``_kernels.play.numeric_step`` (``play_numeric.c``)."""
    if comp.mode.active:
        msg = (
            "C export of a model with asymmetry or creep takes no output mode yet: pass the "
            "pre-inverted target (OutputDynamics.invert) or fit without the mode"
        )
        raise ParameterError(msg)
    p = precision
    e = comp.inverse
    config = _mapped(comp, e.config, K.CFG_REFERENCE, K.CFG_INV_GAIN)
    state = comp.state
    n, n_static, n_lags = comp.n_operators, int(e.static.shape[1]), int(e.lags.shape[1])
    step = float(config[K.CFG_MAX_STEP])
    has_slew = int(np.isfinite(step))
    upper = prefix.upper()
    lines = [
        f"#define N {upper}_N",
        f"#define N_STATIC {n_static}",
        f"#define N_LAGS {n_lags}",
        f"#define HAS_SLEW {has_slew}",
        f"#define DYNAMIC {int(comp.dynamic)}",
        "#define MODE 0",
        f"static const real_t R[N] = {_array(e.tables[K.TAB_R], p)};",
        f"static const real_t W[N] = {_array(e.tables[K.TAB_W], p)};",
        f"static const real_t Z0[N] = {_array(state.operators, p)};",
        *_constants(p, OFFSET=config[K.CFG_OFFSET], V_MIN=config[K.CFG_V_MIN],
                    V_MAX=config[K.CFG_V_MAX], SCALE=config[K.CFG_INV_GAIN],
                    REFERENCE=config[K.CFG_REFERENCE], LAST0=state.command),
    ]  # fmt: skip
    if has_slew:
        lines += _constants(p, MAX_STEP=step)
    if n_static:
        lines += [
            f"static const real_t STATIC_KNOT[N_STATIC] = {_array(e.static[0], p)};",
            f"static const real_t STATIC_UP[N_STATIC] = {_array(e.static[1], p)};",
            f"static const real_t STATIC_DOWN[N_STATIC] = {_array(e.static[2], p)};",
            *_constants(p, STATIC_SCALE=config[K.CFG_STATIC_SCALE]),
        ]
    if n_lags:
        lines += [
            f"static const real_t LAG_G[N_LAGS] = {_array(e.lags[1], p)};",
            f"static const real_t LAG_A[N_LAGS] = {_array(e.lags[2], p)};",
            f"static const real_t C0[N_LAGS] = {_array(state.lags, p)};",
        ]
    init = []
    if comp.dynamic:  # the input lags inverted before the Newton step (play_numeric.c)
        lines += _constants(p, FRACTION=e.dyn[K.DYN_FRACTION], GAIN_B=e.dyn[K.DYN_GAIN_B])
        init = [f"s->w = {_literal(e.dstate[0], p)};", f"s->u = {_literal(e.dstate[1], p)};"]
    lines.append(_init_extra(init))
    spec = comp.spec
    desired_unit = "m" if comp.domain == "displacement" else spec.output_unit
    lag_state = f"\n    {prefix}_real c[{n_lags}];     /* creep lag states, V */" if n_lags else ""
    header = _template("play.h").substitute(
        _names(prefix, precision),
        title="feedforward hysteresis compensator (play operators with asymmetry or creep)",
        model=type(comp.model).__name__, n=n, input_unit=spec.input_unit,
        output_unit=spec.output_unit, desired_unit=desired_unit, v_min=repr(comp.v_min),
        v_max=repr(comp.v_max), notes=_notes(comp), controller=0, dynamic=int(comp.dynamic),
        mode=0, kind="compensator", lag_state=lag_state,
    )  # fmt: skip
    source = _source(prefix, precision, lines, ["ieee.c", "play_numeric.c"], comp)
    return CCode(header, source, f"{prefix}.h")


def _names(prefix: str, precision: Precision) -> dict[str, str]:
    """The header template's names: the prefix, its upper case, the guard and the real type."""
    upper = prefix.upper()
    return {"prefix": prefix, "upper": upper, "guard": f"{upper}_H",
            "real": f"{prefix}_real", "precision": precision}  # fmt: skip


def _constants(precision: Precision, **values: float) -> list[str]:
    """``static const real_t NAME = value;`` for each value."""
    return [f"static const real_t {k} = {_literal(float(v), precision)};"
            for k, v in values.items()]  # fmt: skip


def _init_extra(statements: list[str]) -> str:
    """What ``init`` sets beyond the core's state (feedback, dynamics, mode, lags)."""
    if not statements:
        return "#define INIT_EXTRA(s) (void)(s)"
    body = "".join(f"    {line} \\\n" for line in statements)
    return f"#define INIT_EXTRA(s) do {{ \\\n{body}}} while (0)"


def _mode(comp: Compensator, p: Precision, init: list[str], files: list[str]) -> list[str]:
    """The output mode's constants and state, and ``mode.c`` after the step."""
    if not comp.mode.active:
        return []
    mode = comp.mode
    w = 2.0 * math.pi * mode.f0
    for name, value in zip(("e2", "e1"), comp.mode_history, strict=True):
        v = _literal(float(value), p) if np.isfinite(value) else "not_a_number()"
        init.append(f"s->{name} = {v};")
    files.append("mode.c")
    return _constants(p, MODE_DT=mode.sample_interval, MODE_K1=2.0 * mode.zeta / w,
                      MODE_W2=w * w)  # fmt: skip


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
            f"\n * With the model's mechanical mode ({comp.mode.f0:.6g} Hz), also pass the"
            "\n * desired value of the next sample (NaN: extrapolated from the last two);"
            f"\n * the loop must run at {1.0 / comp.mode.sample_interval:.6g} Hz."
        )
    return notes


def _template(name: str) -> Template:
    return Template(_c_file(name))


def _c_file(name: str) -> str:
    """A C file shipped with the package (``piezohyst/model/cores/c``)."""
    return (resources.files("piezohyst.model.cores") / "c" / name).read_text(encoding="utf-8")


def _target_map(comp: Compensator, precision: Precision) -> list[str]:
    """The constants of ``map.c``: any output map's calibrated displacements (beyond them a
    desired value is counted), and a curved map's coefficients and edges (a linear one is
    folded into REFERENCE and SCALE by :func:`_mapped`)."""
    om = comp.output_map
    if om is None:
        return ["#define HAS_MAP 0", "#define CURVED_MAP 0"]
    lo, hi, s_lo, s_hi, d_lo, d_hi = om.edges()
    rising = s_hi > s_lo
    low_end, high_end = (s_lo, s_hi) if rising else (s_hi, s_lo)
    ends = _constants(precision, MAP_LOW_END=low_end, MAP_HIGH_END=high_end)
    if om.order == 1:
        return ["#define HAS_MAP 1", "#define CURVED_MAP 0", *ends]
    c = np.array(om.coefficients, dtype=np.float64)
    tol = (1e-13 if precision == "double" else 1e-6) * max(abs(high_end - low_end), 1e-300)
    return [
        "#define HAS_MAP 1",
        "#define CURVED_MAP 1",
        *ends,
        f"#define MAP_ORDER {om.order}",
        f"#define MAP_RISING {int(rising)}",
        f"static const real_t MAP_C[{c.size}] = {_array(c, precision)};",
        f"static const real_t MAP_DC[{c.size - 1}] = "
        f"{_array(np.polynomial.polynomial.polyder(c), precision)};",
        *_constants(precision, MAP_CENTER=om.center, MAP_SCALE=om.scale, MAP_LO=lo, MAP_HI=hi,
                    MAP_S_LO=s_lo, MAP_S_HI=s_hi, MAP_D_LO=d_lo, MAP_D_HI=d_hi, MAP_TOL=tol),
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


def _packed_c(comp: Compensator, prefix: str, precision: Precision) -> CCode:
    """C99 for a compensator on a packed core: ``_kernels.packed.core_step`` in C.

    The same arithmetic as the kernel: the step's output is monotone in the
    voltage, so the inverse is Newton's method inside a bracket (bisecting
    whenever a step would leave it), at most ``NEWTON_MAX`` iterations — a
    bounded time per sample.
    """
    p = precision
    params, state = comp.inverse.params, comp.state
    cfg = _mapped(comp, comp.inverse.config, P.CC_REF, P.CC_INV_GAIN)
    kind = int(params[0])
    n_lags = int(comp.inverse.lags.shape[1])
    has_slow = int(comp.inverse.slow.size > 0)
    step = float(cfg[P.CC_MAX_STEP])
    has_slew = int(np.isfinite(step))
    region = comp.inverse.region
    has_region = int(region.shape[1] > 0 and np.isfinite(cfg[P.CC_TOL]))
    lines = [
        f"#define NS {prefix.upper()}_NS",
        f"#define KIND {kind} /* 0 Duhem, 1 Bouc-Wen, 2 Preisach */",
        f"#define HAS_SLEW {has_slew}",
        f"#define DYNAMIC {int(comp.dynamic)}",
        f"#define MODE {int(comp.mode.active)}",
        f"#define HAS_REGION {has_region}",
        f"#define N_LAGS {n_lags} /* kept creep lags beside the core */",
        f"#define SLOW {has_slow} /* a slow (relaxing) Preisach core behind a lag */",
        f"#define NS_MAIN {int(cfg[P.CC_NS])} /* the core values in st; the slow core next */",
        f"#define NEWTON_MAX {P.NEWTON_MAX}",
        f"#define HOLD_RES {P.HOLD_RES!r}",
        f"#define REGION_BISECTIONS {P.REGION_BISECTIONS}",
        f"#define STACK {P.STACK}",
    ]
    files = ["ieee.c", "packed_util.c"]
    if kind == int(P.KIND_BOUC_WEN):
        lines += _constants(p, **{n: params[getattr(P, f"BW_{n if n != 'NEXP' else 'N'}")]
                                  for n in ("C0", "ALPHA", "BETA", "GAMMA", "NEXP", "OFFSET",
                                            "DV_MAX", "G_MAX", "S_MIN")})  # fmt: skip
        files.append("boucwen.c")
    elif kind == int(P.KIND_PREISACH):
        lines.append(_preisach_constants(params, p))
        files += ["preisach_grid.c", "preisach.c"]
    else:
        nv, nq = int(params[P.DU_NV]), int(params[P.DU_NQ])
        cells = nv * nq
        lines += [f"#define NV {nv}", f"#define NQ {nq}"]
        lines += _constants(p, V_LO=params[P.DU_V_LO], V_STEP=params[P.DU_V_STEP],
                            Q_LO=params[P.DU_Q_LO], Q_STEP=params[P.DU_Q_STEP],
                            DV_MAX=params[P.DU_DV_MAX], S_MIN=params[P.DU_F_MIN])  # fmt: skip
        lines += [
            f"static const real_t UP[NV * NQ] = {_array(params[P.DU_UP : P.DU_UP + cells], p)};",
            "static const real_t DOWN[NV * NQ] = "
            f"{_array(params[P.DU_UP + cells : P.DU_UP + 2 * cells], p)};",
        ]
        files.append("duhem.c")
    if has_slow:  # the slow core: the Preisach grid functions again, on its own grid
        lines.append(_preisach_constants(comp.inverse.slow, p, "SLOW_"))
        lines += _constants(p, SLOW_A=cfg[P.CC_SLOW_A])
        files += ["relaxation_begin.h", "preisach_grid.c", "relaxation_end.h"]
    if has_region:
        bins = region.shape[1]
        lines += [
            f"static const real_t REGION_LO[{bins}] = {_array(region[0], p)};",
            f"static const real_t REGION_HI[{bins}] = {_array(region[1], p)};",
        ]
        lines += _constants(p, RV_LO=cfg[P.CC_RV_LO], RV_HI=cfg[P.CC_RV_HI], TOL=cfg[P.CC_TOL])
        lines += [f"#define REGION_BINS {bins}", f"#define REFUSE {int(cfg[P.CC_REFUSE] > 0)}"]
    lines += _constants(p, V_MIN=cfg[P.CC_V_MIN], V_MAX=cfg[P.CC_V_MAX])
    if has_slew:
        lines += _constants(p, MAX_STEP=step)
    lines += _constants(p, SCALE=cfg[P.CC_INV_GAIN], REFERENCE=cfg[P.CC_REF])
    lines.append(f"static const real_t ST0[NS] = {_array(state.operators, p)};")
    lines += _constants(p, LAST0=state.command)
    init: list[str] = []
    if comp.dynamic:
        lines += _constants(p, FRACTION=comp.inverse.dyn[0], GAIN_B=comp.inverse.dyn[1])
        init += [
            f"s->w = {_literal(comp.inverse.dstate[0], p)};",
            f"s->u = {_literal(comp.inverse.dstate[1], p)};",
        ]
    if n_lags:  # gains and 1 - exp(-dt / tau) at the loop's sample rate
        lines += [
            f"static const real_t LAG_G[N_LAGS] = {_array(comp.inverse.lags[1], p)};",
            f"static const real_t LAG_A[N_LAGS] = {_array(comp.inverse.lags[2], p)};",
        ]
        init += [f"s->c[{k}] = {_literal(float(comp.inverse.dstate[P.DYN_LAGS + k]), p)};"
                 for k in range(n_lags)]  # fmt: skip
    files.append("packed.c")
    lines += _mode(comp, p, init, files)
    lines.append(_init_extra(init))
    spec = comp.spec
    names = {int(P.KIND_DUHEM): "Duhem", int(P.KIND_PREISACH): "Preisach",
             int(P.KIND_BOUC_WEN): "Bouc-Wen"}  # fmt: skip
    header = _template("packed.h").substitute(
        _names(prefix, precision), model=type(comp.model).__name__, core=names[kind],
        input_unit=spec.input_unit, output_unit=spec.output_unit,
        desired_unit="m" if comp.domain == "displacement" else spec.output_unit,
        v_min=repr(comp.v_min), v_max=repr(comp.v_max), newton_max=P.NEWTON_MAX,
        libm=" Needs pow() from <math.h> (link with -lm)." if kind == int(P.KIND_BOUC_WEN)
        else "", notes=_notes(comp), ns=comp.n_operators, n_lags=n_lags,
        dynamic=int(comp.dynamic), mode=int(comp.mode.active),
    )  # fmt: skip
    return CCode(header, _source(prefix, precision, lines, files, comp), f"{prefix}.h")


def _feedback_init(ctl: SelfSensingController, p: Precision) -> list[str]:
    """The controller's feedback state as it is now, one assignment per field."""
    fb = ctl.feedback
    lines = []
    for name, idx in (
        ("integral", K.CS_INTEGRAL),
        ("leak", K.CS_LEAK),
        ("frame", K.CS_FRAME),
        ("q_last", K.CS_Q_LAST),
        ("error", K.CS_ERROR),
        ("bias", K.CS_BIAS),
        ("hold_n", K.CS_HOLD_N),
        ("sx", K.CS_SX),
        ("sy", K.CS_SY),
        ("sxx", K.CS_SXX),
        ("sxy", K.CS_SXY),
        ("sm", K.CS_SM),
        ("y0", K.CS_Y0),
    ):
        lines.append(f"s->{name} = {_literal(fb[idx], p)};")
    for name, idx in (("d_prev", K.CS_D_PREV), ("hold_ref", K.CS_HOLD_REF)):
        value = float(fb[idx])
        lines.append(f"s->{name} = {_literal(value if np.isfinite(value) else 0.0, p)};")
    lines.append(f"s->has_prev = {int(np.isfinite(fb[K.CS_D_PREV]))};")
    lines.append(f"s->has_hold = {int(np.isfinite(fb[K.CS_HOLD_REF]))};")
    lines.append(f"s->started = {int(fb[K.CS_STARTED] > 0)};")
    lines.append(f"s->faults = {int(fb[K.CS_FAULTS])}UL;")
    lines.append(f"s->refreshes = {int(fb[K.CS_REFRESHES])}UL;")
    return lines


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


def _preisach_constants(packed: np.ndarray, precision: Precision, prefix: str = "") -> str:
    """A Preisach core's grid and Everett table as C constants (names after ``prefix``)."""
    n = int(packed[P.DU_NV])
    lit = [_literal(float(packed[k]), precision) for k in (P.DU_V_LO, P.DU_V_STEP, P.DU_F_MIN)]
    # the smallest slope bounds the main core's bracket; a slow core's is not needed
    bracket = [] if prefix else [f"static const real_t S_MIN = {lit[2]};"]
    return "\n".join(
        [
            f"enum {{ {prefix}NN = {n} }};",
            f"static const real_t {prefix}V_LO = {lit[0]};",
            f"static const real_t {prefix}H = {lit[1]};",
            *bracket,
            f"static const real_t {prefix}EV[{prefix}NN * {prefix}NN] = "
            f"{_array(packed[P.DU_UP : P.DU_UP + n * n], precision)};",
        ]
    )


def _mapped(comp: Compensator, config: FloatArray, ref: int, scale: int) -> FloatArray:
    """The step's config with a linear output map folded into its reference and scale: the
    charge for a desired displacement d is ``center + (d - c0) / g``."""
    om = comp.output_map
    if om is None or om.order != 1:  # a curved map: inverted before the step (map.c)
        return config
    out = config.copy()
    out[scale] = 1.0 / om.gain
    out[ref] = om.center - om.coefficients[0] / om.gain
    return out


def _taken_prefixes() -> set[str]:
    """Prefixes whose ``_step``, ``_init`` or ``_t`` names the C sources already use."""
    folder = resources.files("piezohyst.model.cores") / "c"
    text = "".join(
        f.read_text(encoding="utf-8") for f in folder.iterdir() if f.name[-2:] in (".c", ".h")
    )
    found = re.findall(r"\b([A-Za-z_][A-Za-z0-9_]*?)_(?:step|init|t)\b", text)
    return {name for name in found if name != "PREFIX"}
