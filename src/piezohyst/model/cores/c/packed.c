/* The packed cores' compensator step: bracketed Newton, region, lags, dynamics, as
 * _kernels.packed.core_step. */
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
/* x after a fraction of a sample's delay, interpolated from the last command */
static real_t advance(PREFIX_t *s, real_t x)
{
    s->w = FRACTION != 0 ? (1 - FRACTION) * x + FRACTION * s->last : x;
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
    s->outside = 0;
    INIT_EXTRA(s);
}

#if MODE /* the public step inverts the mode first (mode.c) */
static real_t hysteresis_step(PREFIX_t *s, real_t desired)
#else
real_t PREFIX_step(PREFIX_t *s, real_t desired)
#endif
{
    real_t y, a = V_MIN, b = V_MAX, u, x, f, trial[NS], lin = 0;
    int clamped, held, i;
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
    y = TARGET(s, desired);
#if N_LAGS
    y -= lags_affine(s, &lin);
#endif
#if HAS_SLEW && !DYNAMIC
    a = max_real(V_MIN, s->last - MAX_STEP);
    b = min_real(V_MAX, s->last + MAX_STEP);
#endif
    u = core_inverse(s->st, y, a, b, &clamped, trial, lin);
    held = clamped && (u <= V_MIN || u >= V_MAX); /* out of reach inside the limits */
#if HAS_SLEW && !DYNAMIC
    if (clamped && !held) { /* held at the slew limit's bracket, inside the voltage limits */
        s->slewed++;
    }
#endif
    x = u;
#if DYNAMIC
    {
        real_t w = GAIN_B > 0 ? s->u + (u - s->u) / GAIN_B : u, tol = 1e-12 * (V_MAX - V_MIN);
        x = FRACTION > 0   ? (1 + FRACTION) * w - FRACTION * s->w
            : FRACTION < 0 ? (w - FRACTION * s->last) / (1 - FRACTION)
                           : w;
        if (non_finite(x)) {
            x = s->last;
        }
        /* the lags' inverse asks beyond a voltage limit: held there (as play.c's limit) */
        held = held || x < V_MIN - tol || x > V_MAX + tol;
        x = min_real(max_real(x, V_MIN), V_MAX);
#if HAS_SLEW
        if (x > s->last + MAX_STEP || x < s->last - MAX_STEP) {
            s->slewed++;
            held = 0; /* the slew limit held it first */
        }
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
    if (held && (x <= V_MIN || x >= V_MAX)) { /* sent at the voltage limit that held it */
        s->saturated++;
    }
    for (i = 0; i < NS; ++i) {
        s->st[i] = trial[i];
    }
    lags_advance(s, s->st[0]);
    s->last = x;
    return x;
}
