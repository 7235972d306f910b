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

void ${prefix}_step(${prefix}_t *s, const ${prefix}_real *desired, ${prefix}_real *command)
{
    ${prefix}_real own[${n}];
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
    if (beyond) {
        s->outside++;
    }
${steps}
}
