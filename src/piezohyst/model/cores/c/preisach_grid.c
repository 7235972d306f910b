/* The Preisach grid functions (cell, Everett, branches): the main core's and, under
 * renamed identifiers, a relaxing core's (relaxation_begin.h / relaxation_end.h). */
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

/* E(a, b), bilinear, and beyond the grid each branch continued at its slope at the edge:
 * E(a', b') + (b - b') E_b(a', b') + (a - a') E_a(a', b'), a' and b' clamped into the grid
 * (as _kernels.packed.everett); *da, *db its derivatives */
static real_t everett(real_t a, real_t b, real_t *da, real_t *db)
{
    real_t hi = V_LO + H * (NN - 1.0), ca, cb, fa, fb, e00, e01, e10, e11, e, dea, deb, cross;
    real_t xa, xb;
    int i, j, in_a, in_b;
    ca = min_real(max_real(a, V_LO), hi);
    cb = min_real(max_real(b, V_LO), hi);
    cell(ca, &i, &fa, &in_a);
    cell(cb, &j, &fb, &in_b);
    e00 = node(i, j);
    e01 = node(i, j + 1);
    e10 = node(i + 1, j);
    e11 = node(i + 1, j + 1);
    e = (1 - fa) * ((1 - fb) * e00 + fb * e01) + fa * ((1 - fb) * e10 + fb * e11);
    dea = ((1 - fb) * (e10 - e00) + fb * (e11 - e01)) / H;
    deb = ((1 - fa) * (e01 - e00) + fa * (e11 - e10)) / H;
    cross = (e11 - e10 - e01 + e00) / (H * H);
    xa = a - ca;
    xb = b - cb;
    *da = dea + (xa == 0 ? xb * cross : 0);
    *db = deb + (xb == 0 ? xa * cross : 0);
    (void)in_a;
    (void)in_b;
    return e + xb * deb + xa * dea;
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

