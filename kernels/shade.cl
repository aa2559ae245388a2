/* shade.cl — the shade stage on the PE array (thesis eq 4.1-4.3): central-
 * difference gradients and two-sided Phong lighting with depth cue. The
 * mathematics is that of host/core/shade.cpp (see its comment), written
 * again here in float.
 *
 * Input: the scalar volume in PE-major cells with a halo of at least 1
 * (kernels/layout.cl, geometry arguments as in common.cl). The halo is the
 * X-Net communication (edge-replicated at the volume's faces, which is the
 * reference's clamped neighbour), so each PE reads only its own block.
 *
 * Output ("voxel cells", host/include/simdvol/stages.hpp): four floats per
 * interior voxel, planar within each PE's block: PE p's block is the
 * 4 * vstride floats from p * 4 * vstride; quantity c of interior voxel
 * (lx, ly, lz), 0 <= l < cell, is float c * vstride + (lz * cy + ly) * cx + lx
 * of the block; vstride = cx * cy * cz rounded up to a multiple of 16, the
 * tails are zero. The quantities are (Id, Is, |g|, v): diffuse, specular,
 * gradient magnitude and the voxel's value, so that classify needs no other
 * input. Interior positions past the volume's far faces (padding) hold the
 * results for the padded (edge-replicated) values; gathers skip them.
 * Planar, not float4 per voxel, and scalar code only: PoCL 3.1's loop
 * vectoriser (work-items as SIMD lanes) gives up on any vector-typed
 * instruction ("instruction return type cannot be vectorized").
 *
 * Four decompositions (ShadeKernel in stages.hpp):
 *   simdvol_shade16 (the default; end of this file): explicit float16 over
 *     chunks of 16 voxels. PoCL 3.1 on these machines (AMD EPYC, AVX2, the
 *     "haswell" target) did NOT vectorise any of the scalar kernels below:
 *     their .so files hold no ymm instruction, and the loop vectoriser's
 *     remarks say "the cost-model indicates that vectorization is not
 *     beneficial" (the guarded body, conditional uniform loads from the
 *     parameters, would need masked loads/stores). Measured interleaved
 *     (bench --sweep, 256^3, 8192 PEs, median of 5, heavily loaded machine):
 *     float16 shade 148-201 ms against scalar rows 190-240 ms; float16
 *     classify 148-173 ms against scalar 787-797 ms; fused 296-340 ms
 *     against 1296-1428 ms. Scalar kernels are the fallback for cells whose
 *     x extent is not 4, 8 or a multiple of 16;
 *   simdvol_shade_rows: one work-item per (row, PE), 2-D range
 *     (cy * cz, pes), looping over the row's cx voxels (scalar code, but
 *     unit-stride streams through one cell row);
 *   simdvol_shade: 3-D range (x, row, PE) = (cx rounded up to LX,
 *     cy * cz rounded up to LY, pes), local size (LX, LY, LZ), lanes over x;
 *   simdvol_shade_voxel: one work-item per output position, (PE, x, y, z)
 *     from integer divisions.
 * Measured with bench/bench_shade_classify.cpp --sweep (PoCL 3.1, 2 cores,
 * 256^3 Shepp-Logan, 8192 PEs, median device time of 5, three work-group
 * sizes, one run; the machine was shared with other builds, so only the
 * ratios within a run mean much): rows 45 ms, 3-D range 83-86 ms, 1-D with
 * divisions 99-108 ms; in a second run under heavier load 92-104 / 170-176 /
 * 218-226 ms. The rows variant was the fastest of the scalar ones in every
 * run, so it is the fallback; the scalar fused shade + classify kernel
 * (classify.cl) uses the 3-D range.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif
/* float16 values passed to and returned from functions on a target without
 * AVX-512 draw clang's -Wpsabi warning ("changes the ABI") once per call
 * site; harmless here (everything is compiled together and inlined). */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif
#define SIMDVOL_SHADE_CL

/* sv_log, sv_exp and their float16 forms are in common.cl. */

/* r = x^n (type T: float or float16) for a whole n >= 1 by repeated
 * squaring: 5 multiplications for the default Phong exponent 24, within a
 * few ulp of the reference's std::pow. */
#define SV_POWN(T, x, n, r)        \
  do {                             \
    T b_ = (x);                    \
    int n_ = (n);                  \
    while (!(n_ & 1)) {            \
      b_ = b_ * b_;                \
      n_ >>= 1;                    \
    }                              \
    (r) = b_;                      \
    for (n_ >>= 1; n_; n_ >>= 1) { \
      b_ = b_ * b_;                \
      if (n_ & 1) (r) = (r)*b_;    \
    }                              \
  } while (0)

