/* local.cl — local (sub-ray) compositing on the PE array (thesis 7.3): each
 * PE composites its samples of each segment front to back with over in
 * premultiplied colour,
 *   acc = over(acc, s):  C' = C'_acc + (1 - a_acc) C'_s,  a = a_acc + (1 - a_acc) a_s
 * (host/core/composite.cpp: composite_direct), giving one (C', a) per
 * segment, written into the PE's footprint: PE p's rectangle rects[p] =
 * {i0, j0, w, h}, pixel (i, j) at rect_off[p] + (j - j0) * w + (i - i0). The
 * footprints must be zeroed first (simdvol_zero4): pixels without a segment
 * stay 0. An empty segment writes 0.
 *
 * One work-item per segment (1-D range over the segments, explicit local
 * size). A segment's PE is found by a binary search of log2(P) steps in the
 * CSR offsets seg_off[P + 1] (the same number of steps for every work-item).
 *
 *   simdvol_local           from the resample stage's samples (sample_off[s]
 *                           = first sample of segment s).
 *   simdvol_resample_local  fused with resample.cl (when it precedes this
 *                           file in the program): samples are never stored.
 *   simdvol_resample_local_v8, _v8_il  the same in float8 lanes, on planar
 *                           or interleaved voxel cells (the frame's path).
 *   simdvol_segment_order   the lanes' order for the float8 kernels.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL FP_CONTRACT OFF

SV_FN float4 sv_over(const float4 acc, const float4 s) {
  const float t = 1.0f - acc.w;
  return (float4)(acc.x + t * s.x, acc.y + t * s.y, acc.z + t * s.z, acc.w + t * s.w);
}

SV_FN int sv_footprint_index(__global const sv_rect* rects, __global const int* rect_off, int p,
                             sv_segment g) {
  const sv_rect r = rects[p];
  return rect_off[p] + (g.j - r.j0) * r.w + (g.i - r.i0);
}

__kernel void simdvol_local(__global const sv_segment* segs, const int nseg,
                            __global const int* seg_off, const int log2p,
                            __global const int* sample_off, __global const float4* samples,
                            __global const sv_rect* rects, __global const int* rect_off,
                            __global float4* foot) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  const int p = sv_pe_of_segment(seg_off, log2p, s);
  __global const float4* in = samples + sample_off[s];
  float4 acc = (float4)(0.0f);
  for (int k = g.k0; k < g.k1; ++k) acc = sv_over(acc, *in++);
  foot[sv_footprint_index(rects, rect_off, p, g)] = acc;
}

#ifdef SIMDVOL_RESAMPLE_CL
__kernel void simdvol_resample_local(__global const sv_segment* segs, const int nseg,
                                     __global const int* seg_off, const int log2p,
                                     __global const sv_view* view, __global const int* table,
                                     __global const float* vox, const int cs,
                                     __global const sv_rect* rects, __global const int* rect_off,
                                     __global float4* foot) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  const int p = sv_pe_of_segment(seg_off, log2p, s);
  const int4 dims = (int4)(view->dims[0], view->dims[1], view->dims[2], 0);
  long X0 = sv_pos(view, 0, g.i, g.j, g.k0), X1 = sv_pos(view, 1, g.i, g.j, g.k0),
       X2 = sv_pos(view, 2, g.i, g.j, g.k0);
  const long s0 = view->step[0][2], s1 = view->step[1][2], s2 = view->step[2][2];
  float4 acc = (float4)(0.0f);
  for (int k = g.k0; k < g.k1; ++k) {
    acc = sv_over(acc, sv_sample(X0, X1, X2, dims, table, vox, cs));
    X0 += s0;
    X1 += s1;
    X2 += s2;
  }
  foot[sv_footprint_index(rects, rect_off, p, g)] = acc;
}
#endif

#ifdef SIMDVOL_RESAMPLE_CL
/* ---- simdvol_resample_local_v8: the fused kernel with explicit vectors ----
 * (resample.cl's simdvol_resample_v8 with over instead of stores; the lanes
 * and sv_sample8 are described there). */
