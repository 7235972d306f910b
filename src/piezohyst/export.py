"""C99 export of a :class:`~piezohyst.Compensator` for microcontrollers.

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
from pathlib import Path
from typing import Literal

import numpy as np

from . import _kernels as K
from .compensator import Compensator
from .errors import ParameterError
from .io import atomic_write_text
from .selfsensing import SelfSensingController

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
    :class:`~piezohyst.selfsensing.SelfSensingController` exports the same
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
    controller: SelfSensingController | None = None
    comp: Compensator
    if isinstance(compensator, SelfSensingController):
        controller, comp = compensator, compensator.compensator
    else:
        comp = compensator
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
    if not comp.analytic:
        msg = (
            "C export covers the analytic inverse (play operators and growth terms); a model "
            "with asymmetry or creep terms runs in Python (ph.Compensator) only."
        )
        raise ParameterError(msg)
    if precision not in ("double", "float"):
        msg = f"precision must be 'double' or 'float'. Got {precision!r}."
        raise ParameterError(msg)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        msg = f"prefix must be a C identifier. Got {prefix!r}."
        raise ParameterError(msg)
    tables = comp.tables
    config = comp.config
    state = comp.state
    n = comp.n_operators
    guard = f"{prefix.upper()}_H"
    real = f"{prefix}_real"
    spec = comp.spec
    desired_unit = "m" if comp.domain == "displacement" else spec.output_unit
    kind = "compensator" if controller is None else "controller"
    feedback_fields = "" if controller is None else _FEEDBACK_FIELDS.format(real=real)
    if comp.dynamic:
        feedback_fields = (
            f"    {real} w, u;               /* input dynamics: after the fractional delay, "
            "after the lag (V) */\n"
        )
    if comp.mode.active:
        feedback_fields += (
            f"    {real} e1, e2;             /* output mode: the last two desired values "
            "(NaN: none) */\n"
        )
    delay_note = (
        f" With the model's input delay of {comp.delay_samples} samples, pass the value\n"
        f" * desired {comp.delay_samples} samples from now (the command acts then).\n *"
        if comp.delay_samples
        else ""
    )
    mode_note = (
        f" With the model's mechanical mode ({comp.mode.f0:.6g} Hz), also pass the\n"
        " * desired value of the next sample (NaN: extrapolated from the last two);\n"
        f" * the loop must run at {1.0 / comp.mode.sample_interval:.6g} Hz.\n *"
        if comp.mode.active
        else ""
    )
    step_args = f"{real} desired, {real} next" if comp.mode.active else f"{real} desired"
    step_doc = (
        f"/* One command (V) for one desired value.{delay_note}{mode_note} */\n"
        f"{real} {prefix}_step({prefix}_t *s, {step_args});"
        if controller is None
        else f"/* One command (V): desired output, and the charge read at this sample before\n"
        f" * this command acts (NaN/inf: feedforward alone for this sample). */\n"
        f"{real} {prefix}_step({prefix}_t *s, {real} desired, {real} measured);"
    )
    title = (
        "feedforward hysteresis compensator"
        if controller is None
        else "self-sensing controller (feedforward + charge feedback)"
    )
    header = f"""/* {prefix}.h: {title} generated by piezohyst.
 *
 * Model: {type(comp.model).__name__}, {n} play operators; input {spec.input_unit},
 * output {spec.output_unit}. Desired values in {desired_unit}.
 * Commands always lie in [{comp.v_min!r}, {comp.v_max!r}] V.
 */
#ifndef {guard}
#define {guard}

typedef {precision} {real};

#define {prefix.upper()}_N {n}

typedef struct {{
    {real} z[{prefix.upper()}_N];    /* forward operator states, V */
    {real} zeta[{prefix.upper()}_N]; /* inverse operator states, output units */
    {real} last;             /* last command, V */
    unsigned long nonfinite; /* NaN/inf desired values (last command held) */
    unsigned long saturated; /* commands clipped to the limits */
{feedback_fields}}} {prefix}_t;

/* Start from the state the {kind} had when it was exported. */
void {prefix}_init({prefix}_t *s);

{step_doc}

