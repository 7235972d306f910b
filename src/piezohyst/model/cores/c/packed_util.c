/* Small helpers of the packed cores' step (Preisach, Duhem, Bouc-Wen). */
static real_t abs_real(real_t x) { return x < 0 ? -x : x; }
static real_t min_real(real_t a, real_t b) { return a < b ? a : b; }
static real_t max_real(real_t a, real_t b) { return a > b ? a : b; }

#if KIND != 2
/* a distance a >= 0 in steps of b > 0: the number of full steps, *rest the last one */
static int steps(real_t a, real_t b, real_t *rest)
{
    int full = (int)(a / b);
    *rest = a - full * b;
    if (*rest < 0) {
        *rest = 0;
    }
    return full;
}
#endif