/* acc[h] = over(acc[h], u[h]) in the lanes with `on` set: lanes 4h .. 4h + 3
 * as (lane, channel), alpha = each lane's alpha index. */
SV_FN_INLINE void sv_over_lanes16(float16* acc, const float16* u, const int8 on,
                                  const uint16 alpha) {
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    const int16 onh = as_int16(sv_spread4(as_float8(on), 4 * h));
    acc[h] = select(acc[h], acc[h] + (1.0f - shuffle(acc[h], alpha)) * u[h], onh);
  }
}

/* The footprint pixel of each of the 8 lanes' segments (positions s0 ..
 * s0 + 7), -1 past nseg: the lanes' PEs from p (the PE of s0) forward (the
 * positions are consecutive, so their PEs ascend; `order` keeps each
 * segment in its PE's range of positions). */
SV_FN_INLINE void sv_lane_feet8(__global const int* seg_off, const int nseg,
                                __global const sv_rect* rects, __global const int* rect_off,
                                const int s0, int p, const int* li, const int* lj, const int* lk,
                                const int* ln, int* fi) {
#pragma unroll
  for (int l = 0; l < 8; ++l) {
    fi[l] = -1;
    if (s0 + l < nseg) {
      while (seg_off[p + 1] <= s0 + l) ++p;
      const sv_segment g = {li[l], lj[l], lk[l], lk[l] + ln[l]};
      fi[l] = sv_footprint_index(rects, rect_off, p, g);
    }
  }
}

/* simdvol_resample_local_v8 (planar cells, il = 0) and _v8_il (interleaved
 * cells, il = 1; cs is 1 there): one body, the layout a constant. */
