/* A template (piezohyst.control.export.structure_c): the dollar-brace names are filled in
 * at export. */

/* ---- shared-library API of a structure's compensator (write_structure_shared) */
/* n samples: target holds n rows of ${m} targets, each ${preview} samples ahead of the
 * command row written at its place in volts (n rows of ${n} commands, V), row by row. 0;
 * -1 for a NULL pointer, -2 for n < 0. */
PH_EXPORT int ${prefix}_process(${prefix}_t *s, const double *target, double *volts, long n)
{
    long k;
    int o, i;
    ${prefix}_real ahead[${m}], command[${n}];
    if (s == NULL || target == NULL || volts == NULL) {
        return -1;
    }
    if (n < 0) {
        return -2;
    }
    for (k = 0; k < n; ++k) {
        for (o = 0; o < ${m}; ++o) {
            ahead[o] = (${prefix}_real)target[k * ${m} + o];
        }
        ${prefix}_step(s, ahead, command);
        for (i = 0; i < ${n}; ++i) {
            volts[k * ${n} + i] = (double)command[i];
        }
    }
    return 0;
}

/* What the limits held since the last reset: counts[0] targets out of reach, counts[1]
 * non-finite targets (held), then per actuator k: counts[2 + 2k] commands at a voltage
 * limit, counts[3 + 2k] commands cut by the slew limit. 0; -1 for a NULL pointer. */
PH_EXPORT int ${prefix}_counts(const ${prefix}_t *s, unsigned long counts[${counts}])
{
    if (s == NULL || counts == NULL) {
        return -1;
    }
    counts[0] = s->outside;
    counts[1] = s->nonfinite;
${count_lines}
    return 0;
}

/* How many samples ahead each target is of its command. */
PH_EXPORT int ${prefix}_preview(void)
{
    return ${preview};
}

PH_EXPORT const char *${prefix}_version(void)
{
    return "${version}";
}
