/*
 * fan.cl -- a camera's rays from a batch of tracers, made, traced and imaged on the device.
 *
 * The device engine's first stage. Ray g of the batch belongs to tracer
 * g / K and aims at the camera's aim point g % K (K rays per tracer). Slot s of the batch
 * (lane s % RIMCL_LANES of work-item s / RIMCL_LANES) traces ray (s / K) K + order[s % K]:
 * `order` groups rays of similar path length in a work-item, whose lanes all step until
 * its longest ray ends (rimcl.engine.lane_order). Each ray is made
 * from float64 tracer and aim positions exactly as rimcl.camera and rimcl.trace_rays make
 * it on the host (difference, two normalisations, float (hi, lo) pairs; behind a window
 * LensCamera.directions' Newton solve, then one normalisation), so the trace sees the same
 * input bits; it is traced by trace_lanes() (rimcl_trace.h); its exit state is refracted
 * by the window (if any), back-projected to the plane the camera images and tested
 * against the camera in float64 with the host's operations (rimcl/optics/trace.py _finish,
 * rimcl/optics/camera.py collected, through_window, image_points, rimcl/imaging/render.py to_pixels),
 * so its image point in pixels is the one the NumPy engine images.
 *
 * Required defines: those of trace.cl (RIMCL_PRECISION, RIMCL_FIELD, RIMCL_INTERP,
 *   RIMCL_PERIODIC; optional RIMCL_LANES, RIMCL_POCL_FAST, RIMCL_ADAPTIVE) and
 *   RIMCL_CAMERA: 0 plane camera (every ray that reaches the exit plane is collected),
 *   1 pupil camera (a ray is collected if its straight continuation passes the pupil;
 *     also a lens camera without a window: its pupil on the x1 axis, its image points
 *     back-projected onto the sheet, which is its focus plane),
 *   2 lens camera behind a flat window (rimcl.camera.LensCamera with a FlatWindow, of
 *     thickness 0 for the bare fluid/air interface): directions solved to reach the pupil
 *     points through fluid (the camera's mean index), glass and outside medium; exit rays
 *     refracted at both window faces with the ray's own index at its exit point (|T|, or
 *     straight_index for a uniform field), tested against the pupil and back-projected
 *     onto the focus plane x1 = focus_x1.
 * Optional: RIMCL_MIE (rimcl_mie.h): 0 (default) every ray weighs 1 and ray_weight is not
 *   written; otherwise each ray's Mie weight from its initial direction goes to ray_weight.
 *   RIMCL_STRAIGHT: 1 for a uniform field (the reference medium, G = 0): no trace, each
 *   ray runs straight to x1 = x_end_exact in float64 as rimcl.trace.straight_rays (0
 *   steps; max_steps past a path of max_length, exit_side past the lateral box box23 =
 *   (lo2, hi2, lo3, hi3), turned_back if it does not move towards the plane); its sample
 *   records are not written (the host makes them). Default 0.
 *   RIMCL_TRACER_DEPTH: 0 (default) tracers are (x2, x3) on the sheet x1 = x_sheet (PTV);
 *   1 tracers are (x1, x2, x3), each at its own depth across a light sheet (PIV).
 *   RIMCL_IMAGE_PLANE: 0 (default) rays are imaged on the sheet (cameras 0, 1) or the lens's
 *   focus plane (camera 2); 1 on each tracer's own plane x1 (rimcl.trace_rays' image_pos,
 *   the plane and pupil cameras of PIV frames, whose depth of field covers the sheet).
 * Needs cl_khr_fp64.
 * Units: lengths in field units; image points in pixels of the camera (pixel i spans
 *   [i, i + 1) from the image origin); refractive indices as ratios (dimensionless).
 * Axis order: 3-vectors are (x1, x2, x3); tracers and image points are (x2, x3).
 * Kernels: trace_fan (the stage); fan_directions (each ray's initial direction, for tests).
 * Work-item: RIMCL_LANES consecutive slots of the batch; fan_directions: one ray.
 * Global size: ceil(n_rays / RIMCL_LANES) (extra items return); fan_directions: n_rays.
 *
 * tracers (B x 4 doubles, or B x 5 with RIMCL_TRACER_DEPTH): tracer positions (x2, x3) on
 *   the sheet, or (x1, x2, x3) at their own depths, then the point (x2, x3) its rays are
 *   aimed from (the tracer, or the tracer minus its aim shift: rimcl/optics/aiming.py).
 * aims    (K x 3 doubles): the camera's aim points (x1, x2, x3) (a lens: its pupil's).
 * order   (K ints): a permutation of the aim points, the order their rays fill lanes in.
 * camera  (CAM_COUNT doubles, offsets CAM_* below; the CAM_WINDOW_* ones only for 2).
 * ray_pixel (n_rays double2): image point (x2, x3) in pixels; NaN unless collected.
 * ray_steps (n_rays int): steps taken.
 * ray_code  (n_rays uchar): status (RAY_*, bits 0-2) | RAY_COLLECTED.
 * mie (rimcl_mie.h layout), mie_terms: the Mie series; ray_weight (n_rays doubles): the
 *   rays' Mie weights (RIMCL_MIE > 0 only).
 * sample_rays (n_sample ints, increasing): rays of the batch whose exit records are
 *   also written, to sample_out (n_sample x RAY_OUT_STRIDE floats) and sample_info, as
 *   trace.cl writes them.
 */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#include "rimcl_mie.h"
