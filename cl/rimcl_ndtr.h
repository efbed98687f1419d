/*
 * rimcl_ndtr.h -- the standard normal distribution function, 8 values at a time, in double.
 *
 * Purpose: ndtr8(a, exp(-a^2/2)) = P(X <= a) for a standard normal X, to a few units in
 * the last place of 1, as scipy.special.ndtr computes it (the exact renderer integrates
 * each ray's Gaussian over pixels as differences of ndtr, as rimcl/imaging/render.py does with
 * scipy); ndtr_exp, the exponential its caller needs at a few points. Pure
 * arithmetic on double8 vectors, no library calls, so that it runs in vector registers on
 * CPUs (GPUs split the vectors); polynomials by Horner's rule in fused multiply-adds
 * (fma: half the operations and latency of a multiply and an add; the image kernel turns
 * contraction off for its host-matching arithmetic, so they are written out):
 *   |x| < 1/sqrt(2) (x = a / sqrt(2)): ndtr = 1/2 + erf(x)/2, erf from its Taylor series;
 *   otherwise: erfc(|x|) = exp(-x^2) erfcx(|x|) (exp(-x^2) = exp(-a^2/2) given), with
 *   (1 + 2z) erfcx(z) a degree-20 polynomial in t = (z - 4)/(z + 4), fitted for z in
 *   [0.7, 27.5] (relative error 4.4e-16 in double arithmetic as one Horner chain, 1e-15
 *   as the even and odd parts evaluated here); beyond 27.5 erfc underflows and is taken
 *   as 0.
 * Also the unaligned double8 loads and stores of the image kernel (LOAD8, STORE8).
 * Required: cl_khr_fp64 (enabled by the including kernel file). Optional define:
 *   RIMCL_POCL_FAST (rimcl_inline.h). Units: none.
 */
#ifndef RIMCL_NDTR_H
#define RIMCL_NDTR_H

#include "rimcl_inline.h"

#if RIMCL_POCL_FAST
/* clang's unaligned vector type: one vector load or store, no library call */
typedef double rimcl_double8_u __attribute__((ext_vector_type(8), aligned(8)));
#define LOAD8(p) (*(__global const rimcl_double8_u *)(p))
#define STORE8(v, p) (*(__global rimcl_double8_u *)(p) = (v))
#else
#define LOAD8(p) vload8(0, (p))
#define STORE8(v, p) vstore8((v), 0, (p))
#endif

/* 2^52 + 2^51: adding and subtracting it rounds a double to an integer (ties to even) */
#define NDTR_ROUNDER 6755399441055744.0

/* exp(y) for y < 709 to about 1 ulp; 0 where the result would be subnormal. */
RIMCL_INLINE double8 ndtr_exp(double8 y)
{
    const double log2e = 1.4426950408889634;
    const double ln2_hi = 0.6931467056274414; /* 21 significant bits: n ln2_hi is exact */
    const double ln2_lo = 4.7493250390316726e-07;
    const double8 n = (y * log2e + NDTR_ROUNDER) - NDTR_ROUNDER;
    const double8 r = (y - n * ln2_hi) - n * ln2_lo;
    /* Taylor series of exp(r), |r| <= ln2 / 2: the 14th term is 4e-18 */
    double8 p = 1.6059043836821613e-10;
    p = fma(p, r, (double8)(2.08767569878681e-09));
    p = fma(p, r, (double8)(2.505210838544172e-08));
    p = fma(p, r, (double8)(2.755731922398589e-07));
    p = fma(p, r, (double8)(2.7557319223985893e-06));
    p = fma(p, r, (double8)(2.48015873015873e-05));
    p = fma(p, r, (double8)(0.0001984126984126984));
    p = fma(p, r, (double8)(0.001388888888888889));
    p = fma(p, r, (double8)(0.008333333333333333));
    p = fma(p, r, (double8)(0.041666666666666664));
    p = fma(p, r, (double8)(0.16666666666666666));
    p = fma(p, r, (double8)(0.5));
    p = fma(p, r, (double8)(1.0));
    p = fma(p, r, (double8)(1.0));
    /* 2^n from the bits of n + NDTR_ROUNDER (its low bits hold n) */
    const long8 k = as_long8(n + NDTR_ROUNDER) - as_long(NDTR_ROUNDER);
    const double8 scale = as_double8((k + 1023) << 52);
    return (n < -1022.0) ? (double8)(0.0) : p * scale;
}

