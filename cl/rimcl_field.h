/*
 * rimcl_field.h -- refractive index n and its gradient at a point.
 *
 * Purpose: field_sample_lanes(p, active, out) -> n, dn/dx1, dn/dx2, dn/dx3 at the
 * positions p (x1, x2, x3) of the active lanes of a work-item (rimcl_real.h), in the
 * working precision `real`; field_sample_lanes_base(p, active, out, n_base) the same with
 * n - n_ref + n_base in place of n (n_base 0: delta_n itself, without the rounding of
 * n_ref + delta_n in float). Trilinear sampling finds cells and weights for all lanes in
 * vector registers and blends lane by lane, or with 16 float lanes on PoCL all lanes at
 * once after a transpose in registers (the same bits); the other kinds call the one-point
 * field_sample_base(p, n_base) per lane. With RIMCL_POCL_FAST, field_prefetch_lanes (trilinear)
 * fetches the cells a step ahead into the cache (RIMCL_FIELD_PREFETCH is then 1).
 * Required defines:
 *   RIMCL_FIELD    RIMCL_FIELD_GRID (0): gridded, interpolated as RIMCL_INTERP says,
 *                  n = n_ref + delta_n;
 *                  closed forms for verification: RIMCL_FIELD_UNIFORM (1) n = a0;
 *                  RIMCL_FIELD_GRIN (2) n^2 = a0^2 (1 - a1^2 x2^2);
 *                  RIMCL_FIELD_FISHEYE (3) n = a0 / (1 + x1^2 + x2^2);
 *                  RIMCL_FIELD_LINEAR (4) n = a0 + a1 x2.
 *   RIMCL_INTERP   (gridded fields) RIMCL_INTERP_TRILINEAR (0, default): software
 *                  trilinear interpolation of float4 nodes (delta_n, dn/dx1, dn/dx2,
 *                  dn/dx3); RIMCL_INTERP_TEXTURE (1): the same nodes in an image3d_t
 *                  (RGBA float) read with the hardware's linear filter;
 *                  RIMCL_INTERP_BSPLINE3 (2): cubic B-spline of delta_n with its
 *                  analytic gradient (rimcl_bspline.h).
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

#define RIMCL_INTERP_TRILINEAR 0
#define RIMCL_INTERP_TEXTURE 1
#define RIMCL_INTERP_BSPLINE3 2

#ifndef RIMCL_FIELD
#error "RIMCL_FIELD must be defined (0 grid, 1 uniform, 2 grin, 3 fisheye, 4 linear)"
#endif
#ifndef RIMCL_PERIODIC
#define RIMCL_PERIODIC 0
#endif
#ifndef RIMCL_INTERP
#define RIMCL_INTERP RIMCL_INTERP_TRILINEAR
#endif

/* The field argument of every kernel and sampler: what one grid node holds. */
#if RIMCL_FIELD == RIMCL_FIELD_GRID && RIMCL_INTERP == RIMCL_INTERP_TEXTURE
#define FIELD_GRID_TYPE __read_only image3d_t
#elif RIMCL_FIELD == RIMCL_FIELD_GRID && RIMCL_INTERP == RIMCL_INTERP_BSPLINE3
#define FIELD_GRID_TYPE __global const float *
#else
#define FIELD_GRID_TYPE __global const float4 *
#endif
#define FIELD_ARGS FIELD_GRID_TYPE grid, int4 counts, __constant const float *params
#define FIELD_PASS grid, counts, params

/* n and grad n of every lane, in lane form */
typedef struct {
    lreal n, g1, g2, g3;
} lsample;

#if RIMCL_FIELD == RIMCL_FIELD_GRID

/* Position in cells (node i at u = i) of point p. */
RIMCL_INLINE real3 grid_coordinates(__constant const float *params, real3 p)
{
    return (p - PARAM3(params, P_ORIGIN_HI, P_ORIGIN_LO)) * PARAM3(params, P_INVH_HI, P_INVH_LO);
}

#if RIMCL_INTERP == RIMCL_INTERP_TRILINEAR

/* Lower node index, weight and index step to the upper node along an axis of n nodes,
 * for every lane. NaN or huge u (a ray that has failed) still gives an index inside
 * the grid. */