/* x^y for x >= 0, y >= 0 as C's pow (0^0 = 1); x below FLT_MIN counts as 0.
 * A whole y in 1..64 by SV_POWN, other y by exp(y log x). */
SV_FN float sv_pow(float x, float y) {
  if (y >= 1.0f && y <= 64.0f && y == floor(y)) {
    float r;
    SV_POWN(float, x, (int)y, r);
    return x < FLT_MIN ? 0.0f : r;
  }
  const float r = sv_exp(y * sv_log(x));
  return x < FLT_MIN ? (y == 0.0f ? 1.0f : 0.0f) : r;
}

/* |N.H|^n, where |N.H| below sp->spec_floor counts as 0 (the power would be
 * below 2^-100: shade.hpp's specular_floor, the reference's rule too), so
 * that the power's multiplications make no denormal numbers (a microcode
 * assist each on the CPU: about a quarter of ch2's shade + classify). */
SV_FN float sv_spec_pow(__constant const sv_shade_params* sp, const float nh) {
  return sv_pow(nh < sp->spec_floor ? 0.0f : nh, sp->shininess);
}

/* The squared length g2 of a gradient and its length |g|: 0 and 0 where a
 * component is not finite (a NaN/inf neighbour, or neighbours further apart
 * than the largest float: no surface). With SV_GRAD_OVER (the host defines
 * it where the volume's range allows it: sv_shade_params::grad_over), where
 * the squares overflow float (|g| above about 1.8e19, as in simulation
 * output of 1e20 and more) g2 = +inf (a surface) and |g| = s |g / s|, s the
 * largest |g_a|: the length the reference takes in double; before, every
 * such voxel was left unlit with |g| = 0. Gradients whose squares stay
 * finite take the plain expression (the same bits either way). Only where
 * defined: the test alone, compiled in, cost the phantom's fused shade +
 * classify 4-6 % (simdvol-bench-options --frames 20, four alternations on
 * a 2-core Zen 4 EPYC, 2026-12-05: 9.34-10.34 -> 10.26-11.09 ms). */
SV_FN void sv_grad_len(const float gx, const float gy, const float gz, float* g2, float* mag) {
  const float q = gx * gx + gy * gy + gz * gz;
  *g2 = isfinite(q) ? q : 0.0f;
  *mag = sqrt(*g2);
#ifdef SV_GRAD_OVER
  if (isinf(q) && isfinite(gx) && isfinite(gy) && isfinite(gz)) {
    const float s = fmax(fmax(fabs(gx), fabs(gy)), fabs(gz));
    const float ux = gx / s, uy = gy / s, uz = gz / s;
    *g2 = q;
    *mag = s * sqrt(ux * ux + uy * uy + uz * uz);
  }
#endif
}

/* The squared gradient length below which a voxel is no surface (N = 0,
 * ambient light only): sp->surface_g2, the host's surface_threshold of the
 * volume's span (1e-12 for a span of 1 or more); 1e-12 where a caller's
 * parameters leave it 0. */
SV_FN_INLINE float sv_surface_g2(__constant const sv_shade_params* sp) {
  return sp->surface_g2 > 0.0f ? sp->surface_g2 : 1e-12f;
}

/* Shading of one voxel whose value is at c (in a padded block with row pitch
 * bx and slice pitch bxy), at global voxel index (ix, iy, iz). Scalar code
 * only: PoCL's loop vectoriser does not take vector types (float3/float4). */
SV_FN void sv_shade_voxel(__constant const sv_shade_params* sp, __global const float* c, int bx,
                          int bxy, float ix, float iy, float iz, float* id, float* is, float* mag) {
  const float gx = 0.5f * (c[1] - c[-1]) * sp->grad_scale[0];
  const float gy = 0.5f * (c[bx] - c[-bx]) * sp->grad_scale[1];
  const float gz = 0.5f * (c[bxy] - c[-bxy]) * sp->grad_scale[2];
  float g2, m;
  sv_grad_len(gx, gy, gz, &g2, &m);
  *mag = m;
  const float d =
      sp->depth_dir[0] * ix + sp->depth_dir[1] * iy + sp->depth_dir[2] * iz + sp->depth_offset;
  const float cue = 1.0f / (sp->k1 + sp->k2 * d);
  const float nl = fabs(gx * sp->light[0] + gy * sp->light[1] + gz * sp->light[2]) / m;
  const float nh = fabs(gx * sp->halfway[0] + gy * sp->halfway[1] + gz * sp->halfway[2]) / m;
  const int surface = g2 >= sv_surface_g2(sp); /* else N = 0: ambient only */
  const float lit_d = surface ? sp->ka + cue * sp->kd * nl : sp->ka;
  const float lit_s = surface ? cue * sp->ks * sv_spec_pow(sp, nh) : 0.0f;
  *id = sp->enabled ? lit_d : 1.0f;
  *is = sp->enabled ? lit_s : 0.0f;
}

