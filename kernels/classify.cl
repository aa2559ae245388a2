/* classify.cl — the classify stage on the PE array (thesis eq 4.4): material
 * mixture or transfer function, opacity-step correction, lit premultiplied
 * RGBA. The mathematics is that of host/core/classify.cpp (see its comment),
 * written again here in float.
 *
 * Input: the shade stage's voxel cells (kernels/shade.cl): float4
 * (Id, Is, |g|, v) per interior voxel, PE-major, vstride float4s per PE.
 * Output: voxel cells of the same shape, float4 premultiplied
 * (a' C_r, a' C_g, a' C_b, a') per interior voxel. Classification is
 * per voxel and the blocks are contiguous, so the kernel runs over the whole
 * buffer, pes * vstride elements, one work-item per element (a 1-D range,
 * local size WGS): the PE-major layout costs nothing here (the block tails
 * are classified too; gathers skip them).
 *
 * Compile-time specialisation (all optional; without them the kernel reads
 * the counts from the parameters and works for every classifier, slower):
 *   SV_KIND        SV_CLASSIFY_MIXTURE or SV_CLASSIFY_TRANSFER
 *   SV_NMAT        number of materials
 *   SV_NK_DENSITY, SV_NK_GRADIENT, SV_NK_RED, SV_NK_GREEN, SV_NK_BLUE
 *                  number of points of each ramp
 * With the counts known, the search for the bracketing material or ramp
 * segment is an unrolled run of compares and selects on values that are the
 * same for every work-item, which PoCL vectorises across work-items (a loop
 * with a run-time trip count would stay scalar).
 *
 * When shade.cl precedes this file in one program (SIMDVOL_SHADE_CL), the
 * fused kernel simdvol_shade_classify (shade + classify in one launch, same
 * decomposition and results as the two stages) and the flat comparison
 * kernel simdvol_shade_classify_flat are compiled too.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#ifdef SV_KIND
#define SV_KIND_OF(cp) (SV_KIND)
#else
#define SV_KIND_OF(cp) ((cp)->kind)
#endif
#ifdef SV_NMAT
#define SV_NMAT_OF(cp) (SV_NMAT)
#else
#define SV_NMAT_OF(cp) ((cp)->material_count)
#endif
#ifdef SV_NK_DENSITY
#define SV_NK_DENSITY_OF(cp) (SV_NK_DENSITY)
#else
#define SV_NK_DENSITY_OF(cp) ((cp)->density.count)
#endif
#ifdef SV_NK_GRADIENT
#define SV_NK_GRADIENT_OF(cp) (SV_NK_GRADIENT)
#else
#define SV_NK_GRADIENT_OF(cp) ((cp)->gradient.count)
#endif
#ifdef SV_NK_RED
#define SV_NK_RED_OF(cp) (SV_NK_RED)
#else
#define SV_NK_RED_OF(cp) ((cp)->red.count)
#endif
#ifdef SV_NK_GREEN
#define SV_NK_GREEN_OF(cp) (SV_NK_GREEN)
#else
#define SV_NK_GREEN_OF(cp) ((cp)->green.count)
#endif
#ifdef SV_NK_BLUE
#define SV_NK_BLUE_OF(cp) (SV_NK_BLUE)
#else
#define SV_NK_BLUE_OF(cp) ((cp)->blue.count)
#endif

/* Ramp r(v) with n points: y_0 at or below x_0 (and for NaN), y_last at or
 * above x_last, else linear on the segment of the last x_k <= v. */
SV_FN float sv_ramp_eval(__constant const sv_ramp* r, const int n, float v) {
  if (n <= 0) return 1.0f;
  const float x0 = r->x[0], y0 = r->y[0];
  if (n == 1) return y0;
  float xa = x0, ya = y0, xb = r->x[1], yb = r->y[1];
  for (int k = 1; k < n - 1; ++k) {
    const bool in = r->x[k] <= v;
    xa = in ? r->x[k] : xa;
    ya = in ? r->y[k] : ya;
    xb = in ? r->x[k + 1] : xb;
    yb = in ? r->y[k + 1] : yb;
  }
  const float t = (v - xa) / (xb - xa);
  float y = ya + t * (yb - ya);
  y = v >= r->x[n - 1] ? r->y[n - 1] : y;
  y = (isnan(v) || v <= x0) ? y0 : y;
  return y;
}

/* Material mixture of the (at most two) materials bracketing I; returns
 * alpha, *col = premultiplied material colour. */
