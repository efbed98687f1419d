/*
 * rimcl_mie.h -- the Mie scattering weight of a ray from its initial direction.
 *
 * Purpose: the light a tracer scatters into a ray's initial direction, as
 * rimcl.mie.MieWeights.weights computes it on the host (same series, same order of float64
 * operations; the dot product and hypot may differ from NumPy's in the last ulp). Used by
 * fan.cl so that Mie weights never leave the device.
 *
 * Defines: RIMCL_MIE 0 none (every ray weighs 1; nothing here is compiled), 1 |S1|^2
 *   (perpendicular), 2 |S2|^2 (parallel), 3 unpolarised (their mean), 4 a linear
 *   polarisation direction (each ray's share of S1 from its scattering plane).
 * Needs cl_khr_fp64.
 * Units: dimensionless (Wiscombe normalisation of S1, S2).
 * Axis order: directions are (x1, x2, x3).
 * Layout of `mie` (doubles): sheet direction k (3), polarisation direction (3), then per
 *   order n = 1 .. n_terms the scaled coefficients (2n + 1) / (n (n + 1)) a_n and b_n as
 *   (Re a, Im a, Re b, Im b).
 * No kernels here; one call per work-item (its RIMCL_LANES rays).
 */
#ifndef RIMCL_MIE_H
#define RIMCL_MIE_H

#include "rimcl_inline.h"

#ifndef RIMCL_MIE
#define RIMCL_MIE 0
#endif

#if RIMCL_MIE
#ifndef RIMCL_LANES
#define RIMCL_LANES 1
#endif
#define MIE_SHEET 0
#define MIE_POLARISATION 3
#define MIE_TERMS 6
/* |k x d| below this: d along k, where S1 = S2 (rimcl.mie._PARALLEL_TOLERANCE) */
#define MIE_PARALLEL_TOLERANCE 1e-9

/* The weights of the RIMCL_LANES rays of a work-item, of unit initial directions d[k]
 * (rimcl/imaging/mie.py: weights, _amplitudes), written to weight[k]. Each ray's series
 * runs the host's operations in its order; the orders n are the outer loop and the lanes
 * the inner one, so that the lanes' independent recurrences (a division per order) overlap
 * and vectorise instead of running one ray after another. */
RIMCL_INLINE void mie_weight_lanes(__global const double *mie, const int n_terms,
                                   const double d[RIMCL_LANES][3], double *weight)
{
    __global const double *k = mie + MIE_SHEET;
    double mu[RIMCL_LANES], pi_previous[RIMCL_LANES], pi_current[RIMCL_LANES];
    double s1_re[RIMCL_LANES], s1_im[RIMCL_LANES], s2_re[RIMCL_LANES], s2_im[RIMCL_LANES];
    for (int lane = 0; lane < RIMCL_LANES; ++lane) {
        mu[lane] = clamp((d[lane][0] * k[0] + d[lane][1] * k[1]) + d[lane][2] * k[2], -1.0, 1.0);
        pi_previous[lane] = 0.0;
        pi_current[lane] = 1.0;
        s1_re[lane] = s1_im[lane] = s2_re[lane] = s2_im[lane] = 0.0;
    }
    for (int n = 1; n <= n_terms; ++n) {
        __global const double *c = mie + MIE_TERMS + 4 * (n - 1);
        const double c0 = c[0], c1 = c[1], c2 = c[2], c3 = c[3];
        for (int lane = 0; lane < RIMCL_LANES; ++lane) {
            const double tau = n * mu[lane] * pi_current[lane] - (n + 1) * pi_previous[lane];
            s1_re[lane] += c0 * pi_current[lane] + c2 * tau;
            s1_im[lane] += c1 * pi_current[lane] + c3 * tau;
            s2_re[lane] += c0 * tau + c2 * pi_current[lane];
            s2_im[lane] += c1 * tau + c3 * pi_current[lane];
            const double next =
                ((2 * n + 1) * mu[lane] * pi_current[lane] - (n + 1) * pi_previous[lane]) / n;
            pi_previous[lane] = pi_current[lane];
            pi_current[lane] = next;
        }
    }
    for (int lane = 0; lane < RIMCL_LANES; ++lane) {
        const double a1 = hypot(s1_re[lane], s1_im[lane]), a2 = hypot(s2_re[lane], s2_im[lane]);
        const double perpendicular = a1 * a1, parallel = a2 * a2;
#if RIMCL_MIE == 1
        (void)parallel;
        weight[lane] = perpendicular;
#elif RIMCL_MIE == 2
        (void)perpendicular;
        weight[lane] = parallel;
#elif RIMCL_MIE == 3
        weight[lane] = 0.5 * (perpendicular + parallel);
#else
        /* e_perp = k x d / |k x d|; its share of the polarisation, squared */
        const double *e = d[lane];
        const double normal[3] = {k[1] * e[2] - k[2] * e[1], k[2] * e[0] - k[0] * e[2],
                                  k[0] * e[1] - k[1] * e[0]};
        const double length = sqrt((normal[0] * normal[0] + normal[1] * normal[1]) +
                                   normal[2] * normal[2]);
        double share = 1.0;
        if (!(length < MIE_PARALLEL_TOLERANCE)) {
            __global const double *p = mie + MIE_POLARISATION;
            const double along = ((normal[0] / length) * p[0] + (normal[1] / length) * p[1]) +
                                 (normal[2] / length) * p[2];
            share = along * along;
        }
        weight[lane] = share * perpendicular + (1.0 - share) * parallel;
#endif
    }
}
#endif

#endif