/* Stores (Id, Is, |g|, v) of voxel e of a PE's planar block. */
SV_FN void sv_store4(__global float* blk, int vstride, int e, float a, float b, float c, float d) {
  blk[e] = a;
  blk[vstride + e] = b;
  blk[2 * vstride + e] = c;
  blk[3 * vstride + e] = d;
}

/* simdvol_shade: see the file comment. cells: input blocks (halo >= 1);
 * out: voxel cells; vstride: floats per plane of a PE block of out. */
__kernel void simdvol_shade(__global const float* restrict cells, __global float* restrict out,
                            __global const int4* restrict origins, int4 dims, int4 cell, int4 block,
                            int pes, int vstride, __constant const sv_shade_params* sp) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  const int rows = cell.y * cell.z;
  if (p >= pes) return;
  const int cvox = rows * cell.x;
  __global float* blk = out + (size_t)p * 4 * (size_t)vstride;
  /* The tail (< 16 per plane; the range has >= 16 work-items per PE, see
   * cell_range in host/cl/voxel_ranges.hpp), without a loop: a loop would
   * stop PoCL vectorising. */
  const int t = row * (int)get_global_size(0) + lx;
  if (t < vstride - cvox) sv_store4(blk, vstride, cvox + t, 0.0f, 0.0f, 0.0f, 0.0f);
  if (lx >= cell.x || row >= rows) return;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  float id, is, mag;
  sv_shade_voxel(sp, c, block.x, block.x * block.y, (float)(o.x + lx), (float)(o.y + ly),
                 (float)(o.z + lz), &id, &is, &mag);
  sv_store4(blk, vstride, row * cell.x + lx, id, is, mag, c[0]);
}

/* simdvol_shade_voxel: the alternative decomposition, one work-item per
 * voxel position of the output (1-D range of pes * vstride), (PE, lx, ly, lz)
 * from integer divisions. Kept for benchmarking. */
__kernel void simdvol_shade_voxel(__global const float* restrict cells,
                                  __global float* restrict out,
                                  __global const int4* restrict origins, int4 dims, int4 cell,
                                  int4 block, int pes, int vstride,
                                  __constant const sv_shade_params* sp) {
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)pes * (size_t)vstride) return;
  const int p = (int)(gid / (size_t)vstride);
  const int e = (int)(gid - (size_t)p * (size_t)vstride);
  __global float* blk = out + (size_t)p * 4 * (size_t)vstride;
  if (e >= cell.x * cell.y * cell.z) {
    sv_store4(blk, vstride, e, 0.0f, 0.0f, 0.0f, 0.0f);
    return;
  }
  const int row = e / cell.x;
  const int lx = e - row * cell.x;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  float id, is, mag;
  sv_shade_voxel(sp, c, block.x, block.x * block.y, (float)(o.x + lx), (float)(o.y + ly),
                 (float)(o.z + lz), &id, &is, &mag);
  sv_store4(blk, vstride, e, id, is, mag, c[0]);
}

/* simdvol_shade_rows: the other alternative, one work-item per (PE, row)
 * looping over the row's cx voxels (2-D range (cy * cz, pes)). Kept for
 * benchmarking. */
__kernel void simdvol_shade_rows(__global const float* restrict cells, __global float* restrict out,
                                 __global const int4* restrict origins, int4 dims, int4 cell,
                                 int4 block, int pes, int vstride,
                                 __constant const sv_shade_params* sp) {
  const int row = (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  const int rows = cell.y * cell.z;
  if (p >= pes || row >= rows) return;
  const int cvox = rows * cell.x;
  __global float* blk = out + (size_t)p * 4 * (size_t)vstride;
  if (row == 0)
    for (int i = cvox; i < vstride; ++i) sv_store4(blk, vstride, i, 0.0f, 0.0f, 0.0f, 0.0f);
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, 0, ly, lz);
  for (int lx = 0; lx < cell.x; ++lx) {
    float id, is, mag;
    sv_shade_voxel(sp, c + lx, block.x, block.x * block.y, (float)(o.x + lx), (float)(o.y + ly),
                   (float)(o.z + lz), &id, &is, &mag);
    sv_store4(blk, vstride, row * cell.x + lx, id, is, mag, c[lx]);
  }
}

