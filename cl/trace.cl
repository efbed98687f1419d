/*
 * trace.cl -- Sharma-Kumar-Ghatak Runge-Kutta-Nystrom ray tracing to an exit plane.
 *
 * Solves d2R/dt2 = D(R), D = n grad(n), T = dR/dt (|T| = n), dt = ds / n, with the
 * 4th-order step (the paper's B is misprinted; this is the correct form):
 *   A = h D(R),  B = h D(R + h T/2 + h A/8),  C = h D(R + h T + h B/2)
 *   R += h (T + (A + 2B)/6),  T += (A + 4B + C)/6
 * The last step is shortened by Newton iteration on its length so that the ray ends
 * on the plane x1 = x_end (crossed in either direction). Straight back-projection and
 * angles are done on the host in float64 from the exit state written here.
 *
 * Required defines: RIMCL_PRECISION (rimcl_real.h), RIMCL_FIELD and RIMCL_PERIODIC
 *   (rimcl_field.h).
 * Units: lengths in field units; h is a step in t (arc length = n h).
 * Axis order: every 3-vector is (x1, x2, x3); x1 is the depth (marching) axis.
 * Work-item: one ray. Global size: number of rays (n_rays; extra items return).
 *
 * rays_in  (n_rays x RAY_IN_STRIDE floats): origin hi[3], origin lo[3],
 *          unit direction hi[3], direction lo[3] (float64 values split in pairs).
 * rays_out (n_rays x RAY_OUT_STRIDE floats): R hi[3], R lo[3], T hi[3], T lo[3],
 *          S = integral of ds, optical path = integral of n ds,
 *          integral of (grad n / n) perpendicular to the ray, ds [3].
 * ray_info (n_rays int2): steps taken, status (RAY_* below).
 */
#include "rimcl_real.h"
#include "rimcl_params.h"
#include "rimcl_field.h"

#define RAY_IN_STRIDE 12
#define RAY_OUT_STRIDE 17

#define RAY_OK 0
#define RAY_EXIT_SIDE 1
#define RAY_TURNED_BACK 2
#define RAY_MAX_STEPS 3
#define RAY_NON_FINITE 4
#define RAY_RUNNING (-1)

#define NEWTON_ITERATIONS 6

#if RIMCL_PRECISION == RIMCL_F64
#define REAL_EPS DBL_EPSILON
#else
#define REAL_EPS FLT_EPSILON
#endif

typedef struct {
    real3 r; /* position (the hi part in f32c) */
    real3 t; /* T = n dR/ds (the hi part in f32c) */
#if RIMCL_PRECISION == RIMCL_F32C
    float3 r_lo;
    float3 t_lo;
#endif
} ray_state;

/* One RKN step of length h from s; d_a = D(s.r). Returns the field samples
 * (n, grad n) at the B and C points for the path integrals. */
inline ray_state sharma_step(FIELD_ARGS, ray_state s, real3 d_a, real h,
                             real4 *sample_b, real4 *sample_c)
{
    const real sixth = (real)1 / (real)6;
    real3 a = h * d_a;
    real3 pb = s.r + (h * (real)0.5) * s.t + (h * (real)0.125) * a;
    real4 sb = field_sample(FIELD_PASS, pb);
    real3 b = (h * sb.x) * sb.yzw;
    real3 pc = s.r + h * s.t + (h * (real)0.5) * b;
    real4 sc = field_sample(FIELD_PASS, pc);
    real3 c = (h * sc.x) * sc.yzw;
    *sample_b = sb;
    *sample_c = sc;
    ray_state out;
#if RIMCL_PRECISION == RIMCL_F32C
    float3 err;
    float3 prod = two_prod3(h, s.t, &err);
    err += h * s.t_lo + (h * sixth) * (a + (real)2 * b);
    out.r = s.r;
    out.r_lo = s.r_lo;
    df_add3(&out.r, &out.r_lo, prod, err);
    out.t = s.t;
    out.t_lo = s.t_lo;
    df_add3(&out.t, &out.t_lo, sixth * (a + (real)4 * b + c), (float3)(0.0f));
#else
    out.r = s.r + h * (s.t + sixth * (a + (real)2 * b));
    out.t = s.t + sixth * (a + (real)4 * b + c);
#endif
    return out;
}