/* erf(x) for |x| < 0.71: x times a polynomial in x^2 (Taylor series to x^31). */
RIMCL_INLINE double8 ndtr_erf_small(double8 x)
{
    const double8 s = x * x;
    double8 p = -2.7835162072109215e-14;
    p = fma(p, s, (double8)(4.4632242632864775e-13));
    p = fma(p, s, (double8)(-6.7113668551641105e-12));
    p = fma(p, s, (double8)(9.422759064650411e-11));
    p = fma(p, s, (double8)(-1.2290555301717928e-09));
    p = fma(p, s, (double8)(1.4807192815879218e-08));
    p = fma(p, s, (double8)(-1.6365844691234924e-07));
    p = fma(p, s, (double8)(1.6462114365889248e-06));
    p = fma(p, s, (double8)(-1.492565035840625e-05));
    p = fma(p, s, (double8)(0.00012055332981789664));
    p = fma(p, s, (double8)(-0.0008548327023450853));
    p = fma(p, s, (double8)(0.005223977625442188));
    p = fma(p, s, (double8)(-0.026866170645131252));
    p = fma(p, s, (double8)(0.11283791670955126));
    p = fma(p, s, (double8)(-0.37612638903183754));
    p = fma(p, s, (double8)(1.1283791670955126));
    return x * p;
}

/* erfcx(z) = exp(z^2) erfc(z) for z >= 0.7. The polynomial in t as its even and odd
 * parts in t^2: two chains of 10 multiply-adds instead of one of 20, whose latency the
 * image kernel waited on. Within 1e-15 of scipy.special.erfcx over [0.7, 27.5]. */
RIMCL_INLINE double8 ndtr_erfcx(double8 z)
{
    const double8 t = (z - 4.0) / (z + 4.0);
    const double8 s = t * t;
    double8 even = -1.7234428715785117e-08;
    double8 odd = 7.785873874860938e-08;
    even = fma(even, s, (double8)(7.94178940695347e-08));
    odd = fma(odd, s, (double8)(-7.908013313281755e-07));
    even = fma(even, s, (double8)(2.865427968428462e-07));
    odd = fma(odd, s, (double8)(5.688288902690869e-06));
    even = fma(even, s, (double8)(-1.1217174704912293e-05));
    odd = fma(odd, s, (double8)(-2.439095894401932e-05));
    even = fma(even, s, (double8)(0.00015061984724729657));
    odd = fma(odd, s, (double8)(-0.00019925871832540145));
    even = fma(even, s, (double8)(-0.0007577728755798006));
    odd = fma(odd, s, (double8)(0.005031970290713591));
    even = fma(even, s, (double8)(-0.016197734113606525));
    odd = fma(odd, s, (double8)(0.037167515508307124));
    even = fma(even, s, (double8)(-0.06633036580793396));
    odd = fma(odd, s, (double8)(0.09373283499985118));
    even = fma(even, s, (double8)(-0.10103906603646996));
    odd = fma(odd, s, (double8)(0.06809705425465713));
    even = fma(even, s, (double8)(0.01537965210262221));
    odd = fma(odd, s, (double8)(-0.13962111684056228));
    even = fma(even, s, (double8)(1.2329951186255526));
    const double8 p = even + t * odd;
    return p / (1.0 + 2.0 * z);
}

/* P(X <= a) for a standard normal X, lane by lane, given gauss = exp(-a^2 / 2) to a few
 * ulp (the caller makes it: image.cl's source_factors takes a source's pixel edges, in
 * arithmetic progression, from two exponentials by a recurrence). */
RIMCL_INLINE double8 ndtr8(double8 a, double8 gauss)
{
    const double sqrth = 0.7071067811865476;
    const double8 x = a * sqrth;
    const double8 z = (x < 0.0) ? -x : x;
    const long8 middle_lane = z < sqrth;
    /* each branch only where some lane needs it (most pixel edges lie in the tails) */
    double8 tail = (double8)(0.0), middle = (double8)(0.0);
    if (!all(middle_lane)) {
        tail = 0.5 * gauss * ndtr_erfcx(middle_lane ? (double8)(0.7) : z);
        tail = (z > 27.5) ? (double8)(0.0) : tail;
    }
    if (any(middle_lane))
        middle = 0.5 + 0.5 * ndtr_erf_small(middle_lane ? x : (double8)(0.0));
    return middle_lane ? middle : ((x > 0.0) ? 1.0 - tail : tail);
}

#endif