/* ---------------------------------------------------------------- float16
 * simdvol_shade16 (the default decomposition): one work-item per chunk of 16
 * consecutive positions of a PE's voxel cell, explicit float16 arithmetic
 * (PoCL's loop vectoriser did not vectorise the scalar kernels above on
 * these machines; explicit vectors always become SIMD instructions). Needs
 * the compile-time row width SV_RW: 16 when cx is a multiple of 16 (a chunk
 * is 16 consecutive voxels of one row), else cx itself, 8 or 4 (a chunk is
 * 16 / cx consecutive rows). Loads are vload16/vload8/vload4 of the block
 * at offsets -1/+1 (x), -bx/+bx (y) and -bx*by/+bx*by (z) from each row's
 * start: unaligned and contiguous. Chunk positions past the cell's voxels
 * (the plane's tail, whole rows since cx divides 16) are written as zeros.
 * SV_RW 1 serves every other cx (e.g. 12, or 6 for non-power-of-two
 * volumes): the lanes' (lx, ly, lz) come from float estimates of the
 * divisions, corrected (sv_chunk_rows), and each load is one 16-float load
 * per cell row the lanes lie in, merged by selects (sv_ld16_rows); the
 * arithmetic stays float16 (the scalar kernels, which PoCL leaves
 * unvectorised, ran 3-5 times slower per voxel). */

/* sv_pow on 16 lanes. SV_POWN against exp(y log x) (~50 operations and a
 * division): simdvol-bench-shade, alternated 3 times, shade 42-45 -> 31-33
 * ms, fused shade + classify 36.1-36.8 -> 33.8-34.5 ms. */
SV_FN float16 sv_pow16(float16 x, float y) {
  if (y >= 1.0f && y <= 64.0f && y == floor(y)) {
    float16 r;
    SV_POWN(float16, x, (int)y, r);
    return select(r, (float16)(0.0f), x < FLT_MIN);
  }
  const float16 r = sv_exp16(y * sv_log16(x));
  return select(r, (float16)(y == 0.0f ? 1.0f : 0.0f), x < FLT_MIN);
}

/* sv_spec_pow on 16 lanes. */
SV_FN_INLINE float16 sv_spec_pow16(__constant const sv_shade_params* sp, const float16 nh) {
  return sv_pow16(select(nh, (float16)(0.0f), nh < sp->spec_floor), sp->shininess);
}

/* sv_grad_len on 16 lanes: one expression for the shading and the kept
 * gradient's reading (classify.cl), so the same bits. */
SV_FN_INLINE void sv_grad_len16(const float16 gx, const float16 gy, const float16 gz, float16* g2,
                                float16* mag) {
  const float16 q = gx * gx + gy * gy + gz * gz;
  *g2 = select((float16)(0.0f), q, isfinite(q));
  *mag = sqrt(*g2);
#ifdef SV_GRAD_OVER
  /* +inf: an infinite component, or squares that overflow */
  if (any(q > FLT_MAX)) {
    const int16 over = isinf(q) & isfinite(gx) & isfinite(gy) & isfinite(gz);
    const float16 s = fmax(fmax(fabs(gx), fabs(gy)), fabs(gz));
    const float16 ux = gx / s, uy = gy / s, uz = gz / s;
    *g2 = select(*g2, q, over);
    *mag = select(*mag, s * sqrt(ux * ux + uy * uy + uz * uz), over);
  }
#endif
}

/* sv_shade_voxel on 16 lanes: neighbours x-/x+, y-/y+, z-/z+ and global
 * voxel coordinates (ix, iy, iz). The same float operations in the same
 * order. */
/* Its first half, the gradient: (gx, gy, gz), g2 = |g|^2 (0 for a NaN/inf
 * neighbour) and mag = |g|. */
SV_FN void sv_grad16(__constant const sv_shade_params* sp, float16 xm, float16 xp, float16 ym,
                     float16 yp, float16 zm, float16 zp, float16* gx, float16* gy, float16* gz,
                     float16* g2, float16* mag) {
  *gx = 0.5f * (xp - xm) * sp->grad_scale[0];
  *gy = 0.5f * (yp - ym) * sp->grad_scale[1];
  *gz = 0.5f * (zp - zm) * sp->grad_scale[2];
  sv_grad_len16(*gx, *gy, *gz, g2, mag);
}