#include "rimcl_trace.h"

#ifndef RIMCL_CAMERA
#error "RIMCL_CAMERA must be defined (0 plane, 1 pupil, 2 lens behind a window)"
#endif

#define CAM_X_SHEET 0 /* the sheet x1 = x_sheet */
#define CAM_IMAGE_ORIGIN 1 /* (x2, x3) of the outer corner of pixel (0, 0) */
#define CAM_PIXEL_SIZE 3
#define CAM_PUPIL_AXIS 4 /* unit viewing axis (x1, x2, x3) */
#define CAM_PUPIL_CENTRE 7
#define CAM_PUPIL_RADIUS 10
/* lens behind a window (RIMCL_CAMERA 2), as rimcl/optics/camera.py LensCamera computes them: */
#define CAM_WINDOW_DEPTHS 11 /* x1 runs in fluid, glass (the thickness), outside to the pupil */
#define CAM_WINDOW_RATIOS 14 /* sine ratios 1, n_fluid / n_glass, n_fluid / n_outside (aiming) */
#define CAM_WINDOW_SLOPES 17 /* depths * ratios, per medium */
#define CAM_WINDOW_TOTAL 20 /* their sum: the paraxial run per unit sine */
#define CAM_WINDOW_CAP 21 /* 0.999 / max(ratios): the largest starting sine */
#define CAM_FOCUS_X1 22 /* the plane the lens is focused on */
#define CAM_GLASS_INDEX 23 /* the window's index */
#define CAM_OUTSIDE_INDEX 24 /* the index between window and lens */
#define CAM_COUNT 25

/* Newton steps of LensCamera.directions */
#define LENS_NEWTON_STEPS 50

#define RAY_COLLECTED 8

#ifndef RIMCL_STRAIGHT
#define RIMCL_STRAIGHT 0
#endif
#ifndef RIMCL_TRACER_DEPTH
#define RIMCL_TRACER_DEPTH 0
#endif
#ifndef RIMCL_IMAGE_PLANE
#define RIMCL_IMAGE_PLANE 0
#endif

/* The start point (x1, x2, x3) of tracer t's rays. */
RIMCL_INLINE void tracer_start(__global const double *tracers, const int t, const double x_sheet,
                               double *start)
{
#if RIMCL_TRACER_DEPTH
    (void)x_sheet;
    for (int q = 0; q < 3; ++q)
        start[q] = tracers[5 * t + q];
#else
    start[0] = x_sheet;
    start[1] = tracers[4 * t];
    start[2] = tracers[4 * t + 1];
#endif
}