SV_FN_INLINE void sv_resample_local8(
    __global const sv_segment* segs, const int nseg, __global const int* seg_off, const int log2p,
    __global const sv_view* view, __global const int* table, __global const float* vox,
    const int cs, __global const sv_rect* rects, __global const int* rect_off,
    __global float4* foot, __global const uchar* reach, const int nbx, const int nby,
    const int skip, __global const int* order, const int ordered, __global const int4* origins,
    const int4 pe_cell, __global const long* pairs, __global const short2* kb, const int use_kb,
    const int il, const int cb) {
  const int s0 = (int)get_global_id(0) * 8;
  if (s0 >= nseg) return;
  int li[8], lj[8], lk[8], ln[8];
  long8 X[3];
  int T = sv_lanes8(segs, order, ordered, nseg, s0, view, li, lj, lk, ln, X, kb, use_kb);
  /* The PE of position s0: the lanes' footprints start from it, and the
   * prefetch steps on from it to the PE SV_VOX_PF positions ahead
   * (sv_pe_after) instead of a second binary search of 13 dependent loads
   * at 8,192 PEs (-DSV_PE_SEARCH2 searches twice, as before). With
   * ordered = 2 the segment order wrote it (order[nseg + s0 / 8]), so none
   * is searched: scripts/bench-ab against ca7a949's build, resample +
   * local (the order included), 2-core Xeon, 2026-12-05: the 256^3 phantom
   * 0.988 / 0.995 (6 pairs each), ch2 0.971, brainsmall 0.949 (4 pairs);
   * the same footprints. Before that:
   * simdvol-bench-options --frames 12, the 256^3 phantom at (20, 35, 10),
   * 2-core Xeon (family 6, model 167), four runs of both orders: resample +
   * local 35.09 / 35.39 / 35.00 / 35.30 -> 34.52 / 34.64 / 34.53 / 34.55 ms;
   * the same images. */
  const int p0 = sv_first_pe(order, ordered, seg_off, log2p, nseg, s0);
  /* The voxel prefetch (resample.cl: sv_pf_begin) spread over the steps:
   * each step asks for max(1, ceil(rows / T)) of this work-item's rows of the
   * PE ahead, the rest after the steps. All at once before the steps
   * (-DSV_PF_BURST, as before the ninth session of 2026-12-05) its prefetches
   * waited for free line-fill buffers, one after another (perf annotate:
   * about 12 % of the kernel's samples on the instructions after them), with
   * no step to run meanwhile; between the steps' instructions the lines come
   * in while the steps run. simdvol-bench-options --frames 12, in turn,
   * -DSV_PF_BURST -> this, resample + local (2-core Intel Xeon, family 6,
   * model 167): the 256^3 phantom at (20, 35, 10) 26.32 / 26.23 -> 24.56 /
   * 24.61 ms, at 512^2 27.14 / 27.10 -> 24.83 / 24.91, ch2 22.27 / 22.19 ->
   * 21.86 / 21.87, brainsmall 3.49 / 3.52 -> 3.32 / 3.35; the same images.
   * (One row a step, or two: the same within 1-2 %; two rows before the
   * steps: 1-3 % slower.) A hint only: no result changes. */
  sv_pf pf;
  sv_pf_begin(seg_off, log2p, nseg, s0, p0, view, table, origins, pe_cell, il, &pf);
#ifdef SV_PF_BURST
  while (pf.r < pf.r1) sv_pf_row(&pf, table, vox, cs, il);
#endif
#ifndef SV_FOOT_LATE
  /* The lanes' footprint pixels, found (and their lines asked for, for
   * writing) before the steps, so that the stores at the end do not wait
   * for them (-DSV_FOOT_LATE finds them at the end and asks for nothing, as
   * before: scripts/bench-ab with it as A, resample + local, 2-core Intel
   * Xeon, 2026-12-05: the 256^3 phantom 0.978 (6 pairs), at 512^2 0.960,
   * brainsmall 0.985, ch2 1.002; the same footprints). */
  int fi[8];
  sv_lane_feet8(seg_off, nseg, rects, rect_off, s0, p0, li, lj, lk, ln, fi);
#pragma unroll
  for (int l = 0; l < 8; ++l)
    if (fi[l] >= 0) SV_PREFETCHW(foot + fi[l]);
#endif
  int8 N = (int8)(ln[0], ln[1], ln[2], ln[3], ln[4], ln[5], ln[6], ln[7]);
  const long s_0 = view->step[0][2], s_1 = view->step[1][2], s_2 = view->step[2][2];
  const int nx = view->dims[0], ny = view->dims[1], nz = view->dims[2];
  /* Each step's reach is tested (and the step left out where no lane's
   * sample is in reach) only in work-items with a lane whose first or last
   * sample is out of reach: in the others (both ends of every lane in
   * reach) a step rarely has no lane in reach, and the test cost about a
   * seventh of the kernel's samples (perf). A step left in there adds +-0
   * to each lane's composite, which leaves it bit for bit as it was (it
   * starts at +0 and never becomes -0).
   * -DSV_STEP_TEST_ALL tests every work-item's steps, for comparison:
   * simdvol-bench-options, resample + local, 15 and 20 frames: the phantom
   * 43.5 / 35.9 -> 39.2 / 33.2 ms, at (0, 45, 0) 40.0 -> 37.9, ch2 30.3 /
   * 31.9 -> 29.4 / 29.8, brainsmall 6.11 -> 5.79 ms; the same images. */
  int steps = skip;
  if (skip) {
    /* (With -DSV_TRIM:) the trim cuts a lane only before its first and
     * after its last sample in reach: a lane whose first and last samples
     * are both in reach keeps every sample, and where every lane's are, the
     * walk over all T steps is not needed (about three work-items in four
     * on the phantom, brainsmall and ch2 at view (20, 35, 10)). Skipping
     * the trim changes no bit: a sample out of reach adds +-0, which leaves
     * the composite as it was (resample.cl, empty-space skipping). When
     * every work-item trimmed, resample + local,
     * `simdvol render --view 20,35,10 --frames 6 --step 0 --times`, three
     * alternations: the 256^3 phantom 130.8-136.0 -> 127.7-130.1 ms,
     * brainsmall 15.1-16.7 -> 15.1-15.9 ms, ch2 102.8-120.9 -> 99.9-107.6
     * ms. */
    const int8 on = N > 0;
    const long8 n1 = convert_long8(max(N - 1, (int8)(0)));
    const long8 Y[3] = {X[0] + n1 * s_0, X[1] + n1 * s_1, X[2] + n1 * s_2};
    int8 FX[3], FY[3];
    sv_floors8(X, FX);
    sv_floors8(Y, FY);
    const int8 ends = sv_reach8(FX, nx, ny, nz, nbx, nby, reach, on) &
                      sv_reach8(FY, nx, ny, nz, nbx, nby, reach, on);
    if (any(on & ~ends)) {
      /* Those work-items step their lanes as they are; -DSV_TRIM first cuts
       * each lane to its first .. last sample in reach (sv_trim8: a walk
       * over all T steps), as before 2026-12-04. Since the corner offsets
       * go through memory (resample.cl) a step costs less than that walk
       * saves: simdvol-bench-options --frames 12, 2-core Xeon (family 6,
       * model 167), resample + local, -DSV_TRIM -> this, both orders: the
       * 256^3 phantom at (20, 35, 10) 31.33 / 30.10 -> 30.26 / 29.19 ms, at
       * (0, 45, 0) 28.66 / 30.04 -> 28.20 / 29.25, at (0, 30, 0) 26.62 ->
       * 25.80, ch2 25.08 -> 24.85, brainsmall 4.19 -> 4.14; the same
       * images (the samples it cut add +-0). */
#ifdef SV_TRIM
      T = sv_trim8(X, &N, T, s_0, s_1, s_2, nx, ny, nz, nbx, nby, reach);
#endif
#ifndef SV_STEP_TEST_ALL
    } else {
      steps = 0;
#endif
    }
  }
  float8 ar = (float8)(0.0f), ag = ar, ab = ar, aa = ar; /* planar: by channel */
  float16 acc[2] = {(float16)(0.0f), (float16)(0.0f)};   /* interleaved: (lane, channel) */
  const uint16 alpha = (uint16)(3, 3, 3, 3, 7, 7, 7, 7, 11, 11, 11, 11, 15, 15, 15, 15);
  /* the positions split (sv_split8) and stepped so */
  int8 F[3];
  uint8 L[3];
  sv_split8(X, F, L);
  const int pf_k = T > 0 ? (pf.r1 - pf.r + T - 1) / T : 0; /* rows a step */
#ifdef SV_PIPE_AVX2
  if (il && !cb) {
    /* AVX2 with the pair table (resample.cl: SV_PIPE_AVX2): step t + 1's
     * gathers and corner offsets (into the other of two buffers) come
     * before step t's corners are loaded and interpolated, so that they run
     * beside this step's arithmetic. Step t's weights are taken from its
     * fractions before the positions step on. The same positions, offsets
     * and samples as the loop below, so the same bits (a step left out
     * there is left out here); the offsets found after the last step are
     * not used (the gathers' indices are clamped into the table). */
    volatile int ofs[2][5][8];
    if (T > 0) sv_addr8_il1(F, nx, ny, nz, pairs, ofs[0]);
    for (int t = 0; t < T; ++t) {
      const int8 on = (int8)(t) < N;
      if (pf.r < pf.r1) {
        sv_pf_row(&pf, table, vox, cs, il);
        for (int i = 1; i < pf_k && pf.r < pf.r1; ++i) sv_pf_row(&pf, table, vox, cs, il);
      }
      const int none = steps && !any(sv_reach8(F, nx, ny, nz, nbx, nby, reach, on));
      float8 tt[3];
#pragma unroll
      for (int a = 0; a < 3; ++a) tt[a] = convert_float8(L[a]) * (1.0f / 4294967296.0f);
      sv_step8(F, L, on, s_0, s_1, s_2);
      sv_addr8_il1(F, nx, ny, nz, pairs, ofs[(t + 1) & 1]);
      /* every stepping lane's sample +-0: over keeps the composite */
      if (none) continue;
      float16 u[2];
      sv_interp8_il1(tt, vox, ofs[t & 1], u);
      sv_over_lanes16(acc, u, on, alpha);
    }
    T = 0; /* (the loop below steps none) */
  }
#endif
  for (int t = 0; t < T; ++t) {
    const int8 on = (int8)(t) < N;
    if (pf.r < pf.r1) {
      sv_pf_row(&pf, table, vox, cs, il);
      for (int i = 1; i < pf_k && pf.r < pf.r1; ++i) sv_pf_row(&pf, table, vox, cs, il);
    }
    if (steps && !any(sv_reach8(F, nx, ny, nz, nbx, nby, reach, on))) {
      /* every stepping lane's sample is +-0: over keeps the composite; a lane
       * past its end stays where it is (sv_step8) */
      sv_step8(F, L, on, s_0, s_1, s_2);
      continue;
    }
    if (il) {
      float16 u[2];
      sv_sample8_il(F, L, nx, ny, nz, table, pairs, vox, u, cb);
      sv_over_lanes16(acc, u, on, alpha);
    } else {
      float8 u[4];
      sv_sample8(F, L, nx, ny, nz, table, vox, cs, u);
      const float8 tr = 1.0f - aa;
      ar = select(ar, ar + tr * u[0], on);
      ag = select(ag, ag + tr * u[1], on);
      ab = select(ab, ab + tr * u[2], on);
      aa = select(aa, aa + tr * u[3], on);
    }
    sv_step8(F, L, on, s_0, s_1, s_2);
  }
  while (pf.r < pf.r1) sv_pf_row(&pf, table, vox, cs, il);
  float4 res[8];
  if (il)
    sv_lanes_of16(acc, res);
  else
    sv_lanes_of8(ar, ag, ab, aa, res);
#ifdef SV_FOOT_LATE
  int fi[8];
#ifdef SV_PE_SEARCH2
  const int pl = sv_pe_of_segment(seg_off, log2p, s0); /* (a second search, for comparison) */
#else
  const int pl = p0;
#endif
  sv_lane_feet8(seg_off, nseg, rects, rect_off, s0, pl, li, lj, lk, ln, fi);
#endif
#pragma unroll
  for (int l = 0; l < 8; ++l)
    if (fi[l] >= 0) foot[fi[l]] = res[l];
}

