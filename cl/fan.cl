/*
 * fan.cl -- a camera's rays from a batch of tracers, made, traced and imaged on the device.
 *
 * The device engine's first stage (DESIGN §14). Ray g of the batch belongs to tracer
 * g / K and aims at the camera's aim point g % K (K rays per tracer). Each ray is made
 * from float64 tracer and aim positions exactly as rimcl.camera and rimcl.trace_rays make
 * it on the host (difference, two normalisations, float (hi, lo) pairs), so the trace sees
 * the same input bits; it is traced by trace_lanes() (rimcl_trace.h); its exit state is
 * back-projected to the sheet and tested against the camera in float64 with the host's
 * operations (rimcl/trace.py _finish, rimcl/camera.py collected, rimcl/render.py
 * to_pixels), so its image point in pixels is the one the NumPy engine images.
 *
 * Required defines: those of trace.cl (RIMCL_PRECISION, RIMCL_FIELD, RIMCL_INTERP,
 *   RIMCL_PERIODIC; optional RIMCL_LANES, RIMCL_POCL_FAST, RIMCL_ADAPTIVE) and
 *   RIMCL_CAMERA: 0 plane camera (every ray that reaches the exit plane is collected),
 *   1 pupil camera (a ray is collected if its straight continuation passes the pupil).
 * Optional: RIMCL_MIE (rimcl_mie.h): 0 (default) every ray weighs 1 and ray_weight is not
 *   written; otherwise each ray's Mie weight from its initial direction goes to ray_weight.
 * Needs cl_khr_fp64.
 * Units: lengths in field units; image points in pixels of the camera (pixel i spans
 *   [i, i + 1) from the image origin).
 * Axis order: 3-vectors are (x1, x2, x3); tracers and image points are (x2, x3).
 * Work-item: RIMCL_LANES consecutive rays of the batch (as trace.cl).
 * Global size: ceil(n_rays / RIMCL_LANES) (extra items return).
 *
 * tracers (B x 2 doubles): tracer positions (x2, x3) on the sheet.
 * aims    (K x 3 doubles): the camera's aim points (x1, x2, x3).
 * camera  (CAM_COUNT doubles, offsets CAM_* below).
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
#error "RIMCL_CAMERA must be defined (0 plane, 1 pupil)"
#endif

#define CAM_X_SHEET 0 /* the sheet x1 = x_sheet */
#define CAM_IMAGE_ORIGIN 1 /* (x2, x3) of the outer corner of pixel (0, 0) */
#define CAM_PIXEL_SIZE 3
#define CAM_PUPIL_AXIS 4 /* unit viewing axis (x1, x2, x3) */
#define CAM_PUPIL_CENTRE 7
#define CAM_PUPIL_RADIUS 10
#define CAM_COUNT 11

#define RAY_COLLECTED 8

/* (x0^2 + x1^2) + x2^2, the order of numpy.linalg.norm over a row of 3 */
RIMCL_INLINE double norm3(double a, double b, double c)
{
    return sqrt((a * a + b * b) + c * c);
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
                        __constant const double *camera, const int rays_per_tracer,
                        const int n_rays, const int max_steps, __global double2 *ray_pixel,
                        __global int *ray_steps, __global uchar *ray_code,
                        __global const int *sample_rays, const int n_sample,
                        __global float *sample_out, __global int4 *sample_info,
                        __global const double *mie, const int mie_terms,
                        __global double *ray_weight)
{
    const int first = get_global_id(0) * RIMCL_LANES;
    if (first >= n_rays)
        return;
    const double x_sheet = camera[CAM_X_SHEET];

    /* Make the rays as rimcl.camera (directions) and rimcl.trace_rays (normalisation,
     * (hi, lo) pairs) do; lanes past the last ray repeat it and are never stored. */
    lvec3 origin_hi, origin_lo, dir_hi, dir_lo;
    lmask valid;
#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        const int ray = (first + k < n_rays) ? first + k : n_rays - 1;
        const int tracer = ray / rays_per_tracer;
        __global const double *aim = aims + 3 * (ray - tracer * rays_per_tracer);
        const double start[3] = {x_sheet, tracers[2 * tracer], tracers[2 * tracer + 1]};
        double d[3] = {aim[0] - start[0], aim[1] - start[1], aim[2] - start[2]};
        double length = norm3(d[0], d[1], d[2]);
        for (int q = 0; q < 3; ++q)
            d[q] = d[q] / length;
#if RIMCL_MIE
        /* the host weighs the camera's unit directions, before trace_rays normalises again */
        if (first + k < n_rays)
            ray_weight[ray] = mie_weight(mie, mie_terms, d);
#endif
        length = norm3(d[0], d[1], d[2]);
        float o_hi[3], o_lo[3], d_hi[3], d_lo[3];
        for (int q = 0; q < 3; ++q) {
            d[q] = d[q] / length;
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

    const lane_result res =
        trace_lanes(FIELD_PASS, origin_hi, origin_lo, dir_hi, dir_lo, valid, max_steps);

#pragma unroll
    for (int k = 0; k < RIMCL_LANES; ++k) {
        const int ray = first + k;
        if (ray >= n_rays)
            break;
        /* the exit record as trace.cl writes it, joined in float64 as the host joins it */
        float record[RAY_OUT_STRIDE];
        int4 info;
        lane_record(&res, k, record, &info);
        const int status = info.y;
        double end[3], tangent[3];
        for (int q = 0; q < 3; ++q) {
            end[q] = (double)record[q] + (double)record[3 + q];
            tangent[q] = (double)record[6 + q] + (double)record[9 + q];
        }
        const double length = norm3(tangent[0], tangent[1], tangent[2]);
        double dir[3];
        for (int q = 0; q < 3; ++q)
            dir[q] = tangent[q] / length;
        /* back-projection to the sheet (the ideal lens focused on it) */
        const double distance = (end[0] - x_sheet) / dir[0];
        const double image2 = end[1] - distance * dir[1];
        const double image3 = end[2] - distance * dir[2];
#if RIMCL_CAMERA == 1
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
        ray_steps[ray] = info.x;
        ray_code[ray] = (uchar)(status | (usable ? RAY_COLLECTED : 0));
        if (n_sample > 0) {
            const int slot = sample_slot(sample_rays, n_sample, ray);
            if (slot >= 0) {
                __global float *out = sample_out + (size_t)slot * RAY_OUT_STRIDE;
                for (int q = 0; q < RAY_OUT_STRIDE; ++q)
                    out[q] = record[q];
                sample_info[slot] = info;
            }
        }
    }
}
