/*
 * rimcl_field.h -- refractive index n and its gradient at a point.
 *
 * Purpose: field_sample(p) -> (n, dn/dx1, dn/dx2, dn/dx3) at position p (x1, x2, x3),
 * in the working precision `real` (rimcl_real.h).
 * Required defines:
 *   RIMCL_FIELD    RIMCL_FIELD_GRID (0): gridded, trilinear interpolation of the
 *                  float4 nodes (delta_n, dn/dx1, dn/dx2, dn/dx3), n = n_ref + delta_n;
 *                  closed forms for verification: RIMCL_FIELD_UNIFORM (1) n = a0;
 *                  RIMCL_FIELD_GRIN (2) n^2 = a0^2 (1 - a1^2 x2^2);
 *                  RIMCL_FIELD_FISHEYE (3) n = a0 / (1 + x1^2 + x2^2);
 *                  RIMCL_FIELD_LINEAR (4) n = a0 + a1 x2.
 *   RIMCL_PERIODIC 1: the grid wraps (holds one period, endpoint excluded);
 *                  0: positions are clamped to the grid (edge values outside).
 * Grid memory order: C-order (n3, n2, n1), x1 fastest; counts = (n1, n2, n3).
 * Units: lengths in field units, gradient in 1 / length.
 */
#ifndef RIMCL_FIELD_H
#define RIMCL_FIELD_H

#include "rimcl_real.h"
#include "rimcl_params.h"

#define RIMCL_FIELD_GRID 0
#define RIMCL_FIELD_UNIFORM 1
#define RIMCL_FIELD_GRIN 2
#define RIMCL_FIELD_FISHEYE 3
#define RIMCL_FIELD_LINEAR 4

#ifndef RIMCL_FIELD
#error "RIMCL_FIELD must be defined (0 grid, 1 uniform, 2 grin, 3 fisheye, 4 linear)"
#endif
#ifndef RIMCL_PERIODIC
#define RIMCL_PERIODIC 0
#endif

#define FIELD_ARGS __global const float4 *grid, int4 counts, __constant const float *params
#define FIELD_PASS grid, counts, params

#if RIMCL_FIELD == RIMCL_FIELD_GRID

/* Lower node index and weight of coordinate u (in cells) along an axis of n nodes. */
inline int cell_of(real u, int n, real *w, int *upper)
{
#if RIMCL_PERIODIC
    real fl = floor(u);
    *w = u - fl;
    int i = (int)fl % n;
    i += (i < 0) ? n : 0;
    *upper = (i + 1 == n) ? 0 : i + 1;
    return i;
#else
    real top = (real)(n - 1);
    u = (u < (real)0) ? (real)0 : ((u > top) ? top : u);
    int i = (int)floor(u);
    i = (i > n - 2) ? max(n - 2, 0) : i;
    *w = u - (real)i;
    *upper = min(i + 1, n - 1);
    return i;
#endif
}

inline real4 field_sample(FIELD_ARGS, real3 p)
{
    real3 u = (p - PARAM3(params, P_ORIGIN_HI, P_ORIGIN_LO)) * PARAM3(params, P_INVH_HI, P_INVH_LO);
    real w1, w2, w3;
    int j1, j2, j3;
    int i1 = cell_of(u.x, counts.x, &w1, &j1);
    int i2 = cell_of(u.y, counts.y, &w2, &j2);
    int i3 = cell_of(u.z, counts.z, &w3, &j3);
    size_t row = (size_t)counts.x;
    size_t plane = row * (size_t)counts.y;
    size_t b00 = (size_t)i3 * plane + (size_t)i2 * row;
    size_t b01 = (size_t)i3 * plane + (size_t)j2 * row;
    size_t b10 = (size_t)j3 * plane + (size_t)i2 * row;
    size_t b11 = (size_t)j3 * plane + (size_t)j2 * row;
    real4 c00 = mix(convert_real4(grid[b00 + i1]), convert_real4(grid[b00 + j1]), w1);
    real4 c01 = mix(convert_real4(grid[b01 + i1]), convert_real4(grid[b01 + j1]), w1);
    real4 c10 = mix(convert_real4(grid[b10 + i1]), convert_real4(grid[b10 + j1]), w1);
    real4 c11 = mix(convert_real4(grid[b11 + i1]), convert_real4(grid[b11 + j1]), w1);
    real4 c0 = mix(c00, c01, w2);
    real4 c1 = mix(c10, c11, w2);
    real4 s = mix(c0, c1, w3);
    s.x += PARAM(params, P_NREF);
    return s;
}

#else /* closed-form fields */

inline real4 field_sample(FIELD_ARGS, real3 p)
{
    (void)grid;
    (void)counts;
    real a0 = real_from_pair(params[P_ANALYTIC_HI], params[P_ANALYTIC_LO]);
    real a1 = real_from_pair(params[P_ANALYTIC_HI + 1], params[P_ANALYTIC_LO + 1]);
#if RIMCL_FIELD == RIMCL_FIELD_UNIFORM
    (void)a1;
    (void)p;
    return (real4)(a0, (real)0, (real)0, (real)0);
#elif RIMCL_FIELD == RIMCL_FIELD_GRIN
    real n = a0 * sqrt((real)1 - a1 * a1 * p.y * p.y);
    return (real4)(n, (real)0, -a0 * a0 * a1 * a1 * p.y / n, (real)0);
#elif RIMCL_FIELD == RIMCL_FIELD_FISHEYE
    (void)a1;
    real q = (real)1 + p.x * p.x + p.y * p.y;
    real n = a0 / q;
    real scale = (real)(-2) * n / q;
    return (real4)(n, scale * p.x, scale * p.y, (real)0);
#elif RIMCL_FIELD == RIMCL_FIELD_LINEAR
    return (real4)(a0 + a1 * p.y, (real)0, a1, (real)0);
#else
#error "unknown RIMCL_FIELD"
#endif
}

#endif /* RIMCL_FIELD */

#endif