/* Signed distance of the ray from the exit plane along x1, at full state precision. */
inline real plane_offset(ray_state s, real x_end_hi, real x_end_lo)
{
#if RIMCL_PRECISION == RIMCL_F32C
    return (s.r.x - x_end_hi) + (s.r_lo.x - x_end_lo);
#else
    return s.r.x - (x_end_hi + x_end_lo);
#endif
}

/* Component of grad n perpendicular to the direction of t. */
inline real3 perpendicular(real3 grad, real3 t)
{
    real3 unit = normalize(t);
    return grad - dot(grad, unit) * unit;
}

/* Running sums of the path integrals (Simpson over each step). */
typedef struct {
    real s;      /* integral of n dt = S */
    real s_c;    /* compensation of s (f32c) */
    real opl;    /* integral of n^2 dt = optical path */
    real opl_c;
    real3 nperp; /* integral of (grad n)_perp dt = integral of (grad n / n)_perp ds */
} path_sums;

inline void add_compensated(real *sum, real *comp, real x)
{
#if RIMCL_PRECISION == RIMCL_F32C
    real y = x - *comp;
    real t = *sum + y;
    *comp = (t - *sum) - y;
    *sum = t;
#else
    (void)comp;
    *sum += x;
#endif
}

inline void add_step_integrals(path_sums *sums, real h, real4 sa, real4 sb, real4 sc,
                               real3 t_start, real3 t_mid, real3 t_end)
{
    real w = h / (real)6;
    add_compensated(&sums->s, &sums->s_c, w * (sa.x + (real)4 * sb.x + sc.x));
    add_compensated(&sums->opl, &sums->opl_c,
                    w * (sa.x * sa.x + (real)4 * sb.x * sb.x + sc.x * sc.x));
    sums->nperp += w * (perpendicular(sa.yzw, t_start) + (real)4 * perpendicular(sb.yzw, t_mid)
                        + perpendicular(sc.yzw, t_end));
}

inline void store_pair3(__global float *out, real3 hi_value, float3 lo_value)
{
#if RIMCL_PRECISION == RIMCL_F64
    float3 hi = convert_float3(hi_value);
    float3 lo = convert_float3(hi_value - convert_double3(hi));
    (void)lo_value;
#else
    float3 hi = hi_value;
    float3 lo = lo_value;
#endif
    out[0] = hi.x;
    out[1] = hi.y;
    out[2] = hi.z;
    out[3] = lo.x;
    out[4] = lo.y;
    out[5] = lo.z;
}

inline bool state_finite(ray_state s)
{
    return all(isfinite(s.r)) && all(isfinite(s.t));
}