#endif /* {guard} */
"""
    p = precision
    step = float(config[K.CFG_MAX_STEP])
    bits_type, mantissa, exp_mask = (
        ("uint64_t", 52, "0x7FF") if precision == "double" else ("uint32_t", 23, "0xFF")
    )
    has_slew = int(np.isfinite(step))
    feedback_init = "" if controller is None else _feedback_init(controller, precision)
    if comp.dynamic:
        feedback_init = (
            f"    s->w = {_literal(comp.dstate[0], precision)};\n"
            f"    s->u = {_literal(comp.dstate[1], precision)};\n"
        )
    if comp.mode.active:
        for name, value in zip(("e2", "e1"), comp.mode_history, strict=True):
            v = _literal(float(value), precision) if np.isfinite(value) else "not_a_number()"
            feedback_init += f"    s->{name} = {v};\n"
    source = f"""/* {prefix}.c: generated by piezohyst; do not edit (re-export instead). */
#include "{prefix}.h"
#include <stdint.h>

#define N {prefix.upper()}_N
#define HAS_SLEW {has_slew}
#define DYNAMIC {int(comp.dynamic)}
#define MODE {int(comp.mode.active)}

static const {real} R[N] = {_array(tables[K.TAB_R], p)};
static const {real} W[N] = {_array(tables[K.TAB_W], p)};
static const {real} S[N] = {_array(tables[K.TAB_S], p)};
static const {real} RI[N] = {_array(tables[K.TAB_RI], p)};
static const {real} WI[N] = {_array(tables[K.TAB_WI], p)};
static const {real} Z0[N] = {_array(state.operators, p)};

static const {real} OFFSET = {_literal(config[K.CFG_OFFSET], p)};
static const {real} INV_OFFSET = {_literal(config[K.CFG_INV_OFFSET], p)};
static const {real} V_MIN = {_literal(config[K.CFG_V_MIN], p)};
static const {real} V_MAX = {_literal(config[K.CFG_V_MAX], p)};
#if HAS_SLEW
static const {real} MAX_STEP = {_literal(step if has_slew else 0.0, p)};
#endif
static const {real} SCALE = {_literal(config[K.CFG_INV_GAIN], p)};
static const {real} REFERENCE = {_literal(config[K.CFG_REFERENCE], p)};
static const {real} BOUND = {_literal(config[K.CFG_BOUND], p)};
static const {real} SAT_TOL = {_literal(1e-12 * (comp.v_max - comp.v_min), p)};
static const {real} LAST0 = {_literal(state.command, p)};

/* NaN or +-inf, decided from the IEEE-754 exponent bits: unlike isfinite(), a check
 * that -ffast-math (which assumes finite arithmetic) cannot optimise away. */
static int non_finite({real} x)
{{
    union {{ {real} value; {bits_type} bits; }} u;
    u.value = x;
    return (int)((u.bits >> {mantissa}) & {exp_mask}) == {exp_mask};
}}

#if MODE
static {real} not_a_number(void)
{{
    union {{ {real} value; {bits_type} bits; }} u;
    u.bits = {"0x7FF8000000000000ULL" if precision == "double" else "0x7FC00000UL"};
    return u.value;
}}
#endif

static {real} clamp({real} x, {real} lo, {real} hi)
{{
    return x < lo ? lo : (x > hi ? hi : x);
}}

/* eq. 18's state map: zeta_i = c + S_i z_i + sum over j > i of w_j z_j */
static void inverse_states({prefix}_t *s)
{{
    {real} tail = 0;
    int i;
    for (i = N - 1; i >= 0; --i) {{
        s->zeta[i] = OFFSET + S[i] * s->z[i] + tail;
        tail += W[i] * s->z[i];
    }}
}}

void {prefix}_init({prefix}_t *s)
{{
    int i;
    for (i = 0; i < N; ++i) {{
        s->z[i] = Z0[i];
    }}
    inverse_states(s);
    s->last = LAST0;
    s->nonfinite = 0;
    s->saturated = 0;
{feedback_init}}}

