/* A template (piezohyst.control.export.stage_c): the dollar-brace names are filled in at
 * export. */
/* ${prefix}.c: see ${prefix}.h. */
#include "${prefix}.h"

${tables}

void ${prefix}_init(${prefix}_t *s)
{
${inits}
    s->outside = 0;
}

void ${prefix}_step(${prefix}_t *s, const ${prefix}_real *desired${measured_param}${next_param},
    ${prefix}_real *command)
{
    ${prefix}_real own[${n}];${next_decl}
    int i, j, beyond = 0;
    for (i = 0; i < ${n}; ++i) { /* what each actuator alone must move */
        own[i] = 0;
        for (j = 0; j < ${m}; ++j) {
            own[i] += INVERSE[i][j] * (desired[j] - OFFSET[j]);
        }
        if (own[i] < REACH_LO[i] - SLACK[i] || own[i] > REACH_HI[i] + SLACK[i]) {
            beyond = 1;
        }
    }
${plane}    if (beyond) {
        s->outside++;
    }
${next_own}${steps}
}

/* The step on doubles, as a host passes them (the shared library's rows, an FMU's
 * variables). */
void ${prefix}_step_doubles(${prefix}_t *s, const double *desired${measured_double}${next_double},
    double *command)
{
    ${prefix}_real d[${m}], v[${n}];${next_copy_decl}${measured_copy_decl}
    int i;
    for (i = 0; i < ${m}; ++i) {
        d[i] = (${prefix}_real)desired[i];${next_copy}
    }${measured_copy}
    ${prefix}_step(s, d${measured_arg}${next_arg}, v);
    for (i = 0; i < ${n}; ++i) {
        command[i] = (double)v[i];
    }
}
