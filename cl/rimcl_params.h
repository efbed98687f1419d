/*
 * rimcl_params.h -- layout of the float parameter block passed to the trace kernels.
 *
 * Purpose: one __constant float array carries every scalar of a trace call, each
 * float64 value as a float32 (hi, lo) pair so that the f64 mode sees it exactly and
 * the float modes use hi. The Python side (rimcl/optics/trace.py, `_param_block`) fills the
 * same offsets. Axis order of 3-vectors: x1, x2, x3. Units: field length units.
 */
#ifndef RIMCL_PARAMS_H
#define RIMCL_PARAMS_H

#define P_ORIGIN_HI 0   /* grid node (0,0,0) position, 3 floats */
#define P_ORIGIN_LO 3
#define P_INVH_HI 6     /* 1 / grid spacing, 3 floats */
#define P_INVH_LO 9
#define P_BOX_LO 12     /* region rays may move in; +-inf where unbounded */
#define P_BOX_HI 15
#define P_NREF 18       /* reference index n_ref, (hi, lo) */
#define P_XEND 20       /* exit plane x1 = x_end, (hi, lo) */
#define P_STEP 22       /* step in t (dt = ds / n), (hi, lo); the first step if adaptive */
#define P_ANALYTIC_HI 24 /* 4 parameters of a closed-form field */
#define P_ANALYTIC_LO 28
#define P_STEP_MIN 32   /* adaptive steps: smallest step in t, (hi, lo) */
#define P_STEP_MAX 34   /* adaptive steps: largest step in t, (hi, lo) */
#define P_TOL 36        /* adaptive steps: allowed r' error per unit arc length, (hi, lo) */
#define P_DEPTH 38      /* adaptive steps: lever arm of direction errors on r', (hi, lo) */
#define P_COUNT 40

#define PARAM(p, i) real_from_pair((p)[i], (p)[(i) + 1])
#define PARAM3(p, hi, lo) \
    ((real3)(real_from_pair((p)[hi], (p)[lo]), real_from_pair((p)[(hi) + 1], (p)[(lo) + 1]), \
             real_from_pair((p)[(hi) + 2], (p)[(lo) + 2])))

#endif
