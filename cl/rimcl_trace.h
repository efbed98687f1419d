/*
 * rimcl_trace.h -- one work-item's rays traced from their start to the exit plane.
 *
 * Purpose: the Sharma-Kumar-Ghatak Runge-Kutta-Nystrom integration of trace.cl as a
 * function, trace_lanes(), shared by every kernel that traces rays (trace.cl: rays given
 * by the host; fan.cl: a camera's rays made on the device), and store_lane_record(),
 * the one writer of the per-ray exit record. trace_lanes() ends every ray that reaches
 * the exit plane with |T| = n sampled at its exit point (at_exit_index: the exit index
 * Snell takes at the wall, for every camera). The method, the step control and the
 * record layout are described in trace.cl.
 * Required defines: as trace.cl (RIMCL_PRECISION, RIMCL_FIELD, RIMCL_INTERP,
 *   RIMCL_PERIODIC; optional RIMCL_LANES, RIMCL_POCL_FAST, RIMCL_ADAPTIVE).
 * Units: lengths in field units; h is a step in t (arc length = n h).
 * Axis order: every 3-vector is (x1, x2, x3). No kernels here.
 */
#ifndef RIMCL_TRACE_H
#define RIMCL_TRACE_H

#include "rimcl_real.h"
#include "rimcl_params.h"
#include "rimcl_field.h"

#ifndef RIMCL_ADAPTIVE
#define RIMCL_ADAPTIVE 0
#endif

#define RAY_IN_STRIDE 12
#define RAY_OUT_STRIDE 17

#define RAY_OK 0
#define RAY_EXIT_SIDE 1
#define RAY_TURNED_BACK 2
#define RAY_MAX_STEPS 3
#define RAY_NON_FINITE 4
#define RAY_RUNNING (-1)

#define NEWTON_ITERATIONS 6

typedef struct {
    lvec3 r; /* position (the hi part in f32c) */
    lvec3 t; /* T = n dR/ds (the hi part in f32c) */
#if RIMCL_PRECISION == RIMCL_F32C
    lvec3 r_lo;
    lvec3 t_lo;
#endif
} ray_state;

RIMCL_INLINE lvec3 lvec3_select(lmask take_b, lvec3 a, lvec3 b)
{
    lvec3 out = {take_b ? b.x : a.x, take_b ? b.y : a.y, take_b ? b.z : a.z};
    return out;
}

RIMCL_INLINE ray_state state_select(lmask take_b, ray_state a, ray_state b)
{
    ray_state out;
    out.r = lvec3_select(take_b, a.r, b.r);
    out.t = lvec3_select(take_b, a.t, b.t);
#if RIMCL_PRECISION == RIMCL_F32C
    out.r_lo = lvec3_select(take_b, a.r_lo, b.r_lo);
    out.t_lo = lvec3_select(take_b, a.t_lo, b.t_lo);
#endif
    return out;
}

#if RIMCL_PRECISION == RIMCL_F32C
/* One component of R += h (T + (A + 2B)/6), T += (A + 4B + C)/6 in double-float: the
 * product h T_hi is split exactly and T's low part enters the update of R. */
RIMCL_INLINE void sharma_update(lreal *r, lreal *r_lo, lreal *t, lreal *t_lo, lreal h, lreal a,
                                lreal b, lreal c)
{
    const real sixth = (real)1 / (real)6;
    lreal err;
    lreal prod = two_prod(h, *t, &err);
    err += h * *t_lo + (h * sixth) * (a + (real)2 * b);
    df_add(r, r_lo, prod, err);
    df_add(t, t_lo, sixth * (a + (real)4 * b + c), (lreal)((real)0));
}
#define SHARMA_UPDATE(s, k) sharma_update(&s.r.k, &s.r_lo.k, &s.t.k, &s.t_lo.k, h, a.k, b.k, c.k)

