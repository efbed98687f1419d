/*
 * image.cl -- tracer images rendered, digitised and located on the device, one row each.
 *
 * The device engine's second stage, the NumPy engine's image_batch
 * (rimcl/imaging/frames.py) in one kernel: for each tracer of a batch, from the image points of
 * its rays (fan.cl, in pixels), the window (rimcl/imaging/render.py Renderer.window_for: bounding
 * box plus the PSF pad, capped at max_window around the floor of the median image point),
 * the image (renderer "exact": each ray's Gaussian integrated over the pixels as
 * differences of ndtr, cut `radius` pixels from the ray, added in ray order, or in the
 * order of pixel tiles where the rays spread wider than one pass of a block takes; "paper":
 * the rays binned to pixels in ray order, then spread with scipy's normalised Gaussian
 * kernel of `radius`),
 * the counts (scale from the reference pass or from the image's own peak; then the
 * deterministic camera: rint, clip; or, with RIMCL_NOISE, rimcl/imaging/sensor.py Sensor.digitize:
 * per pixel the Philox draws of rimcl_philox.h, shot noise, full well, read noise, gain,
 * rint, ADC clip, in the host's order of double operations), the 8-connected components
 * above the threshold (union-find; the root of a component is its smallest pixel index,
 * the order scikit-image numbers them in), the brightest component
 * (by summed centroid weight; ties to the smaller root, as numpy.argmax), and its moments,
 * area, touching of the window edge and perimeter histogram (scikit-image's perimeter with
 * neighborhood=4: border pixels by erosion with the 4-neighbour cross, each scored by
 * 1 + 2 (border 4-neighbours) + 10 (border diagonal neighbours)). Light is float64 and the
 * moments exact integers, so the host forms the centroid with the NumPy engine's
 * arithmetic.
 *
 * Required defines: RIMCL_RENDERER (0 exact, 1 paper), RIMCL_CENTROID (0 excess weights,
 *   1 grey weights). Optional: RIMCL_NOISE (0, default: the deterministic camera; 1: sensor
 *   noise), RIMCL_SPLAT_BLOCK (sources added per pass over the image, default 16),
 *   RIMCL_POCL_FAST (rimcl_inline.h).
 * Needs cl_khr_fp64.
 * Units: pixels of the camera (pixel i spans [i, i + 1)); light in units of ray weight;
 *   counts of the camera; electrons (e-) of the sensor. Pixel (i, j) of a window is pixel
 *   (col0 + i, row0 + j) of the renderer's grid (rimcl/imaging/render.py: origin and pixel size),
 *   the global pixel of the noise draws.
 * Axis order: windows and images are (rows, columns) = (x3, x2); points are (x2, x3).
 * Work-item: one scratch slot (get_global_id); it images one tracer after another, taken
 *   from a shared counter, until the batch is done (the rows do not depend on which
 *   work-item imaged a tracer).
 * Global size: the number of slots.
 *
 * consts (doubles): psf sigma (px), threshold (counts), full scale (counts), the reference
 *   peak (counts, full scale; with noise e-, peak_electrons), background (e-), full well
 *   (e-), read noise (e- rms), gain (e- per count), exp(-32 / sigma^2), exp(-64 / sigma^2)
 *   (the exact renderer's recurrence), then the paper kernel (2 radius + 1 weights). The
 *   sensor's entries are unused without noise.
 * Noise arguments (unused without noise): the key (seed mod 2^32, seed div 2^32), the
 *   stream 2 frame + pass and the global id of the batch's tracer 0 (tracer t draws with
 *   tracer0 + t).
 * rows_l (n_tracers x ROW_LONGS longs), rows_d (n_tracers x ROWD_COUNT doubles): one row
 *   per tracer, offsets ROW_* and ROWD_* below.
 * canvas (canvas_height x canvas_width ints, or unused when canvas_width is 0): the
 *   counts of every window added in (clipped to full scale by the host).
 * Scratch per slot: image (max_window^2 + 8 doubles), labels and border (max_window^2 ints
 *   each), component light (2 max_window^2 ints), sources (rays double2 and rays doubles),
 *   factors (RIMCL_SPLAT_BLOCK x 2 table_width doubles; table_width >= the footprint + 9,
 *   a multiple of 8, with room for the union of a few nearby footprints).
 */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF
#include "rimcl_ndtr.h"
#include "rimcl_philox.h"

#ifndef RIMCL_RENDERER
#error "RIMCL_RENDERER must be defined (0 exact, 1 paper)"
#endif
#ifndef RIMCL_CENTROID
#error "RIMCL_CENTROID must be defined (0 excess, 1 grey)"
#endif
#ifndef RIMCL_NOISE
#define RIMCL_NOISE 0
#endif

#define IMG_SIGMA 0
#define IMG_THRESHOLD 1
#define IMG_FULL_SCALE 2
#define IMG_PEAK 3 /* the reference image's peak: counts, or with noise e- */
#define IMG_BACKGROUND 4
#define IMG_FULL_WELL 5
#define IMG_READ_NOISE 6
#define IMG_GAIN 7
#define IMG_GAUSS_STEP 8 /* exp(-32 / sigma^2): the exact renderer's recurrence */
#define IMG_GROWTH_STEP 9 /* exp(-64 / sigma^2) */
#define IMG_KERNEL 10

/* rimcl/imaging/sensor.py POISSON_INVERSION_MAX and POISSON_INVERSION_KMAX */
#define POISSON_INVERSION_MAX 16.0
#define POISSON_INVERSION_KMAX 64

#define RAY_OK 0
#define RAY_STATUS_MASK 7
#define RAY_COLLECTED 8 /* as fan.cl */

