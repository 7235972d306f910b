/* NaN or +-inf, decided from the IEEE-754 exponent bits: unlike isfinite(), a check
 * that -ffast-math (which assumes finite arithmetic) cannot optimise away. */
#if REAL_IS_DOUBLE
typedef uint64_t real_bits;
#define REAL_MANTISSA 52
#define REAL_EXPONENT 0x7FF
#define REAL_NAN_BITS 0x7FF8000000000000ULL
#else
typedef uint32_t real_bits;
#define REAL_MANTISSA 23
#define REAL_EXPONENT 0xFF
#define REAL_NAN_BITS 0x7FC00000UL
#endif

static int non_finite(real_t x)
{
    union { real_t value; real_bits bits; } u;
    u.value = x;
    return (int)((u.bits >> REAL_MANTISSA) & REAL_EXPONENT) == REAL_EXPONENT;
}

#if MODE
static real_t not_a_number(void)
{
    union { real_t value; real_bits bits; } u;
    u.bits = REAL_NAN_BITS;
    return u.value;
}
#endif