/* (*t, *t_lo) = n (d_hi + d_lo) in double-float. */
RIMCL_INLINE void scale_pair(lreal n, lreal d_hi, lreal d_lo, lreal *t, lreal *t_lo)
{
    lreal err;
    lreal prod = two_prod(n, d_hi, &err);
    err += n * d_lo;
    *t = prod + err;
    *t_lo = err - (*t - prod);
}
#else
RIMCL_INLINE void sharma_update(lreal *r, lreal *t, lreal h, lreal a, lreal b, lreal c)
{
    const real sixth = (real)1 / (real)6;
    *r += h * (*t + sixth * (a + (real)2 * b));
    *t += sixth * (a + (real)4 * b + c);
}
#define SHARMA_UPDATE(s, k) sharma_update(&s.r.k, &s.t.k, h, a.k, b.k, c.k)
#endif

/* One RKN step of length h (per lane) from s for the lanes in `active`; d_a = D(s.r).
 * *sb, *sc receive the field samples at the B and C points (for the path integrals);
 * inactive lanes keep theirs and get a meaningless state. */
RIMCL_INLINE ray_state sharma_step(FIELD_ARGS, ray_state s, lvec3 d_a, lreal h, lmask active,
                                   lsample *sb, lsample *sc)
{
    lreal half_h = h * (real)0.5;
    lreal eighth_h = h * (real)0.125;
    lvec3 a = {h * d_a.x, h * d_a.y, h * d_a.z};
    lvec3 pb = {s.r.x + half_h * s.t.x + eighth_h * a.x, s.r.y + half_h * s.t.y + eighth_h * a.y,
                s.r.z + half_h * s.t.z + eighth_h * a.z};
    field_sample_lanes(FIELD_PASS, pb, active, sb);
    lreal hn = h * sb->n;
    lvec3 b = {hn * sb->g1, hn * sb->g2, hn * sb->g3};
    lvec3 pc = {s.r.x + h * s.t.x + half_h * b.x, s.r.y + h * s.t.y + half_h * b.y,
                s.r.z + h * s.t.z + half_h * b.z};
    field_sample_lanes(FIELD_PASS, pc, active, sc);
    hn = h * sc->n;
    lvec3 c = {hn * sc->g1, hn * sc->g2, hn * sc->g3};
    ray_state out = s;
    SHARMA_UPDATE(out, x);
    SHARMA_UPDATE(out, y);
    SHARMA_UPDATE(out, z);
    return out;
}

/* Signed distance of the ray from the exit plane along x1, at full state precision. */
RIMCL_INLINE lreal plane_offset(ray_state s, real x_end_hi, real x_end_lo)
{
#if RIMCL_PRECISION == RIMCL_F32C
    return (s.r.x - x_end_hi) + (s.r_lo.x - x_end_lo);
#else
    return s.r.x - (x_end_hi + x_end_lo);
#endif
}

RIMCL_INLINE lmask state_finite(ray_state s)
{
    return isfinite(s.r.x) & isfinite(s.r.y) & isfinite(s.r.z) & isfinite(s.t.x) &
           isfinite(s.t.y) & isfinite(s.t.z);
}

/* D = n grad n of a sample */
RIMCL_INLINE lvec3 index_force(lsample s)
{
    lvec3 d = {s.n * s.g1, s.n * s.g2, s.n * s.g3};
    return d;
}

/* Running sums of the path integrals (Simpson over each step). */
typedef struct {
    lreal s;      /* integral of n dt = S */
    lreal s_c;    /* compensation of s (f32c) */
    lreal opl;    /* integral of n^2 dt = optical path */
    lreal opl_c;
    lvec3 nperp; /* integral of (grad n)_perp dt = integral of (grad n / n)_perp ds */
} path_sums;

RIMCL_INLINE void add_compensated(lreal *sum, lreal *comp, lreal x, lmask active)
{
#if RIMCL_PRECISION == RIMCL_F32C
    lreal y = x - *comp;
    lreal t = *sum + y;
    *comp = active ? (t - *sum) - y : *comp;
    *sum = active ? t : *sum;
#else
    (void)comp;
    *sum = active ? *sum + x : *sum;
#endif
}