SV_FN float sv_mixture(__constant const sv_classify_params* cp, const int n, float v,
                       float3* col) {
  __constant const sv_material* m = cp->materials;
  float I = v;
  if (cp->relative) I = cp->range_scale > 0.0f ? (v - cp->range_min) * cp->range_scale : 0.0f;
  /* i = last material with mean_i <= I, j = i + 1 (for mean_0 < I < mean_last). */
  const int j0 = n > 1 ? 1 : 0;
  float mi = m[0].mean, hi = m[0].half_inv_var, li = m[0].log_sigma;
  float ai = m[0].opacity, ri = m[0].r, gi = m[0].g, bi = m[0].b;
  float mj = m[j0].mean, hj = m[j0].half_inv_var, lj = m[j0].log_sigma;
  float aj = m[j0].opacity, rj = m[j0].r, gj = m[j0].g, bj = m[j0].b;
  for (int k = 1; k < n - 1; ++k) {
    const bool in = m[k].mean <= I;
    mi = in ? m[k].mean : mi;
    hi = in ? m[k].half_inv_var : hi;
    li = in ? m[k].log_sigma : li;
    ai = in ? m[k].opacity : ai;
    ri = in ? m[k].r : ri;
    gi = in ? m[k].g : gi;
    bi = in ? m[k].b : bi;
    mj = in ? m[k + 1].mean : mj;
    hj = in ? m[k + 1].half_inv_var : hj;
    lj = in ? m[k + 1].log_sigma : lj;
    aj = in ? m[k + 1].opacity : aj;
    rj = in ? m[k + 1].r : rj;
    gj = in ? m[k + 1].g : gj;
    bj = in ? m[k + 1].b : bj;
  }
  /* p_i = 1 / (1 + exp(L_j - L_i)), L_m = -(I - mean_m)^2 / (2 sigma_m^2) - ln sigma_m. */
  const float di = I - mi, dj = I - mj;
  const float dl = (di * di * hi + li) - (dj * dj * hj + lj);
  float pi = 1.0f / (1.0f + exp(dl));
  /* Pure first / last material outside the means. */
  const bool first = I <= m[0].mean;
  const bool last = I >= m[n - 1].mean;
  pi = (first || last) ? 1.0f : pi;
  ai = first ? m[0].opacity : last ? m[n - 1].opacity : ai;
  ri = first ? m[0].r : last ? m[n - 1].r : ri;
  gi = first ? m[0].g : last ? m[n - 1].g : gi;
  bi = first ? m[0].b : last ? m[n - 1].b : bi;
  const float pj = 1.0f - pi;
  const float wi = pi * ai, wj = pj * aj;
  *col = (float3)(wi * ri + wj * rj, wi * gi + wj * gj, wi * bi + wj * bj);
  return wi + wj;
}

/* Transfer function: alpha = density(v) * gradient(|g|), colour alpha * c(v). */
SV_FN float sv_transfer(__constant const sv_classify_params* cp, float v, float gmag,
                        float3* col) {
  const float a = sv_ramp_eval(&cp->density, SV_NK_DENSITY_OF(cp), v) *
                  sv_ramp_eval(&cp->gradient, SV_NK_GRADIENT_OF(cp), gmag);
  *col = (float3)(a * sv_ramp_eval(&cp->red, SV_NK_RED_OF(cp), v),
                  a * sv_ramp_eval(&cp->green, SV_NK_GREEN_OF(cp), v),
                  a * sv_ramp_eval(&cp->blue, SV_NK_BLUE_OF(cp), v));
  return a;
}

/* One voxel: s = (Id, Is, |g|, v) -> premultiplied RGBA. */
SV_FN float4 sv_classify_voxel(__constant const sv_classify_params* cp, float4 s) {
  const float v = s.w;
  float3 col;
  float a = SV_KIND_OF(cp) == SV_CLASSIFY_TRANSFER ? sv_transfer(cp, v, s.z, &col)
                                                   : sv_mixture(cp, SV_NMAT_OF(cp), v, &col);
  /* a' = 1 - (1 - a)^step, as -expm1(step * log1p(-a)) (accurate for small a). */
  const float a1 = cp->step_is_one ? a : -expm1(cp->opacity_step * log1p(-a));
  const float3 c = fmin((float3)(1.0f), col / a * s.x + s.y);
  const float4 rgba = (float4)(a1 * c, a1);
  /* a <= 0 or NaN (a NaN voxel is transparent). */
  return (a > 0.0f && !isnan(v)) ? rgba : (float4)(0.0f);
}