/* The point (x1, x2, x3) tracer t's rays are aimed from (the camera's directions() of it). */
RIMCL_INLINE void aim_start(__global const double *tracers, const int t, const double *start,
                            double *from)
{
#if RIMCL_TRACER_DEPTH
    from[0] = start[0];
    from[1] = tracers[5 * t + 3];
    from[2] = tracers[5 * t + 4];
#else
    from[0] = start[0];
    from[1] = tracers[4 * t + 2];
    from[2] = tracers[4 * t + 3];
#endif
}

/* (x0^2 + x1^2) + x2^2, the order of numpy.linalg.norm over a row of 3 */
RIMCL_INLINE double norm3(double a, double b, double c)
{
    return sqrt((a * a + b * b) + c * c);
}

#if RIMCL_CAMERA == 2
/* The unit direction from the tracer (x2, x3) = start to the pupil point `aim` through the
 * fluid, the glass and the outside medium, as LensCamera.directions solves it (Newton on
 * the sine of the angle to x1, from the paraxial guess, its operations in its order);
 * trace_fan then normalises it as trace_rays does (normalise3). */
RIMCL_INLINE void window_direction(__constant const double *camera, const double start2,
                                   const double start3, __global const double *aim, double *d)
{
    __constant const double *depths = camera + CAM_WINDOW_DEPTHS;
    __constant const double *ratios = camera + CAM_WINDOW_RATIOS;
    __constant const double *slopes = camera + CAM_WINDOW_SLOPES;
    const double lateral2 = aim[1] - start2;
    const double lateral3 = aim[2] - start3;
    const double reach = sqrt(lateral2 * lateral2 + lateral3 * lateral3);
    const double guess = reach / camera[CAM_WINDOW_TOTAL];
    const double cap = camera[CAM_WINDOW_CAP];
    double sine = (guess < cap) ? guess : cap;
    /* Each step is a fixed function of the sine, so once the iterates repeat (a fixed
     * point, or two values in turn as rounding settles) the host's last iterate is known:
     * stop there, with its bits, instead of running all LENS_NEWTON_STEPS steps (most rays
     * settle within a few; NaN never repeats and runs them all). */
    double before = NAN;
    for (int step = 0; step < LENS_NEWTON_STEPS; ++step) {
        double run = 0.0, slope = 0.0;
        for (int m = 0; m < 3; ++m) {
            const double s = sine * ratios[m];
            const double cosine = sqrt(1.0 - s * s);
            const double term = depths[m] * s / cosine;
            const double rate = slopes[m] / (cosine * cosine * cosine);
            run = (m == 0) ? term : run + term;
            slope = (m == 0) ? rate : slope + rate;
        }
        const double next = sine - (run - reach) / slope;
        if (next == sine)
            break;
        if (next == before) {
            /* iterate step + 1 is `next`; they alternate from here: the host's last one,
             * LENS_NEWTON_STEPS, is `next` where it is an even number of steps on */
            sine = ((LENS_NEWTON_STEPS - step - 1) % 2 == 0) ? next : sine;
            break;
        }
        before = sine;
        sine = next;
    }
    const double unit2 = (reach > 0.0) ? lateral2 / reach : 0.0;
    const double unit3 = (reach > 0.0) ? lateral3 / reach : 0.0;
    d[0] = sqrt(1.0 - sine * sine);
    d[1] = sine * unit2;
    d[2] = sine * unit3;
}

/* Snell at a plane of normal x1 into a medium of n_in / n_out = ratio, as rimcl.camera
 * _refract: the tangential part scaled, the normal one from it; NaN if reflected. */
RIMCL_INLINE void refract_x1(const double *dir, const double ratio, double *out)
{
    const double t2 = dir[1] * ratio;
    const double t3 = dir[2] * ratio;
    const double normal = sqrt(1.0 - (t2 * t2 + t3 * t3));
    out[0] = normal;
    out[1] = isnan(normal) ? NAN : t2;
    out[2] = isnan(normal) ? NAN : t3;
}

/* The exit ray after the window, as LensCamera.through_window with the ray's own index
 * at its exit point (`exit_index`): its point on the outer face (`pos`) and its unit
 * direction outside (`dir`), NaN if reflected totally. */
