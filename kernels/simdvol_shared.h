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
#define SV_CAST(T, x) ((T)(x))
#else
#include <stdint.h>
typedef uint32_t sv_u32;
typedef uint64_t sv_u64;
typedef int64_t sv_i64;
typedef int32_t sv_i32;
#define SV_FN static inline
/* static_cast in C++, so that a program including this header (through the
 * public headers) stays clean under -Wold-style-cast. */
#define SV_CAST(T, x) (static_cast<T>(x))
#endif

/* Fixed-point positions: object-space coordinates in voxel units with
 * SV_FRAC_BITS fractional bits. floor() of a position is an arithmetic shift,
 * identical on host and device, which makes the matching stage exact. */
#define SV_FRAC_BITS 32
#define SV_ONE (SV_CAST(sv_i64, 1) << SV_FRAC_BITS)

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
  sv_u64 p = SV_CAST(sv_u64, a) * SV_CAST(sv_u64, b);
  *hi = SV_CAST(sv_u32, p >> 32);
  return SV_CAST(sv_u32, p);
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

/* Uniform floats in [0, 1) with 24 random bits, for Monte Carlo walks
 * 4q .. 4q + 3 of ray `ray` at depth index `step`: u[w] from word w of the
 * Philox block at counter (ray, q, step, "simd"). One block serves four
 * walks (kernels/mc.cl: sv_uniform8x4 draws 8 walks at 4 steps). The
 * thesis's shared front-end sequence is ray = SV_SHARED_RAY for every ray. */
#define SV_SHARED_RAY 0xFFFFFFFFu
SV_FN void sv_uniform4(sv_u64 seed, sv_u32 ray, sv_u32 q, sv_u32 step, float* u) {
  sv_u32x4 c;
  c.v[0] = ray;
  c.v[1] = q;
  c.v[2] = step;
  c.v[3] = 0x73696d64u; /* "simd" */
  sv_u32x4 r = sv_philox4x32_10(c, SV_CAST(sv_u32, seed), SV_CAST(sv_u32, seed >> 32));
  for (int w = 0; w < 4; ++w) u[w] = SV_CAST(float, r.v[w] >> 8) * (1.0f / 16777216.0f);
}

/* The draw of walk `sample`: sv_uniform4's word sample mod 4. */
SV_FN float sv_uniform(sv_u64 seed, sv_u32 ray, sv_u32 sample, sv_u32 step) {
  float u[4];
  sv_uniform4(seed, ray, sample >> 2, step, u);
  return u[sample & 3u];
}

/* ---- shade and classify stages (kernels/shade.cl, kernels/classify.cl) ----
 * Parameters are plain float/int members only, so the layout is identical in
 * C++ and OpenCL C (the host static_asserts the sizes). The host fills them
 * from ShadeParams/ShadeFrame and Classifier (host/cl/shade.cpp,
 * host/cl/classify.cpp); the kernels read them from a __constant buffer. */
#define SV_MAX_MATERIALS 16
/* Empty-space skipping: bricks of 2^SV_BRICK_LOG2 voxels per axis
 * (resample.cl, classify.cl; the host's kBrick). */
#define SV_BRICK_LOG2 2

/* The fused resample + local kernel's lane order (local.cl:
 * simdvol_segment_order): segments sorted by length within blocks of
 * SV_ORDER_BLOCK consecutive segments (cut at the PEs' boundaries). The
 * lanes' efficiency (samples over 8 x the longest lane's, summed over the
 * work-items; the 256^3 phantom at (20, 35, 10), 8,192 PEs, every PE, on
 * the host): unsorted 0.595, blocks of 256 0.917, 1024 0.929, 4096 0.932
 * after 8 sweeps (0.631 / 0.931 / 0.943 / 0.945 without balancing).
 * scripts/bench-ab, 256 -> 1024, resample + local (the order in it):
 * the phantom 28.75 -> 28.43 ms (0.983, 6 pairs), ch2 23.82 -> 23.39
 * (0.984), brainsmall 3.94 -> 3.83 (0.970) (2-core Intel Xeon,
 * 2026-12-05). */
#define SV_ORDER_BLOCK 1024
/* The balance's per-sweep "moved samples" flags (balance.cl: moves): one
 * int per SV_BAL_MOVES_STRIDE, a cache line each, so that the flag a round
 * reads (the sweep before) shares no line with the one it writes. */
