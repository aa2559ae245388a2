/* common.cl — helpers shared by every simdvol kernel file.
 *
 * Each stage file starts with
 *   #ifndef SIMDVOL_COMMON_CL
 *   #include "common.cl"
 *   #endif
 * so it compiles on its own (with -I kernels) and, in the source the host
 * assembles (defines + simdvol_shared.h + common.cl + stage.cl), skips the
 * #include because the guard is already defined.
 *
 * Cell buffers (see host/include/simdvol/pe_array.hpp): PE p's padded block
 * starts at p * stride floats; local position (lx, ly, lz), each in
 * [-halo, cell + halo), is at ((lz + halo) * by + (ly + halo)) * bx + lx + halo
 * with block = (bx, by, bz) = cell + 2 * halo. Kernels receive the geometry as
 *   int4 dims   volume nx, ny, nz (w unused)
 *   int4 cell   interior cell extent cx, cy, cz; w = halo
 *   int4 block  padded extent bx, by, bz; w = stride (floats per PE block)
 *   global const int4* origins   first voxel of each PE's cell (w unused)
 */
#ifndef SIMDVOL_COMMON_CL
#define SIMDVOL_COMMON_CL

#ifndef SIMDVOL_SHARED_H
#include "simdvol_shared.h"
#endif

/* Unaligned vector loads of 8 and 16 floats: the vector types with 4-byte
 * alignment, loaded through a pointer cast (one vmovups). PoCL 3.1's
 * vload8 / vload16 on these machines became 8-byte loads combined into
 * 2-lane arithmetic (vmovsd, vmovlhps) in the float16 shade kernels. */
typedef float8 sv_float8u __attribute__((aligned(4)));
typedef float16 sv_float16u __attribute__((aligned(4)));
#ifndef SV_VLOAD_BUILTIN
#define SV_VLOAD8(p) (*(__global const sv_float8u*)(p))
#define SV_VLOAD16(p) (*(__global const sv_float16u*)(p))
#else
#define SV_VLOAD8(p) vload8(0, (p))
#define SV_VLOAD16(p) vload16(0, (p))
#endif

/* Store of 16 floats at p, likewise: vstore16 became four 16-byte stores
 * (vmovdqu xmm, vextractf32x4) in the float16 shade and classify kernels;
 * SV_VSTORE_BUILTIN keeps vstore16 for comparison. With SV_NT, a
 * non-temporal store (no read-for-ownership of the line; p 64-byte
 * aligned: planes and chunks start on multiples of 16 floats). */
#if defined(SV_NT) && defined(__clang__)
#define SV_VSTORE16(v, p) __builtin_nontemporal_store((v), (__global float16*)(p))
#elif defined(SV_VSTORE_BUILTIN)
#define SV_VSTORE16(v, p) vstore16((v), 0, (p))
#else
#define SV_VSTORE16(v, p) (*(__global sv_float16u*)(p) = (v))
#endif

/* SV_VSTORE16, or where nt a non-temporal store (p 64-byte aligned): a
 * run-time choice, so that both forms are one program (the fused shade +
 * classify's kc_mode & 8, for voxel cells stored before; a define would
 * build a second program in the frame that first takes it). */
#if defined(__clang__)
#define SV_VSTORE16_NT(v, p, nt)                                \
  do {                                                          \
    if (nt)                                                     \
      __builtin_nontemporal_store((v), (__global float16*)(p)); \
    else                                                        \
      SV_VSTORE16((v), (p));                                    \
  } while (0)
#else
#define SV_VSTORE16_NT(v, p, nt) SV_VSTORE16((v), (p))
#endif

/* A helper LLVM must inline: it kept some of the larger SV_FN helpers as
 * calls, with their array arguments passed through memory (perf: the call
 * to sv_ld16_rows took 8 % of ch2's shade + classify samples). */
#ifndef SV_NO_FORCE_INLINE
#define SV_FN_INLINE static inline __attribute__((always_inline))
#else
#define SV_FN_INLINE SV_FN
#endif

