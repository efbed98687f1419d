/*
 * rimcl_real.h -- precision modes, rays-per-work-item lanes, double-float arithmetic.
 *
 * Purpose: lets one Sharma step be written once for the three precision modes and for
 * any number of rays per work-item.
 * Required define: RIMCL_PRECISION = RIMCL_F32 (0, plain float32 state),
 *   RIMCL_F32C (1, position R and direction T kept as float32 hi+lo pairs,
 *   "double-float", the default) or RIMCL_F64 (2, double state; needs cl_khr_fp64).
 * Optional defines:
 *   RIMCL_LANES      rays advanced together by one work-item, in the lanes of vector
 *                    types: 1 (default; GPUs), 2, 4, 8 or 16 (CPUs, where one ray per
 *                    work-item is latency-bound).
 *   RIMCL_POCL_FAST  1 on PoCL (CPUs): helpers forced inline, clang builtins
 *                    (__builtin_floorf, __builtin_elementwise_floor,
 *                    __builtin_convertvector) in place of OpenCL library calls that
 *                    PoCL may not inline, and cell prefetching (rimcl_field.h);
 *                    0 (default; GPUs) keeps the standard functions.
 * Field samples are float32 in every mode; `real` is the type positions and
 * interpolation weights are computed in (double only in RIMCL_F64); `lreal` holds a
 * `real` per lane, `lint` an integer or a lane mask per lane (all bits set = true for
 * vectors, 1 for one lane); LANE(v, k) / LANE_I(v, k) read and write lane k.
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
#ifndef RIMCL_LANES
#define RIMCL_LANES 1
#endif
#include "rimcl_inline.h"

/* The compensated sums below rely on every operation being rounded as written. */
#pragma OPENCL FP_CONTRACT OFF

#if RIMCL_PRECISION == RIMCL_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define RIMCL_REAL_TYPE double
typedef double real;
typedef double3 real3;
typedef double4 real4;
#define convert_real4 convert_double4
#define REAL_EPS DBL_EPSILON
#else
#define RIMCL_REAL_TYPE float
typedef float real;
typedef float3 real3;
typedef float4 real4;
#define convert_real4 convert_float4
#define REAL_EPS FLT_EPSILON
#endif

/* ---- PoCL switch: the hot loop without library calls ---- */
#if RIMCL_POCL_FAST
#if RIMCL_PRECISION == RIMCL_F64
#define real_floor(x) __builtin_floor(x)
#else
#define real_floor(x) __builtin_floorf(x)
#endif
#else
#define real_floor(x) floor(x)
#endif

/* ---- lanes: RIMCL_LANES rays side by side in vector types ---- */
#define RIMCL_CAT_(a, b) a##b
#define RIMCL_CAT(a, b) RIMCL_CAT_(a, b)

#if RIMCL_LANES == 1
typedef real lreal;
typedef int lint; /* per-lane integers (counters, status) and lane masks */
#define LANES_ANY(mask) (mask)
#define LANE(v, k) (v)
#define LANE_I(v, k) (v)
#define lreal_floor(x) real_floor(x)
#define convert_lint(x) ((int)(x))
#define convert_lreal(x) ((real)(x))
#elif RIMCL_LANES == 2 || RIMCL_LANES == 4 || RIMCL_LANES == 8 || RIMCL_LANES == 16
typedef RIMCL_CAT(RIMCL_REAL_TYPE, RIMCL_LANES) lreal;
/* comparisons of lreal give lint masks (all bits set = true) */
#if RIMCL_PRECISION == RIMCL_F64
typedef long lint_scalar;
typedef RIMCL_CAT(long, RIMCL_LANES) lint;
#else
typedef int lint_scalar;
typedef RIMCL_CAT(int, RIMCL_LANES) lint;
#endif
#define LANES_ANY(mask) any(mask)
#if RIMCL_POCL_FAST
#define lreal_floor(x) __builtin_elementwise_floor(x)
#define convert_lint(x) __builtin_convertvector((x), lint)
#define convert_lreal(x) __builtin_convertvector((x), lreal)
#elif RIMCL_PRECISION == RIMCL_F64
#define lreal_floor(x) floor(x)
#define convert_lint RIMCL_CAT(convert_long, RIMCL_LANES)
#define convert_lreal RIMCL_CAT(convert_double, RIMCL_LANES)
#else
#define lreal_floor(x) floor(x)
#define convert_lint RIMCL_CAT(convert_int, RIMCL_LANES)
#define convert_lreal RIMCL_CAT(convert_float, RIMCL_LANES)
#endif
/* lane k of a private lreal (LANE) or lint (LANE_I) variable, readable and writable;
 * clang subscripts vectors in registers, other compilers go through memory */
#ifdef __clang__
#define LANE(v, k) ((v)[k])
#define LANE_I(v, k) ((v)[k])
#else
#define LANE(v, k) (((real *)&(v))[k])
#define LANE_I(v, k) (((lint_scalar *)&(v))[k])
#endif
#else
#error "RIMCL_LANES must be 1, 2, 4, 8 or 16"
#endif
/* lane masks are lint: nonzero (scalar) or all bits set (vector) where true */
typedef lint lmask;

typedef struct {
    lreal x, y, z;
} lvec3;

/* ---- double-float (f32c) arithmetic: a value is hi + lo with |lo| <= ulp(hi)/2 ---- */

/* s + e == a + b exactly (Knuth's two-sum, no ordering requirement). */
RIMCL_INLINE lreal two_sum(lreal a, lreal b, lreal *err)
{
    lreal s = a + b;
    lreal bb = s - a;
    *err = (a - (s - bb)) + (b - bb);
    return s;
}

/* p + e == a * b exactly (needs a correctly rounded fma). */
RIMCL_INLINE lreal two_prod(lreal a, lreal b, lreal *err)
{
    lreal p = a * b;
    *err = fma(a, b, -p);
    return p;
}

/* (hi, lo) += (b_hi, b_lo), renormalised. */
RIMCL_INLINE void df_add(lreal *hi, lreal *lo, lreal b_hi, lreal b_lo)
{
    lreal e;
    lreal s = two_sum(*hi, b_hi, &e);
    e += *lo + b_lo;
    *hi = s + e;
    *lo = e - (*hi - s);
}

/* Value of a double-float parameter pair (hi, lo) at the working precision. */
RIMCL_INLINE real real_from_pair(float hi, float lo)
{
#if RIMCL_PRECISION == RIMCL_F64
    return (double)hi + (double)lo;
#else
    (void)lo;
    return hi;
#endif
}

#endif