RIMCL_INLINE void through_window(__constant const double *camera, const double exit_index,
                                 double *pos, double *dir)
{
    double glass[3], outside[3];
    refract_x1(dir, exit_index / camera[CAM_GLASS_INDEX], glass);
    refract_x1(dir, exit_index / camera[CAM_OUTSIDE_INDEX], outside);
    const double run = camera[CAM_WINDOW_DEPTHS + 1] / glass[0];
    for (int q = 0; q < 3; ++q) {
        pos[q] = pos[q] + run * glass[q];
        dir[q] = outside[q];
    }
}
#endif

/* The camera's unit initial direction from `start` (x1, x2, x3) towards the aim point
 * `aim`, as its directions() makes it on the host. */
RIMCL_INLINE void camera_direction(__constant const double *camera, const double *start,
                                   __global const double *aim, double *d)
{
#if RIMCL_CAMERA == 2
    window_direction(camera, start[1], start[2], aim, d);
#else
    for (int q = 0; q < 3; ++q)
        d[q] = aim[q] - start[q];
    const double length = norm3(d[0], d[1], d[2]);
    for (int q = 0; q < 3; ++q)
        d[q] = d[q] / length;
#endif
}

/* trace_rays normalises the directions it is given once more */
RIMCL_INLINE void normalise3(double *d)
{
    const double length = norm3(d[0], d[1], d[2]);
    for (int q = 0; q < 3; ++q)
        d[q] = d[q] / length;
}

/* Where in the batch's sample ray `ray` goes, or -1 (binary search of sample_rays). */
RIMCL_INLINE int sample_slot(__global const int *sample_rays, const int n_sample, const int ray)
{
    int lo = 0, hi = n_sample;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (sample_rays[mid] < ray)
            lo = mid + 1;
        else
            hi = mid;
    }
    return (lo < n_sample && sample_rays[lo] == ray) ? lo : -1;
}

__kernel void trace_fan(FIELD_GRID_TYPE grid, const int4 counts, __constant const float *params,
                        __global const double *tracers, __global const double *aims,
                        __global const int *order, __constant const double *camera,
                        const int rays_per_tracer, const int n_rays, const int max_steps,
                        __global double2 *ray_pixel,
                        __global int *ray_steps, __global uchar *ray_code,
                        __global const int *sample_rays, const int n_sample,
                        __global float *sample_out, __global int4 *sample_info,
                        __global const double *mie, const int mie_terms,
                        __global double *ray_weight, const double x_end_exact,
                        const double max_length, const double4 box23,
                        const double straight_index)
{
    const int first = get_global_id(0) * RIMCL_LANES;
    if (first >= n_rays)
        return;
    const double x_sheet = camera[CAM_X_SHEET];

    /* Make the rays as rimcl.camera (directions) and rimcl.trace_rays (normalisation,
     * (hi, lo) pairs) do; lanes past the last ray repeat it and are never stored. */
    lvec3 origin_hi, origin_lo, dir_hi, dir_lo;
    lmask valid;
    int lane_ray[RIMCL_LANES];
    double lane_x1[RIMCL_LANES];
#if RIMCL_STRAIGHT
    double lane_start[RIMCL_LANES][3], lane_dir[RIMCL_LANES][3];
#endif
#if RIMCL_MIE
    double lane_aim_dir[RIMCL_LANES][3];
#endif
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        const int slot = (first + k < n_rays) ? first + k : n_rays - 1;
        const int tracer = slot / rays_per_tracer;
        const int aim_index = order[slot - tracer * rays_per_tracer];
        const int ray = tracer * rays_per_tracer + aim_index;
        lane_ray[k] = ray;
        __global const double *aim = aims + 3 * aim_index;
        double start[3];
        tracer_start(tracers, tracer, x_sheet, start);
        lane_x1[k] = start[0];
        double from[3], d[3];
        aim_start(tracers, tracer, start, from);
        camera_direction(camera, from, aim, d);
#if RIMCL_MIE
        /* the host weighs the camera's directions, before trace_rays normalises again */
        for (int q = 0; q < 3; ++q)
            lane_aim_dir[k][q] = d[q];
#endif
        normalise3(d);
#if RIMCL_STRAIGHT
        for (int q = 0; q < 3; ++q) {
            lane_start[k][q] = start[q];
            lane_dir[k][q] = d[q];
        }
#endif
        float o_hi[3], o_lo[3], d_hi[3], d_lo[3];
        for (int q = 0; q < 3; ++q) {
            o_hi[q] = (float)start[q];
            o_lo[q] = (float)(start[q] - (double)o_hi[q]);
            d_hi[q] = (float)d[q];
            d_lo[q] = (float)(d[q] - (double)d_hi[q]);
        }
        LANE(origin_hi.x, k) = o_hi[0];
        LANE(origin_hi.y, k) = o_hi[1];
        LANE(origin_hi.z, k) = o_hi[2];
        LANE(origin_lo.x, k) = o_lo[0];
        LANE(origin_lo.y, k) = o_lo[1];
        LANE(origin_lo.z, k) = o_lo[2];
        LANE(dir_hi.x, k) = d_hi[0];
        LANE(dir_hi.y, k) = d_hi[1];
        LANE(dir_hi.z, k) = d_hi[2];
        LANE(dir_lo.x, k) = d_lo[0];
        LANE(dir_lo.y, k) = d_lo[1];
        LANE(dir_lo.z, k) = d_lo[2];
#if RIMCL_LANES == 1
        valid = 1;
#else
        LANE_I(valid, k) = (first + k < n_rays) ? -1 : 0;
#endif
    }