#if !DYNAMIC
/* eq. 18 for a finite target q (model output units), limits and slew applied */
static {real} core_step({prefix}_t *s, {real} q)
{{
    {real} x, v;
    int i, limited = 0;
    q = clamp(q, OFFSET - BOUND, OFFSET + BOUND);
    x = INV_OFFSET;
    for (i = 0; i < N; ++i) {{
        s->zeta[i] = clamp(s->zeta[i], q - RI[i], q + RI[i]);
        x += WI[i] * s->zeta[i];
    }}
    v = x;
    if (non_finite(v)) {{
        s->nonfinite++;
        inverse_states(s);
        return s->last;
    }}
    if (v < V_MIN || v > V_MAX) {{
        /* count real overshoots, not a limit reached exactly but for rounding */
        if (v < V_MIN - SAT_TOL || v > V_MAX + SAT_TOL) {{
            s->saturated++;
        }}
        v = clamp(v, V_MIN, V_MAX);
        limited = 1;
    }}
#if HAS_SLEW
    if (v > s->last + MAX_STEP) {{
        v = s->last + MAX_STEP;
        limited = 1;
    }} else if (v < s->last - MAX_STEP) {{
        v = s->last - MAX_STEP;
        limited = 1;
    }}
#endif
    for (i = 0; i < N; ++i) {{
        s->z[i] = clamp(s->z[i], v - R[i], v + R[i]);
    }}
    if (limited) {{
        inverse_states(s);
    }}
    s->last = v;
    return v;
}}
#endif
"""
    # with a mode, the step proper is internal and the public step inverts the mode first
    inner = "static {real} hysteresis_step" if comp.mode.active else f"{real} {prefix}_step"
    inner = inner.format(real=real)
    if controller is None and comp.dynamic:
        source += _dynamic_source(comp, prefix, precision, inner)
    elif controller is None:
        source += f"""
{inner}({prefix}_t *s, {real} desired)
{{
    if (non_finite(desired)) {{
        s->nonfinite++;
        return s->last;
    }}
    return core_step(s, REFERENCE + desired * SCALE);
}}
"""
    else:
        source += _controller_source(controller, prefix, precision)
    if comp.mode.active:
        source += _mode_source(comp, prefix, precision)
    return CCode(header=header, source=source, header_name=f"{prefix}.h")


def _mode_source(comp: Compensator, prefix: str, p: Precision) -> str:
    """The mode's inverse (``OutputDynamics.invert`` for one sample) before the step."""
    real = f"{prefix}_real"
    mode = comp.mode
    w = 2.0 * math.pi * mode.f0
    return f"""
/* the mode: y + 2 zeta/w y' + y''/w^2 from differences, half a sample before the end */
static const {real} MODE_DT = {_literal(mode.sample_interval, p)};
static const {real} MODE_K1 = {_literal(2.0 * mode.zeta / w, p)}; /* 2 zeta / w */
static const {real} MODE_W2 = {_literal(w * w, p)};

{real} {prefix}_step({prefix}_t *s, {real} desired, {real} next)
{{
    {real} b0 = non_finite(s->e2) ? desired : s->e2;
    {real} b1 = non_finite(s->e1) ? desired : s->e1;
    {real} nxt = non_finite(next) ? 2.0 * desired - b1 : next;
    {real} mid = 0.5 * (desired + b1);
    {real} d1 = (desired - b1) / MODE_DT;
    {real} d2 = ((nxt - desired) - (b1 - b0)) / (2.0 * MODE_DT * MODE_DT);
    s->e2 = s->e1;
    s->e1 = desired;
    return hysteresis_step(s, mid + MODE_K1 * d1 + d2 / MODE_W2);
}}
"""


_FEEDBACK_FIELDS = """    /* feedback on the measured charge (see piezohyst.selfsensing) */
    {real} integral;         /* integral action, model output units */
    {real} leak;             /* leaked charge since the frame was set */
    {real} frame;            /* measured charge -> model output */
    {real} d_prev;           /* the previous desired output, model units */
    {real} q_last;           /* the last finite measured charge */
    {real} error;            /* the last charge error */
    {real} bias;             /* bias current in use (refreshed from holds if enabled) */
    {real} hold_ref, hold_n, sx, sy, sxx, sxy, sm, y0; /* leakage refresh on holds */
    int started, has_prev, has_hold;
    unsigned long faults;    /* non-finite measurements (feedforward used) */
    unsigned long refreshes; /* bias refreshes made */
"""