/* The kernels: planar cells (il = 0), interleaved cells (il = 1), and
 * interleaved cells whose pair table carries the cell bits (_ilc: cb = 1 at
 * order 1; resample_cell_bits): the same footprints, bit for bit. */
#define SV_RESAMPLE_LOCAL_KERNEL(NAME, IL, CB)                                                     \
  __kernel void NAME(__global const sv_segment* segs, const int nseg, __global const int* seg_off, \
                     const int log2p, __global const sv_view* view, __global const int* table,     \
                     __global const float* vox, const int cs, __global const sv_rect* rects,       \
                     __global const int* rect_off, __global float4* foot,                          \
                     __global const uchar* reach, const int nbx, const int nby, const int skip,    \
                     __global const int* order, const int ordered, __global const int4* origins,   \
                     const int4 pe_cell, __global const long* pairs, __global const short2* kb,    \
                     const int use_kb) {                                                           \
    sv_resample_local8(segs, nseg, seg_off, log2p, view, table, vox, cs, rects, rect_off, foot,    \
                       reach, nbx, nby, skip, order, ordered, origins, pe_cell, pairs, kb, use_kb, \
                       IL, CB);                                                                    \
  }
SV_RESAMPLE_LOCAL_KERNEL(simdvol_resample_local_v8, 0, 0)
SV_RESAMPLE_LOCAL_KERNEL(simdvol_resample_local_v8_il, 1, 0)
SV_RESAMPLE_LOCAL_KERNEL(simdvol_resample_local_v8_ilc, 1, ORDER == 1)
#undef SV_RESAMPLE_LOCAL_KERNEL
#endif