/* The part of a sample's gradient perpendicular to direction t. */
RIMCL_INLINE lvec3 perpendicular(lsample s, lvec3 t)
{
    lreal along = (s.g1 * t.x + s.g2 * t.y + s.g3 * t.z) / (t.x * t.x + t.y * t.y + t.z * t.z);
    lvec3 out = {s.g1 - along * t.x, s.g2 - along * t.y, s.g3 - along * t.z};
    return out;
}

/* Add Simpson's rule over one step of length h from direction t0 to t1 for the lanes
 * in `active`; sa, sb, sc are the samples at the start, B and C points. */
RIMCL_INLINE void add_step_integrals(path_sums *sums, lmask active, lreal h, lsample sa,
                                     lsample sb, lsample sc, lvec3 t0, lvec3 t1)
{
    lreal w = h * ((real)1 / (real)6);
    add_compensated(&sums->s, &sums->s_c, w * (sa.n + (real)4 * sb.n + sc.n), active);
    add_compensated(&sums->opl, &sums->opl_c,
                    w * (sa.n * sa.n + (real)4 * sb.n * sb.n + sc.n * sc.n), active);
    lvec3 t_mid = {t0.x + (real)0.5 * (t1.x - t0.x), t0.y + (real)0.5 * (t1.y - t0.y),
                   t0.z + (real)0.5 * (t1.z - t0.z)};
    lvec3 pa = perpendicular(sa, t0);
    lvec3 pb = perpendicular(sb, t_mid);
    lvec3 pc = perpendicular(sc, t1);
    w = active ? w : (lreal)((real)0);
    sums->nperp.x += w * (pa.x + (real)4 * pb.x + pc.x);
    sums->nperp.y += w * (pa.y + (real)4 * pb.y + pc.y);
    sums->nperp.z += w * (pa.z + (real)4 * pb.z + pc.z);
}

/* Shorten the step from s of the lanes in `crossing` (which crossed the exit plane with
 * a step of length h) so that they end on the plane: Newton on the step length from the
 * secant guess, all such lanes at once. Replaces their *next, *sb, *sc and *h_used. */
RIMCL_INLINE void end_on_plane(FIELD_ARGS, ray_state s, lvec3 d_a, lreal h, lreal offset,
                               lreal next_offset, lmask crossing, real x_end_hi, real x_end_lo,
                               ray_state *next, lsample *sb, lsample *sc, lreal *h_used,
                               lint *evaluations)
{
    lreal hk = crossing ? h * offset / (offset - next_offset) : h;
    lmask todo = crossing;
    for (int k = 0; k < NEWTON_ITERATIONS && LANES_ANY(todo); ++k) {
        ray_state trial = sharma_step(FIELD_PASS, s, d_a, hk, todo, sb, sc);
        *evaluations = todo ? *evaluations + 1 : *evaluations;
        *next = state_select(todo, *next, trial);
        *h_used = todo ? hk : *h_used;
        lreal dh = plane_offset(trial, x_end_hi, x_end_lo) / trial.t.x;
        todo = todo & (fabs(dh) > (real)4 * REAL_EPS * hk);
        lreal moved = hk - dh;
        moved = (moved > (real)0) ? ((moved < h) ? moved : h) : (lreal)((real)0);
        hk = todo ? moved : hk;
    }
}

#if RIMCL_ADAPTIVE
/* Estimated error of the two half steps `fine` against the full step `coarse`, as a
 * displacement of the back-projected image (length units). */
