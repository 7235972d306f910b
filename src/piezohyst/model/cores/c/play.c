/* The play-operator compensator step in C: eq. 18 with limits and slew, the same
 * arithmetic as _kernels.compensator_step (and dynamic_step, controller_step). */
static real_t clamp(real_t x, real_t lo, real_t hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* eq. 18's state map: zeta_i = c + S_i z_i + sum over j > i of w_j z_j */
static void inverse_states(PREFIX_t *s)
{
    real_t tail = 0;
    int i;
    for (i = N - 1; i >= 0; --i) {
        s->zeta[i] = OFFSET + S[i] * s->z[i] + tail;
        tail += W[i] * s->z[i];
    }
}

void PREFIX_init(PREFIX_t *s)
{
    int i;
    for (i = 0; i < N; ++i) {
        s->z[i] = Z0[i];
    }
    inverse_states(s);
    INIT_EXTRA(s);
}

#if MODE /* the public step inverts the mode first (mode.c) */
#define STEP_SIGNATURE static real_t hysteresis_step
#else
#define STEP_SIGNATURE real_t PREFIX_step
#endif

#if !DYNAMIC
/* eq. 18 for a finite target q (model output units), limits and slew applied */
static real_t core_step(PREFIX_t *s, real_t q)
{
    real_t x, v;
    int i, limited = 0, over = 0;
    q = clamp(q, OFFSET - BOUND, OFFSET + BOUND);
    x = INV_OFFSET;
    for (i = 0; i < N; ++i) {
        s->zeta[i] = clamp(s->zeta[i], q - RI[i], q + RI[i]);
        x += WI[i] * s->zeta[i];
    }
    v = x;
    if (non_finite(v)) {
        s->nonfinite++;
        inverse_states(s);
        return s->last;
    }
    if (v < V_MIN || v > V_MAX) {
        /* count real overshoots, not a limit reached exactly but for rounding */
        over = v < V_MIN - SAT_TOL || v > V_MAX + SAT_TOL;
        v = clamp(v, V_MIN, V_MAX);
        limited = 1;
    }
#if HAS_SLEW
    if (v > s->last + MAX_STEP) {
        v = s->last + MAX_STEP;
        limited = 1;
        s->slewed++;
    } else if (v < s->last - MAX_STEP) {
        v = s->last - MAX_STEP;
        limited = 1;
        s->slewed++;
    } else
#endif
    if (over) { /* sent at the voltage limit, not where the slew limit held it first */
        s->saturated++;
    }
    for (i = 0; i < N; ++i) {
        s->z[i] = clamp(s->z[i], v - R[i], v + R[i]);
    }
    if (limited) {
        inverse_states(s);
    }
    s->last = v;
    return v;
}
#endif

#if !CONTROLLER && !DYNAMIC /* otherwise play_controller.c or play_dynamic.c follows */
STEP_SIGNATURE(PREFIX_t *s, real_t desired)
{
    if (non_finite(desired)) {
        s->nonfinite++;
        return s->last;
    }
    return core_step(s, TARGET(s, desired));
}
#endif