RIMCL_INLINE lint lanes_cell_of(lreal u, int n, lreal *w, lint *step_up)
{
#if RIMCL_PERIODIC
    u = (fabs(u) < (real)1e6) ? u : (lreal)((real)0);
    lreal fl = lreal_floor(u);
    *w = u - fl;
    /* fl modulo n without integer division (vector units have none) */
    lint i = convert_lint(fl - (real)n * lreal_floor(fl * ((real)1 / (real)n)));
    i += (i < 0) ? (lint)n : (lint)0;
    i -= (i >= n) ? (lint)n : (lint)0;
    *step_up = (i + 1 == n) ? (lint)(1 - n) : (lint)1;
    return i;
#else
    real top = (real)(n - 1);
    u = (u >= (real)0) ? ((u <= top) ? u : (lreal)top) : (lreal)((real)0);
    lint i = convert_lint(u);
    int last = (n > 1) ? n - 2 : 0;
    i = (i > last) ? (lint)last : i;
    *w = u - convert_lreal(i);
    *step_up = (n > 1) ? (lint)1 : (lint)0;
    return i;
#endif
}

/* Node index of the lower corner of the cell holding p, and the index steps to the
 * upper neighbours along x1, x2, x3, for every lane. */
RIMCL_INLINE lint lanes_cell(FIELD_ARGS, lvec3 p, lreal *w1, lreal *w2, lreal *w3, lint *up1,
                             lint *up2, lint *up3)
{
    const real3 origin = PARAM3(params, P_ORIGIN_HI, P_ORIGIN_LO);
    const real3 inv_h = PARAM3(params, P_INVH_HI, P_INVH_LO);
    lint i1 = lanes_cell_of((p.x - origin.x) * inv_h.x, counts.x, w1, up1);
    lint i2 = lanes_cell_of((p.y - origin.y) * inv_h.y, counts.y, w2, up2);
    lint i3 = lanes_cell_of((p.z - origin.z) * inv_h.z, counts.z, w3, up3);
    const int row = counts.x;
    const int plane = counts.x * counts.y;
    *up2 *= row;
    *up3 *= plane;
    return i3 * plane + i2 * row + i1;
}

RIMCL_INLINE real4 lerp4(float4 a, float4 b, real w)
{
    real4 low = convert_real4(a);
    return low + w * (convert_real4(b) - low);
}

#if RIMCL_POCL_FAST && RIMCL_PRECISION != RIMCL_F64 && RIMCL_LANES == 16
/* The nodes of four lanes side by side: (δn, g1, g2, g3) of lane a, then b, c, d. */
#define NODES4(g, i, a) \
    __builtin_shufflevector( \
        __builtin_shufflevector(g[(i)[a]], g[(i)[(a) + 1]], 0, 1, 2, 3, 4, 5, 6, 7), \
        __builtin_shufflevector(g[(i)[(a) + 2]], g[(i)[(a) + 3]], 0, 1, 2, 3, 4, 5, 6, 7), 0, 1, \
        2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
/* Of the nodes of eight lanes (lanes 0-3 in lo, 4-7 in hi): δn and g1 of the eight lanes
 * (N_G1), or g2 and g3 (G2_G3). */
#define N_G1(lo, hi) \
    __builtin_shufflevector(lo, hi, 0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29)
#define G2_G3(lo, hi) \
    __builtin_shufflevector(lo, hi, 2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31)

/* The node values of the 16 lanes at node index idx, as one lreal per component: the
 * lanes' float4 nodes loaded one by one, then transposed in registers (a lane-by-lane
 * copy into the components doubles the time of the whole trace). */
RIMCL_INLINE void lanes_nodes(__global const float4 *grid, lint idx, lreal *v)
{
    const float16 first = N_G1(NODES4(grid, idx, 0), NODES4(grid, idx, 4));
    const float16 second = G2_G3(NODES4(grid, idx, 0), NODES4(grid, idx, 4));
    const float16 first_hi = N_G1(NODES4(grid, idx, 8), NODES4(grid, idx, 12));
    const float16 second_hi = G2_G3(NODES4(grid, idx, 8), NODES4(grid, idx, 12));
#define LOWER_HALVES(a, b) \
    __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23)
#define UPPER_HALVES(a, b) \
    __builtin_shufflevector(a, b, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31)
    v[0] = LOWER_HALVES(first, first_hi);
    v[1] = UPPER_HALVES(first, first_hi);
    v[2] = LOWER_HALVES(second, second_hi);
    v[3] = UPPER_HALVES(second, second_hi);
#undef LOWER_HALVES
#undef UPPER_HALVES
}
#undef NODES4
#undef N_G1
#undef G2_G3