#if RIMCL_MIE
    {
        double weight[RIMCL_LANES];
        mie_weight_lanes(mie, mie_terms, lane_aim_dir, weight);
        for (int k = 0; k < RIMCL_LANES; ++k)
            if (first + k < n_rays)
                ray_weight[lane_ray[k]] = weight[k];
    }
#endif
#if RIMCL_STRAIGHT
    (void)valid;
    (void)max_steps;
#else
    const lane_result res =
        trace_lanes(FIELD_PASS, origin_hi, origin_lo, dir_hi, dir_lo, valid, max_steps);
#endif

#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        if (first + k >= n_rays)
            continue;
        const int ray = lane_ray[k];
        double end[3], dir[3];
#if RIMCL_STRAIGHT
        int status, steps = 0;
        const double exit_index = straight_index; /* a uniform field's index */
        {
            /* rimcl.trace.straight_rays, the same float64 operations, none fused */
#pragma OPENCL FP_CONTRACT OFF
            const double *start = lane_start[k], *d = lane_dir[k];
            const double run_x = (x_end_exact - start[0]) / d[0];
            const double length = norm3(d[0], d[1], d[2]);
            for (int q = 0; q < 3; ++q) {
                end[q] = start[q] + run_x * d[q];
                dir[q] = d[q] / length;
            }
            const int outside = (end[1] < box23.x) | (end[1] > box23.y) | (end[2] < box23.z) |
                                (end[2] > box23.w);
            const int finite = isfinite(end[0]) && isfinite(end[1]) && isfinite(end[2]) &&
                               isfinite(dir[0]) && isfinite(dir[1]) && isfinite(dir[2]);
            status = finite ? RAY_OK : RAY_NON_FINITE;
            status = (run_x > max_length) ? RAY_MAX_STEPS : status;
            status = outside ? RAY_EXIT_SIDE : status;
            status = (!(run_x > 0.0) || isinf(run_x)) ? RAY_TURNED_BACK : status;
        }
