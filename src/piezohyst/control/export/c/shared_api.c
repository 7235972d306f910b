/* The shared-library API after an exported step (piezohyst export-c --shared).
 * A template: the dollar-brace names are filled in at export. */

/* ---- shared-library API (piezohyst export-c --shared) ---- */
#include <math.h>
/* n commands (V) into volts: 0; -1 for a NULL pointer, -2 for n < 0. */
PH_EXPORT int ${prefix}_process(${prefix}_t *s, const double *target, ${charge_arg}double *volts,
                               long n)
{
    long k;
    if (s == NULL || target == NULL || volts == NULL${charge_null}) {
        return -1;
    }
    if (n < 0) {
        return -2;
    }
    for (k = 0; k < n; ++k) {
        volts[k] = (double)${prefix}_step(s, (${prefix}_real)target[k]${charge_use});
    }
    return 0;
}

/* What the limits held since the last reset: counts[0] non-finite targets (the last
 * command held), counts[1] targets out of reach (the nearer voltage limit sent),
 * counts[2] commands cut by the slew limit, counts[3] targets beyond the output map's
 * calibrated range (the map extended linearly; 0 without a map). 0; -1 for a NULL pointer. */
PH_EXPORT int ${prefix}_counts(const ${prefix}_t *s, unsigned long counts[4])
{
    if (s == NULL || counts == NULL) {
        return -1;
    }
    counts[0] = s->nonfinite;
    counts[1] = s->saturated;
    counts[2] = s->slewed;
    counts[3] = s->extrapolated;
    return 0;
}

PH_EXPORT const char *${prefix}_version(void)
{
    return "${version}";
}
