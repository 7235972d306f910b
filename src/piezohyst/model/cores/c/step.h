#if ${upper}_DYNAMIC
    ${real} w, u;               /* input dynamics: after the fractional delay, after the lag (V) */
#endif
#if ${upper}_MODE
    ${real} e1, e2;             /* output mode: the last two desired values (NaN: none) */
#endif
} ${prefix}_t;

/* Start from the state the ${kind} had when it was exported. */
void ${prefix}_init(${prefix}_t *s);

#if ${upper}_CONTROLLER && ${upper}_MODE
/* One command (V): desired output, the charge read at this sample before this
 * command acts (NaN/inf: feedforward alone for this sample), and the next desired
 * value (see above). */
${real} ${prefix}_step(${prefix}_t *s, ${real} desired, ${real} measured, ${real} next);
#elif ${upper}_CONTROLLER
/* One command (V): desired output, and the charge read at this sample before
 * this command acts (NaN/inf: feedforward alone for this sample). */
${real} ${prefix}_step(${prefix}_t *s, ${real} desired, ${real} measured);
#elif ${upper}_MODE
/* One command (V) for one desired value and the next (see above). */
${real} ${prefix}_step(${prefix}_t *s, ${real} desired, ${real} next);
#else
/* One command (V) for one desired value (see above). */
${real} ${prefix}_step(${prefix}_t *s, ${real} desired);
#endif

#endif /* ${guard} */
