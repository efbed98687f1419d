/*
 * trace.cl -- Sharma-Kumar-Ghatak Runge-Kutta-Nystrom ray tracing to an exit plane.
 *
 * Solves d2R/dt2 = D(R), D = n grad(n), T = dR/dt (|T| = n), dt = ds / n, with the
 * 4th-order step (the paper's B is misprinted; this is the correct form):
 *   A = h D(R),  B = h D(R + h T/2 + h A/8),  C = h D(R + h T + h B/2)
 *   R += h (T + (A + 2B)/6),  T += (A + 4B + C)/6
 * The last step is shortened by Newton iteration on its length so that the ray ends
 * on the plane x1 = x_end (crossed in either direction). A ray that ends there has its T
 * rescaled so that |T| = n sampled at the exit point (the exit index; its direction is
 * kept). Straight back-projection and angles are done on the host in float64 from the
 * exit state written here.
 *
 * Step control (RIMCL_ADAPTIVE): 0, every step is h = P_STEP; 1, step doubling: each
 * attempt takes one step of h and two of h/2; their difference estimates the error of
 * the two half steps, e = (|dR| + depth |dT| / n_ref) / 15 (max norms, depth = P_DEPTH:
 * the lever arm of a direction error on the back-projected image r'). The attempt is
 * kept if e <= P_TOL * n h (error per unit arc length times the arc of the step) and
 * h is rescaled by 0.9 (allowed / e)^(1/4) within [0.2, 2] (no growth straight after a
 * rejection) and within [P_STEP_MIN, P_STEP_MAX]. A ray whose accepted attempt crosses
 * the exit plane ends with one step from the attempt's start, shortened by Newton.
 *
 * Required defines: RIMCL_PRECISION (rimcl_real.h), RIMCL_FIELD, RIMCL_INTERP and
 *   RIMCL_PERIODIC (rimcl_field.h). Optional: RIMCL_LANES, RIMCL_POCL_FAST
 *   (rimcl_real.h), RIMCL_ADAPTIVE (default 0).
 * Units: lengths in field units; h is a step in t (arc length = n h).
 * Axis order: every 3-vector is (x1, x2, x3); x1 is the depth (marching) axis.
 * Work-item: RIMCL_LANES consecutive rays, advanced together in the lanes of vector
 *   types (finished rays are frozen until every lane has finished).
 * Global size: ceil(n_rays / RIMCL_LANES) (extra items return).
 *
 * rays_in  (n_rays x RAY_IN_STRIDE floats): origin hi[3], origin lo[3],
 *          unit direction hi[3], direction lo[3] (float64 values split in pairs).
 * rays_out (n_rays x RAY_OUT_STRIDE floats): R hi[3], R lo[3], T hi[3], T lo[3] (|T| = n at
 *          the exit point for rays that end on the plane),
 *          S = integral of ds, optical path = integral of n ds,
 *          integral of (grad n / n) perpendicular to the ray, ds [3].
 * ray_info (n_rays int4): steps taken (accepted steps if adaptive), status (RAY_* of
 *          rimcl_trace.h), rejected step attempts, Sharma steps evaluated in all (the work).
 */
#include "rimcl_trace.h"

__kernel void trace_rays(FIELD_GRID_TYPE grid, const int4 counts, __constant const float *params,
                         __global const float *rays_in, __global float *rays_out,
                         __global int4 *ray_info, const int max_steps, const int n_rays)
{
    const int first = get_global_id(0) * RIMCL_LANES;
    if (first >= n_rays)
        return;

    /* Load the rays; lanes past the last ray repeat it and are never stored. */
    lvec3 origin_hi, origin_lo, dir_hi, dir_lo;
    lmask valid;
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        int ray = (first + k < n_rays) ? first + k : n_rays - 1;
        __global const float *in = rays_in + (size_t)ray * RAY_IN_STRIDE;
        LANE(origin_hi.x, k) = in[0];
        LANE(origin_hi.y, k) = in[1];
        LANE(origin_hi.z, k) = in[2];
        LANE(origin_lo.x, k) = in[3];
        LANE(origin_lo.y, k) = in[4];
        LANE(origin_lo.z, k) = in[5];
        LANE(dir_hi.x, k) = in[6];
        LANE(dir_hi.y, k) = in[7];
        LANE(dir_hi.z, k) = in[8];
        LANE(dir_lo.x, k) = in[9];
        LANE(dir_lo.y, k) = in[10];
        LANE(dir_lo.z, k) = in[11];
#if RIMCL_LANES == 1
        valid = 1;
#else
        LANE_I(valid, k) = (first + k < n_rays) ? -1 : 0;
#endif
    }

    const lane_result res = trace_lanes(FIELD_PASS, origin_hi, origin_lo, dir_hi, dir_lo, valid,
                                        max_steps);
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        if (first + k >= n_rays)
            break;
        store_lane_record(rays_out + (size_t)(first + k) * RAY_OUT_STRIDE, ray_info + first + k,
                          &res, k);
    }
}
