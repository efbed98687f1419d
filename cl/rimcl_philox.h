/*
 * rimcl_philox.h -- counter-based random numbers: Philox-4x32-10 and its uniforms.
 *
 * Purpose: rimcl_philox4x32_10(counter, key), Random123's philox4x32 with 10 rounds
 * (Salmon et al., SC'11), bit-exact with rimcl/imaging/sensor.py philox4x32 (32-bit integer
 * multiplies and xors only, so every device draws the same words); and, where the device
 * has cl_khr_fp64, rimcl_philox_uniform(w) = (w + 0.5) 2^-32, the uniform in (0, 1) of one
 * output word (rimcl/imaging/sensor.py pixel_uniforms). The sensor noise of cl/image.cl draws one
 * counter per pixel: (column, row, tracer, 2 frame + pass) under the key
 * (seed mod 2^32, seed div 2^32).
 * Defines: none required. Optional: RIMCL_POCL_FAST (rimcl_inline.h). Kernels: none.
 * Units: none (counters, keys and words are uint32; uniforms are dimensionless).
 */
#ifndef RIMCL_PHILOX_H
#define RIMCL_PHILOX_H

#include "rimcl_inline.h"

#define RIMCL_PHILOX_M0 0xD2511F53u /* round multipliers */
#define RIMCL_PHILOX_M1 0xCD9E8D57u
#define RIMCL_PHILOX_W0 0x9E3779B9u /* key increments (Weyl sequence) */
#define RIMCL_PHILOX_W1 0xBB67AE85u
#define RIMCL_PHILOX_ROUNDS 10

/* One Philox round: two 32 x 32 -> 64-bit products, their halves swapped and keyed. */
RIMCL_INLINE uint4 rimcl_philox_round(const uint4 c, const uint2 k)
{
    const uint hi0 = mul_hi(RIMCL_PHILOX_M0, c.x), lo0 = RIMCL_PHILOX_M0 * c.x;
    const uint hi1 = mul_hi(RIMCL_PHILOX_M1, c.z), lo1 = RIMCL_PHILOX_M1 * c.z;
    return (uint4)(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
}

/* Philox-4x32-10 of one counter (c0, c1, c2, c3) under the key (k0, k1). */
RIMCL_INLINE uint4 rimcl_philox4x32_10(uint4 counter, uint2 key)
{
    counter = rimcl_philox_round(counter, key);
    for (int r = 1; r < RIMCL_PHILOX_ROUNDS; ++r) {
        key += (uint2)(RIMCL_PHILOX_W0, RIMCL_PHILOX_W1);
        counter = rimcl_philox_round(counter, key);
    }
    return counter;
}

#ifdef cl_khr_fp64
/* The uniform of one word, (w + 0.5) 2^-32 in (0, 1): exact in double. */
RIMCL_INLINE double rimcl_philox_uniform(const uint word)
{
    return ((double)word + 0.5) * 0x1p-32;
}
#endif

#endif
