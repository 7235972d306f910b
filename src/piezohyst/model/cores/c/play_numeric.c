/* The play-operator compensator beside kept asymmetry or creep terms (GeneralizedPI): the
 * same arithmetic as _kernels.play.numeric_step. The hysteresis part is strictly increasing
 * in the new command, so the command is the root of output(v) = target inside the limits,
 * found by Newton's method inside a bracket (bisecting whenever a step would leave it), at
 * most NEWTON_MAX iterations; creep lags advance with the command sent. */
#define NEWTON_MAX 200

static real_t clamp(real_t x, real_t lo, real_t hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

static real_t fabs_real(real_t x)
{
    return x < 0 ? -x : x;
}

/* the hysteresis part's output for command v from the current state, and its slope in v */
static real_t numeric_output(const PREFIX_t *s, real_t v, real_t *slope)
{
    real_t y = OFFSET, dy = 0, lo, hi, d;
    int i;
    for (i = 0; i < N; ++i) {
        lo = v - R[i];
        hi = v + R[i];
        if (s->z[i] < lo) {
            y += W[i] * lo;
            dy += W[i];
        } else if (s->z[i] > hi) {
            y += W[i] * hi;
            dy += W[i];
        } else {
            y += W[i] * s->z[i];
        }
    }
#if N_STATIC
    for (i = 0; i < N_STATIC; ++i) {
        d = v - STATIC_KNOT[i];
        if (d > 0) {
            y += STATIC_UP[i] * d * d / STATIC_SCALE;
            dy += 2 * STATIC_UP[i] * d / STATIC_SCALE;
        } else {
            y -= STATIC_DOWN[i] * d * d / STATIC_SCALE;
            dy -= 2 * STATIC_DOWN[i] * d / STATIC_SCALE;
        }
    }
#endif
#if N_LAGS
    for (i = 0; i < N_LAGS; ++i) {
        y += LAG_G[i] * (s->c[i] + LAG_A[i] * (v - s->c[i]));
        dy += LAG_G[i] * LAG_A[i];
    }
#endif
    (void)d;
    *slope = dy;
    return y;
}

static void advance_lags(PREFIX_t *s, real_t v)
{
#if N_LAGS
    int k;
    for (k = 0; k < N_LAGS; ++k) {
        s->c[k] += LAG_A[k] * (v - s->c[k]);
    }
#else
    (void)s;
    (void)v;
#endif
}

void PREFIX_init(PREFIX_t *s)
{
    int i;
    for (i = 0; i < N; ++i) {
        s->z[i] = Z0[i];
        s->zeta[i] = 0;
    }
#if N_LAGS
    for (i = 0; i < N_LAGS; ++i) {
        s->c[i] = C0[i];
    }
#endif
    s->last = LAST0;
    s->nonfinite = 0;
    s->saturated = 0;
    s->slewed = 0;
    s->extrapolated = 0;
}

real_t PREFIX_step(PREFIX_t *s, real_t desired)
{
    real_t q, lo = V_MIN, hi = V_MAX, y_lo, y_hi, y, slope, err, trial, v, tol;
    int i, k;
    if (non_finite(desired)) {
        s->nonfinite++;
        advance_lags(s, s->last);
        return s->last;
    }
    q = TARGET(s, desired);
    y_lo = numeric_output(s, lo, &slope);
    y_hi = numeric_output(s, hi, &slope);
    if (q <= y_lo) {
        v = lo;
    } else if (q >= y_hi) {
        v = hi;
    } else {
        v = clamp(s->last, lo, hi);
        for (k = 0; k < NEWTON_MAX; ++k) {
            y = numeric_output(s, v, &slope);
            err = y - q;
            if (err == 0) {
                break;
            }
            if (err > 0) {
                hi = v;
            } else {
                lo = v;
            }
            if (hi - lo <= (real_t)1e-15 * (fabs_real(lo) + fabs_real(hi) + (real_t)1e-300)) {
                break;
            }
            trial = slope > 0 ? v - err / slope : (real_t)0.5 * (lo + hi);
            v = (lo < trial && trial < hi) ? trial : (real_t)0.5 * (lo + hi);
        }
    }
    tol = (real_t)1e-12 * (y_hi - y_lo);
#if HAS_SLEW
    if (v > s->last + MAX_STEP) {
        v = s->last + MAX_STEP;
        s->slewed++;
    } else if (v < s->last - MAX_STEP) {
        v = s->last - MAX_STEP;
        s->slewed++;
    } else
#endif
    if (q < y_lo - tol || q > y_hi + tol) { /* sent at the voltage limit (see play.c) */
        s->saturated++;
    }
    for (i = 0; i < N; ++i) {
        s->z[i] = clamp(s->z[i], v - R[i], v + R[i]);
    }
    advance_lags(s, v);
    s->last = v;
    return v;
}