/* Trilinear interpolation of the float4 nodes with the 16 lanes in vectors (structure of
 * arrays; PoCL, float): cells, weights and the blend of all lanes at once, the same
 * operations in the same order as the lane-by-lane version below, so the same bits.
 * Measured (2-core AMD EPYC Zen 5, PoCL 3.1): the fan kernel 13 % faster on the 64³
 * sample; through trace_rays 25 % faster than 8 lanes lane by lane on a 128³ field; at 8
 * lanes it was 10 % slower than lane by lane.
 * Inactive lanes load from a cell inside the grid too (lanes_cell_of) and keep their
 * values in *out (finished rays are frozen). */
RIMCL_INLINE void field_sample_lanes_base(FIELD_ARGS, lvec3 p, lmask active, lsample *out,
                                          const real n_base)
{
    lreal w1, w2, w3;
    lint up1, up2, up3;
    const lint base = lanes_cell(FIELD_PASS, p, &w1, &w2, &w3, &up1, &up2, &up3);
    lreal c000[4], c100[4], c010[4], c110[4], c001[4], c101[4], c011[4], c111[4];
    lanes_nodes(grid, base, c000);
    lanes_nodes(grid, base + up1, c100);
    lanes_nodes(grid, base + up2, c010);
    lanes_nodes(grid, base + up2 + up1, c110);
    lanes_nodes(grid, base + up3, c001);
    lanes_nodes(grid, base + up3 + up1, c101);
    lanes_nodes(grid, base + up3 + up2, c011);
    lanes_nodes(grid, base + up3 + up2 + up1, c111);
    lreal s[4];
#pragma unroll
    for (int m = 0; m < 4; ++m) {
        const lreal c00 = c000[m] + w1 * (c100[m] - c000[m]);
        const lreal c01 = c010[m] + w1 * (c110[m] - c010[m]);
        const lreal c10 = c001[m] + w1 * (c101[m] - c001[m]);
        const lreal c11 = c011[m] + w1 * (c111[m] - c011[m]);
        const lreal c0 = c00 + w2 * (c01 - c00);
        s[m] = c0 + w3 * (c10 + w2 * (c11 - c10) - c0);
    }
    out->n = active ? n_base + s[0] : out->n;
    out->g1 = active ? s[1] : out->g1;
    out->g2 = active ? s[2] : out->g2;
    out->g3 = active ? s[3] : out->g3;
}
#else
/* Trilinear interpolation of the float4 nodes: the cells and weights of all lanes are
 * found at once in vector registers, the 8 corner loads and the blend lane by lane.
 * Lanes not in `active` keep their values in *out (finished rays are frozen). */
RIMCL_INLINE void field_sample_lanes_base(FIELD_ARGS, lvec3 p, lmask active, lsample *out,
                                          const real n_base)
{
    lreal w1, w2, w3;
    lint up1, up2, up3;
    lint base = lanes_cell(FIELD_PASS, p, &w1, &w2, &w3, &up1, &up2, &up3);
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        if (LANE_I(active, k)) {
            __global const float4 *c = grid + LANE_I(base, k);
            const int d1 = LANE_I(up1, k), d2 = LANE_I(up2, k), d3 = LANE_I(up3, k);
            const real f1 = LANE(w1, k), f2 = LANE(w2, k), f3 = LANE(w3, k);
            real4 c00 = lerp4(c[0], c[d1], f1);
            real4 c01 = lerp4(c[d2], c[d2 + d1], f1);
            real4 c10 = lerp4(c[d3], c[d3 + d1], f1);
            real4 c11 = lerp4(c[d3 + d2], c[d3 + d2 + d1], f1);
            real4 c0 = c00 + f2 * (c01 - c00);
            real4 s = c0 + f3 * (c10 + f2 * (c11 - c10) - c0);
            LANE(out->n, k) = n_base + s.x;
            LANE(out->g1, k) = s.y;
            LANE(out->g2, k) = s.z;
            LANE(out->g3, k) = s.w;
        }
    }
}
#endif
#define RIMCL_LANE_SAMPLER

#if RIMCL_POCL_FAST
/* Ask the CPU to fetch the cells at the positions p of the active lanes into its cache
 * (a ray's next cells are known a step ahead: the path bends little over a step). Fields
 * are usually larger than the cache, and a field that fits runs 20-30 % faster;
 * measured here: +15-40 % on 128^3 nodes, -8 % when the field fits. */
