/* The Bouc-Wen core's step in C: RK4 in steps of DV_MAX, as _kernels.packed.bw_next. */
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