#define SV_BAL_MOVES_STRIDE 16
/* The pairs one balance round work-item takes (balance.cl: _round; the host
 * launches ceil(pairs / SV_BAL_PES) work-items). */
#define SV_BAL_PES 16
#define SV_MAX_KNOTS 32
#define SV_CLASSIFY_MIXTURE 0
#define SV_CLASSIFY_TRANSFER 1

typedef struct sv_shade_params {
  float light[4];      /* unit L in object space ([3] unused) */
  float halfway[4];    /* unit H in object space ([3] unused) */
  float depth_dir[4];  /* d = dot(depth_dir, voxel index) + depth_offset ([3] unused) */
  float grad_scale[4]; /* min spacing / spacing per axis ([3] unused) */
  float depth_offset;
  float ka, kd, ks;
  float shininess;  /* Phong exponent n */
  float k1, k2;     /* depth cue 1 / (k1 + k2 d) */
  sv_i32 enabled;   /* 0: Id = 1, Is = 0 */
  float spec_floor; /* |N.H| below it: |N.H|^n counts as 0 (specular_floor, shade.hpp) */
  sv_i32 grad_over; /* 1: the volume's range allows gradients whose squares overflow float
                       (ShadeFrame::grad_over); the host then builds with SV_GRAD_OVER */
  float surface_g2; /* |g|^2 below it: no surface, ambient light only (ShadeFrame::surface_g2,
                       surface_threshold in shade.hpp); 0 or less: 1e-12 */
} sv_shade_params;

/* The materials of a mixture, one array per quantity (not an array of
 * structs: PoCL's SLP pass packs loads of adjacent struct fields into vector
 * instructions, which then stop its vectorisation across work-items). */
typedef struct sv_materials {
  float mean[SV_MAX_MATERIALS];
  float sigma[SV_MAX_MATERIALS];
  float r[SV_MAX_MATERIALS], g[SV_MAX_MATERIALS], b[SV_MAX_MATERIALS];
  float opacity[SV_MAX_MATERIALS];
  /* Materials k and k + 1 (k < count - 1): L_{k+1} - L_k = (qa x + qb) x
   * + qc at x = I - c (classify.hpp, mixture_pair). */
  float pair_c[SV_MAX_MATERIALS], pair_qa[SV_MAX_MATERIALS];
  float pair_qb[SV_MAX_MATERIALS], pair_qc[SV_MAX_MATERIALS];
} sv_materials;

/* Piecewise-linear ramp: count points (x ascending); count 0 is the constant 1. */
typedef struct sv_ramp {
  sv_i32 count;
  sv_i32 pad[3];
  float x[SV_MAX_KNOTS];
  float y[SV_MAX_KNOTS];
} sv_ramp;

typedef struct sv_classify_params {
  sv_i32 kind;           /* SV_CLASSIFY_MIXTURE or SV_CLASSIFY_TRANSFER */
  sv_i32 relative;       /* mixture: I = (v - range_min) * range_scale */
  sv_i32 material_count; /* 1..SV_MAX_MATERIALS, strictly ascending means */
  sv_i32 step_is_one;    /* opacity_step == 1 exactly: no opacity correction */
  float range_min;
  float range_scale; /* 1 / (max - min), or 0 when max == min (then I = 0) */
  float opacity_step;
  float pad;
  sv_materials materials;
  sv_ramp density, gradient, red, green, blue;
} sv_classify_params;

/* ---- match, balance, resample, local (kernels/match.cl ... local.cl) ----
 * A segment: the samples [k0, k1) of ray (i, j) that one PE resamples. A PE's
 * segments are stored contiguously (CSR: seg_offset[p] .. seg_offset[p+1]),
 * sorted by (j, i). Balancing only moves k0/k1 between face neighbours; a
 * segment may become empty (k0 == k1). */
typedef struct sv_segment {
  sv_i32 i, j;   /* ray = intermediate-image pixel */
  sv_i32 k0, k1; /* depth range, front to back */
} sv_segment;

/* A PE's footprint: the bounding rectangle of its segments' rays
 * (w = h = 0 when it has none). */
typedef struct sv_rect {
  sv_i32 i0, j0, w, h;
} sv_rect;

#endif /* SIMDVOL_SHARED_H */