/* Its second half, the lighting (Id, Is) from sv_grad16's results at global
 * voxel coordinates (ix, iy, iz). With AVX2 and no AVX-512 (PoCL's
 * `haswell` target) it is always inlined (SV_SHADE_FN): LLVM kept it a
 * call there, and a float16 argument without AVX-512 goes through memory,
 * so each chunk stored its nine float16 into PoCL's per-work-item context
 * arrays, copied them to the call's stack arguments and the callee loaded
 * them again (perf: the fused shade + classify spent a fifth of its samples
 * in the call and about a quarter of the rest on those copies). With
 * sv_light_rows and sv_grad_rows (below) inlined too, on a 2-core Zen 3
 * EPYC (2026-12-07, simdvol-bench-options --frames 12, alternated twice,
 * -DSV_NO_SHADE_INLINE against this, both with the interleaved stores'
 * AVX2 transpose of classify.cl off): shade + classify of the 256^3
 * phantom at (20, 35, 10) 61.0 -> 46.8 ms mean (0.77; a loaded machine).
 * SV_NO_SHADE_INLINE leaves them to LLVM (for comparison); AVX-512
 * targets are left as they were (not measured there). */
#if defined(__clang__) && defined(__AVX2__) && !defined(__AVX512F__) && !defined(SV_NO_SHADE_INLINE)
#define SV_SHADE_FN SV_FN_INLINE
#else
#define SV_SHADE_FN SV_FN
#endif
SV_SHADE_FN void sv_light16(__constant const sv_shade_params* sp, float16 gx, float16 gy,
                            float16 gz, float16 g2, float16 m, float16 ix, float16 iy, float16 iz,
                            float16* id, float16* is) {
  const float16 d =
      sp->depth_dir[0] * ix + sp->depth_dir[1] * iy + sp->depth_dir[2] * iz + sp->depth_offset;
  const float16 cue = 1.0f / (sp->k1 + sp->k2 * d);
  const float16 nl = fabs(gx * sp->light[0] + gy * sp->light[1] + gz * sp->light[2]) / m;
  const float16 nh = fabs(gx * sp->halfway[0] + gy * sp->halfway[1] + gz * sp->halfway[2]) / m;
  const int16 surface = g2 >= sv_surface_g2(sp); /* else N = 0: ambient only */
  const float16 lit_d = select((float16)(sp->ka), sp->ka + cue * sp->kd * nl, surface);
  const float16 lit_s = select((float16)(0.0f), cue * sp->ks * sv_spec_pow16(sp, nh), surface);
  *id = sp->enabled ? lit_d : (float16)(1.0f);
  *is = sp->enabled ? lit_s : (float16)(0.0f);
}

SV_FN void sv_shade16(__constant const sv_shade_params* sp, float16 xm, float16 xp, float16 ym,
                      float16 yp, float16 zm, float16 zp, float16 ix, float16 iy, float16 iz,
                      float16* id, float16* is, float16* mag) {
  float16 gx, gy, gz, g2;
  sv_grad16(sp, xm, xp, ym, yp, zm, zp, &gx, &gy, &gz, &g2, mag);
  sv_light16(sp, gx, gy, gz, g2, *mag, ix, iy, iz, id, is);
}

#ifdef SV_RW
#if SV_RW == 16
#define SV_NR 1
#define SV_LD16(c, rb, off) SV_VLOAD16((c) + (rb)[0] + (off))
#define SV_ROWS16(a) ((float16)((a)[0]))
#define SV_IOTA16 ((float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#elif SV_RW == 8
#define SV_NR 2
#define SV_LD16(c, rb, off) \
  ((float16)(SV_VLOAD8((c) + (rb)[0] + (off)), SV_VLOAD8((c) + (rb)[1] + (off))))
#define SV_ROWS16(a) ((float16)((float8)((a)[0]), (float8)((a)[1])))
#define SV_IOTA16 ((float16)(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7))
#elif SV_RW == 4
#define SV_NR 4
#define SV_LD16(c, rb, off)                                                      \
  ((float16)(vload4(0, (c) + (rb)[0] + (off)), vload4(0, (c) + (rb)[1] + (off)), \
             vload4(0, (c) + (rb)[2] + (off)), vload4(0, (c) + (rb)[3] + (off))))
#define SV_ROWS16(a) \
  ((float16)((float4)((a)[0]), (float4)((a)[1]), (float4)((a)[2]), (float4)((a)[3])))
#define SV_IOTA16 ((float16)(0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3))
#elif SV_RW == 1
#define SV_NR 16
/* rb for SV_RW 1 (sv_chunk_rows): [0, 16) each lane's block offset; [16]
 * the number n of cell rows the chunk's lanes lie in; [17] 1 if the loads
 * below stay inside the PE's block; [18 + 2j], [19 + 2j] (j < n): row j's
 * block offset minus its first lane, and that first lane. */
#define SV_NRB 50
#define SV_LD16(c, rb, off) sv_ld16_rows((c), (rb), (off))