__kernel void trace_rays(__global const float4 *grid, const int4 counts,
                         __constant const float *params, __global const float *rays_in,
                         __global float *rays_out, __global int2 *ray_info,
                         const int max_steps, const int n_rays)
{
    const int gid = get_global_id(0);
    if (gid >= n_rays)
        return;
    __global const float *in = rays_in + (size_t)gid * RAY_IN_STRIDE;
    float3 origin_hi = vload3(0, in);
    float3 origin_lo = vload3(1, in);
    float3 dir_hi = vload3(2, in);
    float3 dir_lo = vload3(3, in);

    const real h = PARAM(params, P_STEP);
    const real x_end_hi = params[P_XEND];
    const real x_end_lo = params[P_XEND + 1];
    const real3 box_lo = (real3)(params[P_BOX_LO], params[P_BOX_LO + 1], params[P_BOX_LO + 2]);
    const real3 box_hi = (real3)(params[P_BOX_HI], params[P_BOX_HI + 1], params[P_BOX_HI + 2]);

    ray_state s;
    s.r = real3_from_pair(origin_hi, origin_lo);
    real4 sa = field_sample(FIELD_PASS, s.r);
#if RIMCL_PRECISION == RIMCL_F32C
    s.r_lo = origin_lo;
    {
        float3 err;
        float3 prod = two_prod3(sa.x, dir_hi, &err);
        err += sa.x * dir_lo;
        s.t = prod + err;
        s.t_lo = err - (s.t - prod);
    }
#else
    s.t = sa.x * real3_from_pair(dir_hi, dir_lo);
#endif

    /* The ray ends when it reaches the plane from the side it is on; a ray that starts
     * on the plane may turn and come back to it (the fish-eye), any other ray that
     * turns away from the plane has failed. */
    real offset = plane_offset(s, x_end_hi, x_end_lo);
    const bool starts_on_plane = (offset == (real)0);
    const real side = starts_on_plane ? ((s.t.x >= (real)0) ? (real)1 : (real)(-1))
                                      : ((offset > (real)0) ? (real)1 : (real)(-1));

    path_sums sums;
    sums.s = sums.s_c = sums.opl = sums.opl_c = (real)0;
    sums.nperp = (real3)((real)0);

    int status = RAY_RUNNING;
    int steps = 0;
    while (status == RAY_RUNNING) {
        if (steps >= max_steps) {
            status = RAY_MAX_STEPS;
            break;
        }
        real3 d_a = sa.x * sa.yzw;
        real4 sb, sc;
        ray_state next = sharma_step(FIELD_PASS, s, d_a, h, &sb, &sc);
        ++steps;
        real next_offset = plane_offset(next, x_end_hi, x_end_lo);
        if (!state_finite(next)) {
            s = next;
            status = RAY_NON_FINITE;
            break;
        }
        real h_used = h;
        if (side * next_offset <= (real)0) {
            /* Crossed the plane: Newton on the step length, from the secant guess. */
            real hk = h * offset / (offset - next_offset);
            for (int k = 0; k < NEWTON_ITERATIONS; ++k) {
                next = sharma_step(FIELD_PASS, s, d_a, hk, &sb, &sc);
                real dh = plane_offset(next, x_end_hi, x_end_lo) / next.t.x;
                if (!(fabs(dh) > (real)4 * REAL_EPS * hk))
                    break;
                hk = hk - dh;
                hk = (hk < (real)0) ? (real)0 : ((hk > h) ? h : hk);
            }
            h_used = hk;
            status = RAY_OK;
        }
        add_step_integrals(&sums, h_used, sa, sb, sc, s.t, s.t + (real)0.5 * (next.t - s.t),
                           next.t);
        s = next;
        offset = next_offset;
        if (status != RAY_RUNNING)
            break;
        if (any(s.r < box_lo) || any(s.r > box_hi)) {
            status = RAY_EXIT_SIDE;
            break;
        }
        if (!starts_on_plane && (-side) * s.t.x <= (real)0) {
            status = RAY_TURNED_BACK;
            break;
        }
        sa = field_sample(FIELD_PASS, s.r);
    }

    __global float *out = rays_out + (size_t)gid * RAY_OUT_STRIDE;
#if RIMCL_PRECISION == RIMCL_F32C
    store_pair3(out, s.r, s.r_lo);
    store_pair3(out + 6, s.t, s.t_lo);
#else
    store_pair3(out, s.r, (float3)(0.0f));
    store_pair3(out + 6, s.t, (float3)(0.0f));
#endif
    out[12] = (float)(sums.s - sums.s_c);
    out[13] = (float)(sums.opl - sums.opl_c);
    out[14] = (float)sums.nperp.x;
    out[15] = (float)sums.nperp.y;
    out[16] = (float)sums.nperp.z;
    ray_info[gid] = (int2)(steps, status);
}
