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
from typing import TYPE_CHECKING, Literal

import numpy as np

from ._lazy import LazyModule
from .compensator import Compensator
from .errors import ParameterError
from .io import atomic_write_text
from .selfsensing import SelfSensingController

if TYPE_CHECKING:
    from . import _diffkernels as D
    from . import _kernels as K
else:  # numba loads when a model first runs (see _lazy)
    D = LazyModule("piezohyst._diffkernels", globals(), "D")
    K = LazyModule("piezohyst._kernels", globals(), "K")

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
    if precision not in ("double", "float"):
        msg = f"precision must be 'double' or 'float'. Got {precision!r}."
        raise ParameterError(msg)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        msg = f"prefix must be a C identifier. Got {prefix!r}."
        raise ParameterError(msg)
    engine = comp.inverse.name
    if engine == "packed":  # Preisach, Duhem, Bouc-Wen: the bracketed Newton step in C
        return _core_c(comp, prefix, precision)
    if engine != "play":
        msg = (
            f"C export covers play operators and the Preisach, Duhem and Bouc-Wen cores; a "
            f"{type(comp.spec.operator).__name__} core runs in Python (ph.Compensator) only."
        )
        raise ParameterError(msg)
    if not comp.analytic:
        msg = (
            "C export covers the analytic inverse (play operators and growth terms) and the "
            "Duhem and Bouc-Wen cores; a model with asymmetry or creep terms runs in Python "
            "(ph.Compensator) only."
        )
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

{_ieee_helpers(real, precision)}
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


def _ieee_helpers(real: str, precision: Precision) -> str:
    """``non_finite`` (NaN or +-inf from the IEEE-754 exponent bits: unlike isfinite(), a
    check -ffast-math cannot optimise away) and, with a mode, ``not_a_number``."""
    bits, mantissa, mask, nan = (
        ("uint64_t", 52, "0x7FF", "0x7FF8000000000000ULL")
        if precision == "double"
        else ("uint32_t", 23, "0xFF", "0x7FC00000UL")
    )
    return f"""/* NaN or +-inf, decided from the IEEE-754 exponent bits: unlike isfinite(), a check
 * that -ffast-math (which assumes finite arithmetic) cannot optimise away. */
static int non_finite({real} x)
{{
    union {{ {real} value; {bits} bits; }} u;
    u.value = x;
    return (int)((u.bits >> {mantissa}) & {mask}) == {mask};
}}

#if MODE
static {real} not_a_number(void)
{{
    union {{ {real} value; {bits} bits; }} u;
    u.bits = {nan};
    return u.value;
}}
#endif
"""


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


