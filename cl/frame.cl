/*
 * frame.cl -- full PIV frames: the rays of many tracers splatted into one frame, on the device.
 *
 * Purpose: the device counterpart of rimcl/piv/frame_pair.py deposit_rays. After cl/fan.cl
 * has made, traced and imaged a batch of tracers' rays (their image points in pixels),
 *   tracer_rows: one row per tracer: its rays' status counts, collected and vignetted
 *     rays, collected rays whose own pixel is off the frame, the bounding box of their
 *     pixels and the sums of their image points (the host bins tracers to tiles from the
 *     boxes and forms the mean image points from the sums);
 *   splat_tiles: each tile of the frame adds, in a fixed order (its tracers by increasing
 *     index, each tracer's rays in ray order), the pixel-integrated Gaussian of every
 *     collected ray of those tracers over the tile's pixels within `pad` pixels of the
 *     ray's own pixel, as deposit_rays does:
 *       share(c) = ndtr(((c - p) + 1) / sigma) - ndtr((c - p) / sigma),
 *       light[row][col] += (share_row * weight) * share_col,
 *     weight = the tracer's sheet intensity (times the ray's Mie weight with RIMCL_MIE).
 *     A pixel belongs to one tile and one work-item, so no value is added atomically and
 *     every pixel's sum runs in the same order on every device, run after run; the
 *     batches of a frame are added in the order they are enqueued (one in-order queue).
 * ndtr is rimcl_ndtr.h's (a few ulp of 1 from scipy.special.ndtr), so a pixel's light
 * differs from the NumPy engine's by a few ulp of the light it holds.
 *
 * Required defines: none. Optional: RIMCL_MIE (0 default: every ray of a tracer weighs its
 *   sheet intensity; 1: times ray_weight, fan.cl's Mie weights), RIMCL_POCL_FAST
 *   (rimcl_inline.h), RIMCL_TILE (tile side in pixels, default 32, at most 64).
 * Needs cl_khr_fp64.
 * Units: pixels of the camera (pixel i spans [i, i + 1) from the image origin, as fan.cl
 *   writes the image points); light in units of ray weight.
 * Axis order: the frame is (rows, columns) = (x3, x2), row-major; points are (x2, x3).
 * Work-items: tracer_rows one tracer; splat_tiles one tile (tile t covers columns
 *   (t % tiles_x) RIMCL_TILE + [0, RIMCL_TILE), rows (t / tiles_x) RIMCL_TILE + [0, ...)).
 * Global size: tracer_rows >= n_tracers; splat_tiles >= the number of tiles (extra items
 *   return).
 *
 * ray_pixel (n_rays double2), ray_code (n_rays uchar), ray_weight (n_rays doubles, RIMCL_MIE
 *   only): fan.cl's, ray g of tracer g / rays.
 * rows_l (n_tracers x ROW_LONGS longs), rows_d (n_tracers x 2 doubles): ROW_* below; the
 *   sums of the collected rays' image points (x2, x3) in pixels.
 * intensity (n_tracers doubles): each tracer's sheet intensity.
 * tile_start (n_tiles + 1 ints), tile_tracers: the tracers of tile t are
 *   tile_tracers[tile_start[t] .. tile_start[t + 1]), increasing.
 * light (height x width doubles): the frame, added to.
 */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF
#include "rimcl_ndtr.h"

#ifndef RIMCL_MIE
#define RIMCL_MIE 0
#endif
#ifndef RIMCL_TILE
#define RIMCL_TILE 32
#endif

#define RAY_OK 0
#define RAY_STATUS_MASK 7
#define RAY_COLLECTED 8 /* as fan.cl */

#define ROW_COLLECTED 0
#define ROW_VIGNETTED 1 /* traced ok, missed the camera */
#define ROW_OFF_FRAME 2 /* collected, own pixel outside the frame */
#define ROW_STATUS 3    /* 5 counts by trace status */
#define ROW_BOX 8       /* lowest column, lowest row, highest column, highest row (pixels) */
#define ROW_LONGS 12

/* pixels farther than this from 0 are clamped (they lie far outside any frame) */
#define CELL_LIMIT 1073741824.0

RIMCL_INLINE long cell_of(double x)
{
    const double c = floor(x);
    return (long)((c < -CELL_LIMIT) ? -CELL_LIMIT : ((c > CELL_LIMIT) ? CELL_LIMIT : c));
}

