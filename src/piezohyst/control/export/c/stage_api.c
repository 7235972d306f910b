/* A template (piezohyst.control.export.stage_c): the dollar-brace names are filled in at
 * export. */

/* ---- shared-library API of a coupled stage (piezohyst.control.export.write_stage_shared) */
#include <math.h>
/* n samples: target holds n rows of ${m} desired positions, volts gets n rows of ${n}
 * commands (V), both row by row. 0; -1 for a NULL pointer, -2 for n < 0.${api_measured_said}${process_said} */
PH_EXPORT int ${prefix}_process(${prefix}_t *s, const double *target${api_measured}, double *volts,
    long n)
{
    long k;${process_decl}
    if (s == NULL || target == NULL || volts == NULL${api_measured_null}) {
        return -1;
    }
    if (n < 0) {
        return -2;
    }
    for (k = 0; k < n; ++k) {
        ${process_step}
    }
    return 0;
}

/* What the limits held since the last reset: counts[0] desired positions beyond the
 * stage's reach, then per actuator k: counts[1 + 3k] non-finite targets (held),
 * counts[2 + 3k] commands at a voltage limit, counts[3 + 3k] commands cut by the slew
 * limit. 0; -1 for a NULL pointer. */
PH_EXPORT int ${prefix}_counts(const ${prefix}_t *s, unsigned long counts[${counts}])
{
    if (s == NULL || counts == NULL) {
        return -1;
    }
    counts[0] = s->outside;
${count_lines}
    return 0;
}

PH_EXPORT const char *${prefix}_version(void)
{
    return "${version}";
}