def _core_c(comp: Compensator, prefix: str, precision: Precision) -> CCode:
    """C99 for a compensator on a differential core: ``_diffkernels.core_step`` in C.

    The same arithmetic as the kernel: the step's output is monotone in the
    voltage, so the inverse is Newton's method inside a bracket (bisecting
    whenever a step would leave it), at most ``NEWTON_MAX`` iterations — a
    bounded time per sample.
    """
    p = precision
    real = f"{prefix}_real"
    guard = f"{prefix.upper()}_H"
    params = comp.params
    cfg = comp.config
    kind = int(params[0])
    ns = comp.n_operators
    spec = comp.spec
    state = comp.state
    desired_unit = "m" if comp.domain == "displacement" else spec.output_unit
    names = {int(D.KIND_DUHEM): "Duhem", int(D.KIND_PREISACH): "Preisach",
             int(D.KIND_BOUC_WEN): "Bouc-Wen"}  # fmt: skip
    fields = ""
    if comp.dynamic:
        fields += f"    {real} w, u;               /* input dynamics: after the fractional delay, after the lag (V) */\n"  # noqa: E501
    if comp.mode.active:
        fields += f"    {real} e1, e2;             /* output mode: the last two desired values (NaN: none) */\n"  # noqa: E501
    n_lags = int(comp.lags.shape[1])
    has_slow = int(comp.slow.size > 0)
    ns_main = int(comp.config[D.CC_NS])
    if n_lags:
        fields += f"    {real} c[{n_lags}];              /* creep lag states (V) */\n"
    delay_note = (
        f" With the model's input delay of {comp.delay_samples} samples, pass the value\n"
        f" * desired {comp.delay_samples} samples from now (the command acts then).\n *"
        if comp.delay_samples
        else ""
    )
    step_args = f"{real} desired, {real} next" if comp.mode.active else f"{real} desired"
    libm = " Needs pow() from <math.h> (link with -lm)." if kind == int(D.KIND_BOUC_WEN) else ""
    header = f"""/* {prefix}.h: feedforward hysteresis compensator generated by piezohyst.
 *
 * Model: {type(comp.model).__name__}, a {names[kind]} core; input {spec.input_unit},
 * output {spec.output_unit}. Desired values in {desired_unit}.
 * Commands always lie in [{comp.v_min!r}, {comp.v_max!r}] V. Each step inverts the core by
 * Newton's method in a bracket, at most {D.NEWTON_MAX} iterations.{libm}
 */
#ifndef {guard}
#define {guard}

typedef {precision} {real};

#define {prefix.upper()}_NS {ns}

typedef struct {{
    {real} st[{prefix.upper()}_NS];  /* the core's state: voltage, internal variable, ... */
    {real} last;             /* last command, V */
    unsigned long nonfinite; /* NaN/inf desired values (last command held) */
    unsigned long saturated; /* desired values out of reach (the nearer limit sent) */
    unsigned long outside;   /* commands that would leave the identified region */
{fields}}} {prefix}_t;

/* Start from the state the compensator had when it was exported. */
void {prefix}_init({prefix}_t *s);

/* One command (V) for one desired value.{delay_note} */
{real} {prefix}_step({prefix}_t *s, {step_args});

#endif /* {guard} */
"""
    step = float(cfg[D.CC_MAX_STEP])
    has_slew = int(np.isfinite(step))
    region = comp.region
    has_region = int(region.shape[1] > 0 and np.isfinite(cfg[D.CC_TOL]))
    init = ""
    if comp.dynamic:
        init += f"    s->w = {_literal(comp.dstate[0], p)};\n"
        init += f"    s->u = {_literal(comp.dstate[1], p)};\n"
    for k in range(n_lags):
        init += f"    s->c[{k}] = {_literal(float(comp.dstate[D.DYN_LAGS + k]), p)};\n"
    if comp.mode.active:
        for name, value in zip(("e2", "e1"), comp.mode_history, strict=True):
            v = _literal(float(value), p) if np.isfinite(value) else "not_a_number()"
            init += f"    s->{name} = {v};\n"
    if kind == int(D.KIND_BOUC_WEN):
        constants = "\n".join(
            f"static const {real} {n} = {_literal(float(params[i]), p)};"
            for n, i in (("C0", D.BW_C0), ("ALPHA", D.BW_ALPHA), ("BETA", D.BW_BETA),
                         ("GAMMA", D.BW_GAMMA), ("NEXP", D.BW_N), ("OFFSET", D.BW_OFFSET),
                         ("DV_MAX", D.BW_DV_MAX), ("G_MAX", D.BW_G_MAX), ("S_MIN", D.BW_S_MIN))
        )  # fmt: skip
    elif kind == int(D.KIND_PREISACH):
        constants = _preisach_constants(params, real, p)
    else:
        nv, nq = int(params[D.DU_NV]), int(params[D.DU_NQ])
        cells = nv * nq
        constants = "\n".join(
            [
                f"#define NV {nv}",
                f"#define NQ {nq}",
                *(
                    f"static const {real} {n} = {_literal(float(params[i]), p)};"
                    for n, i in (
                        ("V_LO", D.DU_V_LO),
                        ("V_STEP", D.DU_V_STEP),
                        ("Q_LO", D.DU_Q_LO),
                        ("Q_STEP", D.DU_Q_STEP),
                        ("DV_MAX", D.DU_DV_MAX),
                        ("S_MIN", D.DU_F_MIN),
                    )
                ),
                f"static const {real} UP[NV * NQ] = "
                f"{_array(params[D.DU_UP : D.DU_UP + cells], p)};",
                f"static const {real} DOWN[NV * NQ] = "
                f"{_array(params[D.DU_UP + cells : D.DU_UP + 2 * cells], p)};",
            ]
        )
    lag_c = ""
    if n_lags:  # gains and 1 - exp(-dt / tau) at the loop's sample rate
        lag_c = (
            f"static const {real} LAG_G[N_LAGS] = {_array(comp.lags[1], p)};\n"
            f"static const {real} LAG_A[N_LAGS] = {_array(comp.lags[2], p)};\n"
        )
    region_c = ""
    if has_region:
        region_c = (
            f"static const {real} REGION_LO[{region.shape[1]}] = {_array(region[0], p)};\n"
            f"static const {real} REGION_HI[{region.shape[1]}] = {_array(region[1], p)};\n"
            f"static const {real} RV_LO = {_literal(cfg[D.CC_RV_LO], p)};\n"
            f"static const {real} RV_HI = {_literal(cfg[D.CC_RV_HI], p)};\n"
            f"static const {real} TOL = {_literal(cfg[D.CC_TOL], p)};\n"
            f"#define REGION_BINS {region.shape[1]}\n"
            f"#define REFUSE {int(cfg[D.CC_REFUSE] > 0)}\n"
        )
    source = f"""/* {prefix}.c: generated by piezohyst; do not edit (re-export instead). */
#include "{prefix}.h"
#include <stdint.h>
{"#include <math.h>" if kind == int(D.KIND_BOUC_WEN) else ""}
#define NS {prefix.upper()}_NS
#define KIND {kind} /* 0 Duhem, 1 Bouc-Wen, 2 Preisach */
#define HAS_SLEW {has_slew}
#define DYNAMIC {int(comp.dynamic)}
#define MODE {int(comp.mode.active)}
#define HAS_REGION {has_region}
#define N_LAGS {n_lags} /* kept creep lags beside the core */
#define SLOW {has_slow} /* a slow (relaxing) Preisach core behind a lag */
#define NS_MAIN {ns_main} /* the core's values in st; the slow core's follow */
#define NEWTON_MAX {D.NEWTON_MAX}
#define HOLD_RES {D.HOLD_RES!r}
#define REGION_BISECTIONS {D.REGION_BISECTIONS}
#define STACK {D.STACK}

{constants}
{region_c}
static const {real} V_MIN = {_literal(cfg[D.CC_V_MIN], p)};
static const {real} V_MAX = {_literal(cfg[D.CC_V_MAX], p)};
#if HAS_SLEW
static const {real} MAX_STEP = {_literal(step if has_slew else 0.0, p)};
#endif
static const {real} SCALE = {_literal(cfg[D.CC_INV_GAIN], p)};
static const {real} REFERENCE = {_literal(cfg[D.CC_REF], p)};
static const {real} ST0[NS] = {_array(state.operators, p)};
static const {real} LAST0 = {_literal(state.command, p)};
#if DYNAMIC
static const {real} GAIN_A = {_literal(float(comp.dyn[0]), p)}; /* the fractional delay, as a lag */
static const {real} GAIN_B = {_literal(float(comp.dyn[1]), p)}; /* the amplifier's lag */
#endif
{lag_c}
{_ieee_helpers(real, precision)}
static {real} abs_real({real} x) {{ return x < 0 ? -x : x; }}
static {real} min_real({real} a, {real} b) {{ return a < b ? a : b; }}
static {real} max_real({real} a, {real} b) {{ return a > b ? a : b; }}

#if KIND != 2
/* a distance a >= 0 in steps of b > 0: the number of full steps, *rest the last one */
static int steps({real} a, {real} b, {real} *rest)
{{
    int full = (int)(a / b);
    *rest = a - full * b;
    if (*rest < 0) {{
        *rest = 0;
    }}
    return full;
}}
#endif
{_core_c_source(kind)}
{_slow_c(comp, real, p) if has_slow else ""}
{_CORE_C_COMMON}"""
    source = source.replace("real_t", real).replace("PREFIX_t", f"{prefix}_t")
    source = source.replace("PREFIX_init", f"{prefix}_init").replace("INIT_EXTRA", init)
    inner = "static real_t hysteresis_step" if comp.mode.active else "real_t PREFIX_step"
    source = source.replace("STEP_SIGNATURE", inner.replace("real_t", real).replace(
        "PREFIX", prefix))  # fmt: skip
    if comp.mode.active:
        source += _mode_source(comp, prefix, precision)
    return CCode(header=header, source=source, header_name=f"{prefix}.h")