__kernel void tracer_rows(__global const double2 *ray_pixel, __global const uchar *ray_code,
                          const int rays, const int n_tracers, const int width, const int height,
                          __global long *rows_l, __global double *rows_d)
{
    const int t = get_global_id(0);
    if (t >= n_tracers)
        return;
    long counts[ROW_LONGS];
    for (int q = 0; q < ROW_LONGS; ++q)
        counts[q] = 0;
    long lo_x = LONG_MAX, lo_y = LONG_MAX, hi_x = LONG_MIN, hi_y = LONG_MIN;
    double sum_x = 0.0, sum_y = 0.0;
    const size_t first = (size_t)t * rays;
    for (int k = 0; k < rays; ++k) {
        const int code = ray_code[first + k];
        const int status = code & RAY_STATUS_MASK;
        counts[ROW_STATUS + status] += 1;
        if (code & RAY_COLLECTED) {
            const double2 p = ray_pixel[first + k];
            const long cx = cell_of(p.x), cy = cell_of(p.y);
            counts[ROW_COLLECTED] += 1;
            counts[ROW_OFF_FRAME] += (cx < 0) | (cx >= width) | (cy < 0) | (cy >= height);
            lo_x = min(lo_x, cx);
            hi_x = max(hi_x, cx);
            lo_y = min(lo_y, cy);
            hi_y = max(hi_y, cy);
            sum_x += p.x;
            sum_y += p.y;
        } else if (status == RAY_OK) {
            counts[ROW_VIGNETTED] += 1;
        }
    }
    counts[ROW_BOX] = lo_x;
    counts[ROW_BOX + 1] = lo_y;
    counts[ROW_BOX + 2] = hi_x;
    counts[ROW_BOX + 3] = hi_y;
    for (int q = 0; q < ROW_LONGS; ++q)
        rows_l[(size_t)t * ROW_LONGS + q] = counts[q];
    rows_d[2 * (size_t)t] = sum_x;
    rows_d[2 * (size_t)t + 1] = sum_y;
}

/* The shares of pixels first .. first + count - 1 (count <= RIMCL_TILE) of a ray at
 * `position` along one axis, times `weight`, as deposit_rays forms them. */
RIMCL_INLINE void shares(const double position, const int first, const int count,
                         const double sigma, const double weight, double *out)
{
    const double8 lanes = (double8)(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
    for (int i = 0; i < count; i += 8) {
        const double8 centred = ((double)(first + i) + lanes) - position;
        const double8 left = centred / sigma;
        const double8 right = (centred + 1.0) / sigma;
        const double8 share = ndtr8(right, ndtr_exp(-0.5 * (right * right))) -
                              ndtr8(left, ndtr_exp(-0.5 * (left * left)));
        double values[8];
        vstore8(share, 0, values);
        for (int q = 0; q < 8 && i + q < count; ++q)
            out[i + q] = values[q] * weight;
    }
}

__kernel void splat_tiles(__global const double2 *ray_pixel, __global const uchar *ray_code,
                          __global const double *ray_weight, __global const double *intensity,
                          __global const int *tile_start, __global const int *tile_tracers,
                          const int rays, const int tiles_x, const int n_tiles, const int width,
                          const int height, const int pad, const double sigma,
                          __global double *light)
{
    const int tile = get_global_id(0);
    if (tile >= n_tiles)
        return;
    const int x0 = (tile % tiles_x) * RIMCL_TILE, y0 = (tile / tiles_x) * RIMCL_TILE;
    const int x1 = min(x0 + RIMCL_TILE, width), y1 = min(y0 + RIMCL_TILE, height);
    double across[RIMCL_TILE], down[RIMCL_TILE];
    for (int e = tile_start[tile]; e < tile_start[tile + 1]; ++e) {
        const int t = tile_tracers[e];
        const size_t first = (size_t)t * rays;
        const double tracer_light = intensity[t];
        for (int k = 0; k < rays; ++k) {
            if (!(ray_code[first + k] & RAY_COLLECTED))
                continue;
            const double2 p = ray_pixel[first + k];
            const long cx = cell_of(p.x), cy = cell_of(p.y);
            const int lo_x = (int)max((long)x0, cx - pad), hi_x = (int)min((long)x1, cx + pad + 1);
            const int lo_y = (int)max((long)y0, cy - pad), hi_y = (int)min((long)y1, cy + pad + 1);
            if (lo_x >= hi_x || lo_y >= hi_y)
                continue;
#if RIMCL_MIE
            const double weight = tracer_light * ray_weight[first + k];
#else
            (void)ray_weight;
            const double weight = tracer_light;
#endif
            shares(p.x, lo_x, hi_x - lo_x, sigma, 1.0, across);
            shares(p.y, lo_y, hi_y - lo_y, sigma, weight, down);
            for (int j = lo_y; j < hi_y; ++j) {
                __global double *line = light + (size_t)j * width;
                const double g = down[j - lo_y];
                for (int i = lo_x; i < hi_x; ++i)
                    line[i] = line[i] + g * across[i - lo_x];
            }
        }
    }
}
