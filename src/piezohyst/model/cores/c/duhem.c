/* The Duhem core's step in C: the same arithmetic as _kernels.packed.duhem_next. */
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