/* simdvol_classify: see the file comment. n = number of elements
 * (pes * vstride). */
__kernel void simdvol_classify(__global const float4* restrict shading,
                               __global float4* restrict out, long n,
                               __constant const sv_classify_params* cp) {
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)n) return;
  out[gid] = sv_classify_voxel(cp, shading[gid]);
}

/* simdvol_gather_voxels: the in-volume voxels of voxel cells to a flat
 * array (x fastest). Same 3-D range and local size as simdvol_shade. */
__kernel void simdvol_gather_voxels(__global const float4* restrict voxels,
                                    __global float4* restrict flat,
                                    __global const int4* restrict origins, int4 dims, int4 cell,
                                    int pes, int vstride) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  if (p >= pes || row >= cell.y * cell.z || lx >= cell.x) return;
  const int4 o = origins[p];
  const int x = o.x + lx, y = o.y + row % cell.y, z = o.z + row / cell.y;
  if (x >= dims.x || y >= dims.y || z >= dims.z) return;
  flat[sv_flat_index(dims, x, y, z)] =
      voxels[(size_t)p * (size_t)vstride + (size_t)row * (size_t)cell.x + (size_t)lx];
}

#ifdef SIMDVOL_SHADE_CL
/* simdvol_shade_classify: shade and classify in one launch; decomposition
 * and arguments as simdvol_shade (kernels/shade.cl), output as
 * simdvol_classify. Equals running the two stages (the same float code). */
__kernel void simdvol_shade_classify(__global const float* restrict cells,
                                     __global float4* restrict out,
                                     __global const int4* restrict origins, int4 dims, int4 cell,
                                     int4 block, int pes, int vstride,
                                     __constant const sv_shade_params* sp,
                                     __constant const sv_classify_params* cp) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  const int rows = cell.y * cell.z;
  if (p >= pes || row >= rows) return;
  const int cvox = rows * cell.x;
  __global float4* dst = out + (size_t)p * (size_t)vstride;
  if (row == 0 && lx < vstride - cvox) dst[cvox + lx] = (float4)(0.0f);
  if (lx >= cell.x) return;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  const float3 idx = (float3)((float)(o.x + lx), (float)(o.y + ly), (float)(o.z + lz));
  const float4 s = sv_shade_voxel(sp, c, block.x, block.x * block.y, idx);
  dst[(size_t)row * (size_t)cell.x + (size_t)lx] = sv_classify_voxel(cp, s);
}

/* simdvol_shade_classify_flat: the same on the flat volume (x fastest), one
 * work-item per voxel over the 3-D range (nx, ny, nz), neighbours clamped;
 * out is flat too. Not a pipeline stage: kept to measure what the PE-major
 * layout costs (bench/bench_shade_classify.cpp). */
__kernel void simdvol_shade_classify_flat(__global const float* restrict volume,
                                          __global float4* restrict out, int4 dims,
                                          __constant const sv_shade_params* sp,
                                          __constant const sv_classify_params* cp) {
  const int x = (int)get_global_id(0);
  const int y = (int)get_global_id(1);
  const int z = (int)get_global_id(2);
  if (x >= dims.x || y >= dims.y || z >= dims.z) return;
  const size_t i = sv_flat_index(dims, x, y, z);
  const size_t sy = (size_t)dims.x, sz = (size_t)dims.x * (size_t)dims.y;
  float3 g;
  g.x = 0.5f * (volume[i + (x + 1 < dims.x)] - volume[i - (x > 0)]) * sp->grad_scale[0];
  g.y = 0.5f * (volume[i + (y + 1 < dims.y ? sy : 0)] - volume[i - (y > 0 ? sy : 0)]) *
        sp->grad_scale[1];
  g.z = 0.5f * (volume[i + (z + 1 < dims.z ? sz : 0)] - volume[i - (z > 0 ? sz : 0)]) *
        sp->grad_scale[2];
  float g2 = dot(g, g);
  if (!isfinite(g2)) g2 = 0.0f;
  const float mag = sqrt(g2);
  const float2 l = sv_phong(sp, g, g2, mag, (float3)((float)x, (float)y, (float)z));
  out[i] = sv_classify_voxel(cp, (float4)(l.x, l.y, mag, volume[i]));
}
#endif /* SIMDVOL_SHADE_CL */
