/* The Preisach core's step in C: reversal memory and wiping-out, as _kernels.packed.rev_move. */
static real_t core_output(const real_t *st) { return st[1]; }

/* the slope of the step's first instant from st in direction up */
static real_t first_slope(const real_t *st, int up, real_t dy)
{
    int reverse = st[2] != 0 && (up ? 1.0 : -1.0) != st[2];
    real_t top = reverse ? st[0] : st[4 + (int)st[3] - 1];
    (void)dy;
    return branch_slope(st[0], top, up);
}
