/*
 * rimcl_bspline.h -- cubic B-spline interpolation of delta_n with its analytic gradient.
 *
 * Purpose: field_sample(p) for RIMCL_INTERP == RIMCL_INTERP_BSPLINE3 (included by
 * rimcl_field.h, not on its own). n and grad n come from the same C2 spline, so they
 * are consistent (DESIGN §4.3); 4 x 4 x 4 = 64 coefficients per sample.
 * The coefficients are prefiltered on the host (rimcl/bspline.py) so that the spline
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
    u = (fabs(u) < (real)1e9) ? u : (real)0;
    real fl = real_floor(u);
    int i = (int)fl % n;
    i += (i < 0) ? n : 0;
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

RIMCL_INLINE real4 field_sample(FIELD_ARGS, real3 p)
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
    real value = (real)0, g1 = (real)0, g2 = (real)0, g3 = (real)0;
#pragma unroll
    for (int c = 0; c < 4; ++c) {
        /* sums over one x2-x1 plane of taps: value, d/du1, d/du2 */
        real pv = (real)0, p1 = (real)0, p2 = (real)0;
#pragma unroll
        for (int b = 0; b < 4; ++b) {
            __global const float *line = grid + (size_t)t3[c] * plane + (size_t)t2[b] * row;
            real q0 = line[t1[0]], q1 = line[t1[1]], q2 = line[t1[2]], q3 = line[t1[3]];
            real rv = w1[0] * q0 + w1[1] * q1 + w1[2] * q2 + w1[3] * q3;
            real rd = d1[0] * q0 + d1[1] * q1 + d1[2] * q2 + d1[3] * q3;
            pv += w2[b] * rv;
            p1 += w2[b] * rd;
            p2 += d2[b] * rv;
        }
        value += w3[c] * pv;
        g1 += w3[c] * p1;
        g2 += w3[c] * p2;
        g3 += d3[c] * pv;
    }
    real3 grad = (real3)(g1, g2, g3) * PARAM3(params, P_INVH_HI, P_INVH_LO);
    return (real4)(value + PARAM(params, P_NREF), grad.x, grad.y, grad.z);
}

#endif
