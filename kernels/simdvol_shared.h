/* simdvol_shared.h — definitions shared by the C++ host/reference and the
 * OpenCL C kernels. Compiles as C++20 and as OpenCL C 1.2.
 *
 * Only plain data and bit-exact integer arithmetic live here (the view's
 * fixed-point geometry and the counter-based random generator): things that
 * must agree bit for bit between the reference and the kernels. The float
 * mathematics of each stage is written twice on purpose, once in the
 * reference (host/core) and once in the kernel, so that one checks the other.
 */
#ifndef SIMDVOL_SHARED_H
#define SIMDVOL_SHARED_H

#ifdef __OPENCL_VERSION__
typedef uint sv_u32;
typedef ulong sv_u64;
typedef long sv_i64;
typedef int sv_i32;
#define SV_FN static inline
#else
#include <stdint.h>
typedef uint32_t sv_u32;
typedef uint64_t sv_u64;
typedef int64_t sv_i64;
typedef int32_t sv_i32;
#define SV_FN static inline
#endif

/* Fixed-point positions: object-space coordinates in voxel units with
 * SV_FRAC_BITS fractional bits. floor() of a position is an arithmetic shift,
 * identical on host and device, which makes the matching stage exact. */
#define SV_FRAC_BITS 32
#define SV_ONE ((sv_i64)1 << SV_FRAC_BITS)

/* The viewing grid and its map into the volume (thesis eq 5.1/5.5):
 *   X_a(i, j, k) = origin[a] + i * step[a][0] + j * step[a][1] + k * step[a][2]
 * with (i, j) the intermediate-image pixel and k the depth index (front to
 * back), X in fixed point. A sample lies inside the volume iff
 * 0 <= floor(X_a) < dims[a] for a = x, y, z. */
typedef struct sv_view {
  sv_i64 origin[4];  /* [3] unused */
  sv_i64 step[3][4]; /* step[a][0..2] = d X_a / d(i, j, k); [a][3] unused */
  sv_i32 dims[4];    /* volume nx, ny, nz; [3] unused */
  sv_i32 grid[4];    /* intermediate image width, height, depth count D; [3] unused */
} sv_view;

/* Philox4x32-10 (Salmon et al., SC'11), the counter-based generator behind
 * the Monte Carlo compositing. Known answer: counter 0, key 0 gives
 * {0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8}. */
typedef struct sv_u32x4 {
  sv_u32 v[4];
} sv_u32x4;

SV_FN sv_u32 sv_mulhilo(sv_u32 a, sv_u32 b, sv_u32* hi) {
  sv_u64 p = (sv_u64)a * (sv_u64)b;
  *hi = (sv_u32)(p >> 32);
  return (sv_u32)p;
}

SV_FN sv_u32x4 sv_philox4x32_10(sv_u32x4 c, sv_u32 k0, sv_u32 k1) {
  for (int r = 0; r < 10; ++r) {
    sv_u32 hi0, hi1;
    sv_u32 lo0 = sv_mulhilo(0xD2511F53u, c.v[0], &hi0);
    sv_u32 lo1 = sv_mulhilo(0xCD9E8D57u, c.v[2], &hi1);
    sv_u32x4 n;
    n.v[0] = hi1 ^ c.v[1] ^ k0;
    n.v[1] = lo1;
    n.v[2] = hi0 ^ c.v[3] ^ k1;
    n.v[3] = lo0;
    c = n;
    k0 += 0x9E3779B9u;
    k1 += 0xBB67AE85u;
  }
  return c;
}

/* Uniform float in [0, 1) with 24 random bits, for Monte Carlo walk `sample`
 * of ray `ray` at depth index `step`. The thesis's shared front-end sequence
 * is ray = SV_SHARED_RAY for every ray. */
#define SV_SHARED_RAY 0xFFFFFFFFu
SV_FN float sv_uniform(sv_u64 seed, sv_u32 ray, sv_u32 sample, sv_u32 step) {
  sv_u32x4 c;
  c.v[0] = ray;
  c.v[1] = sample;
  c.v[2] = step;
  c.v[3] = 0x73696d64u; /* "simd" */
  sv_u32x4 r = sv_philox4x32_10(c, (sv_u32)seed, (sv_u32)(seed >> 32));
  return (float)(r.v[0] >> 8) * (1.0f / 16777216.0f);
}

#endif /* SIMDVOL_SHARED_H */
