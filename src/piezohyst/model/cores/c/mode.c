/* The output mode's inverse before the hysteresis step (OutputDynamics.invert for one
 * sample): y + 2 zeta/w y' + y''/w^2 from differences, half a sample before the end. The
 * self-sensing controller's step (an output map's mode) also takes the measured charge. */
#if CONTROLLER
real_t PREFIX_step(PREFIX_t *s, real_t desired, real_t measured, real_t next)
#else
real_t PREFIX_step(PREFIX_t *s, real_t desired, real_t next)
#endif
{
    real_t b0, b1, nxt, mid, d1, d2;
    if (!non_finite(desired)) { /* the output map first (map.c): the mode acts on charges */
        MAP_COUNT(s, desired);
        desired = MAP_D(desired);
    }
    if (!non_finite(next)) {
        next = MAP_D(next);
    }
    b1 = non_finite(s->e1) ? desired : s->e1; /* not known yet: the first one known */
    b0 = non_finite(s->e2) ? b1 : s->e2;
    nxt = non_finite(next) ? 2.0 * desired - b1 : next;
    mid = 0.5 * (desired + b1);
    d1 = (desired - b1) / MODE_DT;
    d2 = ((nxt - desired) - (b1 - b0)) / (2.0 * MODE_DT * MODE_DT);
    s->e2 = s->e1;
    s->e1 = desired;
#if CONTROLLER
    return controller_step(s, mid + MODE_K1 * d1 + d2 / MODE_W2, measured);
#else
    return hysteresis_step(s, mid + MODE_K1 * d1 + d2 / MODE_W2);
#endif
}