/* ---- simdvol_segment_order: the fused kernel's lane order ----
 * One work-item per block of SV_ORDER_BLOCK consecutive positions
 * (simdvol_shared.h), cut at the PEs' boundaries: each piece [b0, b1) of
 * one PE gets its segments by length (k1 - k0, lengths >= SV_ORDER_BUCKETS
 * - 1 together), longest first, a counting sort. The 8 lanes of
 * simdvol_resample_local_v8 step together as long as their longest segment:
 * 8 consecutive segments of a PE's row, cut from an oblique cell, differ in
 * length (lane efficiency 0.61 / 0.67 at 30 / 45 deg for the 256^3 phantom
 * at 8192 PEs). Segments stay within their PE's range, so the PE of
 * position s is still that of segment s (the fused kernel's search), and
 * the lanes still read one or two PEs' voxels. */
#define SV_ORDER_BUCKETS 64
SV_FN int sv_order_key(__global const sv_segment* segs, __global const short2* kb, const int use_kb,
                       const int s) {
  const int n = use_kb ? kb[s].y - kb[s].x : segs[s].k1 - segs[s].k0;
  return clamp(n, 0, SV_ORDER_BUCKETS - 1);
}

/* use_kb: the lengths from the balanced bounds a deferred unpack left in kb
 * (match_cl.hpp: BalanceUnpack), not from the segments. */
