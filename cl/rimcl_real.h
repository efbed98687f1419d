/*
 * rimcl_real.h -- precision modes of the ray state and double-float arithmetic.
 *
 * Purpose: lets one Sharma step be written once for the three precision modes.
 * Required define: RIMCL_PRECISION = RIMCL_F32 (0, plain float32 state),
 *   RIMCL_F32C (1, position R and direction T kept as float32 hi+lo pairs,
 *   "double-float", the default) or RIMCL_F64 (2, double state; needs cl_khr_fp64).
 * Field samples are float32 in every mode; `real` is the type positions and
 * interpolation weights are computed in (double only in RIMCL_F64).
 * No kernels here. Units: none.
 */
#ifndef RIMCL_REAL_H
#define RIMCL_REAL_H

#define RIMCL_F32 0
#define RIMCL_F32C 1
#define RIMCL_F64 2

#ifndef RIMCL_PRECISION
#error "RIMCL_PRECISION must be defined (0 = f32, 1 = f32c, 2 = f64)"
#endif

/* The compensated sums below rely on every operation being rounded as written. */
#pragma OPENCL FP_CONTRACT OFF

#if RIMCL_PRECISION == RIMCL_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double3 real3;
typedef double4 real4;
#define convert_real3 convert_double3
#define convert_real4 convert_double4
#else
typedef float real;
typedef float3 real3;
typedef float4 real4;
#define convert_real3 convert_float3
#define convert_real4 convert_float4
#endif

/* Value of a double-float parameter pair (hi, lo) at the working precision. */
inline real real_from_pair(float hi, float lo)
{
#if RIMCL_PRECISION == RIMCL_F64
    return (double)hi + (double)lo;
#else
    (void)lo;
    return hi;
#endif
}

inline real3 real3_from_pair(float3 hi, float3 lo)
{
#if RIMCL_PRECISION == RIMCL_F64
    return convert_double3(hi) + convert_double3(lo);
#else
    (void)lo;
    return hi;
#endif
}

/* ---- double-float (f32c) arithmetic: a value is hi + lo with |lo| <= ulp(hi)/2 ---- */

/* s + e == a + b exactly (Knuth's two-sum, no ordering requirement). */
inline float3 two_sum3(float3 a, float3 b, float3 *err)
{
    float3 s = a + b;
    float3 bb = s - a;
    *err = (a - (s - bb)) + (b - bb);
    return s;
}

/* p + e == a * b exactly (needs a correctly rounded fma). */
inline float3 two_prod3(float a, float3 b, float3 *err)
{
    float3 p = a * b;
    *err = fma((float3)(a), b, -p);
    return p;
}

/* (hi, lo) += (b_hi, b_lo), renormalised. */
inline void df_add3(float3 *hi, float3 *lo, float3 b_hi, float3 b_lo)
{
    float3 e;
    float3 s = two_sum3(*hi, b_hi, &e);
    e += *lo + b_lo;
    *hi = s + e;
    *lo = e - (*hi - s);
}

#endif