def _feedback_init(ctl: SelfSensingController, p: Precision) -> str:
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
        lines.append(f"    s->{name} = {_literal(fb[idx], p)};")
    for name, idx in (("d_prev", K.CS_D_PREV), ("hold_ref", K.CS_HOLD_REF)):
        value = float(fb[idx])
        lines.append(f"    s->{name} = {_literal(value if np.isfinite(value) else 0.0, p)};")
    lines.append(f"    s->has_prev = {int(np.isfinite(fb[K.CS_D_PREV]))};")
    lines.append(f"    s->has_hold = {int(np.isfinite(fb[K.CS_HOLD_REF]))};")
    lines.append(f"    s->started = {int(fb[K.CS_STARTED] > 0)};")
    lines.append(f"    s->faults = {int(fb[K.CS_FAULTS])}UL;")
    lines.append(f"    s->refreshes = {int(fb[K.CS_REFRESHES])}UL;")
    return "\n".join(lines) + "\n"


def _dynamic_source(comp: Compensator, prefix: str, p: Precision, signature: str) -> str:
    """The compensator step with the input lags inverted: the kernel's ``dynamic_step`` in C."""
    real = f"{prefix}_real"
    gain_a = float(comp.dyn[K.DYN_GAIN_A])
    gain_b = float(comp.dyn[K.DYN_GAIN_B])
    return f"""
static const {real} GAIN_A = {_literal(gain_a, p)}; /* the fractional delay, as a lag */
static const {real} GAIN_B = {_literal(gain_b, p)}; /* the amplifier's lag */

static {real} advance({prefix}_t *s, {real} x)
{{
    s->w = GAIN_A > 0 ? s->w + GAIN_A * (x - s->w) : x;
    s->u = GAIN_B > 0 ? s->u + GAIN_B * (s->w - s->u) : s->w;
    return s->u;
}}

static {real} abs_real({real} x)
{{
    return x < 0 ? -x : x;
}}

{signature}({prefix}_t *s, {real} desired)
{{
    {real} q, target, w_target, x, u;
    int i;
    if (non_finite(desired)) {{ /* hold: the piezo keeps settling on the last command */
        s->nonfinite++;
        u = advance(s, s->last);
        for (i = 0; i < N; ++i) {{
            s->z[i] = clamp(s->z[i], u - R[i], u + R[i]);
        }}
        inverse_states(s);
        return s->last;
    }}
    q = clamp(REFERENCE + desired * SCALE, OFFSET - BOUND, OFFSET + BOUND);
    target = INV_OFFSET;
    for (i = 0; i < N; ++i) {{
        s->zeta[i] = clamp(s->zeta[i], q - RI[i], q + RI[i]);
        target += WI[i] * s->zeta[i];
    }}
    w_target = GAIN_B > 0 ? s->u + (target - s->u) / GAIN_B : target;
    x = GAIN_A > 0 ? s->w + (w_target - s->w) / GAIN_A : w_target;
    if (non_finite(x)) {{
        s->nonfinite++;
        inverse_states(s);
        return s->last;
    }}
    if (x < V_MIN || x > V_MAX) {{
        if (x < V_MIN - SAT_TOL || x > V_MAX + SAT_TOL) {{
            s->saturated++;
        }}
        x = clamp(x, V_MIN, V_MAX);
    }}
#if HAS_SLEW
    if (x > s->last + MAX_STEP) {{
        x = s->last + MAX_STEP;
    }} else if (x < s->last - MAX_STEP) {{
        x = s->last - MAX_STEP;
    }}
#endif
    u = advance(s, x);
    for (i = 0; i < N; ++i) {{
        s->z[i] = clamp(s->z[i], u - R[i], u + R[i]);
    }}
    if (abs_real(u - target) > 1e-12 * (V_MAX - V_MIN)) {{
        inverse_states(s);
    }}
    s->last = x;
    return x;
}}
"""