_CORE_C_DUHEM = """
/* bilinear slope f+ (up) or f- at (v, q), clamped at the grid's edges */
static void cell(real_t u, real_t lo, real_t step, int nodes, int *i, real_t *frac)
{
    real_t a = (u - lo) / step;
    if (a < 0) {
        a = 0;
    } else if (a > nodes - 1.0) {
        a = nodes - 1.0;
    }
    *i = (int)a;
    if (*i > nodes - 2) {
        *i = nodes - 2;
    }
    *frac = a - *i;
}

static real_t slope(real_t v, real_t m, int up)
{
    const real_t *c = up ? UP : DOWN;
    int i, j;
    real_t fa, fb;
    cell(v, V_LO, V_STEP, NV, &i, &fa);
    cell(m, Q_LO, Q_STEP, NQ, &j, &fb);
    return (1 - fa) * ((1 - fb) * c[i * NQ + j] + fb * c[i * NQ + j + 1])
        + fa * ((1 - fb) * c[(i + 1) * NQ + j] + fb * c[(i + 1) * NQ + j + 1]);
}

/* Euler sub-steps of at most DV_MAX; returns the output, *f the slope at the end */
static real_t core_move(real_t *st, real_t v1, int commit, real_t *f)
{
    real_t v0 = st[0], q = st[1], dv = v1 - v0;
    int up = dv > 0, k, m;
    if (abs_real(dv) <= DV_MAX) {
        q = q + slope(v0, q, up) * dv;
    } else {
        real_t d, rest, v = v0, s = up ? 1.0 : -1.0;
        int full = steps(abs_real(dv), DV_MAX, &rest);
        m = full + (rest > 0 ? 1 : 0);
        for (k = 0; k < m; ++k) {
            d = s * (k < full ? DV_MAX : rest);
            q += slope(v, q, up) * d;
            v += d;
        }
    }
    *f = slope(v1, q, v1 >= v0);
    if (commit) {
        st[0] = v1;
        st[1] = q;
    }
    return q;
}

static real_t core_output(const real_t *st) { return st[1]; }

/* the slope of the step's first instant from st in direction up */
static real_t first_slope(const real_t *st, int up, real_t dy)
{
    (void)dy;
    return slope(st[0], st[1], up);
}
"""