/* TracerFlag bits (rimcl/imaging/centroid.py) */
#define FLAG_NO_RAYS 1
#define FLAG_BELOW_THRESHOLD 2
#define FLAG_SPLIT 4
#define FLAG_TOUCHES_EDGE 8
#define FLAG_RAYS_FAILED 16
#define FLAG_RAYS_VIGNETTED 32
#define FLAG_RAYS_OUTSIDE_WINDOW 64
#define FLAG_SATURATED 128

#define ROW_FLAGS 0
#define ROW_USABLE 1 /* rays traced ok and collected */
#define ROW_STATUS 2 /* 5 counts by trace status */
#define ROW_VIGNETTED 7
#define ROW_STEPS 8
#define ROW_WINDOW 9 /* col0, row0, width, height */
#define ROW_OUTSIDE 13 /* usable rays outside the window */
#define ROW_AREA 14
#define ROW_SUM 15 /* sum of counts over the component */
#define ROW_SUM_COL 16 /* sum of counts (2 col + 1) */
#define ROW_SUM_ROW 17 /* sum of counts (2 row + 1) */
#define ROW_COLS 18 /* sum of (2 col + 1) */
#define ROW_ROWS 19 /* sum of (2 row + 1) */
#define ROW_PERIMETER 20 /* border pixels scoring 5, 7, 13, 15, 17, 21, 23, 25, 27, 33 */
#define PERIMETER_BINS 10
#define ROW_LONGS 30

#define ROWD_PEAK 0 /* brightest pixel before scaling */
#define ROWD_SCALE 1 /* counts (with noise e-) per unit of light used */
#define ROWD_LIGHT 2 /* sum of the usable rays' weights */
#define ROWD_LIGHT_X 3 /* sum of weight x image point, pixels (x2) */
#define ROWD_LIGHT_Y 4 /* (x3) */
#define ROWD_COUNT 5

/* image points farther than this from 0 are clamped (they only make the window capped,
 * and they lie outside it) */
#define CELL_LIMIT 1073741824.0

typedef struct {
    __global double *image;     /* light, then counts */
    __global int *labels;       /* bins (paper) or tile counts (exact), then components */
    __global int *border;       /* border pixels of the tracer's component */
    __global int *light_low;    /* per component root: sum of (counts & 255) */
    __global int *light_high;   /* per component root: sum of (counts >> 8) */
    __global double2 *sources;  /* paper: pixels hit; exact: spread rays in tile order */
    __global double *weights;   /* their light; scratch of the median */
    __global double *factors;   /* 2 x table_width: one source's factors */
} slot_scratch;

RIMCL_INLINE long cell_of(double x)
{
    const double c = dbl_floor(x);
    return (long)((c < -CELL_LIMIT) ? -CELL_LIMIT : ((c > CELL_LIMIT) ? CELL_LIMIT : c));
}

RIMCL_INLINE double axis_of(double2 p, int axis)
{
    return axis ? p.y : p.x;
}

/* The k-th smallest of values[0, n) (Hoare's quickselect, middle pivot; reorders). */
RIMCL_INLINE double select_kth(__global double *values, long n, long kth)
{
    long lo = 0, hi = n - 1;
    while (lo < hi) {
        const double pivot = values[lo + (hi - lo) / 2];
        long i = lo, j = hi;
        while (i <= j) {
            while (values[i] < pivot)
                ++i;
            while (values[j] > pivot)
                --j;
            if (i <= j) {
                const double swap = values[i];
                values[i] = values[j];
                values[j] = swap;
                ++i;
                --j;
            }
        }
        if (kth <= j)
            hi = j;
        else if (kth >= i)
            lo = i;
        else
            return values[kth];
    }
    return values[kth];
}

/* floor(numpy.median) of the usable rays' coordinate `axis`. */
RIMCL_INLINE long median_cell(__global const double2 *ray_pixel, __global const uchar *ray_code,
                              const int rays, const int axis, __global double *scratch)
{
    long n = 0;
    for (int k = 0; k < rays; ++k)
        if (ray_code[k] & RAY_COLLECTED)
            scratch[n++] = axis_of(ray_pixel[k], axis);
    const long middle = n / 2;
    double median = select_kth(scratch, n, middle);
    if (n % 2 == 0) {
        /* the largest value below the upper middle (the partition put them there) */
        double below = scratch[0];
        for (long k = 1; k < middle; ++k)
            below = fmax(below, scratch[k]);
        median = (below + median) / 2.0;
    }
    return cell_of(median);
}

/* Union-find over pixel indices: the larger root is linked under the smaller. */
RIMCL_INLINE int find_root(__global int *labels, int p)
{
    while (labels[p] != p) {
        labels[p] = labels[labels[p]]; /* path halving */
        p = labels[p];
    }
    return p;
}

RIMCL_INLINE void unite(__global int *labels, int a, int b)
{
    a = find_root(labels, a);
    b = find_root(labels, b);
    if (a < b)
        labels[b] = a;
    else if (b < a)
        labels[a] = b;
}

/* A component's summed centroid weight, times 65536 for excess weights (exact for
 * thresholds that are multiples of 1/65536). */
RIMCL_INLINE long component_light(long sum, long area, long threshold_fixed)
{
#if RIMCL_CENTROID == 0
    return sum * 65536 - threshold_fixed * area;
#else
    (void)area;
    (void)threshold_fixed;
    return sum;
#endif
}

RIMCL_INLINE int perimeter_bin(int score)
{
    switch (score) {
    case 5: return 0;
    case 7: return 1;
    case 13: return 2;
    case 15: return 3;
    case 17: return 4;
    case 21: return 5;
    case 23: return 6;
    case 25: return 7;
    case 27: return 8;
    case 33: return 9;
    default: return -1;
    }
}

