/*
 * rimcl_inline.h -- helper functions inlined on every device; the PoCL switch.
 *
 * Purpose: RIMCL_INLINE, the storage class of every helper function, and the double
 * precision builtins that PoCL's pip build leaves as library calls, so that
 * loops calling them vectorise: dbl_floor, dbl_rint, dbl_fabs.
 * Optional define: RIMCL_POCL_FAST 1 on PoCL (forced inlining, clang builtins), 0
 *   (default; GPUs) standard functions. No kernels here. Units: none.
 */
#ifndef RIMCL_INLINE_H
#define RIMCL_INLINE_H

#ifndef RIMCL_POCL_FAST
#define RIMCL_POCL_FAST 0
#endif

#if RIMCL_POCL_FAST
#define RIMCL_INLINE inline __attribute__((always_inline))
#define dbl_floor(x) __builtin_floor(x)
#define dbl_rint(x) __builtin_rint(x)
#define dbl_fabs(x) __builtin_fabs(x)
#else
/* static: NVIDIA's compiler treats a plain C99 `inline` as needing an external
 * definition and fails with "ptxas fatal: Unresolved extern function". */
#define RIMCL_INLINE static inline
#define dbl_floor(x) floor(x)
#define dbl_rint(x) rint(x)
#define dbl_fabs(x) fabs(x)
#endif

#endif