_CORE_C_PREISACH = """
/* the cell of u on the grid, clamped; *frac its fraction, *inside whether u lies on it */
static void cell(real_t u, int *i, real_t *frac, int *inside)
{
    real_t a = (u - V_LO) / H;
    *inside = 1;
    if (a < 0) {
        a = 0;
        *inside = 0;
    } else if (a > NN - 1.0) {
        a = NN - 1.0;
        *inside = 0;
    }
    *i = (int)a;
    if (*i > NN - 2) {
        *i = NN - 2;
    }
    *frac = a - *i;
}

/* the Everett function at nodes, antisymmetric below the diagonal */
static real_t node(int i, int j) { return i <= j ? EV[i * NN + j] : -EV[j * NN + i]; }

/* E(a, b), bilinear, continued with the smallest slope beyond the grid; *da, *db its
 * derivatives */
static real_t everett(real_t a, real_t b, real_t *da, real_t *db)
{
    real_t hi = V_LO + H * (NN - 1.0), extra = 0, fa, fb, e00, e01, e10, e11;
    real_t da_out = 0, db_out = 0;
    int i, j, in_a, in_b;
    if (b > hi) {
        extra += S_MIN * (b - hi);
        db_out = S_MIN;
    }
    if (a < V_LO) {
        extra += S_MIN * (V_LO - a);
        da_out = -S_MIN;
    }
    cell(a, &i, &fa, &in_a);
    cell(b, &j, &fb, &in_b);
    e00 = node(i, j);
    e01 = node(i, j + 1);
    e10 = node(i + 1, j);
    e11 = node(i + 1, j + 1);
    *da = in_a ? ((1 - fb) * (e10 - e00) + fb * (e11 - e01)) / H : da_out;
    *db = in_b ? ((1 - fa) * (e01 - e00) + fa * (e11 - e10)) / H : db_out;
    return (1 - fa) * ((1 - fb) * e00 + fb * e01) + fa * ((1 - fb) * e10 + fb * e11) + extra;
}

/* the output change along a branch from u0 to u1 with reversal point top */
static real_t branch(real_t u0, real_t u1, real_t top, int up)
{
    real_t da, db;
    if (up) {
        return everett(top, u1, &da, &db) - everett(top, u0, &da, &db);
    }
    return everett(u0, top, &da, &db) - everett(u1, top, &da, &db);
}

static real_t branch_slope(real_t v, real_t top, int up)
{
    real_t da, db;
    if (up) {
        everett(top, v, &da, &db);
        return db;
    }
    everett(v, top, &da, &db);
    return -da;
}
/* st = [v, q, direction, k, R[0..STACK-1]]: reversal points with Preisach's wiping-out */
static real_t core_move(real_t *st, real_t v1, int commit, real_t *f)
{
    real_t v0 = st[0], q = st[1], dv = v1 - v0, top, u, sd;
    int k = (int)st[3], kk, push, up;
    top = st[4 + k - 1];
    if (dv == 0) {
        *f = branch_slope(v0, top, st[2] >= 0);
        return q;
    }
    sd = dv > 0 ? 1.0 : -1.0;
    up = sd > 0;
    push = st[2] != 0 && sd != st[2];
    kk = push ? k + 1 : k;
    if (push) {
        top = v0;
    }
    u = v0;
    for (;;) {
        real_t end = v1, prev;
        int popped = 0;
        if (kk >= 3) {
            prev = (push && kk - 2 == k) ? v0 : st[4 + kk - 2];
            if ((up && prev <= v1 && prev >= u) || (!up && prev >= v1 && prev <= u)) {
                end = prev;
                popped = 1;
            }
        }
        q += branch(u, end, top, up);
        if (!popped) {
            break;
        }
        kk -= 2;
        top = (push && kk - 1 == k) ? v0 : st[4 + kk - 1];
        u = end;
    }
    *f = branch_slope(v1, top, up);
    if (commit) {
        if (push && kk == k + 1) {
            if (k >= STACK) { /* full: forget the innermost pair, the smallest loop */
                kk -= 2;
                k -= 2;
            }
            st[4 + k] = v0;
        }
        st[3] = kk;
        st[2] = sd;
        st[0] = v1;
        st[1] = q;
    }
    return q;
}

static real_t core_output(const real_t *st) { return st[1]; }

/* the slope of the step's first instant from st in direction up */
static real_t first_slope(const real_t *st, int up, real_t dy)
{
    int reverse = st[2] != 0 && (up ? 1.0 : -1.0) != st[2];
    real_t top = reverse ? st[0] : st[4 + (int)st[3] - 1];
    (void)dy;
    return branch_slope(st[0], top, up);
}
"""

