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
 * Output ("voxel cells", float4 per interior voxel, PE-major): PE p's block
 * starts at p * vstride float4s; interior voxel (lx, ly, lz) of the cell,
 * 0 <= l < cell, is at (lz * cy + ly) * cx + lx within the block; vstride is
 * cx * cy * cz rounded up to a multiple of 4 (64 bytes) and the tail is zero.
 * Each element is (Id, Is, |g|, v): diffuse, specular, gradient magnitude and
 * the voxel's value, so that classify needs no other input. Interior
 * positions past the volume's far faces (padding) hold the results for the
 * padded (edge-replicated) values; gathers skip them.
 *
 * Work decomposition: a 3-D range (x, row, PE) = (cx rounded up to LX,
 * cy * cz rounded up to LY, pes) with local size (LX, LY, 1). PoCL
 * vectorises the work-item loop over x, so consecutive lanes read and write
 * consecutive voxels of one cell row; the row's (ly, lz) and the PE are
 * uniform across the lanes (one division per row, not per voxel). Measured
 * (PoCL 3.1, 2 cores, 256^3, 8192 PEs, kernel time, median of 7, same run):
 * this 3-D range 37 ms; one work-item per voxel of a 1-D range with the
 * (PE, x, y, z) decomposed by integer divisions 62 ms; one work-item per
 * (PE, row) looping over x (scalar) 96 ms. See bench/bench_shade_classify.cpp.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif
#define SIMDVOL_SHADE_CL

/* (Id, Is) of one voxel from its gradient g (already scaled) and index i. */
SV_FN float2 sv_phong(__constant const sv_shade_params* sp, float3 g, float g2, float mag,
                      float3 idx) {
  if (!sp->enabled) return (float2)(1.0f, 0.0f);
  const float3 L = (float3)(sp->light[0], sp->light[1], sp->light[2]);
  const float3 H = (float3)(sp->halfway[0], sp->halfway[1], sp->halfway[2]);
  const float d = sp->depth_dir[0] * idx.x + sp->depth_dir[1] * idx.y + sp->depth_dir[2] * idx.z +
                  sp->depth_offset;
  const float cue = 1.0f / (sp->k1 + sp->k2 * d);
  const float nl = fabs(dot(g, L)) / mag;
  const float nh = fabs(dot(g, H)) / mag;
  /* pow(0, 0) = 1 as in C; nh >= 0 so powr-style domain issues do not arise. */
  const float id = sp->ka + cue * sp->kd * nl;
  const float is = cue * sp->ks * pow(nh, sp->shininess);
  /* g2 < 1e-12: no surface (N = 0), ambient only. */
  return g2 < 1e-12f ? (float2)(sp->ka, 0.0f) : (float2)(id, is);
}

/* Gradient and shading of the voxel whose value is at c (in a padded block
 * with row pitch bx and slice pitch bxy), at global voxel index idx. */
SV_FN float4 sv_shade_voxel(__constant const sv_shade_params* sp, __global const float* c, int bx,
                            int bxy, float3 idx) {
  const float v = c[0];
  float3 g;
  g.x = 0.5f * (c[1] - c[-1]) * sp->grad_scale[0];
  g.y = 0.5f * (c[bx] - c[-bx]) * sp->grad_scale[1];
  g.z = 0.5f * (c[bxy] - c[-bxy]) * sp->grad_scale[2];
  float g2 = dot(g, g);
  if (!isfinite(g2)) g2 = 0.0f; /* a NaN/inf neighbour: no surface */
  const float mag = sqrt(g2);
  const float2 l = sv_phong(sp, g, g2, mag, idx);
  return (float4)(l.x, l.y, mag, v);
}

/* simdvol_shade: see the file comment. cells: input blocks (halo >= 1);
 * out: voxel cells; vstride: float4s per PE block of out. */
__kernel void simdvol_shade(__global const float* restrict cells, __global float4* restrict out,
                            __global const int4* restrict origins, int4 dims, int4 cell,
                            int4 block, int pes, int vstride,
                            __constant const sv_shade_params* sp) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  const int rows = cell.y * cell.z;
  if (p >= pes || row >= rows) return;
  const int cvox = rows * cell.x;
  __global float4* dst = out + (size_t)p * (size_t)vstride;
  /* The tail (< 4 elements, no loop: a loop would stop PoCL vectorising). */
  if (row == 0 && lx < vstride - cvox) dst[cvox + lx] = (float4)(0.0f);
  if (lx >= cell.x) return;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  const float3 idx = (float3)((float)(o.x + lx), (float)(o.y + ly), (float)(o.z + lz));
  dst[(size_t)row * (size_t)cell.x + (size_t)lx] =
      sv_shade_voxel(sp, c, block.x, block.x * block.y, idx);
}

/* simdvol_shade_voxel: the alternative decomposition, one work-item per
 * element of the output (1-D range of pes * vstride), (PE, lx, ly, lz) from
 * integer divisions. Kept for benchmarking. */
__kernel void simdvol_shade_voxel(__global const float* restrict cells,
                                  __global float4* restrict out,
                                  __global const int4* restrict origins, int4 dims, int4 cell,
                                  int4 block, int pes, int vstride,
                                  __constant const sv_shade_params* sp) {
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)pes * (size_t)vstride) return;
  const int p = (int)(gid / (size_t)vstride);
  const int e = (int)(gid - (size_t)p * (size_t)vstride);
  if (e >= cell.x * cell.y * cell.z) {
    out[gid] = (float4)(0.0f);
    return;
  }
  const int row = e / cell.x;
  const int lx = e - row * cell.x;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  const float3 idx = (float3)((float)(o.x + lx), (float)(o.y + ly), (float)(o.z + lz));
  out[gid] = sv_shade_voxel(sp, c, block.x, block.x * block.y, idx);
}

/* simdvol_shade_rows: the other alternative, one work-item per (PE, row)
 * looping over the row's cx voxels (2-D range (cy * cz, pes)). Kept for
 * benchmarking. */
__kernel void simdvol_shade_rows(__global const float* restrict cells,
                                 __global float4* restrict out,
                                 __global const int4* restrict origins, int4 dims, int4 cell,
                                 int4 block, int pes, int vstride,
                                 __constant const sv_shade_params* sp) {
  const int row = (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  const int rows = cell.y * cell.z;
  if (p >= pes || row >= rows) return;
  const int cvox = rows * cell.x;
  __global float4* dst = out + (size_t)p * (size_t)vstride;
  if (row == 0)
    for (int i = cvox; i < vstride; ++i) dst[i] = (float4)(0.0f);
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, 0, ly, lz);
  for (int lx = 0; lx < cell.x; ++lx) {
    const float3 idx = (float3)((float)(o.x + lx), (float)(o.y + ly), (float)(o.z + lz));
    dst[(size_t)row * (size_t)cell.x + (size_t)lx] =
        sv_shade_voxel(sp, c + lx, block.x, block.x * block.y, idx);
  }
}