/* The factors of one source along one axis of `size` pixels: its footprint [*lo, *hi)
 * (within the window), the light of each pixel in it times `weight`, then zeros up to the
 * next multiple of 8 (the splat adds whole double8 vectors). */
RIMCL_INLINE void source_factors(const double position, const int size, const int radius,
                                 const double weight, __constant const double *consts,
                                 __global double *factors, int *lo, int *hi)
{
    const int cell = (int)position;
    const int first = max(0, cell - radius);
    const int last = min(size, cell + radius + 1);
    const int count = last - first;
    const double8 lanes = (double8)(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
#if RIMCL_RENDERER == 0
    /* ndtr at the pixel edges, then differences (rimcl/imaging/render.py _render_exact). The
     * edges a_k = a_0 + k / sigma (in sigmas) are in arithmetic progression, so 8 edges
     * on, exp(-a^2/2) is the last one times exp(-8 a / sigma) exp(-32 / sigma^2), and
     * exp(-8 a / sigma) the last one times exp(-64 / sigma^2): two exponentials per
     * source and axis instead of one per edge, within a few ulp (2 roundings per
     * 8 edges; a direct exponential where that would overflow). */
    const double inv_sigma = 1.0 / consts[IMG_SIGMA];
    double8 a = (((double)first + lanes) - position) * inv_sigma;
    double8 gauss = ndtr_exp(-0.5 * (a * a));
    double8 growth = ndtr_exp((-8.0 * inv_sigma) * a);
    for (int i = 0; i <= count; i += 8) {
        STORE8(ndtr8(a, gauss), factors + i);
        a = (((double)(first + i + 8) + lanes) - position) * inv_sigma;
        const double8 next = gauss * (growth * consts[IMG_GAUSS_STEP]);
        gauss = all(next <= DBL_MAX) ? next : ndtr_exp(-0.5 * (a * a));
        growth = growth * consts[IMG_GROWTH_STEP];
    }
    for (int i = 0; i < count; i += 8) {
        const double8 light = (LOAD8(factors + i + 1) - LOAD8(factors + i)) * weight;
        STORE8(((double)i + lanes < (double)count) ? light : (double8)(0.0), factors + i);
    }
#else
    /* the binned light spread by the filter's kernel (rimcl/imaging/render.py _render_paper) */
    for (int i = 0; i < count; ++i)
        factors[i] = consts[IMG_KERNEL + radius + first + i - cell] * weight;
    for (int i = count; i < (count + 7) / 8 * 8; ++i)
        factors[i] = 0.0;
#endif
    *lo = first;
    *hi = last;
}

/* sum + g x across, one rounding (a fused multiply-add: half the operations of a multiply
 * and an add where the window's sums run at the speed of the arithmetic). */
RIMCL_INLINE double8 add_light(const double8 sum, const double g, const double8 across)
{
    return fma((double8)(g), across, sum);
}

/* Add one source's separable footprint to the window image (whole double8 vectors: the
 * zeros past the footprint add nothing; the image has 8 spare doubles at its end). */
RIMCL_INLINE void splat(const double2 position, const double weight, const int width,
                        const int height, const int radius, const int table_width,
                        __constant const double *consts, __global double *image,
                        __global double *factors)
{
    int x0, x1, y0, y1;
    __global double *across = factors;
    __global double *down = factors + table_width;
    source_factors(position.x, width, radius, 1.0, consts, across, &x0, &x1);
    source_factors(position.y, height, radius, weight, consts, down, &y0, &y1);
    for (int j = y0; j < y1; ++j) {
        const double g = down[j - y0];
        __global double *line = image + j * width + x0;
        for (int i = 0; i < x1 - x0; i += 8)
            STORE8(add_light(LOAD8(line + i), g, LOAD8(across + i)), line + i);
    }
}

/* Sources added in one pass over their union footprint (each pixel loaded and stored
 * once per block instead of once per source; the sums keep the source order). */
#ifndef RIMCL_SPLAT_BLOCK
#define RIMCL_SPLAT_BLOCK 16
#endif

/* splat() of `count` sources one after another in one pass over their union footprint,
 * which fits the factor tables (splat_block sees to it): every pixel adds the sources'
 * light in their order, adding an exact 0 for a source whose footprint misses it, so the
 * sums are splat()'s bit for bit. `factors` holds RIMCL_SPLAT_BLOCK x 2 tables of
 * table_width doubles. */
RIMCL_INLINE void splat_run(const double2 *positions, const double *weights, const int count,
                            const int width, const int height, const int radius,
                            const int table_width, __constant const double *consts,
                            __global double *image, __global double *factors)
{
    int x0[RIMCL_SPLAT_BLOCK], y0[RIMCL_SPLAT_BLOCK];
    int lo_x = width, hi_x = 0, lo_y = height, hi_y = 0;
    for (int k = 0; k < count; ++k) {
        const int cx = (int)positions[k].x, cy = (int)positions[k].y;
        x0[k] = max(0, cx - radius);
        y0[k] = max(0, cy - radius);
        lo_x = min(lo_x, x0[k]);
        hi_x = max(hi_x, min(width, cx + radius + 1));
        lo_y = min(lo_y, y0[k]);
        hi_y = max(hi_y, min(height, cy + radius + 1));
    }
    const int span = hi_x - lo_x;
    /* the vectors of a pass read the tables up to 7 entries past the union */
    const int read_x = min(table_width, span + 8), read_y = min(table_width, hi_y - lo_y + 8);
    for (int k = 0; k < count; ++k) {
        __global double *across = factors + 2 * k * table_width;
        __global double *down = across + table_width;
        int f0, f1, g0, g1;
        /* this source's factors at its place in the union; zeros elsewhere */
        source_factors(positions[k].x, width, radius, 1.0, consts, across + (x0[k] - lo_x),
                       &f0, &f1);
        for (int i = 0; i < x0[k] - lo_x; ++i)
            across[i] = 0.0;
        for (int i = f1 - lo_x; i < read_x; ++i)
            across[i] = 0.0;
        source_factors(positions[k].y, height, radius, weights[k], consts, down + (y0[k] - lo_y),
                       &g0, &g1);
        for (int i = 0; i < y0[k] - lo_y; ++i)
            down[i] = 0.0;
        for (int i = g1 - lo_y; i < read_y; ++i)
            down[i] = 0.0;
    }
    /* two rows at a time (each factor vector loaded once for both), where the vectors of
     * one row cannot reach the other's in the same pass (32 pixels per pass) */
    int j = lo_y;
    for (; width >= 32 && j + 1 < hi_y; j += 2) {
        /* source k's factor of row j at down[2 k table_width], of row j + 1 next to it */
        __global const double *down = factors + table_width + (j - lo_y);
        __global double *line = image + j * width + lo_x;
        __global double *below = line + width;
        int i = 0;
        /* four vectors at a time: each pixel's sum is a chain of dependent additions (the
         * source order), so independent pixels are interleaved to hide their latency */
        for (; i + 24 < span; i += 32) {
            double8 sum0 = LOAD8(line + i), sum1 = LOAD8(line + i + 8);
            double8 sum2 = LOAD8(line + i + 16), sum3 = LOAD8(line + i + 24);
            double8 next0 = LOAD8(below + i), next1 = LOAD8(below + i + 8);
            double8 next2 = LOAD8(below + i + 16), next3 = LOAD8(below + i + 24);
            for (int k = 0; k < count; ++k) {
                __global const double *across = factors + 2 * k * table_width + i;
                const double8 a0 = LOAD8(across), a1 = LOAD8(across + 8);
                const double8 a2 = LOAD8(across + 16), a3 = LOAD8(across + 24);
                const double g = down[2 * k * table_width], h = down[2 * k * table_width + 1];
                sum0 = add_light(sum0, g, a0);
                sum1 = add_light(sum1, g, a1);
                sum2 = add_light(sum2, g, a2);
                sum3 = add_light(sum3, g, a3);
                next0 = add_light(next0, h, a0);
                next1 = add_light(next1, h, a1);
                next2 = add_light(next2, h, a2);
                next3 = add_light(next3, h, a3);
            }
            STORE8(sum0, line + i);
            STORE8(sum1, line + i + 8);
            STORE8(sum2, line + i + 16);
            STORE8(sum3, line + i + 24);
            STORE8(next0, below + i);
            STORE8(next1, below + i + 8);
            STORE8(next2, below + i + 16);
            STORE8(next3, below + i + 24);
        }
        for (; i < span; i += 8) {
            double8 sum = LOAD8(line + i), next = LOAD8(below + i);
            for (int k = 0; k < count; ++k) {
                const double8 a = LOAD8(factors + 2 * k * table_width + i);
                const double g = down[2 * k * table_width], h = down[2 * k * table_width + 1];
                sum = add_light(sum, g, a);
                next = add_light(next, h, a);
            }
            STORE8(sum, line + i);
            STORE8(next, below + i);
        }
    }
    for (; j < hi_y; ++j) {
        __global const double *down = factors + table_width + (j - lo_y);
        __global double *line = image + j * width + lo_x;
        int i = 0;
        for (; i + 24 < span; i += 32) {
            double8 sum0 = LOAD8(line + i), sum1 = LOAD8(line + i + 8);
            double8 sum2 = LOAD8(line + i + 16), sum3 = LOAD8(line + i + 24);
            for (int k = 0; k < count; ++k) {
                __global const double *across = factors + 2 * k * table_width + i;
                const double g = down[2 * k * table_width];
                sum0 = add_light(sum0, g, LOAD8(across));
                sum1 = add_light(sum1, g, LOAD8(across + 8));
                sum2 = add_light(sum2, g, LOAD8(across + 16));
                sum3 = add_light(sum3, g, LOAD8(across + 24));
            }
            STORE8(sum0, line + i);
            STORE8(sum1, line + i + 8);
            STORE8(sum2, line + i + 16);
            STORE8(sum3, line + i + 24);
        }
        for (; i < span; i += 8) {
            double8 sum = LOAD8(line + i);
            for (int k = 0; k < count; ++k)
                sum = add_light(sum, down[2 * k * table_width],
                                LOAD8(factors + 2 * k * table_width + i));
            STORE8(sum, line + i);
        }
    }
}

/* splat() of `count` sources one after another: runs of consecutive sources whose union
 * footprint fits the factor tables (at most table_width - 8 pixels across and down) in
 * one pass each (splat_run), a source alone by splat(). Every pixel still adds the
 * sources in their order, so the sums are splat()'s bit for bit. */
RIMCL_INLINE void splat_block(const double2 *positions, const double *weights, const int count,
                              const int width, const int height, const int radius,
                              const int table_width, __constant const double *consts,
                              __global double *image, __global double *factors)
{
    int first = 0;
    while (first < count) {
        int lo_x = width, hi_x = 0, lo_y = height, hi_y = 0, end = first;
        for (; end < count; ++end) {
            const int cx = (int)positions[end].x, cy = (int)positions[end].y;
            const int next_lo_x = min(lo_x, max(0, cx - radius));
            const int next_hi_x = max(hi_x, min(width, cx + radius + 1));
            const int next_lo_y = min(lo_y, max(0, cy - radius));
            const int next_hi_y = max(hi_y, min(height, cy + radius + 1));
            if (end > first && (next_hi_x - next_lo_x + 8 > table_width ||
                                next_hi_y - next_lo_y + 8 > table_width))
                break;
            lo_x = next_lo_x;
            hi_x = next_hi_x;
            lo_y = next_lo_y;
            hi_y = next_hi_y;
        }
        if (end - first == 1)
            splat(positions[first], weights[first], width, height, radius, table_width, consts,
                  image, factors);
        else
            splat_run(positions + first, weights + first, end - first, width, height, radius,
                      table_width, consts, image, factors);
        first = end;
    }
}

/* Whether an image point (relative to the window's corner, pixels) lies in the window. */
RIMCL_INLINE int in_window(const double2 spot, const double width, const double height)
{
    return spot.x >= 0.0 && spot.x < width && spot.y >= 0.0 && spot.y < height;
}

/* splat_block() of `count` sources held in global memory, RIMCL_SPLAT_BLOCK at a time. */
RIMCL_INLINE void splat_sources(__global const double2 *sources, __global const double *weights,
                                const int count, const int width, const int height,
                                const int radius, const int table_width,
                                __constant const double *consts, __global double *image,
                                __global double *factors)
{
    for (int n = 0; n < count; n += RIMCL_SPLAT_BLOCK) {
        double2 block[RIMCL_SPLAT_BLOCK];
        double block_weight[RIMCL_SPLAT_BLOCK];
        const int in_block = min(RIMCL_SPLAT_BLOCK, count - n);
        for (int k = 0; k < in_block; ++k) {
            block[k] = sources[n + k];
            block_weight[k] = weights[n + k];
        }
        splat_block(block, block_weight, in_block, width, height, radius, table_width, consts,
                    image, factors);
    }
}

/* The usable rays inside the window (spots relative to its corner) in the order of square
 * tiles of `tile` pixels, row by row, in ray order within a tile (a stable counting sort
 * with one count per tile in `counts`), into sources and source_weights; returns how many.
 * Rays spread wider than the factor tables take in one pass are added in this order, so
 * that a block's sources lie close together and share one pass over their union
 * (splat_block); every pixel then adds the sources in this order. */
RIMCL_INLINE int sources_in_tiles(const int rays, __global const uchar *ray_code,
                                  __global const double2 *ray_pixel,
                                  __global const double *ray_weight, const double2 corner,
                                  const int width, const int height, const int tile,
                                  __global int *counts, __global double2 *sources,
                                  __global double *source_weights)
{
    const int tiles_x = (width + tile - 1) / tile;
    const int n_tiles = tiles_x * ((height + tile - 1) / tile);
    for (int q = 0; q < n_tiles; ++q)
        counts[q] = 0;
    for (int pass = 0; pass < 2; ++pass) {
        for (int k = 0; k < rays; ++k) {
            if (!(ray_code[k] & RAY_COLLECTED))
                continue;
            const double2 spot = ray_pixel[k] - corner;
            if (!in_window(spot, width, height))
                continue;
            const int q = ((int)spot.y / tile) * tiles_x + (int)spot.x / tile;
            if (pass == 0) {
                counts[q] += 1;
            } else {
                const int at = counts[q]++;
                sources[at] = spot;
                source_weights[at] = ray_weight[k];
            }
        }
        if (pass == 0) {
            int total = 0; /* each tile's first place */
            for (int q = 0; q < n_tiles; ++q) {
                const int in_tile = counts[q];
                counts[q] = total;
                total += in_tile;
            }
        }
    }
    return counts[n_tiles - 1];
}

#if RIMCL_NOISE
/* rimcl/imaging/sensor.py _box_muller: a standard normal of two uniforms. */
RIMCL_INLINE double box_muller(const double u_radius, const double u_angle)
{
    return sqrt(-2.0 * log(u_radius)) * cos(2.0 * M_PI * u_angle);
}

/* The counts of one pixel of `light` (unscaled) with the draws `words` (rimcl/imaging/sensor.py
 * Sensor.digitize and poisson_from_uniforms, the same double operations in the same
 * order); *saturated is set where the full well is reached or the ADC clips. */
RIMCL_INLINE double sensor_counts(const double light, const double scale, const uint4 words,
                                  __constant const double *consts, int *saturated)
{
    const double u0 = rimcl_philox_uniform(words.x), u1 = rimcl_philox_uniform(words.y);
    const double scaled = light * scale;
    const double mean = ((scaled > 0.0) ? scaled : 0.0) + consts[IMG_BACKGROUND];
    double electrons;
    if (mean <= POISSON_INVERSION_MAX) {
        /* inversion: the cumulative sum never decreases, so the loop is numpy's count */
        double term = exp(-mean), cumulative = term;
        int k = 0;
        while (u0 > cumulative && k < POISSON_INVERSION_KMAX) {
            k += 1;
            term = term * (mean / (double)k);
            cumulative = cumulative + term;
        }
        electrons = (double)k;
    } else {
        const double rounded = dbl_rint(mean + sqrt(mean) * box_muller(u0, u1));
        electrons = (rounded > 0.0) ? rounded : 0.0;
    }
    const double full_well = consts[IMG_FULL_WELL];
    *saturated |= electrons >= full_well;
    electrons = (electrons < full_well) ? electrons : full_well;
    const double read_noise = consts[IMG_READ_NOISE];
    if (read_noise > 0.0) {
        const double z1 = box_muller(rimcl_philox_uniform(words.z), rimcl_philox_uniform(words.w));
        electrons = electrons + read_noise * z1;
    }
    const double counts = dbl_rint(electrons / consts[IMG_GAIN]);
    const double full_scale = consts[IMG_FULL_SCALE];
    *saturated |= counts > full_scale;
    return (counts < 0.0) ? 0.0 : ((counts > full_scale) ? full_scale : counts);
}
#endif

/* The window image of tracer t: its rows. */
RIMCL_INLINE void image_tracer(const int t, const slot_scratch s, __constant const double *consts,
                               const int rays, const int max_window, const int pad,
                               const int radius, const int table_width, const int weights_per_ray,
                               const int own_scale, const long threshold_fixed,
                               __global const double2 *ray_pixel_all, __global const int *ray_steps,
                               __global const uchar *ray_code_all, __global const double *weights,
                               __global const double *scales, __global long *row_l,
                               __global double *row_d, __global int *canvas,
                               const int canvas_width, const int canvas_height,
                               const uint2 noise_key, const uint noise_stream,
                               const uint noise_tracer0)
{
    const size_t first = (size_t)t * rays;
    __global const double2 *ray_pixel = ray_pixel_all + first;
    __global const uchar *ray_code = ray_code_all + first;
    __global const double *ray_weight = weights + (weights_per_ray ? first : 0);
    const double threshold = consts[IMG_THRESHOLD];
    const double full_scale = consts[IMG_FULL_SCALE];

    /* ---- the rays: counts, bounding box, light ---- */
    long usable = 0, vignetted = 0, steps = 0;
    long status_count[5] = {0, 0, 0, 0, 0};
    long lo_x = LONG_MAX, lo_y = LONG_MAX, hi_x = LONG_MIN, hi_y = LONG_MIN;
    double light = 0.0, light_x = 0.0, light_y = 0.0;
    for (int k = 0; k < rays; ++k) {
        const int code = ray_code[k];
        const int status = code & RAY_STATUS_MASK;
        steps += ray_steps[first + k];
        for (int q = 0; q < 5; ++q)
            status_count[q] += (status == q);
        if (code & RAY_COLLECTED) {
            const double2 p = ray_pixel[k];
            const double w = ray_weight[k];
            usable += 1;
            const long cx = cell_of(p.x), cy = cell_of(p.y);
            lo_x = min(lo_x, cx);
            hi_x = max(hi_x, cx);
            lo_y = min(lo_y, cy);
            hi_y = max(hi_y, cy);
            light += w;
            light_x += w * p.x;
            light_y += w * p.y;
        } else if (status == RAY_OK) {
            vignetted += 1;
        }
    }
    long flags = (status_count[RAY_OK] < rays) ? FLAG_RAYS_FAILED : 0;
    flags |= (vignetted > 0) ? FLAG_RAYS_VIGNETTED : 0;
    for (int q = 0; q < ROW_LONGS; ++q)
        row_l[q] = 0;
    row_l[ROW_USABLE] = usable;
    for (int q = 0; q < 5; ++q)
        row_l[ROW_STATUS + q] = status_count[q];
    row_l[ROW_VIGNETTED] = vignetted;
    row_l[ROW_STEPS] = steps;
    row_d[ROWD_PEAK] = NAN;
    row_d[ROWD_SCALE] = own_scale ? NAN : scales[t];
    row_d[ROWD_LIGHT] = light;
    row_d[ROWD_LIGHT_X] = light_x;
    row_d[ROWD_LIGHT_Y] = light_y;
    if (usable == 0) {
        row_l[ROW_FLAGS] = flags | FLAG_NO_RAYS;
        return;
    }

    /* ---- the window (Renderer.window_for) ---- */
    long col0 = lo_x - pad, row0 = lo_y - pad;
    long width = hi_x + pad + 1 - col0, height = hi_y + pad + 1 - row0;
    if (width > max_window) {
        col0 = median_cell(ray_pixel, ray_code, rays, 0, s.weights) - max_window / 2;
        width = max_window;
    }
    if (height > max_window) {
        row0 = median_cell(ray_pixel, ray_code, rays, 1, s.weights) - max_window / 2;
        height = max_window;
    }
    const int w_px = (int)width, h_px = (int)height;
    const double2 corner = (double2)((double)col0, (double)row0);
    __global double *image = s.image;
    __global int *labels = s.labels;

    /* ---- the image ---- */
    for (int p = 0; p < w_px * h_px; ++p)
        image[p] = 0.0;
    long outside = 0;
#if RIMCL_RENDERER == 0
    /* each usable ray inside the window, RIMCL_SPLAT_BLOCK at a time: in ray order, or in
     * tile order when the rays spread wider than `spread` pixels, the widest spread of a
     * block's sources whose union footprint fits the factor tables */
    const int spread = table_width - 9 - 2 * radius;
    if (hi_x - lo_x >= spread || hi_y - lo_y >= spread) {
        const int n_sources = sources_in_tiles(rays, ray_code, ray_pixel, ray_weight, corner,
                                               w_px, h_px, max(1, spread / 2), labels,
                                               s.sources, s.weights);
        outside = usable - n_sources;
        splat_sources(s.sources, s.weights, n_sources, w_px, h_px, radius, table_width, consts,
                      image, s.factors);
    } else {
        double2 block[RIMCL_SPLAT_BLOCK];
        double block_weight[RIMCL_SPLAT_BLOCK];
        int in_block = 0;
        for (int k = 0; k < rays; ++k) {
            if (!(ray_code[k] & RAY_COLLECTED))
                continue;
            const double2 spot = ray_pixel[k] - corner;
            if (!in_window(spot, width, height)) {
                outside += 1;
                continue;
            }
            block[in_block] = spot;
            block_weight[in_block++] = ray_weight[k];
            if (in_block == RIMCL_SPLAT_BLOCK) {
                splat_block(block, block_weight, in_block, w_px, h_px, radius, table_width,
                            consts, image, s.factors);
                in_block = 0;
            }
        }
        if (in_block > 0)
            splat_block(block, block_weight, in_block, w_px, h_px, radius, table_width, consts,
                        image, s.factors);
    }
#else
    /* the pixels hit, in the order of first hit, each with its summed weight (numpy's
     * bincount adds the weights in ray order), then each spread by the kernel */
    for (int p = 0; p < w_px * h_px; ++p)
        labels[p] = -1;
    int n_sources = 0;
    for (int k = 0; k < rays; ++k) {
        if (!(ray_code[k] & RAY_COLLECTED))
            continue;
        const double2 spot = ray_pixel[k] - corner;
        if (!in_window(spot, width, height)) {
            outside += 1;
            continue;
        }
        const int cx = (int)dbl_floor(spot.x), cy = (int)dbl_floor(spot.y);
        const int pixel = cy * w_px + cx;
        if (labels[pixel] < 0) {
            labels[pixel] = n_sources;
            s.sources[n_sources] = (double2)((double)cx, (double)cy);
            s.weights[n_sources] = 0.0;
            n_sources += 1;
        }
        s.weights[labels[pixel]] += ray_weight[k];
    }
    splat_sources(s.sources, s.weights, n_sources, w_px, h_px, radius, table_width, consts,
                  image, s.factors);
#endif
    flags |= (outside > 0) ? FLAG_RAYS_OUTSIDE_WINDOW : 0;

    /* ---- counts (rimcl/imaging/sensor.py Sensor.scale_for, Sensor.digitize) ---- */
    double peak = -INFINITY;
    for (int p = 0; p < w_px * h_px; ++p)
        peak = fmax(peak, image[p]);
    const double target = consts[IMG_PEAK];
    const double scale = own_scale ? ((peak > 0.0) ? target / peak : NAN) : scales[t];
    row_l[ROW_WINDOW] = col0;
    row_l[ROW_WINDOW + 1] = row0;
    row_l[ROW_WINDOW + 2] = width;
    row_l[ROW_WINDOW + 3] = height;
    row_l[ROW_OUTSIDE] = outside;
    row_d[ROWD_PEAK] = peak;
    row_d[ROWD_SCALE] = scale;
    if (!(scale == scale)) {
        row_l[ROW_FLAGS] = flags | FLAG_BELOW_THRESHOLD;
        return;
    }
    int saturated = 0;
    int ai0 = INT_MAX, ai1 = -1, aj0 = INT_MAX, aj1 = -1;
#if RIMCL_NOISE
    const uint noise_tracer = noise_tracer0 + (uint)t;
    (void)full_scale; /* the sensor's clip reads it from consts */
#else
    (void)noise_key;
    (void)noise_stream;
    (void)noise_tracer0;
#endif
    for (int j = 0; j < h_px; ++j) {
        for (int i = 0; i < w_px; ++i) {
#if RIMCL_NOISE
            /* the global pixel, wrapped to 32 bits as the host's counters */
            const uint4 counter =
                (uint4)((uint)(col0 + i), (uint)(row0 + j), noise_tracer, noise_stream);
            const double counts = sensor_counts(image[j * w_px + i], scale,
                                                rimcl_philox4x32_10(counter, noise_key), consts,
                                                &saturated);
#else
            double counts = dbl_rint(image[j * w_px + i] * scale);
            saturated |= counts > full_scale;
            counts = (counts < 0.0) ? 0.0 : ((counts > full_scale) ? full_scale : counts);
#endif
            image[j * w_px + i] = counts;
            if (counts > threshold) {
                ai0 = min(ai0, i);
                ai1 = max(ai1, i);
                aj0 = min(aj0, j);
                aj1 = max(aj1, j);
            }
        }
    }
    flags |= saturated ? FLAG_SATURATED : 0;
    if (canvas_width > 0) {
        for (int j = 0; j < h_px; ++j) {
            for (int i = 0; i < w_px; ++i) {
                const long x = col0 + i, y = row0 + j;
                const int counts = (int)image[j * w_px + i];
                if (counts > 0 && x >= 0 && x < canvas_width && y >= 0 && y < canvas_height)
                    atomic_add(&canvas[y * canvas_width + x], counts);
            }
        }
    }
    if (ai1 < 0) {
        row_l[ROW_FLAGS] = flags | FLAG_BELOW_THRESHOLD;
        return;
    }

    /* ---- 8-connected components of the pixels above the threshold (rimcl/imaging/centroid.py) */
    for (int j = aj0; j <= aj1; ++j)
        for (int i = ai0; i <= ai1; ++i)
            labels[j * w_px + i] = (image[j * w_px + i] > threshold) ? j * w_px + i : -1;
    for (int j = aj0; j <= aj1; ++j) {
        for (int i = ai0; i <= ai1; ++i) {
            const int p = j * w_px + i;
            if (labels[p] < 0)
                continue;
            if (i > ai0 && labels[p - 1] >= 0)
                unite(labels, p, p - 1);
            if (j > aj0) {
                const int q = p - w_px;
                if (i > ai0 && labels[q - 1] >= 0)
                    unite(labels, p, q - 1);
                if (labels[q] >= 0)
                    unite(labels, p, q);
                if (i < ai1 && labels[q + 1] >= 0)
                    unite(labels, p, q + 1);
            }
        }
    }
    /* each pixel to its root; each root's light */
    for (int j = aj0; j <= aj1; ++j) {
        for (int i = ai0; i <= ai1; ++i) {
            const int p = j * w_px + i;
            if (labels[p] < 0)
                continue;
            const int root = find_root(labels, p);
            labels[p] = root;
            const int counts = (int)image[p];
            if (root == p) {
                s.border[p] = 0; /* the area, for now */
                s.light_low[p] = 0;
                s.light_high[p] = 0;
            }
            s.border[root] += 1;
            s.light_low[root] += counts & 255;
            s.light_high[root] += counts >> 8;
        }
    }
    long best_light = LONG_MIN;
    int best = -1, components = 0;
    for (int j = aj0; j <= aj1; ++j) {
        for (int i = ai0; i <= ai1; ++i) {
            const int p = j * w_px + i;
            if (labels[p] != p)
                continue;
            components += 1;
            const long sum = (long)s.light_low[p] + 256 * (long)s.light_high[p];
            const long light_p = component_light(sum, s.border[p], threshold_fixed);
            if (light_p > best_light) {
                best_light = light_p;
                best = p;
            }
        }
    }
    flags |= (components > 1) ? FLAG_SPLIT : 0;

    /* ---- moments of the tracer's component ---- */
    long area = 0, sum = 0, sum_col = 0, sum_row = 0, cols = 0, rows = 0;
    int ci0 = INT_MAX, ci1 = -1, cj0 = INT_MAX, cj1 = -1;
    for (int j = aj0; j <= aj1; ++j) {
        for (int i = ai0; i <= ai1; ++i) {
            const int p = j * w_px + i;
            if (labels[p] != best)
                continue;
            const long counts = (long)image[p];
            area += 1;
            sum += counts;
            sum_col += counts * (2 * i + 1);
            sum_row += counts * (2 * j + 1);
            cols += 2 * i + 1;
            rows += 2 * j + 1;
            ci0 = min(ci0, i);
            ci1 = max(ci1, i);
            cj0 = min(cj0, j);
            cj1 = max(cj1, j);
        }
    }
    if (ci0 == 0 || cj0 == 0 || ci1 == w_px - 1 || cj1 == h_px - 1)
        flags |= FLAG_TOUCHES_EDGE;

    /* ---- perimeter (skimage.measure.perimeter, neighborhood=4) ---- */
    /* border pixels: in the component, with a 4-neighbour outside it or the window */
    __global int *border = s.border;
#define IN_COMPONENT(i, j) \
    ((i) >= ci0 && (i) <= ci1 && (j) >= cj0 && (j) <= cj1 && labels[(j) * w_px + (i)] == best)
    for (int j = cj0; j <= cj1; ++j) {
        for (int i = ci0; i <= ci1; ++i) {
            border[j * w_px + i] =
                IN_COMPONENT(i, j) && !(IN_COMPONENT(i - 1, j) && IN_COMPONENT(i + 1, j) &&
                                        IN_COMPONENT(i, j - 1) && IN_COMPONENT(i, j + 1));
        }
    }
#undef IN_COMPONENT
#define BORDER(i, j) \
    (((i) >= ci0 && (i) <= ci1 && (j) >= cj0 && (j) <= cj1) ? border[(j) * w_px + (i)] : 0)
    long histogram[PERIMETER_BINS] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int j = cj0; j <= cj1; ++j) {
        for (int i = ci0; i <= ci1; ++i) {
            if (!border[j * w_px + i])
                continue;
            const int score = 1 +
                              2 * (BORDER(i - 1, j) + BORDER(i + 1, j) + BORDER(i, j - 1) +
                                   BORDER(i, j + 1)) +
                              10 * (BORDER(i - 1, j - 1) + BORDER(i + 1, j - 1) +
                                    BORDER(i - 1, j + 1) + BORDER(i + 1, j + 1));
            const int bin = perimeter_bin(score);
            if (bin >= 0)
                histogram[bin] += 1;
        }
    }
#undef BORDER

    row_l[ROW_FLAGS] = flags;
    row_l[ROW_AREA] = area;
    row_l[ROW_SUM] = sum;
    row_l[ROW_SUM_COL] = sum_col;
    row_l[ROW_SUM_ROW] = sum_row;
    row_l[ROW_COLS] = cols;
    row_l[ROW_ROWS] = rows;
    for (int q = 0; q < PERIMETER_BINS; ++q)
        row_l[ROW_PERIMETER + q] = histogram[q];
}