_CORE_C_BW = """
static real_t g(real_t h, real_t s)
{
    real_t ah = abs_real(h), hn, sh, r;
    hn = NEXP == 1.0 ? ah : (NEXP == 2.0 ? ah * ah : (real_t)pow(ah, NEXP));
    sh = h >= 0 ? 1.0 : -1.0;
    r = 1.0 - hn * (BETA * sh * s + GAMMA);
    return min_real(max_real(r, 0.0), G_MAX);
}

/* RK4 sub-steps of at most DV_MAX; returns the output, *f the slope at the end */
static real_t core_move(real_t *st, real_t v1, int commit, real_t *f)
{
    real_t v0 = st[0], h = st[1], dv = v1 - v0, s = v1 >= v0 ? 1.0 : -1.0;
    if (dv != 0) {
        real_t rest, d;
        int full = steps(abs_real(dv), DV_MAX, &rest), k;
        int m = full + (rest > 0 ? 1 : 0);
        for (k = 0; k < m; ++k) {
            real_t k1;
            d = s * (k < full ? DV_MAX : rest);
            k1 = g(h, s);
            real_t k2 = g(h + 0.5 * d * k1, s);
            real_t k3 = g(h + 0.5 * d * k2, s);
            real_t k4 = g(h + d * k3, s);
            h += d * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0;
        }
    }
    *f = C0 + ALPHA * g(h, s);
    if (commit) {
        st[0] = v1;
        st[1] = h;
    }
    return C0 * v1 + ALPHA * h + OFFSET;
}

static real_t core_output(const real_t *st) { return C0 * st[0] + ALPHA * st[1] + OFFSET; }

/* Heun's guess for a step of output change dy: the slope averaged with the one an Euler
 * step would end on */
static real_t first_slope(const real_t *st, int up, real_t dy)
{
    real_t s = up ? 1.0 : -1.0, g0 = g(st[1], s);
    real_t g1 = g(st[1] + g0 * dy / (C0 + ALPHA * g0), s);
    return C0 + ALPHA * 0.5 * (g0 + g1);
}
"""

