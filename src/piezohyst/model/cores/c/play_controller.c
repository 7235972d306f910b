/* The self-sensing controller step: the same arithmetic, in the same order, as
 * _kernels.controller_step (with input dynamics, _kernels.dynamic_controller_step: the
 * inverse is play_dynamic.c's, and the leakage flows at the piezo's voltage, the lag's). */

#if DYNAMIC
#define PIEZO_VOLTAGE(s) ((s)->u)
#else
#define PIEZO_VOLTAGE(s) ((s)->last)
static real_t abs_real(real_t x)
{
    return x < 0 ? -x : x;
}
#endif

static void hold_reset(PREFIX_t *s)
{
    s->hold_n = 0;
    s->sx = 0;
    s->sy = 0;
    s->sxx = 0;
    s->sxy = 0;
    s->sm = 0;
}

static real_t model_output(const PREFIX_t *s)
{
    real_t y = OFFSET;
    int i;
    for (i = 0; i < N; ++i) {
        y += W[i] * s->z[i];
    }
    return y;
}

#if MODE /* the public step inverts the output map's mode first (mode.c) */
static real_t controller_step(PREFIX_t *s, real_t desired, real_t measured)
#else
real_t PREFIX_step(PREFIX_t *s, real_t desired, real_t measured)
#endif
{
    real_t e = 0, current, qc, d, integral, u, v, y, k, yi, m, den, slope;
    int delivered;
    int measured_ok = !non_finite(measured);
    if (measured_ok) {
        s->q_last = measured;
    }
    if (s->started) { /* leakage over the sample the last command was held */
        v = PIEZO_VOLTAGE(s);
        current = G0 * v + G1 * v * abs_real(v) * INV_SCALE;
        current += s->bias - DISCHARGE * s->q_last;
        s->leak += current * DT;
    }
    if (measured_ok) {
        qc = measured - s->leak;
        if (!s->started) {
            s->frame = model_output(s) - qc;
            s->started = 1;
        }
        qc += s->frame;
        if (s->has_prev) {
            e = s->d_prev - qc;
        }
    } else {
        s->faults++;
    }
    s->error = e;
    if (non_finite(desired)) { /* hold the last safe command */
        s->has_prev = 0;
        hold_reset(s);
#if DYNAMIC
        return core_step(s, desired); /* held and counted, the piezo settling on it */
#else
        s->nonfinite++;
        return s->last;
#endif
    }
    d = TARGET(s, desired);
    integral = s->integral + KI * e;
    u = d + KP * e + integral;
#if DYNAMIC
    v = core_step(s, u); /* a non-finite u held and counted there */
#else
    if (non_finite(u)) {
        s->nonfinite++;
        v = s->last;
    } else {
        v = core_step(s, u);
    }
#endif
    y = model_output(s);
    delivered = !non_finite(u) && abs_real(y - u) <= TOL;
    if (delivered) {
        s->integral = integral;
    }
    s->d_prev = d;
    s->has_prev = 1;
    if (REFRESH > 0) { /* the integral's drift on a hold is the leakage error */
        if (delivered && s->has_hold && abs_real(d - s->hold_ref) <= HOLD_TOL) {
            s->hold_n += 1;
            k = s->hold_n;
            if (k > 0.25 * HOLD_SAMPLES) {
                if (s->sm == 0) {
                    s->y0 = s->integral;
                }
                yi = s->integral - s->y0;
                s->sm += 1;
                s->sx += k;
                s->sy += yi;
                s->sxx += k * k;
                s->sxy += k * yi;
            }
            if (k >= HOLD_SAMPLES) {
                m = s->sm;
                den = m * s->sxx - s->sx * s->sx;
                if (m > 2 && den > 0) {
                    slope = (m * s->sxy - s->sx * s->sy) / den;
                    s->bias -= REFRESH * slope / DT;
                    s->refreshes++;
                }
                hold_reset(s);
            }
        } else {
            s->hold_ref = d;
            s->has_hold = 1;
            hold_reset(s);
        }
    }
    return v;
}
