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
 * Three decompositions (ShadeKernel in stages.hpp):
 *   simdvol_shade_rows (the default): one work-item per (row, PE), 2-D range
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
 * 218-226 ms. The rows variant was the fastest in every run, so it is the
 * stage's default; the fused shade + classify kernel (classify.cl) uses the
 * 3-D range.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif
#define SIMDVOL_SHADE_CL

/* Vectorisable ln and exp (kept identical in shade.cl and classify.cl; the
 * guard lets both files form one program). PoCL 3.1's pow() and log() are
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
      1.0f +
      r * (1.0f +
           r * (0.5f +
                r * (0.166666667f +
                     r * (0.0416666667f +
                          r * (0.00833333333f + r * (0.00138888889f + r * 0.000198412698f))))));
  const float y = p * as_float(((int)kf + 127) << 23);
  return x < -87.3f ? 0.0f : (x > 88.0f ? INFINITY : y);
}
#endif /* SV_VMATH */

/* x^y for x >= 0, y >= 0 as C's pow (0^0 = 1); x below FLT_MIN counts as 0. */
SV_FN float sv_pow(float x, float y) {
  const float r = sv_exp(y * sv_log(x));
  return x < FLT_MIN ? (y == 0.0f ? 1.0f : 0.0f) : r;
}

/* Shading of one voxel whose value is at c (in a padded block with row pitch
 * bx and slice pitch bxy), at global voxel index (ix, iy, iz). Scalar code
 * only: PoCL's loop vectoriser does not take vector types (float3/float4). */
SV_FN void sv_shade_voxel(__constant const sv_shade_params* sp, __global const float* c, int bx,
                          int bxy, float ix, float iy, float iz, float* id, float* is,
                          float* mag) {
  const float gx = 0.5f * (c[1] - c[-1]) * sp->grad_scale[0];
  const float gy = 0.5f * (c[bx] - c[-bx]) * sp->grad_scale[1];
  const float gz = 0.5f * (c[bxy] - c[-bxy]) * sp->grad_scale[2];
  float g2 = gx * gx + gy * gy + gz * gz;
  g2 = isfinite(g2) ? g2 : 0.0f; /* a NaN/inf neighbour: no surface */
  const float m = sqrt(g2);
  *mag = m;
  const float d =
      sp->depth_dir[0] * ix + sp->depth_dir[1] * iy + sp->depth_dir[2] * iz + sp->depth_offset;
  const float cue = 1.0f / (sp->k1 + sp->k2 * d);
  const float nl = fabs(gx * sp->light[0] + gy * sp->light[1] + gz * sp->light[2]) / m;
  const float nh = fabs(gx * sp->halfway[0] + gy * sp->halfway[1] + gz * sp->halfway[2]) / m;
  const int surface = g2 >= 1e-12f; /* else N = 0: ambient only */
  const float lit_d = surface ? sp->ka + cue * sp->kd * nl : sp->ka;
  const float lit_s = surface ? cue * sp->ks * sv_pow(nh, sp->shininess) : 0.0f;
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
                            __global const int4* restrict origins, int4 dims, int4 cell,
                            int4 block, int pes, int vstride,
                            __constant const sv_shade_params* sp) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  const int rows = cell.y * cell.z;
  if (p >= pes) return;
  const int cvox = rows * cell.x;
  __global float* blk = out + (size_t)p * 4 * (size_t)vstride;
  /* The tail (< 16 per plane; the group has >= 16 work-items per PE, see
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
__kernel void simdvol_shade_rows(__global const float* restrict cells,
                                 __global float* restrict out,
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