RIMCL_INLINE void field_prefetch_lanes(FIELD_ARGS, lvec3 p, lmask active)
{
    lreal w1, w2, w3;
    lint up1, up2, up3;
    lint base = lanes_cell(FIELD_PASS, p, &w1, &w2, &w3, &up1, &up2, &up3);
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        if (LANE_I(active, k)) {
            __global const float4 *c = grid + LANE_I(base, k);
            const int d2 = LANE_I(up2, k), d3 = LANE_I(up3, k);
            __builtin_prefetch(c, 0, 3);
            __builtin_prefetch(c + d2, 0, 3);
            __builtin_prefetch(c + d3, 0, 3);
            __builtin_prefetch(c + d2 + d3, 0, 3);
        }
    }
}
#define RIMCL_FIELD_PREFETCH 1
#endif

#elif RIMCL_INTERP == RIMCL_INTERP_TEXTURE

/* Node i sits at the centre of texel i, i.e. at texture coordinate i + 0.5. A periodic
 * grid needs CLK_ADDRESS_REPEAT, which only exists with normalised coordinates. */
#if RIMCL_PERIODIC
__constant sampler_t field_sampler =
    CLK_NORMALIZED_COORDS_TRUE | CLK_ADDRESS_REPEAT | CLK_FILTER_LINEAR;
#else
__constant sampler_t field_sampler =
    CLK_NORMALIZED_COORDS_FALSE | CLK_ADDRESS_CLAMP_TO_EDGE | CLK_FILTER_LINEAR;
#endif

RIMCL_INLINE real4 field_sample_base(FIELD_ARGS, real3 p, const real n_base)
{
    (void)counts;
    real3 u = grid_coordinates(params, p);
    float4 at = (float4)((float)u.x, (float)u.y, (float)u.z, 0.0f) + 0.5f;
#if RIMCL_PERIODIC
    at /= convert_float4(get_image_dim(grid));
    at.w = 0.0f;
#endif
    real4 s = convert_real4(read_imagef(grid, field_sampler, at));
    s.x += n_base;
    return s;
}

#elif RIMCL_INTERP == RIMCL_INTERP_BSPLINE3

#include "rimcl_bspline.h"

#else
#error "unknown RIMCL_INTERP"
#endif

#else /* closed-form fields */

/* Closed forms give n itself: n_base other than n_ref shifts it by n_base - n_ref. */
RIMCL_INLINE real4 field_sample_closed(FIELD_ARGS, real3 p)
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


RIMCL_INLINE real4 field_sample_base(FIELD_ARGS, real3 p, const real n_base)
{
    real4 s = field_sample_closed(FIELD_PASS, p);
    s.x += n_base - PARAM(params, P_NREF);
    return s;
}

#endif /* RIMCL_FIELD */

#ifndef RIMCL_LANE_SAMPLER
/* Sample the field at the positions of the lanes in `active`, one lane at a time; the
 * other lanes of *out keep their values (finished rays are frozen). The loop is not
 * unrolled: a sample is long (64 taps for bspline3), and 8 copies of it build slowly
 * (13 s against 3 s on PoCL) for no gain in speed. */
RIMCL_INLINE void field_sample_lanes_base(FIELD_ARGS, lvec3 p, lmask active, lsample *out,
                                          const real n_base)
{
#pragma unroll 1
    for (int k = 0; k < RIMCL_LANES; ++k) {
        if (LANE_I(active, k)) {
            real4 s = field_sample_base(FIELD_PASS, (real3)(LANE(p.x, k), LANE(p.y, k), LANE(p.z, k)),
                                        n_base);
            LANE(out->n, k) = s.x;
            LANE(out->g1, k) = s.y;
            LANE(out->g2, k) = s.z;
            LANE(out->g3, k) = s.w;
        }
    }
}
#endif

/* n, dn/dx1, dn/dx2, dn/dx3 at the positions of the lanes in `active`. */
RIMCL_INLINE void field_sample_lanes(FIELD_ARGS, lvec3 p, lmask active, lsample *out)
{
    field_sample_lanes_base(FIELD_PASS, p, active, out, PARAM(params, P_NREF));
}

#ifndef RIMCL_FIELD_PREFETCH
#define RIMCL_FIELD_PREFETCH 0
#endif

#endif
