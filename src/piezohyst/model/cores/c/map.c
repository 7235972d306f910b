/* The desired value as the step's reference. Without an output map, or with a linear one
 * folded into REFERENCE and SCALE, an affine map (a linear map before an output mode is not
 * folded: LINEAR_MAP, its inverse as OutputMap.inverse computes it); with a curved map from capacitor charge to
 * displacement (calibrate_gain, monotone over its calibrated charges), its inverse first, as
 * OutputMap.inverse computes it: Newton's method from the chord, kept inside the calibrated
 * range, and the linear extension from the range's edge beyond it. With any map, a desired
 * value beyond the calibrated displacements is counted (s->extrapolated), as the
 * compensator's extrapolated_count. With an output mode, mode.c maps the desired values
 * before the mode's inverse (the compensator's order) and the step takes charges. */
#if CURVED_MAP || LINEAR_MAP
/* beyond the calibrated displacements: the edge's tangent (0: inside) */
static int map_beyond(real_t d, real_t *q)
{
    if (d < MAP_LOW_END) {
        *q = MAP_RISING ? MAP_LO + (d - MAP_S_LO) / MAP_D_LO : MAP_HI + (d - MAP_S_HI) / MAP_D_HI;
        return 1;
    }
    if (d > MAP_HIGH_END) {
        *q = MAP_RISING ? MAP_HI + (d - MAP_S_HI) / MAP_D_HI : MAP_LO + (d - MAP_S_LO) / MAP_D_LO;
        return 1;
    }
    return 0;
}
#endif
#if LINEAR_MAP /* before an output mode: not folded, the inverse in monotone_charges' order */
static real_t map_charge(real_t d)
{
    real_t q;
    if (map_beyond(d, &q)) {
        return q;
    }
    return MAP_CENTER + MAP_SCALE * (d - MAP_C0) / MAP_C1;
}
#define MAP_D(d) map_charge(d)
#elif CURVED_MAP
static real_t map_horner(const real_t *c, int order, real_t u)
{
    real_t y = c[order];
    for (int k = order - 1; k >= 0; --k) {
        y = c[k] + y * u;
    }
    return y;
}

static real_t map_charge(real_t d)
{
    real_t q, f;
    if (map_beyond(d, &q)) {
        return q;
    }
    q = MAP_LO + (MAP_HI - MAP_LO) * (d - MAP_S_LO) / (MAP_S_HI - MAP_S_LO);
    for (int it = 0; it < 50; ++it) {
        real_t u = (q - MAP_CENTER) / MAP_SCALE;
        f = map_horner(MAP_C, MAP_ORDER, u) - d;
        if ((f < 0 ? -f : f) <= MAP_TOL) {
            break;
        }
        q = q - f / (map_horner(MAP_DC, MAP_ORDER - 1, u) / MAP_SCALE);
        q = q < MAP_LO ? MAP_LO : (q > MAP_HI ? MAP_HI : q);
    }
    return q;
}
#define MAP_D(d) map_charge(d)
#else
#define MAP_D(d) (d)
#endif
#if HAS_MAP /* NaN compares false: not counted (the step counts it as non-finite) */
#define MAP_COUNT(s, d) ((d) < MAP_LOW_END || (d) > MAP_HIGH_END ? (void)(s)->extrapolated++ \
                                                                 : (void)0)
#else
#define MAP_COUNT(s, d) ((void)(s))
#endif
#if MODE
#define TARGET(s, d) (REFERENCE + (d) * SCALE)
#else
#define TARGET(s, d) (MAP_COUNT(s, d), REFERENCE + MAP_D(d) * SCALE)
#endif
