/* adaptive.cl — the render engine's helpers for the sample-based
 * compositing modes (engine.cpp): the segments' sample offsets on the device,
 * and whole-ray adaptive compositing (Levoy's early termination).
 *
 *   simdvol_sample_pe_count  one work-item per PE: its segments' samples
 *   simdvol_sample_pe_scan   one work-item: exclusive prefix over the P PE
 *                            totals (long), the grand total in total[0]
 *   simdvol_sample_offsets   one work-item per PE: sample_off[s] for its
 *                            segments (and sample_off[nseg] from the last PE)
 * The result equals sample_offsets(m) (local.hpp) as int32; the host reads
 * total[0] and refuses totals above INT_MAX before using the offsets.
 *
 *   simdvol_adaptive_whole   one work-item per pixel (the pixel's owner after
 *                            the swap, as simdvol_mc_whole): over() front to
 *                            back along the ray's segments in increasing k0
 *                            (the ray lists of mc.cl), stopping once the
 *                            accumulated alpha >= threshold. The arithmetic
 *                            is composite_adaptive's (composite.cpp),
 *                            FP_CONTRACT off: equal bit for bit.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL FP_CONTRACT OFF

__kernel void simdvol_sample_pe_count(__global const sv_segment* segs,
                                      __global const int* seg_offset, const int pes,
                                      __global long* pe_total) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  long acc = 0;
  for (int s = seg_offset[p]; s < seg_offset[p + 1]; ++s) acc += max(segs[s].k1 - segs[s].k0, 0);
  pe_total[p] = acc;
}

__kernel void simdvol_sample_pe_scan(__global long* pe_total, const int pes, __global long* total) {
  if (get_global_id(0) != 0) return;
  long acc = 0;
  for (int p = 0; p < pes; ++p) {
    const long t = pe_total[p];
    pe_total[p] = acc;
    acc += t;
  }
  total[0] = acc;
}

__kernel void simdvol_sample_offsets(__global const sv_segment* segs,
                                     __global const int* seg_offset, const int pes,
                                     __global const long* pe_base, __global int* sample_off) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  long acc = pe_base[p];
  const int e = seg_offset[p + 1];
  for (int s = seg_offset[p]; s < e; ++s) {
    sample_off[s] = (int)min(acc, (long)INT_MAX);
    acc += max(segs[s].k1 - segs[s].k0, 0);
  }
  if (p == pes - 1) sample_off[e] = (int)min(acc, (long)INT_MAX);
}

__kernel void simdvol_adaptive_whole(__global const sv_segment* segs,
                                     __global const int* sample_off, __global const float4* samples,
                                     __global const int* ray_off, __global const int* ray_items,
                                     const int npx, const float threshold, __global float4* image) {
  const int q = (int)get_global_id(0);
  if (q >= npx) return;
  float4 acc = (float4)(0.0f);
  const int e = ray_off[q + 1];
  for (int t = ray_off[q]; t < e && !(acc.w >= threshold); ++t) {
    const int s = ray_items[t];
    const sv_segment g = segs[s];
    __global const float4* in = samples + sample_off[s];
    const int n = g.k1 - g.k0;
    for (int u = 0; u < n; ++u) {
      if (acc.w >= threshold) break; /* Levoy's adaptive termination */
      const float4 f = in[u];
      const float tr = 1.0f - acc.w;
      acc = (float4)(acc.x + tr * f.x, acc.y + tr * f.y, acc.z + tr * f.z, acc.w + tr * f.w);
    }
  }
  image[q] = acc;
}
