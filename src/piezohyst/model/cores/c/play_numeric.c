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
    INIT_EXTRA(s);
}

/* the piezo voltage in [V_MIN, V_MAX] whose output is q (the nearer limit when out of reach,
 * *held set): _kernels.play._numeric_piezo, Newton from start inside a bracket */
static real_t numeric_piezo(const PREFIX_t *s, real_t q, real_t start, int *held)
{
    real_t lo = V_MIN, hi = V_MAX, y_lo, y_hi, y, slope, err, trial, v, tol;
    int k;
    y_lo = numeric_output(s, lo, &slope);
    y_hi = numeric_output(s, hi, &slope);
    tol = (real_t)1e-12 * (y_hi - y_lo);
    *held = 0;
    if (q <= y_lo) {
        *held = q < y_lo - tol;
        return lo;
    }
    if (q >= y_hi) {
        *held = q > y_hi + tol;
        return hi;
    }
    v = clamp(start, lo, hi);
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
    return v;
}

#if DYNAMIC
/* the piezo voltage after command x is held for one sample (as play_dynamic.c) */
static real_t advance(PREFIX_t *s, real_t x)
{
    s->w = FRACTION != 0 ? (1 - FRACTION) * x + FRACTION * s->last : x;
    s->u = GAIN_B > 0 ? s->u + GAIN_B * (s->w - s->u) : s->w;
    return s->u;
}

/* The step behind input dynamics: _kernels.play.numeric_dynamic_step */
real_t PREFIX_step(PREFIX_t *s, real_t desired)
{
    real_t target, w, x, sent, u, tol = (real_t)1e-12 * (V_MAX - V_MIN);
    int i, held;
    if (non_finite(desired)) { /* hold: the piezo keeps settling on the last command */
        s->nonfinite++;
        u = advance(s, s->last);
    } else {
        target = numeric_piezo(s, TARGET(s, desired), s->u, &held);
        w = GAIN_B > 0 ? s->u + (target - s->u) / GAIN_B : target;
        x = FRACTION > 0   ? (1 + FRACTION) * w - FRACTION * s->w
            : FRACTION < 0 ? (w - FRACTION * s->last) / (1 - FRACTION)
                           : w;
        if (non_finite(x)) {
            x = s->last;
        }
        held = held || x < V_MIN - tol || x > V_MAX + tol; /* the lags' inverse asks beyond */
        x = clamp(x, V_MIN, V_MAX);
        sent = x;
#if HAS_SLEW
        sent = clamp(x, s->last - MAX_STEP, s->last + MAX_STEP);
        if (sent != x) {
            s->slewed++;
        }
#endif
        if (held && sent == x && (x <= V_MIN || x >= V_MAX)) { /* held by a voltage limit */
            s->saturated++;
        }
        u = advance(s, sent);
        s->last = sent;
    }
    for (i = 0; i < N; ++i) {
        s->z[i] = clamp(s->z[i], u - R[i], u + R[i]);
    }
    advance_lags(s, u);
    return s->last;
}
#else

real_t PREFIX_step(PREFIX_t *s, real_t desired)
{
    real_t v;
    int i, out_of_reach;
    if (non_finite(desired)) {
        s->nonfinite++;
        advance_lags(s, s->last);
        return s->last;
    }
    v = numeric_piezo(s, TARGET(s, desired), s->last, &out_of_reach);
#if HAS_SLEW
    if (v > s->last + MAX_STEP) {
        v = s->last + MAX_STEP;
        s->slewed++;
    } else if (v < s->last - MAX_STEP) {
        v = s->last - MAX_STEP;
        s->slewed++;
    } else
#endif
    if (out_of_reach) { /* sent at the voltage limit (see play.c) */
        s->saturated++;
    }
    for (i = 0; i < N; ++i) {
        s->z[i] = clamp(s->z[i], v - R[i], v + R[i]);
    }
    advance_lags(s, v);
    s->last = v;
    return v;
}
#endif