#else
        (void)x_end_exact;
        (void)max_length;
        (void)box23;
        (void)straight_index;
        /* the exit record as trace.cl writes it, joined in float64 as the host joins it */
        float record[RAY_OUT_STRIDE];
        int4 info;
        lane_record(&res, k, record, &info);
        const int status = info.y, steps = info.x;
        double tangent[3];
        for (int q = 0; q < 3; ++q) {
            end[q] = (double)record[q] + (double)record[3 + q];
            tangent[q] = (double)record[6 + q] + (double)record[9 + q];
        }
        /* |T| = n at the exit point (T = n dR/ds): the index Snell takes at the wall */
        const double exit_index = norm3(tangent[0], tangent[1], tangent[2]);
        for (int q = 0; q < 3; ++q)
            dir[q] = tangent[q] / exit_index;
#endif
#if RIMCL_CAMERA == 2
        /* through the window; back-projection onto the focus plane (LensCamera.image_points) */
        through_window(camera, exit_index, end, dir);
        const double focus_x1 = camera[CAM_FOCUS_X1];
#elif RIMCL_IMAGE_PLANE == 1
        /* back-projection to the tracer's own plane (rimcl.trace_rays' image_pos) */
        const double focus_x1 = lane_x1[k];
#else
        (void)exit_index;
        /* back-projection to the sheet (the ideal lens focused on it) */
        const double focus_x1 = x_sheet;
#endif
        const double distance = (end[0] - focus_x1) / dir[0];
        const double image2 = end[1] - distance * dir[1];
        const double image3 = end[2] - distance * dir[2];
#if RIMCL_CAMERA >= 1
        __constant const double *axis = camera + CAM_PUPIL_AXIS;
        __constant const double *centre = camera + CAM_PUPIL_CENTRE;
        const double towards = (dir[0] * axis[0] + dir[1] * axis[1]) + dir[2] * axis[2];
        const double run = (((centre[0] - end[0]) * axis[0] + (centre[1] - end[1]) * axis[1]) +
                            (centre[2] - end[2]) * axis[2]) /
                           towards;
        const double off_axis = norm3((end[0] + run * dir[0]) - centre[0],
                                      (end[1] + run * dir[1]) - centre[1],
                                      (end[2] + run * dir[2]) - centre[2]);
        const int collected =
            (towards > 0.0) && (run >= 0.0) && (off_axis <= camera[CAM_PUPIL_RADIUS]);
#else
        const int collected = 1;
#endif
        const int usable = (status == RAY_OK) & collected;
        const double pixel_size = camera[CAM_PIXEL_SIZE];
        ray_pixel[ray] =
            usable ? (double2)((image2 - camera[CAM_IMAGE_ORIGIN]) / pixel_size,
                               (image3 - camera[CAM_IMAGE_ORIGIN + 1]) / pixel_size)
                   : (double2)(NAN, NAN);
        ray_steps[ray] = steps;
        ray_code[ray] = (uchar)(status | (usable ? RAY_COLLECTED : 0));
#if !RIMCL_STRAIGHT
        if (n_sample > 0) {
            const int slot = sample_slot(sample_rays, n_sample, ray);
            if (slot >= 0) {
                __global float *out = sample_out + (size_t)slot * RAY_OUT_STRIDE;
                for (int q = 0; q < RAY_OUT_STRIDE; ++q)
                    out[q] = record[q];
                sample_info[slot] = info;
            }
        }
#else
        (void)sample_rays;
        (void)n_sample;
        (void)sample_out;
        (void)sample_info;
#endif
    }
}

/* The initial direction of each ray of the batch, as trace_fan makes it (for tests):
 * directions (n_rays x 3 doubles). One ray per work-item; global size >= n_rays. */
__kernel void fan_directions(__global const double *tracers, __global const double *aims,
                             __constant const double *camera, const int rays_per_tracer,
                             const int n_rays, __global double *directions)
{
    const int ray = get_global_id(0);
    if (ray >= n_rays)
        return;
    const int tracer = ray / rays_per_tracer;
    double start[3];
    tracer_start(tracers, tracer, camera[CAM_X_SHEET], start);
    double from[3], d[3];
    aim_start(tracers, tracer, start, from);
    camera_direction(camera, from, aims + 3 * (ray - tracer * rays_per_tracer), d);
    normalise3(d);
    for (int q = 0; q < 3; ++q)
        directions[3 * ray + q] = d[q];
}