/* The 16 lanes' values at block offset rb[l] + off. A row's lanes are
 * consecutive voxels, so each row is one 16-float load from its offset
 * minus its first lane, its lanes taken by a select: n loads and n - 1
 * selects (n <= 4 for cx >= 5) instead of a 16-lane gather, which spent
 * more than half of the float16 shade kernel's time on ch2's 6-wide cells
 * (perf annotate). Where a load could leave the PE's block (chunks at its
 * first and last rows), and with SV_RW1_GATHER, the gather. */
SV_FN_INLINE float16 sv_ld16_rows(__global const float* c, const int* rb, const int off) {
#ifndef SV_RW1_GATHER
  if (rb[17]) {
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    float16 v = SV_VLOAD16(c + rb[18] + off);
    for (int j = 1; j < rb[16]; ++j)
      v = select(v, SV_VLOAD16(c + rb[18 + 2 * j] + off), lane >= (int16)(rb[19 + 2 * j]));
    return v;
  }
#endif
  return (float16)(c[rb[0] + off], c[rb[1] + off], c[rb[2] + off], c[rb[3] + off], c[rb[4] + off],
                   c[rb[5] + off], c[rb[6] + off], c[rb[7] + off], c[rb[8] + off], c[rb[9] + off],
                   c[rb[10] + off], c[rb[11] + off], c[rb[12] + off], c[rb[13] + off],
                   c[rb[14] + off], c[rb[15] + off]);
}
#define SV_ROWS16(a)                                                                         \
  ((float16)((a)[0], (a)[1], (a)[2], (a)[3], (a)[4], (a)[5], (a)[6], (a)[7], (a)[8], (a)[9], \
             (a)[10], (a)[11], (a)[12], (a)[13], (a)[14], (a)[15]))
#else
#error "SV_RW must be 16, 8, 4 or 1"
#endif
#ifndef SV_NRB
#define SV_NRB SV_NR /* the length of rb */
#endif

/* The chunk of 16 positions from e0 (a multiple of 16) of PE p's cell, in
 * SV_NR rows: rb = block offsets (of each row's first lane; of each lane
 * for SV_RW 1), fx, fy, fz = volume coordinates (fx per lane for SV_RW 1,
 * else fx[0] = x of lane 0 of every row), ok = 1 for rows (lanes) that are
 * voxels of the cell, 0 for the plane's tail (their values are those of
 * the last row, to be discarded). */