/* A software prefetch of the line at p, only on CPU targets (x86-64,
 * AArch64), where it is a hint that never faults, so it may point past a
 * buffer's end; elsewhere nothing (a GPU's prefetch may fault out of
 * bounds). */
#if defined(__clang__) && (defined(__x86_64__) || defined(__aarch64__))
#define SV_PREFETCH(p) __builtin_prefetch(p)
#define SV_PREFETCHW(p) __builtin_prefetch((p), 1)
/* ... into the second-level cache (x86-64: prefetcht1) */
#define SV_PREFETCH_L2(p) __builtin_prefetch((p), 0, 2)
#else
#define SV_PREFETCH(p) ((void)0)
#define SV_PREFETCHW(p) ((void)0)
#define SV_PREFETCH_L2(p) ((void)0)
#endif

/* Marks brick word *p of an occupancy buffer (zero before the kernel,
 * read after it): a plain store of 1. Every writer stores the same word,
 * so the races between work-items leave 1 wherever any of them marked,
 * without a locked read-modify-write per mark; -DSV_MARK_ATOMIC gives
 * atomic_or instead. The frame's shade + classify on the 256^3 phantom
 * (simdvol-bench-options, 20 frames per variant, three runs): 21.2 / 21.1
 * / 21.5 -> 20.3 / 20.5 / 20.4 ms, the same images; brainsmall 3.9 -> 3.7
 * ms; ch2 (odd cell widths, fewer marks) the same. */
#ifdef SV_MARK_ATOMIC
#define SV_MARK(p) atomic_or((p), 1u)
#else
#define SV_MARK(p) ((void)(*(p) = 1u))
#endif

/* Largest p with seg_off[p] <= s: the PE of segment s (P = 2^log2p). */
SV_FN int sv_pe_of_segment(__global const int* seg_off, const int log2p, const int s) {
  int p = 0;
  for (int b = log2p - 1; b >= 0; --b) {
    const int c = p | (1 << b);
    p = seg_off[c] <= s ? c : p;
  }
  return p;
}

/* The PE of position s >= seg_off[p], found by stepping on from p (a few
 * PEs on, as a work-item's prefetch looks) and by the search past
 * SV_PE_STEPS of them: sv_pe_of_segment's PE. */
#ifndef SV_PE_STEPS
#define SV_PE_STEPS 8
#endif
SV_FN int sv_pe_after(__global const int* seg_off, const int log2p, int p, const int s) {
  for (int i = 0; i < SV_PE_STEPS; ++i, ++p)
    if (seg_off[p + 1] > s) return p;
  return sv_pe_of_segment(seg_off, log2p, s);
}

/* Work-group size of 1-D kernels; the host passes the same value as the
 * local size. */
#ifndef WGS
#define WGS 64
#endif

/* Index of local position (lx, ly, lz) within a PE's block (not counting the
 * block's start p * stride). */
SV_FN size_t sv_block_offset(int4 cell, int4 block, int lx, int ly, int lz) {
  const int h = cell.w;
  return ((size_t)(lz + h) * (size_t)block.y + (size_t)(ly + h)) * (size_t)block.x +
         (size_t)(lx + h);
}

/* Start of PE p's block. */
SV_FN size_t sv_block_start(int4 block, int p) {
  return (size_t)p * (size_t)block.w;
}

/* Index of voxel (x, y, z) in a flat volume, x fastest. */
SV_FN size_t sv_flat_index(int4 dims, int x, int y, int z) {
  return ((size_t)z * (size_t)dims.y + (size_t)y) * (size_t)dims.x + (size_t)x;
}

/* float16 arguments change the ABI without AVX-512: clang warns per call
 * site (-Wpsabi); harmless, everything is inlined. */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif

