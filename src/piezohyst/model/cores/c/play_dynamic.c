/* The play compensator step with the input lags inverted: _kernels.dynamic_step in C.
 * Under a controller it is the loop's inverse, core_step (play_controller.c follows): its
 * target in model output units already. */

/* x after a fraction of a sample's delay, interpolated from the last command */
static real_t advance(PREFIX_t *s, real_t x)
{
    s->w = FRACTION != 0 ? (1 - FRACTION) * x + FRACTION * s->last : x;
    s->u = GAIN_B > 0 ? s->u + GAIN_B * (s->w - s->u) : s->w;
    return s->u;
}

static real_t abs_real(real_t x)
{
    return x < 0 ? -x : x;
}

#if CONTROLLER
#define DYNAMIC_TARGET(s, d) (d)
static real_t core_step(PREFIX_t *s, real_t desired)
#else
#define DYNAMIC_TARGET(s, d) TARGET(s, d)
STEP_SIGNATURE(PREFIX_t *s, real_t desired)
#endif
{
    real_t q, target, w_target, x, u;
    int i, over = 0;
    if (non_finite(desired)) { /* hold: the piezo keeps settling on the last command */
        s->nonfinite++;
        u = advance(s, s->last);
        for (i = 0; i < N; ++i) {
            s->z[i] = clamp(s->z[i], u - R[i], u + R[i]);
        }
        inverse_states(s);
        return s->last;
    }
    q = clamp(DYNAMIC_TARGET(s, desired), OFFSET - BOUND, OFFSET + BOUND);
    target = INV_OFFSET;
    for (i = 0; i < N; ++i) {
        s->zeta[i] = clamp(s->zeta[i], q - RI[i], q + RI[i]);
        target += WI[i] * s->zeta[i];
    }
    w_target = GAIN_B > 0 ? s->u + (target - s->u) / GAIN_B : target;
    x = FRACTION > 0   ? (1 + FRACTION) * w_target - FRACTION * s->w
        : FRACTION < 0 ? (w_target - FRACTION * s->last) / (1 - FRACTION)
                       : w_target;
    if (non_finite(x)) {
        s->nonfinite++;
        inverse_states(s);
        return s->last;
    }
    if (x < V_MIN || x > V_MAX) {
        over = x < V_MIN - SAT_TOL || x > V_MAX + SAT_TOL;
        x = clamp(x, V_MIN, V_MAX);
    }
#if HAS_SLEW
    if (x > s->last + MAX_STEP) {
        x = s->last + MAX_STEP;
        s->slewed++;
    } else if (x < s->last - MAX_STEP) {
        x = s->last - MAX_STEP;
        s->slewed++;
    } else
#endif
    if (over) { /* sent at the voltage limit (see play.c) */
        s->saturated++;
    }
    u = advance(s, x);
    for (i = 0; i < N; ++i) {
        s->z[i] = clamp(s->z[i], u - R[i], u + R[i]);
    }
    if (abs_real(u - target) > 1e-12 * (V_MAX - V_MIN)) {
        inverse_states(s);
    }
    s->last = x;
    return x;
}