def _controller_source(ctl: SelfSensingController, prefix: str, p: Precision) -> str:
    """The controller step in C: the same arithmetic, in the same order, as the kernel."""
    c = ctl.ctl
    real = f"{prefix}_real"

    def lit(idx: int) -> str:
        return _literal(float(c[idx]), p)

    return f"""
static const {real} KP = {lit(K.CTL_KP)};
static const {real} KI = {lit(K.CTL_KI)};
static const {real} G0 = {lit(K.CTL_G0)};
static const {real} G1 = {lit(K.CTL_G1)};
static const {real} INV_SCALE = {lit(K.CTL_INV_SCALE)};
static const {real} DT = {lit(K.CTL_DT)};
static const {real} TOL = {lit(K.CTL_TOL)};
static const {real} HOLD_TOL = {lit(K.CTL_HOLD_TOL)};
static const {real} HOLD_SAMPLES = {lit(K.CTL_HOLD_SAMPLES)};
static const {real} REFRESH = {lit(K.CTL_REFRESH)};
static const {real} DISCHARGE = {lit(K.CTL_DISCHARGE)};

static {real} abs_real({real} x)
{{
    return x < 0 ? -x : x;
}}

static void hold_reset({prefix}_t *s)
{{
    s->hold_n = 0;
    s->sx = 0;
    s->sy = 0;
    s->sxx = 0;
    s->sxy = 0;
    s->sm = 0;
}}

static {real} model_output(const {prefix}_t *s)
{{
    {real} y = OFFSET;
    int i;
    for (i = 0; i < N; ++i) {{
        y += W[i] * s->z[i];
    }}
    return y;
}}

{real} {prefix}_step({prefix}_t *s, {real} desired, {real} measured)
{{
    {real} e = 0, current, qc, d, integral, u, v, y, k, yi, m, den, slope;
    int delivered;
    int measured_ok = !non_finite(measured);
    if (measured_ok) {{
        s->q_last = measured;
    }}
    if (s->started) {{ /* leakage over the sample the last command was held */
        current = G0 * s->last + G1 * s->last * abs_real(s->last) * INV_SCALE;
        current += s->bias - DISCHARGE * s->q_last;
        s->leak += current * DT;
    }}
    if (measured_ok) {{
        qc = measured - s->leak;
        if (!s->started) {{
            s->frame = model_output(s) - qc;
            s->started = 1;
        }}
        qc += s->frame;
        if (s->has_prev) {{
            e = s->d_prev - qc;
        }}
    }} else {{
        s->faults++;
    }}
    s->error = e;
    if (non_finite(desired)) {{ /* hold the last safe command */
        s->nonfinite++;
        s->has_prev = 0;
        hold_reset(s);
        return s->last;
    }}
    d = REFERENCE + desired * SCALE;
    integral = s->integral + KI * e;
    u = d + KP * e + integral;
    if (non_finite(u)) {{
        s->nonfinite++;
        v = s->last;
    }} else {{
        v = core_step(s, u);
    }}
    y = model_output(s);
    delivered = !non_finite(u) && abs_real(y - u) <= TOL;
    if (delivered) {{
        s->integral = integral;
    }}
    s->d_prev = d;
    s->has_prev = 1;
    if (REFRESH > 0) {{ /* the integral's drift on a hold is the leakage error */
        if (delivered && s->has_hold && abs_real(d - s->hold_ref) <= HOLD_TOL) {{
            s->hold_n += 1;
            k = s->hold_n;
            if (k > 0.25 * HOLD_SAMPLES) {{
                if (s->sm == 0) {{
                    s->y0 = s->integral;
                }}
                yi = s->integral - s->y0;
                s->sm += 1;
                s->sx += k;
                s->sy += yi;
                s->sxx += k * k;
                s->sxy += k * yi;
            }}
            if (k >= HOLD_SAMPLES) {{
                m = s->sm;
                den = m * s->sxx - s->sx * s->sx;
                if (m > 2 && den > 0) {{
                    slope = (m * s->sxy - s->sx * s->sy) / den;
                    s->bias -= REFRESH * slope / DT;
                    s->refreshes++;
                }}
                hold_reset(s);
            }}
        }} else {{
            s->hold_ref = d;
            s->has_hold = 1;
            hold_reset(s);
        }}
    }}
    return v;
}}
"""


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