__kernel void image_tracers(__constant const double *consts, const int n_tracers, const int rays,
                            const int max_window, const int pad, const int radius,
                            const int table_width, const int weights_per_ray, const int own_scale,
                            const long threshold_fixed, __global const double2 *ray_pixel,
                            __global const int *ray_steps, __global const uchar *ray_code,
                            __global const double *weights, __global const double *scales,
                            __global int *next_tracer, __global double *image_pool,
                            __global int *int_pool, __global double2 *source_pool,
                            __global double *source_weight_pool, __global double *factor_pool,
                            __global long *rows_l, __global double *rows_d,
                            __global int *canvas, const int canvas_width,
                            const int canvas_height, const uint seed_low, const uint seed_high,
                            const uint noise_stream, const uint noise_tracer0)
{
    const size_t slot = get_global_id(0);
    const size_t window_area = (size_t)max_window * max_window;
    slot_scratch s;
    s.image = image_pool + slot * (window_area + 8);
    s.labels = int_pool + slot * 4 * window_area;
    s.border = s.labels + window_area;
    s.light_low = s.border + window_area;
    s.light_high = s.light_low + window_area;
    s.sources = source_pool + slot * rays;
    s.weights = source_weight_pool + slot * rays;
    s.factors = factor_pool + slot * 2 * RIMCL_SPLAT_BLOCK * table_width;
    for (;;) {
        const int t = atomic_inc(next_tracer);
        if (t >= n_tracers)
            break;
        image_tracer(t, s, consts, rays, max_window, pad, radius, table_width, weights_per_ray,
                     own_scale, threshold_fixed, ray_pixel, ray_steps, ray_code, weights, scales,
                     rows_l + (size_t)t * ROW_LONGS, rows_d + (size_t)t * ROWD_COUNT, canvas,
                     canvas_width, canvas_height, (uint2)(seed_low, seed_high), noise_stream,
                     noise_tracer0);
    }
}