/* Vectorisable ln and exp (shared by shade.cl and
 * classify.cl). PoCL 3.1's pow() and log() are
 * calls that stop its loop vectoriser (pow() ran ~100x slower than this), and
 * exp() vectorised only in some contexts; these are plain float arithmetic.
 * sv_log: x = m 2^e, m in [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s) with
 * s = (m - 1)/(m + 1), |s| < 0.1716, series to s^9 (truncation < 1e-9), ln 2
 * in two parts; for normal finite x > 0. sv_exp: x = k ln 2 + r,
 * |r| <= ln(2)/2, Taylor series to r^7 (truncation < 1e-8 relative), times
 * 2^k from the exponent bits; 0 below -87.3, +inf above 88. Both within a
 * few ulp. */
#ifndef SV_VMATH
#define SV_VMATH
SV_FN float sv_log(float x) {
  const int ix = as_int(x);
  int e = ((ix >> 23) & 0xff) - 127;
  float m = as_float((ix & 0x007fffff) | 0x3f800000);
  const int big = m > 1.41421356f;
  m = big ? 0.5f * m : m;
  e = big ? e + 1 : e;
  const float s = (m - 1.0f) / (m + 1.0f);
  const float s2 = s * s;
  const float p =
      s * (2.0f + s2 * (0.666666667f + s2 * (0.4f + s2 * (0.285714286f + s2 * 0.222222222f))));
  const float fe = (float)e;
  return fe * 0.693145751953125f + (fe * 1.42860682e-6f + p);
}
SV_FN float sv_exp(float x) {
  const float xc = fmin(fmax(x, -87.3f), 88.0f);
  const float kf = floor(xc * 1.44269504f + 0.5f);
  const float r = (xc - kf * 0.693145751953125f) - kf * 1.42860682e-6f;
  const float p =
      1.0f + r * (1.0f + r * (0.5f + r * (0.166666667f +
                                          r * (0.0416666667f +
                                               r * (0.00833333333f +
                                                    r * (0.00138888889f + r * 0.000198412698f))))));
  const float y = p * as_float(((int)kf + 127) << 23);
  return x < -87.3f ? 0.0f : (x > 88.0f ? INFINITY : y);
}
#endif /* SV_VMATH */

/* float16 forms of sv_log and sv_exp (the same operations lane by lane, so
 * the same results). */
#ifndef SV_VMATH16
#define SV_VMATH16
SV_FN float16 sv_log16(float16 x) {
  const int16 ix = as_int16(x);
  int16 e = ((ix >> 23) & 0xff) - 127;
  float16 m = as_float16((ix & 0x007fffff) | 0x3f800000);
  const int16 big = m > 1.41421356f;
  m = select(m, 0.5f * m, big);
  e = select(e, e + 1, big);
  const float16 s = (m - 1.0f) / (m + 1.0f);
  const float16 s2 = s * s;
  const float16 p =
      s * (2.0f + s2 * (0.666666667f + s2 * (0.4f + s2 * (0.285714286f + s2 * 0.222222222f))));
  const float16 fe = convert_float16(e);
  return fe * 0.693145751953125f + (fe * 1.42860682e-6f + p);
}
SV_FN float16 sv_exp16(float16 x) {
  const float16 xc = fmin(fmax(x, -87.3f), 88.0f);
  const float16 kf = floor(xc * 1.44269504f + 0.5f);
  const float16 r = (xc - kf * 0.693145751953125f) - kf * 1.42860682e-6f;
  const float16 p =
      1.0f + r * (1.0f + r * (0.5f + r * (0.166666667f +
                                          r * (0.0416666667f +
                                               r * (0.00833333333f +
                                                    r * (0.00138888889f + r * 0.000198412698f))))));
  const float16 y = p * as_float16((convert_int16(kf) + 127) << 23);
  return select(select(y, (float16)(INFINITY), x > 88.0f), (float16)(0.0f), x < -87.3f);
}
#endif /* SV_VMATH16 */

#endif /* SIMDVOL_COMMON_CL */
