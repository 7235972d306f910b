/* A template: the dollar-brace names are filled in at export. Every shared library's
 * handle (the step's state on the heap), before its own process and counts. */
#include <stdlib.h>
#if defined(_WIN32)
#define PH_EXPORT __declspec(dllexport)
#else
#define PH_EXPORT __attribute__((visibility("default")))
#endif

/* A handle in the exported state; NULL if memory ran out. */
PH_EXPORT ${prefix}_t *${prefix}_new(void)
{
    ${prefix}_t *s = (${prefix}_t *)malloc(sizeof(${prefix}_t));
    if (s != NULL) {
        ${prefix}_init(s);
    }
    return s;
}

PH_EXPORT void ${prefix}_free(${prefix}_t *s)
{
    free(s);
}

/* Back to the exported state (the counters too). */
PH_EXPORT void ${prefix}_reset(${prefix}_t *s)
{
    if (s != NULL) {
        ${prefix}_init(s);
    }
}