_CORE_C_COMMON = """
/* trial = the state after moving from st to v; returns the output there, *f the slope */
static real_t try_move(const real_t *st, real_t *trial, real_t v, real_t *f)
{
    int i;
    real_t y;
    for (i = 0; i < NS; ++i) {
        trial[i] = st[i];
    }
    y = core_move(trial, v, 1, f);
#if SLOW /* the slow core's input moves along its lag: its output adds a slope >= 0 */
    {
        real_t fs, c = st[NS_MAIN];
        y += slow_move(trial + NS_MAIN, c + SLOW_A * (v - c), 1, &fs);
        *f += SLOW_A * fs;
    }
#endif
    return y;
}

#if DYNAMIC || SLOW
/* the state moves to the piezo voltage v (core and slow core) */
static void move_to(real_t *st, real_t v)
{
    real_t trial[NS], f;
    int i;
    try_move(st, trial, v, &f);
    for (i = 0; i < NS; ++i) {
        st[i] = trial[i];
    }
}
#endif

/* the input in [lo, hi] whose step from st gives y, or the nearer end (*clamped);
 * trial holds the state after the step to it */
static real_t core_inverse(real_t *st, real_t y, real_t lo, real_t hi, int *clamped,
                           real_t *trial, real_t lin)
{
    /* the output solved for is the core's plus lin * v (the creep lags' part; 0: none) */
    real_t v0 = st[0], dy, v, far, a, b, eps, tol, f1, y1;
    real_t res, vn;
    int it, at_hi, at_lo;
#if SLOW /* the slow core moves along its lag even if the voltage stays */
    dy = y - try_move(st, trial, v0, &f1) - lin * v0;
#else
    dy = y - core_output(st) - lin * v0;
#endif
    *clamped = 0;
    v = dy == 0 ? v0 : v0 + dy / (first_slope(st, dy > 0, dy) + lin);
    if (abs_real(v - v0) <= HOLD_RES * (2 * abs_real(v0) + 1.0)) {
        /* below the solve's resolution (a held target's rounding): hold, or the command
         * dithers and a Preisach stack fills with reversals a few ulp wide */
        *clamped = v0 < lo || v0 > hi;
        v = min_real(max_real(v0, lo), hi);
        try_move(st, trial, v, &f1);
        return v;
    }
#if KIND == 0 && !SLOW
    if (abs_real(v - v0) <= DV_MAX && lo <= v && v <= hi) {
        try_move(st, trial, v, &f1);
        return v; /* one Euler step: the explicit inverse is exact */
    }
#endif
    far = v0 + 1.000001 * dy / (S_MIN + lin); /* as flat as S_MIN: the root at its end */
    a = max_real(min_real(v0, far), lo);
    b = min_real(max_real(v0, far), hi);
    if (a >= b) { /* at or beyond a limit and asked to go further out */
        v = dy > 0 ? b : a;
        *clamped = 1;
        try_move(st, trial, v, &f1);
        return v;
    }
    at_hi = max_real(v0, far) > hi; /* try a limit only if Newton heads there */
    at_lo = min_real(v0, far) < lo;
    if (!(a < v && v < b)) {
        if (v >= b) {
            v = at_hi ? b : 0.5 * (a + b);
        } else {
            v = at_lo ? a : 0.5 * (a + b);
        }
    }
    tol = 1e-12 * abs_real(dy) + 4e-16 * abs_real(y);
    eps = HOLD_RES * (abs_real(a) + abs_real(b) + 1.0);
    for (it = 0; it < NEWTON_MAX; ++it) {
        y1 = try_move(st, trial, v, &f1);
        res = y1 + lin * v - y;
        f1 += lin;
        if (abs_real(res) <= tol) {
            return v;
        }
        if (res < 0) {
            if (v >= b) { /* at the upper limit and still short: out of reach */
                *clamped = 1;
                return v;
            }
            a = v;
        } else {
            if (v <= a) { /* at the lower limit and still above */
                *clamped = 1;
                return v;
            }
            b = v;
        }
        vn = f1 > 0 ? v - res / f1 : 0.5 * (a + b);
        if (!(a < vn && vn < b)) {
            if (vn >= b && at_hi && b >= hi) {
                vn = b;
            } else if (vn <= a && at_lo && a <= lo) {
                vn = a;
            } else {
                vn = 0.5 * (a + b);
            }
        }
        if (abs_real(vn - v) <= eps || b - a <= eps) {
            return v;
        }
        v = vn;
    }
    try_move(st, trial, v, &f1); /* the iterations ran out: the state at the v returned */
    return v;
}

#if HAS_REGION
static real_t region_distance(real_t v, real_t y)
{
    int b = (int)((v - RV_LO) / (RV_HI - RV_LO) * REGION_BINS);
    b = b < 0 ? 0 : (b > REGION_BINS - 1 ? REGION_BINS - 1 : b);
    return max_real(max_real(REGION_LO[b] - y, y - REGION_HI[b]), 0.0);
}
#endif

#if N_LAGS
/* the creep lags' output at this sample is *lin * u + (returned): affine in the voltage u */
static real_t lags_affine(const PREFIX_t *s, real_t *lin)
{
    real_t base = 0;
    int k;
    *lin = 0;
    for (k = 0; k < N_LAGS; ++k) {
        *lin += LAG_G[k] * LAG_A[k];
        base += LAG_G[k] * (1 - LAG_A[k]) * s->c[k];
    }
    return base;
}
#endif

/* every creep lag after the piezo voltage u is held one sample */
static void lags_advance(PREFIX_t *s, real_t u)
{
#if N_LAGS
    int k;
    for (k = 0; k < N_LAGS; ++k) {
        s->c[k] += LAG_A[k] * (u - s->c[k]);
    }
#else
    (void)s;
    (void)u;
#endif
}

#if DYNAMIC
static real_t advance(PREFIX_t *s, real_t x)
{
    s->w = GAIN_A > 0 ? s->w + GAIN_A * (x - s->w) : x;
    s->u = GAIN_B > 0 ? s->u + GAIN_B * (s->w - s->u) : s->w;
    return s->u;
}
#endif

void PREFIX_init(PREFIX_t *s)
{
    int i;
    for (i = 0; i < NS; ++i) {
        s->st[i] = ST0[i];
    }
    s->last = LAST0;
    s->nonfinite = 0;
    s->saturated = 0;
    s->outside = 0;
INIT_EXTRA}

STEP_SIGNATURE(PREFIX_t *s, real_t desired)
{
    real_t y, a = V_MIN, b = V_MAX, u, x, f, trial[NS], lin = 0;
    int clamped, i;
#if DYNAMIC
    real_t saved_w = s->w, saved_u = s->u;
#endif
    if (non_finite(desired)) { /* hold the last command */
        s->nonfinite++;
#if DYNAMIC
        move_to(s->st, advance(s, s->last));
#elif SLOW
        move_to(s->st, s->st[0]);
#endif
        lags_advance(s, s->st[0]);
        return s->last;
    }
    y = REFERENCE + desired * SCALE;
#if N_LAGS
    y -= lags_affine(s, &lin);
#endif
#if HAS_SLEW && !DYNAMIC
    a = max_real(V_MIN, s->last - MAX_STEP);
    b = min_real(V_MAX, s->last + MAX_STEP);
#endif
    u = core_inverse(s->st, y, a, b, &clamped, trial, lin);
    if (clamped && (u <= V_MIN || u >= V_MAX)) {
        s->saturated++;
    }
    x = u;
#if DYNAMIC
    {
        real_t w = GAIN_B > 0 ? s->u + (u - s->u) / GAIN_B : u;
        x = GAIN_A > 0 ? s->w + (w - s->w) / GAIN_A : w;
        if (non_finite(x)) {
            x = s->last;
        }
        x = min_real(max_real(x, V_MIN), V_MAX);
#if HAS_SLEW
        x = min_real(max_real(x, s->last - MAX_STEP), s->last + MAX_STEP);
#endif
        u = advance(s, x);
        if (trial[0] != u) {
            try_move(s->st, trial, u, &f);
        }
    }
#endif
#if HAS_REGION /* leaving the region (moves back towards it always pass) */
    y = region_distance(u, core_output(trial));
    f = region_distance(s->st[0], core_output(s->st));
    if (y > TOL && y > f) {
        s->outside++;
#if REFUSE
#if DYNAMIC /* hold the last command instead */
        s->w = saved_w;
        s->u = saved_u;
        move_to(s->st, advance(s, s->last));
        lags_advance(s, s->st[0]);
        return s->last;
#else /* stop at the region's edge: the largest move towards u that stays inside */
        {
            real_t edge = max_real(TOL, f), lo_v = s->st[0], hi_v = u, mid;
            for (i = 0; i < REGION_BISECTIONS; ++i) {
                mid = 0.5 * (lo_v + hi_v);
                try_move(s->st, trial, mid, &y);
                if (region_distance(mid, core_output(trial)) <= edge) {
                    lo_v = mid;
                } else {
                    hi_v = mid;
                }
            }
            u = lo_v;
            x = lo_v;
            try_move(s->st, trial, u, &f);
        }
#endif
#endif
    }
#endif
#if DYNAMIC
    (void)saved_w; /* used only when refusing to leave the region */
    (void)saved_u;
#endif
    (void)f;
    for (i = 0; i < NS; ++i) {
        s->st[i] = trial[i];
    }
    lags_advance(s, s->st[0]);
    s->last = x;
    return x;
}
"""


