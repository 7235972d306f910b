/* A template (piezohyst.control.export.structure_c): the dollar-brace names are filled in
 * at export. */
/* ${prefix}.c: see ${prefix}.h. StructureCompensator's step in C, in the same order. */
#include <math.h>
#include "${prefix}.h"

typedef ${prefix}_real real_t;

${tables}

/* Each actuator's operators z moved by its stroke T y; their lags behind it into lag. */
static void play(const real_t *y, real_t z[${na}][${nk}], real_t *lag)
{
    int o, q, j;
    for (q = 0; q < ${na}; ++q) {
        real_t sq = 0;
        for (o = 0; o < ${m}; ++o) {
            sq += T[q][o] * y[o];
        }
        for (j = 0; j < ${nk}; ++j) {
            real_t zj = z[q][j];
            zj = zj > sq - R[q][j] ? zj : sq - R[q][j];
            zj = zj < sq + R[q][j] ? zj : sq + R[q][j];
            z[q][j] = zj;
            lag[q * ${nk} + j] = zj - sq;
        }
    }
}

/* A target's row of the ring: the target less the offsets, then each actuator's operators'
 * lags behind its stroke (the operators on the targets' strokes advanced by it). */
static void push(${prefix}_t *s, const real_t *target, long slot)
{
    int o;
    for (o = 0; o < ${m}; ++o) {
        s->ring[slot][o] = target[o] - OFF[o];
    }
    play(target, s->zd, s->ring[slot] + ${m});
}

void ${prefix}_init(${prefix}_t *s)
{
    int i, q, j;
    long k;
    for (i = 0; i < ${nx}; ++i) {
        s->x[i] = 0;
    }
    for (q = 0; q < ${na}; ++q) {
        real_t rest = 0;
        for (i = 0; i < ${m}; ++i) {
            rest += T[q][i] * OFF[i];
        }
        for (j = 0; j < ${nk}; ++j) {
            s->z[q][j] = rest;
            s->zd[q][j] = rest;
        }
    }
    for (i = 0; i < ${m}; ++i) {
        s->target[i] = OFF[i];
    }
    for (k = 0; k < ${slots}; ++k) {
        push(s, s->target, k);
        s->hold[k] = 0;
    }
    s->head = 0;
    for (i = 0; i < ${n}; ++i) {
        s->last[i] = 0;
        s->prev[i] = 0;
        s->arrived[i] = 0;
        s->saturated[i] = 0;
        s->slewed[i] = 0;
    }
    s->outside = 0;
    s->nonfinite = 0;
}

void ${prefix}_step(${prefix}_t *s, const real_t *ahead, real_t *command)
{
    int i, o, c, j, finite = 1, beyond = 0;
    long k, slot;
    real_t y[${m}], p[${na} * ${nk}], xn[${nx}];
    /* the target ahead enters the ring's last slot (the one the command leaves) */
    for (o = 0; o < ${m}; ++o) {
        finite = finite && isfinite(ahead[o]);
    }
    slot = (s->head + ${preview}) % ${slots};
    if (finite) {
        for (o = 0; o < ${m}; ++o) {
            s->target[o] = ahead[o];
        }
    }
    push(s, s->target, slot);
    s->hold[slot] = (unsigned char)!finite;
    /* this sample's commands: the feed-forward of the targets ahead, less the feedback */
    for (i = 0; i < ${n}; ++i) {
        real_t acc = 0, v;
        if (s->hold[s->head]) {
            v = s->last[i];
        } else {
            for (c = 0; c < ${q}; ++c) {
                acc += F0[i][c] * s->ring[s->head][c];
            }
            for (k = 0; k < ${preview}; ++k) {
                const real_t *zk = s->ring[(s->head + 1 + k) % ${slots}];
                for (c = 0; c < ${q}; ++c) {
                    acc += L[k][i][c] * zk[c];
                }
            }
            for (j = 0; j < ${nx}; ++j) {
                acc -= GAIN[i][j] * s->x[j];
            }
            v = acc > s->last[i] - STEP[i] ? acc : s->last[i] - STEP[i];
            v = v < s->last[i] + STEP[i] ? v : s->last[i] + STEP[i];
            if (v < LO[i] - SLACK[i] || v > HI[i] + SLACK[i]) {
                beyond = 1;
            }
            v = v > LO[i] ? v : LO[i];
            v = v < HI[i] ? v : HI[i];
        }
        { /* the limits' tally, as the Python compensator's */
            int held = fabs(v - s->prev[i]) >= TOL[i];
            s->prev[i] = v;
            if (v <= LO[i] || v >= HI[i]) {
                s->saturated[i]++;
            }
            if (s->arrived[i] || !held) {
                s->arrived[i] = 1;
                if (held) {
                    s->slewed[i]++;
                }
            }
        }
        s->last[i] = v;
        command[i] = v;
    }
    if (s->hold[s->head]) {
        s->nonfinite++;
    }
    if (beyond) {
        s->outside++;
    }
    /* the model runs on the commands sent: its outputs, its operators, its next state */
    for (o = 0; o < ${m}; ++o) {
        real_t acc = OFF[o];
        for (j = 0; j < ${nx}; ++j) {
            acc += C[o][j] * s->x[j];
        }
        for (i = 0; i < ${n}; ++i) {
            acc += D[o][i] * s->last[i];
        }
        y[o] = acc;
    }
    play(y, s->z, p);
    for (j = 0; j < ${nx}; ++j) {
        real_t acc = 0;
        for (c = 0; c < ${nx}; ++c) {
            acc += A[j][c] * s->x[c];
        }
        for (i = 0; i < ${n}; ++i) {
            acc += B[j][i] * s->last[i];
        }
        for (c = 0; c < ${na} * ${nk}; ++c) {
            acc += E[j][c] * p[c];
        }
        xn[j] = acc;
    }
    for (j = 0; j < ${nx}; ++j) {
        s->x[j] = xn[j];
    }
    s->head = (s->head + 1) % ${slots};
}

/* The step on doubles, as a host passes them (the shared library's rows, an FMU's
 * variables). */
void ${prefix}_step_doubles(${prefix}_t *s, const double *ahead, double *command)
{
    real_t d[${m}], v[${n}];
    int i;
    for (i = 0; i < ${m}; ++i) {
        d[i] = (real_t)ahead[i];
    }
    ${prefix}_step(s, d, v);
    for (i = 0; i < ${n}; ++i) {
        command[i] = (double)v[i];
    }
}