RIMCL_INLINE lreal step_error(ray_state fine, ray_state coarse, real depth_per_n)
{
#if RIMCL_PRECISION == RIMCL_F32C
#define STATE_DIFF(f, k) ((fine.f.k - coarse.f.k) + (fine.f##_lo.k - coarse.f##_lo.k))
#else
#define STATE_DIFF(f, k) (fine.f.k - coarse.f.k)
#endif
    lreal dr = fmax(fmax(fabs(STATE_DIFF(r, x)), fabs(STATE_DIFF(r, y))), fabs(STATE_DIFF(r, z)));
    lreal dt = fmax(fmax(fabs(STATE_DIFF(t, x)), fabs(STATE_DIFF(t, y))), fabs(STATE_DIFF(t, z)));
#undef STATE_DIFF
    return (dr + depth_per_n * dt) * ((real)1 / (real)15);
}
#endif

/* The exit index: rescale T of the lanes in `done` so that |T| = n sampled at their exit
 * point, leaving the direction T/|T| as it is. The integrated |T| drifts from the sampled
 * n (the interpolated grad n is not the gradient of the interpolated n, and the steps
 * have errors); the exit record's |T| is the index that Snell at the exit face takes
 * (rimcl.optics.trace.TraceResult.exit_index), so it is the field's n at the point where
 * the ray leaves. In f32c, n = n_ref (hi, lo) + delta_n and |T| are formed as float pairs
 * and T moves by its relative change, so |T| = n to about 1e-11, not to the float
 * rounding of n (6e-8 of it, comparable to the whole refraction at weak cases). The NumPy
 * twin (rimcl/optics/reference.py) does the same in float64. */
RIMCL_INLINE void at_exit_index(FIELD_ARGS, ray_state *s, lmask done)
{
    if (!LANES_ANY(done))
        return;
    const lreal zero = (real)0;
    lsample se = {zero, zero, zero, zero};
#if RIMCL_PRECISION == RIMCL_F32C
    field_sample_lanes_base(FIELD_PASS, s->r, done, &se, (real)0); /* delta_n alone */
    lreal n_lo;
    const lreal n_hi = two_sum((lreal)params[P_NREF], se.n, &n_lo);
    n_lo += params[P_NREF + 1];
    /* |T|^2 as a pair (exact squares of the hi parts), then its square root */
    lreal q_hi = zero, q_lo = zero, err;
    lreal sq = two_prod(s->t.x, s->t.x, &err);
    df_add(&q_hi, &q_lo, sq, err + (real)2 * s->t.x * s->t_lo.x);
    sq = two_prod(s->t.y, s->t.y, &err);
    df_add(&q_hi, &q_lo, sq, err + (real)2 * s->t.y * s->t_lo.y);
    sq = two_prod(s->t.z, s->t.z, &err);
    df_add(&q_hi, &q_lo, sq, err + (real)2 * s->t.z * s->t_lo.z);
    const lreal norm_hi = sqrt(q_hi);
    sq = two_prod(norm_hi, norm_hi, &err);
    const lreal norm_lo = (((q_hi - sq) - err) + q_lo) / ((real)2 * norm_hi);
    /* T += eps T, eps = (n - |T|) / |T| (n and |T| within a factor 2: n_hi - norm_hi exact) */
    const lreal eps = ((n_hi - norm_hi) + (n_lo - norm_lo)) / norm_hi;
    lvec3 hi = s->t, lo = s->t_lo;
    df_add(&hi.x, &lo.x, eps * s->t.x, eps * s->t_lo.x);
    df_add(&hi.y, &lo.y, eps * s->t.y, eps * s->t_lo.y);
    df_add(&hi.z, &lo.z, eps * s->t.z, eps * s->t_lo.z);
    /* the other lanes keep their state bit for bit */
    s->t = lvec3_select(done, s->t, hi);
    s->t_lo = lvec3_select(done, s->t_lo, lo);
#else
    field_sample_lanes(FIELD_PASS, s->r, done, &se);
    lreal factor = se.n / sqrt(s->t.x * s->t.x + s->t.y * s->t.y + s->t.z * s->t.z);
    factor = done ? factor : (lreal)((real)1);
    s->t.x *= factor;
    s->t.y *= factor;
    s->t.z *= factor;
#endif
}