def _slow_c(comp: Compensator, real: str, precision: Precision) -> str:
    """The slow core: the Preisach functions again, on their own grid and Everett values."""
    code = _CORE_C_PREISACH[: _CORE_C_PREISACH.index("static real_t core_output")]
    names = ("cell", "node", "everett", "branch", "branch_slope", "NN", "EV", "V_LO", "H",
             "S_MIN")  # fmt: skip
    for name in names:
        code = re.sub(rf"\b{name}\b", f"SLOW_{name}" if name.isupper() else f"slow_{name}", code)
    code = code.replace("core_move", "slow_move")
    a = _literal(float(comp.config[D.CC_SLOW_A]), precision)
    constants = _preisach_constants(comp.slow, real, precision, "SLOW_")  # flat beyond its grid
    return (
        f"/* the slow (relaxing) Preisach core */\n{constants}\n"
        f"static const {real} SLOW_A = {a}; /* 1 - exp(-dt / tau) */\n{code}"
    )


def _preisach_constants(
    packed: np.ndarray, real: str, precision: Precision, prefix: str = ""
) -> str:
    """A Preisach core's grid and Everett table as C constants (names after ``prefix``)."""
    n = int(packed[D.DU_NV])
    lit = [_literal(float(packed[k]), precision) for k in (D.DU_V_LO, D.DU_V_STEP, D.DU_F_MIN)]
    return "\n".join(
        [
            f"#define {prefix}NN {n}",
            f"static const {real} {prefix}V_LO = {lit[0]};",
            f"static const {real} {prefix}H = {lit[1]};",
            f"static const {real} {prefix}S_MIN = {lit[2]};",
            f"static const {real} {prefix}EV[{prefix}NN * {prefix}NN] = "
            f"{_array(packed[D.DU_UP : D.DU_UP + n * n], precision)};",
        ]
    )


def _core_c_source(kind: int) -> str:
    """The C functions of a core kind (looked up when used: the kernels load lazily)."""
    return {
        int(D.KIND_DUHEM): _CORE_C_DUHEM,
        int(D.KIND_BOUC_WEN): _CORE_C_BW,
        int(D.KIND_PREISACH): _CORE_C_PREISACH,
    }[kind]
