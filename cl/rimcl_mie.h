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
 * No kernels here; one call per ray.
 */
#ifndef RIMCL_MIE_H
#define RIMCL_MIE_H

#include "rimcl_inline.h"

#ifndef RIMCL_MIE
#define RIMCL_MIE 0
#endif

#if RIMCL_MIE
#define MIE_SHEET 0
#define MIE_POLARISATION 3
#define MIE_TERMS 6
/* |k x d| below this: d along k, where S1 = S2 (rimcl.mie._PARALLEL_TOLERANCE) */
#define MIE_PARALLEL_TOLERANCE 1e-9

/* The weight of a ray of unit initial direction d (rimcl/imaging/mie.py: weights, _amplitudes). */
RIMCL_INLINE double mie_weight(__global const double *mie, const int n_terms, const double d[3])
{
    __global const double *k = mie + MIE_SHEET;
    const double mu = clamp((d[0] * k[0] + d[1] * k[1]) + d[2] * k[2], -1.0, 1.0);
    double s1_re = 0.0, s1_im = 0.0, s2_re = 0.0, s2_im = 0.0;
    double pi_previous = 0.0, pi_current = 1.0;
    for (int n = 1; n <= n_terms; ++n) {
        __global const double *c = mie + MIE_TERMS + 4 * (n - 1);
        const double tau = n * mu * pi_current - (n + 1) * pi_previous;
        s1_re += c[0] * pi_current + c[2] * tau;
        s1_im += c[1] * pi_current + c[3] * tau;
        s2_re += c[0] * tau + c[2] * pi_current;
        s2_im += c[1] * tau + c[3] * pi_current;
        const double next = ((2 * n + 1) * mu * pi_current - (n + 1) * pi_previous) / n;
        pi_previous = pi_current;
        pi_current = next;
    }
    const double a1 = hypot(s1_re, s1_im), a2 = hypot(s2_re, s2_im);
    const double perpendicular = a1 * a1, parallel = a2 * a2;
#if RIMCL_MIE == 1
    return perpendicular;
#elif RIMCL_MIE == 2
    return parallel;
#elif RIMCL_MIE == 3
    return 0.5 * (perpendicular + parallel);
#else
    /* e_perp = k x d / |k x d|; its share of the polarisation, squared */
    const double normal[3] = {k[1] * d[2] - k[2] * d[1], k[2] * d[0] - k[0] * d[2],
                              k[0] * d[1] - k[1] * d[0]};
    const double length = sqrt((normal[0] * normal[0] + normal[1] * normal[1]) +
                               normal[2] * normal[2]);
    double share = 1.0;
    if (!(length < MIE_PARALLEL_TOLERANCE)) {
        __global const double *p = mie + MIE_POLARISATION;
        const double along = ((normal[0] / length) * p[0] + (normal[1] / length) * p[1]) +
                             (normal[2] / length) * p[2];
        share = along * along;
    }
    return share * perpendicular + (1.0 - share) * parallel;
#endif
}
#endif

#endif