/* Everything a traced lane ends with. */
typedef struct {
    ray_state s;     /* exit state (last state for failed rays) */
    path_sums sums;  /* path integrals */
    lint status;     /* RAY_* */
    lint steps;      /* steps taken (accepted steps if adaptive) */
    lint rejected;   /* rejected step attempts (adaptive) */
    lint evaluations; /* Sharma steps evaluated in all */
} lane_result;

/* Trace the rays in the lanes of `valid` from origin (hi, lo) along the unit direction
 * (hi, lo) until they end on the exit plane, fail, or take max_steps steps. */
RIMCL_INLINE lane_result trace_lanes(FIELD_ARGS, lvec3 origin_hi, lvec3 origin_lo, lvec3 dir_hi,
                                     lvec3 dir_lo, lmask valid, const int max_steps)
{
    const real h_fixed = PARAM(params, P_STEP);
    const real x_end_hi = params[P_XEND];
    const real x_end_lo = params[P_XEND + 1];
    const real box_lo1 = params[P_BOX_LO], box_lo2 = params[P_BOX_LO + 1],
               box_lo3 = params[P_BOX_LO + 2];
    const real box_hi1 = params[P_BOX_HI], box_hi2 = params[P_BOX_HI + 1],
               box_hi3 = params[P_BOX_HI + 2];

    ray_state s;
    lsample sa = {(lreal)((real)0), (lreal)((real)0), (lreal)((real)0), (lreal)((real)0)};
#if RIMCL_PRECISION == RIMCL_F64
    s.r.x = origin_hi.x + origin_lo.x;
    s.r.y = origin_hi.y + origin_lo.y;
    s.r.z = origin_hi.z + origin_lo.z;
    field_sample_lanes(FIELD_PASS, s.r, valid, &sa);
    s.t.x = sa.n * (dir_hi.x + dir_lo.x);
    s.t.y = sa.n * (dir_hi.y + dir_lo.y);
    s.t.z = sa.n * (dir_hi.z + dir_lo.z);
#elif RIMCL_PRECISION == RIMCL_F32C
    s.r = origin_hi;
    s.r_lo = origin_lo;
    field_sample_lanes(FIELD_PASS, s.r, valid, &sa);
    scale_pair(sa.n, dir_hi.x, dir_lo.x, &s.t.x, &s.t_lo.x);
    scale_pair(sa.n, dir_hi.y, dir_lo.y, &s.t.y, &s.t_lo.y);
    scale_pair(sa.n, dir_hi.z, dir_lo.z, &s.t.z, &s.t_lo.z);
#else
    s.r = origin_hi;
    field_sample_lanes(FIELD_PASS, s.r, valid, &sa);
    s.t.x = sa.n * dir_hi.x;
    s.t.y = sa.n * dir_hi.y;
    s.t.z = sa.n * dir_hi.z;
#endif

    /* The ray ends when it reaches the plane from the side it is on; a ray that starts
     * on the plane may turn and come back to it (the fish-eye), any other ray that
     * turns away from the plane has failed. */
    lreal offset = plane_offset(s, x_end_hi, x_end_lo);
    const lmask starts_on_plane = (offset == (real)0);
    const lreal side = starts_on_plane ? ((s.t.x >= (real)0) ? (lreal)((real)1) : (lreal)((real)-1))
                                       : ((offset > (real)0) ? (lreal)((real)1) : (lreal)((real)-1));

    const lreal zero = (real)0;
    path_sums sums = {zero, zero, zero, zero, {zero, zero, zero}};
    lint status = RAY_RUNNING;
    lint steps = 0;
    lint rejected = 0;
    lint evaluations = 0;
    lmask running = valid;
#if RIMCL_ADAPTIVE
    lreal h = h_fixed;
    const real h_min = PARAM(params, P_STEP_MIN);
    const real h_max = PARAM(params, P_STEP_MAX);
    const real tol_per_arc = PARAM(params, P_TOL);
    const real depth_per_n = PARAM(params, P_DEPTH) / PARAM(params, P_NREF);
    lmask last_rejected = 0;
#else
    const lreal h = h_fixed;
#endif

    while (LANES_ANY(running)) {
        lmask at_limit = running & (steps >= max_steps);
        status = at_limit ? (lint)RAY_MAX_STEPS : status;
        running &= ~at_limit;
        if (!LANES_ANY(running))
            break;
        lvec3 d_a = index_force(sa);
        lsample sb = sa, sc = sa;
#if RIMCL_ADAPTIVE
        /* one step of h and two of h/2; the lanes whose error is too large take no step
         * (`moving` false) and try again with a smaller h */
        lsample fb = sa, fc = sa;
        ray_state full = sharma_step(FIELD_PASS, s, d_a, h, running, &fb, &fc);
        lreal half_h = h * (real)0.5;
        ray_state mid = sharma_step(FIELD_PASS, s, d_a, half_h, running, &sb, &sc);
        lsample sm = sa;
        field_sample_lanes(FIELD_PASS, mid.r, running, &sm);
        lsample sb2 = sm, sc2 = sm;
        ray_state next = sharma_step(FIELD_PASS, mid, index_force(sm), half_h, running, &sb2, &sc2);
        evaluations = running ? evaluations + 3 : evaluations;

        lreal error = step_error(next, full, depth_per_n);
        lreal allowed = tol_per_arc * sa.n * h;
        lmask moving = running & ((error <= allowed) | (h <= h_min));
        /* grow by 2 at most, and not at all straight after a rejection */
        lreal factor = (real)0.9 * sqrt(sqrt(allowed / error));
        lreal growth = (last_rejected != 0) ? (lreal)((real)1) : (lreal)((real)2);
        factor = (factor > (real)0.2) ? ((factor < growth) ? factor : growth) : (real)0.2;
        lreal h_next = h * factor;
        h_next = (h_next < h_max) ? ((h_next > h_min) ? h_next : h_min) : h_max;
        rejected = (running & ~moving) ? rejected + 1 : rejected;
        last_rejected = running ? (running & ~moving) : last_rejected;
        const lreal h_step = h;
        h = running ? h_next : h;
        if (!LANES_ANY(moving))
            continue;
#else
        ray_state next = sharma_step(FIELD_PASS, s, d_a, h, running, &sb, &sc);
        evaluations = running ? evaluations + 1 : evaluations;
        const lmask moving = running;
        const lreal h_step = h;
#endif
        steps = moving ? steps + 1 : steps;
        lreal next_offset = plane_offset(next, x_end_hi, x_end_lo);
        lmask finite = state_finite(next);
        lmask crossed = moving & finite & (side * next_offset <= (real)0);
        if (LANES_ANY(crossed)) {
            lsample nb = sb, nc = sc;
            lreal h_used = h_step;
            end_on_plane(FIELD_PASS, s, d_a, h_step, offset, next_offset, crossed, x_end_hi,
                         x_end_lo, &next, &nb, &nc, &h_used, &evaluations);
            add_step_integrals(&sums, crossed, h_used, sa, nb, nc, s.t, next.t);
        }
#if RIMCL_ADAPTIVE
        add_step_integrals(&sums, moving & ~crossed, half_h, sa, sb, sc, s.t, mid.t);
        add_step_integrals(&sums, moving & ~crossed, half_h, sm, sb2, sc2, mid.t, next.t);
#else
        add_step_integrals(&sums, moving & ~crossed, h_step, sa, sb, sc, s.t, next.t);
#endif
        s = state_select(moving, s, next);
        offset = moving ? next_offset : offset;
        status = (moving & ~finite) ? (lint)RAY_NON_FINITE : status;
        status = crossed ? (lint)RAY_OK : status;
        lmask still = moving & finite & ~crossed;
        lmask outside = (s.r.x < box_lo1) | (s.r.y < box_lo2) | (s.r.z < box_lo3) |
                        (s.r.x > box_hi1) | (s.r.y > box_hi2) | (s.r.z > box_hi3);
        status = (still & outside) ? (lint)RAY_EXIT_SIDE : status;
        still &= ~outside;
        lmask turned = still & ~starts_on_plane & (-side * s.t.x <= (real)0);
        status = turned ? (lint)RAY_TURNED_BACK : status;
        still &= ~turned;
        /* lanes that retry a step keep running with the same sample */
        running = (running & ~moving) | still;
        field_sample_lanes(FIELD_PASS, s.r, still, &sa);
#if RIMCL_FIELD_PREFETCH
        {
            /* the end of the next step */
            lreal ahead = h * (real)2;
            lvec3 q = {s.r.x + ahead * s.t.x, s.r.y + ahead * s.t.y, s.r.z + ahead * s.t.z};
            field_prefetch_lanes(FIELD_PASS, q, still);
        }
#endif
    }

    at_exit_index(FIELD_PASS, &s, valid & (status == (lint)RAY_OK));
    lane_result out = {s, sums, status, steps, rejected, evaluations};
    return out;
}