SV_FN void sv_chunk_rows(__global const int4* origins, int4 cell, int4 block, int p, int e0,
                         int* rb, float* fx, float* fy, float* fz, float* ok) {
  const int rows = cell.y * cell.z;
  const int4 o = origins[p];
#if SV_RW == 1
  const int cvox = rows * cell.x;
#ifndef SV_RW1_SCALAR
  if (cvox <= (1 << 22)) {
    /* Lane l is position q = e0 + l (lanes past the cell's voxels take the
     * last voxel and are reported as not in the cell), 16 lanes at once:
     * row = q / cx and lz = row / cy from a float estimate, within 1 for
     * q <= 2^22 (q exact in float, two roundings of 2^-24), then corrected
     * by the remainder; lx = q - row * cx, ly = row - lz * cy. The same
     * offsets and coordinates as the lane-by-lane steps below (used for
     * larger cells, and with SV_RW1_SCALAR), which took 48 scalar
     * conversions and 48 inserts per chunk. */
    const int16 pos = (int16)(e0) + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 q = min(pos, (int16)(cvox - 1));
    /* (comparisons give -1 where true) */
    int16 row = convert_int16(convert_float16(q) * (1.0f / (float)cell.x));
    int16 qx = q - row * cell.x;
    row = row - (qx >= cell.x) + (qx < 0);
    qx = q - row * cell.x;
    int16 qz = convert_int16(convert_float16(row) * (1.0f / (float)cell.y));
    int16 qy = row - qz * cell.y;
    qz = qz - (qy >= cell.y) + (qy < 0);
    qy = row - qz * cell.y;
    const int h = cell.w;
    const int16 off = ((qz + h) * block.y + (qy + h)) * block.x + qx + h;
    vstore16(off, 0, rb);
    vstore16(convert_float16(qx + o.x), 0, fx);
    vstore16(convert_float16(qy + o.y), 0, fy);
    vstore16(convert_float16(qz + o.z), 0, fz);
    vstore16(select((float16)(0.0f), (float16)(1.0f), pos < cvox), 0, ok);
    /* The rows the lanes lie in (sv_ld16_rows): row 0 from lane 0, then a
     * row per cx lanes, up to the cell's last row; each row's offset minus
     * its first lane, and whether every load (offsets -bxy .. +bxy, 16
     * floats) stays in the block. */
    const int bxy = block.x * block.y;
    int base = off.s0, a = 0, n = 0, inside = 1;
    int ly = qy.s0, lz = qz.s0, r = row.s0;
    for (;;) {
      rb[18 + 2 * n] = base - a;
      rb[19 + 2 * n] = a;
      inside &= base - a - bxy >= 0 && base - a + bxy + 16 <= block.w;
      ++n;
      a += n == 1 ? cell.x - qx.s0 : cell.x;
      if (a >= 16 || ++r >= rows) break;
      if (++ly == cell.y) {
        ly = 0;
        ++lz;
      }
      base = ((lz + h) * block.y + (ly + h)) * block.x + h;
    }
    rb[16] = n;
    rb[17] = inside;
    return;
  }
#endif
  /* Lane l is position e0 + l: (lx, row) stepped from e0's without a
   * division per lane; lanes past the cell's voxels repeat the last voxel
   * and are reported as not in the cell. */
  int row = e0 / cell.x;
  int lx = e0 - row * cell.x;
  int ly = row % cell.y, lz = row / cell.y;
#pragma unroll
  for (int l = 0; l < 16; ++l) {
    const int in = e0 + l < cvox;
    const int qx = in ? lx : cell.x - 1, qy = in ? ly : cell.y - 1, qz = in ? lz : cell.z - 1;
    rb[l] = (int)sv_block_offset(cell, block, qx, qy, qz);
    fx[l] = (float)(o.x + qx);
    fy[l] = (float)(o.y + qy);
    fz[l] = (float)(o.z + qz);
    ok[l] = in ? 1.0f : 0.0f;
    if (++lx == cell.x) {
      lx = 0;
      if (++ly == cell.y) {
        ly = 0;
        ++lz;
      }
    }
  }
  rb[16] = 0;
  rb[17] = 0; /* sv_ld16_rows gathers */
#else
#if SV_RW == 16
  const int row0 = e0 / cell.x;
  const int lx0 = e0 - row0 * cell.x;
#else
  const int row0 = e0 / SV_RW; /* cell.x == SV_RW */
  const int lx0 = 0;
#endif
#ifdef SV_ROW_DIVS
#pragma unroll
  for (int r = 0; r < SV_NR; ++r) {
    const int row = min(row0 + r, rows - 1);
    const int ly = row % cell.y, lz = row / cell.y;
#else
  /* One division for the chunk's first row, then a step per row (rows past
   * the cell repeat its last): the (ly, lz) of min(row0 + r, rows - 1)
   * without an integer division per row (SV_ROW_DIVS divides). */
  const int rr0 = min(row0, rows - 1);
  int ly = rr0 % cell.y, lz = rr0 / cell.y;
#pragma unroll
  for (int r = 0; r < SV_NR; ++r) {
    if (r > 0 && row0 + r < rows && ++ly == cell.y) {
      ly = 0;
      ++lz;
    }
#endif
    rb[r] = (int)sv_block_offset(cell, block, lx0, ly, lz);
    fx[r] = (float)(o.x + lx0);
    fy[r] = (float)(o.y + ly);
    fz[r] = (float)(o.z + lz);
    ok[r] = row0 + r < rows ? 1.0f : 0.0f;
  }
#endif /* SV_RW == 1 */
}

/* The gradient of the chunk given by sv_chunk_rows (sv_grad16); c = the
 * start of the PE's block. (SV_SHADE_FN: with SV_RW 1, LLVM kept it a call
 * on AVX2, its five float16 results through memory.) */
SV_SHADE_FN void sv_grad_rows(__constant const sv_shade_params* sp, __global const float* c,
                              int4 block, const int* rb, float16* gx, float16* gy, float16* gz,
                              float16* g2, float16* mag) {
  const int bx = block.x, bxy = block.x * block.y;
  sv_grad16(sp, SV_LD16(c, rb, -1), SV_LD16(c, rb, 1), SV_LD16(c, rb, -bx), SV_LD16(c, rb, bx),
            SV_LD16(c, rb, -bxy), SV_LD16(c, rb, bxy), gx, gy, gz, g2, mag);
}

/* The lighting of that chunk from its gradient (sv_light16; inlined as it
 * is, SV_SHADE_FN: with sv_light16 inlined alone, LLVM made this one the
 * call, the same float16 arguments through memory). */
SV_SHADE_FN void sv_light_rows(__constant const sv_shade_params* sp, const float* fx,
                               const float* fy, const float* fz, float16 gx, float16 gy, float16 gz,
                               float16 g2, float16 mag, float16* id, float16* is) {
#if SV_RW == 1
  const float16 x = SV_ROWS16(fx);
#else
  const float16 x = fx[0] + SV_IOTA16;
#endif
  sv_light16(sp, gx, gy, gz, g2, mag, x, SV_ROWS16(fy), SV_ROWS16(fz), id, is);
}

/* Shades the chunk given by sv_chunk_rows; c = the start of the PE's block. */
SV_FN void sv_shade_rows(__constant const sv_shade_params* sp, __global const float* c, int4 block,
                         const int* rb, const float* fx, const float* fy, const float* fz,
                         float16* id, float16* is, float16* mag) {
  float16 gx, gy, gz, g2;
  sv_grad_rows(sp, c, block, rb, &gx, &gy, &gz, &g2, mag);
  sv_light_rows(sp, fx, fy, fz, gx, gy, gz, g2, *mag, id, is);
}

/* Prefetches the two lines (128 bytes) SV_PF floats past the chunk's first
 * row in the cells (4 KiB by default; SV_PF 0: none). A work-group covers
 * part of one PE's block (a few KiB of rows with their halo) and PoCL deals
 * the work-groups out to its threads, so the hardware's stream prefetch
 * sees short runs; the fused shade + classify kernel waited on its first
 * loads (perf annotate: a quarter of its samples behind them). SV_PREFETCH
 * (common.cl): past the buffer's end it does nothing.
 * simdvol-bench-shade, 256^3 phantom, alternated three times: fused
 * 17.4 / 15.4 / 15.9 -> 13.9 / 14.1 / 15.7 ms, PE-major / flat 1.27-1.40
 * -> 1.07-1.23; the same in the flat kernel gained nothing. */
#ifndef SV_PF
#define SV_PF 1024
#endif
SV_FN void sv_prefetch_ahead(__global const float* c, const int* rb) {
#if SV_PF > 0
  SV_PREFETCH(c + rb[0] + SV_PF);
  SV_PREFETCH(c + rb[0] + SV_PF + 16);
#endif
}

/* Shades the chunk of 16 positions from e0 of PE p's cell (sv_chunk_rows);
 * returns the lanes that are voxels of the cell (-1) or the plane's tail
 * (0). */
SV_FN int16 sv_shade_chunk(__constant const sv_shade_params* sp, __global const float* cells,
                           __global const int4* origins, int4 cell, int4 block, int p, int e0,
                           float16* id, float16* is, float16* mag, float16* v) {
  int rb[SV_NRB];
  float fx[SV_NR], fy[SV_NR], fz[SV_NR], ok[SV_NR];
  sv_chunk_rows(origins, cell, block, p, e0, rb, fx, fy, fz, ok);
  __global const float* c = cells + sv_block_start(block, p);
  sv_prefetch_ahead(c, rb);
  *v = SV_LD16(c, rb, 0);
  sv_shade_rows(sp, c, block, rb, fx, fy, fz, id, is, mag);
  return SV_ROWS16(ok) != 0.0f;
}

/* Stores 16 lanes of (a, b, c, d) at position e0 of a PE's planar block
 * (non-temporally where nt, SV_VSTORE16_NT). */
SV_FN void sv_store16(__global float* blk, int vstride, int e0, float16 a, float16 b, float16 c,
                      float16 d, const int nt) {
  SV_VSTORE16_NT(a, blk + e0, nt);
  SV_VSTORE16_NT(b, blk + vstride + e0, nt);
  SV_VSTORE16_NT(c, blk + 2 * vstride + e0, nt);
  SV_VSTORE16_NT(d, blk + 3 * vstride + e0, nt);
}

/* simdvol_shade16: 2-D range (chunk, PE) = (vstride / 16 rounded up to the
 * local size, pes); arguments as simdvol_shade. */
__kernel void simdvol_shade16(__global const float* restrict cells, __global float* restrict out,
                              __global const int4* restrict origins, int4 dims, int4 cell,
                              int4 block, int pes, int vstride,
                              __constant const sv_shade_params* sp) {
  const int e0 = 16 * (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (p >= pes || e0 >= vstride) return;
  float16 id, is, mag, v;
  const int16 in = sv_shade_chunk(sp, cells, origins, cell, block, p, e0, &id, &is, &mag, &v);
  const float16 z = 0.0f;
  sv_store16(out + (size_t)p * 4 * (size_t)vstride, vstride, e0, select(z, id, in),
             select(z, is, in), select(z, mag, in), select(z, v, in), 0);
}
#endif /* SV_RW */