__kernel void simdvol_segment_order(__global const sv_segment* segs, const int nseg,
                                    __global const int* seg_off, const int log2p,
                                    __global int* order, __global const short2* kb,
                                    const int use_kb, const int with_pe) {
  const int c0 = (int)get_global_id(0) * SV_ORDER_BLOCK;
  if (c0 >= nseg) return;
  const int c1 = min(c0 + SV_ORDER_BLOCK, nseg);
#ifndef SV_ORDER_NO_PFW
  /* The block's lines of the order asked for first, for writing (the
   * pieces' scatters hit them in no order the hardware follows): `simdvol
   * render --view 20,35,10 --frames 10 --step 0 --trace`, frames 2-9, two
   * alternations, 2-core Intel Xeon, 2026-12-05: 1.17 / 1.23 -> 1.04 /
   * 1.00 ms on the 256^3 phantom (-DSV_ORDER_NO_PFW leaves it out). */
  for (int s = c0; s < c1; s += 16) SV_PREFETCHW(order + s);
#endif
  int p = sv_pe_of_segment(seg_off, log2p, c0);
  for (int b0 = c0; b0 < c1; ++p) {
    const int b1 = min(c1, seg_off[p + 1]);
    if (b1 <= b0) continue; /* a PE without segments */
    /* with_pe: the PE of each float8 work-item's first position 8 w after
     * the order, order[nseg + w] (the float8 kernels' ordered = 2), so that
     * they need not search for it (SV_ORDER_BLOCK is a multiple of 8) */
    if (with_pe)
      for (int w = (b0 + 7) >> 3; 8 * w < b1; ++w) order[nseg + w] = p;
    int start[SV_ORDER_BUCKETS];
    for (int k = 0; k < SV_ORDER_BUCKETS; ++k) start[k] = 0;
    /* The keys kept from the count for the scatter (not loaded and
     * computed again): simdvol-bench-options --frames 20, two alternations
     * in one process, resample + local (the segment order in it) at (20,
     * 35, 10) 30.25 / 30.00 -> 29.66 / 29.78 ms, at (0, 45, 0) 28.25 /
     * 28.05 -> 28.06 / 28.06, brainsmall the same; the same order. */
    uchar key[SV_ORDER_BLOCK];
    for (int s = b0; s < b1; ++s) {
      const int k = sv_order_key(segs, kb, use_kb, s);
      key[s - b0] = (uchar)k;
      ++start[k];
    }
    int at = b0;
    for (int k = SV_ORDER_BUCKETS - 1; k >= 0; --k) {
      const int c = start[k];
      start[k] = at;
      at += c;
    }
    for (int s = b0; s < b1; ++s) order[start[key[s - b0]]++] = s;
    b0 = b1;
  }
}
