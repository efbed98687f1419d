/*
 * rimcl_bspline.h -- cubic B-spline interpolation of delta_n with its analytic gradient.
 *
 * Purpose: field_sample_base(p, n_base) for RIMCL_INTERP == RIMCL_INTERP_BSPLINE3 (included by
 * rimcl_field.h, not on its own). n and grad n come from the same C2 spline, so they
 * are consistent; 4 x 4 x 4 = 64 coefficients per sample.
 * The coefficients are prefiltered on the host (rimcl/fields/bspline.py) so that the spline
 * interpolates delta_n at the nodes:
 *   RIMCL_PERIODIC 0: array (n3 + 3, n2 + 3, n1 + 3), coefficient of node i at index
 *                     i + 1 (nodes -1 .. n + 1 along every axis); positions are clamped
 *                     to the grid, as for trilinear interpolation.
 *   RIMCL_PERIODIC 1: array (n3, n2, n1), indices wrap.
 * Required defines: as rimcl_field.h. Memory order: C-order, x1 fastest.
 * Units: lengths in field units, gradient in 1 / length.
 */
#ifndef RIMCL_BSPLINE_H
#define RIMCL_BSPLINE_H

/* Uniform cubic B-spline weights of the taps i-1, i, i+1, i+2 at fraction t in [0, 1],
 * and their derivatives with respect to t. */
RIMCL_INLINE void bspline_weights(real t, real *w, real *dw)
{
    const real sixth = (real)1 / (real)6;
    real s = (real)1 - t;
    real t2 = t * t;
    w[0] = sixth * s * s * s;
    w[1] = (real)2 / (real)3 - t2 + (real)0.5 * t2 * t;
    w[2] = sixth + (real)0.5 * (t + t2 - t2 * t);
    w[3] = sixth * t2 * t;
    dw[0] = (real)(-0.5) * s * s;
    dw[1] = (real)1.5 * t2 - (real)2 * t;
    dw[2] = (real)0.5 + t - (real)1.5 * t2;
    dw[3] = (real)0.5 * t2;
}

/* Array indices of the 4 taps along an axis of n nodes, the tap weights and their
 * derivatives, at coordinate u (in cells). */
RIMCL_INLINE void bspline_axis(real u, int n, int *taps, real *w, real *dw)
{
#if RIMCL_PERIODIC
    u = (fabs(u) < (real)1e6) ? u : (real)0;
    real fl = real_floor(u);
    /* fl modulo n without an integer division */
    int i = (int)(fl - (real)n * real_floor(fl * ((real)1 / (real)n)));
    i += (i < 0) ? n : 0;
    i -= (i >= n) ? n : 0;
#pragma unroll
    for (int k = 0; k < 4; ++k) {
        int j = i - 1 + k;
        taps[k] = (j < 0) ? j + n : ((j >= n) ? j - n : j);
    }
    bspline_weights(u - fl, w, dw);
#else
    real top = (real)(n - 1);
    u = (u >= (real)0) ? ((u <= top) ? u : top) : (real)0;
    int i = (int)u;
    int last = (n > 1) ? n - 2 : 0;
    i = (i > last) ? last : i;
#pragma unroll
    for (int k = 0; k < 4; ++k)
        taps[k] = i + k; /* node i - 1 + k is stored at i + k */
    bspline_weights(u - (real)i, w, dw);
#endif
}

RIMCL_INLINE real4 field_sample_base(FIELD_ARGS, real3 p, const real n_base)
{
    real3 u = grid_coordinates(params, p);
    int t1[4], t2[4], t3[4];
    real w1[4], w2[4], w3[4], d1[4], d2[4], d3[4];
    bspline_axis(u.x, counts.x, t1, w1, d1);
    bspline_axis(u.y, counts.y, t2, w2, d2);
    bspline_axis(u.z, counts.z, t3, w3, d3);
#if RIMCL_PERIODIC
    size_t row = (size_t)counts.x;
    size_t plane = row * (size_t)counts.y;
#else
    size_t row = (size_t)counts.x + 3;
    size_t plane = row * ((size_t)counts.y + 3);
#endif
    /* x1 rows of 4 coefficients summed over the x2 taps (weights w2 and dw2) in each x3
     * plane, then over the planes (w3 and dw3); the dot with the x1 weights comes last */
    real4 sum = (real4)((real)0), sum2 = (real4)((real)0), sum3 = (real4)((real)0);
#pragma unroll
    for (int c = 0; c < 4; ++c) {
        real4 plane_sum = (real4)((real)0), plane_sum2 = (real4)((real)0);
#pragma unroll
        for (int b = 0; b < 4; ++b) {
            __global const float *line = grid + (size_t)t3[c] * plane + (size_t)t2[b] * row;
            real4 q = convert_real4((float4)(line[t1[0]], line[t1[1]], line[t1[2]], line[t1[3]]));
            plane_sum += w2[b] * q;
            plane_sum2 += d2[b] * q;
        }
        sum += w3[c] * plane_sum;
        sum2 += w3[c] * plane_sum2;
        sum3 += d3[c] * plane_sum;
    }
    real4 x1_weights = (real4)(w1[0], w1[1], w1[2], w1[3]);
    real4 x1_slopes = (real4)(d1[0], d1[1], d1[2], d1[3]);
    real value = dot(sum, x1_weights);
    real g1 = dot(sum, x1_slopes);
    real g2 = dot(sum2, x1_weights);
    real g3 = dot(sum3, x1_weights);
    real3 grad = (real3)(g1, g2, g3) * PARAM3(params, P_INVH_HI, P_INVH_LO);
    return (real4)(value + n_base, grad.x, grad.y, grad.z);
}

#endif