/* Lane k of a traced work-item as the exit record of trace.cl: RAY_OUT_STRIDE floats
 * (R and T as float (hi, lo) pairs, path integrals) and its ray_info. */
RIMCL_INLINE void lane_record(const lane_result *res, const int k, float *record, int4 *info)
{
    real r_hi[3] = {LANE(res->s.r.x, k), LANE(res->s.r.y, k), LANE(res->s.r.z, k)};
    real t_hi[3] = {LANE(res->s.t.x, k), LANE(res->s.t.y, k), LANE(res->s.t.z, k)};
#if RIMCL_PRECISION == RIMCL_F32C
    real r_lo[3] = {LANE(res->s.r_lo.x, k), LANE(res->s.r_lo.y, k), LANE(res->s.r_lo.z, k)};
    real t_lo[3] = {LANE(res->s.t_lo.x, k), LANE(res->s.t_lo.y, k), LANE(res->s.t_lo.z, k)};
#endif
    for (int q = 0; q < 3; ++q) {
        record[q] = (float)r_hi[q];
        record[6 + q] = (float)t_hi[q];
#if RIMCL_PRECISION == RIMCL_F32C
        record[3 + q] = r_lo[q];
        record[9 + q] = t_lo[q];
#elif RIMCL_PRECISION == RIMCL_F64
        record[3 + q] = (float)(r_hi[q] - (double)(float)r_hi[q]);
        record[9 + q] = (float)(t_hi[q] - (double)(float)t_hi[q]);
#else
        record[3 + q] = 0.0f;
        record[9 + q] = 0.0f;
#endif
    }
    record[12] = (float)(LANE(res->sums.s, k) - LANE(res->sums.s_c, k));
    record[13] = (float)(LANE(res->sums.opl, k) - LANE(res->sums.opl_c, k));
    record[14] = (float)LANE(res->sums.nperp.x, k);
    record[15] = (float)LANE(res->sums.nperp.y, k);
    record[16] = (float)LANE(res->sums.nperp.z, k);
    *info = (int4)((int)LANE_I(res->steps, k), (int)LANE_I(res->status, k),
                   (int)LANE_I(res->rejected, k), (int)LANE_I(res->evaluations, k));
}

/* Write lane k's exit record (lane_record) to `out` and `info`. */
RIMCL_INLINE void store_lane_record(__global float *out, __global int4 *info,
                                    const lane_result *res, const int k)
{
    float record[RAY_OUT_STRIDE];
    int4 lane_info;
    lane_record(res, k, record, &lane_info);
    for (int q = 0; q < RAY_OUT_STRIDE; ++q)
        out[q] = record[q];
    *info = lane_info;
}

#endif
