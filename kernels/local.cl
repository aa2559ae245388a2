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
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL FP_CONTRACT OFF
/* long8/float8 arguments of helper functions change the ABI without AVX-512;
 * clang warns once per call site (-Wpsabi). Harmless inside one program. */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
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
 * PoCL vectorises only loops over work-items whose bodies have no inner
 * loops of varying trip count; a segment's samples are such a loop, so the
 * one-segment-per-work-item kernel above runs scalar. Here each work-item
 * takes 8 consecutive segments (of one PE, mostly: neighbouring rays of
 * similar length) as the 8 lanes of float8/int8/long8 values and steps them
 * together max(k1 - k0) times; a lane whose segment has ended keeps its
 * composite (select) and reads clamped, harmless voxels. Element-wise vector
 * arithmetic is the scalar IEEE arithmetic, so the results are those of
 * simdvol_resample_local bit for bit. Voxel gathers are 8 scalar loads each. */
#define SV_G8(p, ix)                                                                  \
  ((float8)((p)[(ix).s0], (p)[(ix).s1], (p)[(ix).s2], (p)[(ix).s3], (p)[(ix).s4],     \
            (p)[(ix).s5], (p)[(ix).s6], (p)[(ix).s7]))
#define SV_GI8(p, ix)                                                                 \
  ((int8)((p)[(ix).s0], (p)[(ix).s1], (p)[(ix).s2], (p)[(ix).s3], (p)[(ix).s4],       \
          (p)[(ix).s5], (p)[(ix).s6], (p)[(ix).s7]))

SV_FN void sv_axis8(long8 X, int n, __global const int* table, int8* addr, float8* d, int8* low) {
  const int8 f = convert_int8(X >> SV_FRAC_BITS);
  const float8 t = convert_float8(convert_uint8(X & 0xFFFFFFFFL)) * (1.0f / 4294967296.0f);
  const int8 lo = t <= 0.5f; /* -1 where low */
  *low = lo;
#pragma unroll
  for (int e = 0; e < SV_M; ++e) {
    const int8 p = select((int8)(1 - SV_LOWPOS(e)), (int8)(SV_LOWPOS(e)), lo);
    const int8 g = clamp(f + p, (int8)(0), (int8)(n - 1));
    addr[e] = SV_GI8(table, g);
    d[e] = convert_float8(-p) + t;
  }
}

SV_FN void sv_neville8(float8* q, const int R, const float8* d, const int8 low) {
#pragma unroll
  for (int k = 1; k <= ORDER; ++k) {
#pragma unroll
    for (int i = k - 1; i >= 0; --i) {
      const int c = SV_LOWPOS(k) - SV_LOWPOS(i);
      const float8 di = d[i], dk = d[k];
      if (c == 3 || c == -3) {
        const float8 den = select((float8)((float)(-c)), (float8)((float)c), low);
#pragma unroll
        for (int r = 0; r < R; ++r) q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) / den;
      } else {
        const float8 rc = select((float8)(-1.0f / (float)c), (float8)(1.0f / (float)c), low);
#pragma unroll
        for (int r = 0; r < R; ++r) q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) * rc;
      }
    }
  }
}

__kernel void simdvol_resample_local_v8(__global const sv_segment* segs, const int nseg,
                                        __global const int* seg_off, const int log2p,
                                        __global const sv_view* view, __global const int* table,
                                        __global const float* vox, const int cs,
                                        __global const sv_rect* rects,
                                        __global const int* rect_off, __global float4* foot) {
  const int s0 = (int)get_global_id(0) * 8;
  if (s0 >= nseg) return;
  int li[8], lj[8], lk[8], ln[8];
  int T = 0;
#pragma unroll
  for (int l = 0; l < 8; ++l) {
    const int s = min(s0 + l, nseg - 1);
    const sv_segment g = segs[s];
    li[l] = g.i;
    lj[l] = g.j;
    lk[l] = g.k0;
    ln[l] = s0 + l < nseg ? g.k1 - g.k0 : 0;
    T = max(T, ln[l]);
  }
  const int8 I = (int8)(li[0], li[1], li[2], li[3], li[4], li[5], li[6], li[7]);
  const int8 J = (int8)(lj[0], lj[1], lj[2], lj[3], lj[4], lj[5], lj[6], lj[7]);
  const int8 K = (int8)(lk[0], lk[1], lk[2], lk[3], lk[4], lk[5], lk[6], lk[7]);
  const int8 N = (int8)(ln[0], ln[1], ln[2], ln[3], ln[4], ln[5], ln[6], ln[7]);
  long8 X[3];
#pragma unroll
  for (int a = 0; a < 3; ++a)
    X[a] = (long8)(view->origin[a]) + convert_long8(I) * view->step[a][0] +
           convert_long8(J) * view->step[a][1] + convert_long8(K) * view->step[a][2];
  const long s_0 = view->step[0][2], s_1 = view->step[1][2], s_2 = view->step[2][2];
  const int nx = view->dims[0], ny = view->dims[1], nz = view->dims[2];
  float8 ar = (float8)(0.0f), ag = ar, ab = ar, aa = ar;
  for (int t = 0; t < T; ++t) {
    int8 ax[SV_M], ay[SV_M], az[SV_M];
    float8 dx[SV_M], dy[SV_M], dz[SV_M];
    int8 lx, ly, lz;
    sv_axis8(X[0], nx, table, ax, dx, &lx);
    sv_axis8(X[1], ny, table + nx, ay, dy, &ly);
    sv_axis8(X[2], nz, table + nx + ny, az, dz, &lz);
    const int R = 4 * SV_M * SV_M;
    float8 v[SV_M * 4 * SV_M * SV_M];
#pragma unroll
    for (int c = 0; c < SV_M; ++c)
#pragma unroll
      for (int b = 0; b < SV_M; ++b) {
        const int8 row = ay[b] + az[c];
#pragma unroll
        for (int a = 0; a < SV_M; ++a) {
          const int8 o = row + ax[a];
#pragma unroll
          for (int ch = 0; ch < 4; ++ch) {
            const int8 oc = o + ch * cs;
            v[a * R + ch * SV_M * SV_M + c * SV_M + b] = SV_G8(vox, oc);
          }
        }
      }
    sv_neville8(v, R, dx, lx);
    float8 w[SV_M * 4 * SV_M];
#pragma unroll
    for (int ch = 0; ch < 4; ++ch)
#pragma unroll
      for (int c = 0; c < SV_M; ++c)
#pragma unroll
        for (int b = 0; b < SV_M; ++b)
          w[b * 4 * SV_M + ch * SV_M + c] = v[ch * SV_M * SV_M + c * SV_M + b];
    sv_neville8(w, 4 * SV_M, dy, ly);
    float8 u[SV_M * 4];
#pragma unroll
    for (int ch = 0; ch < 4; ++ch)
#pragma unroll
      for (int c = 0; c < SV_M; ++c) u[c * 4 + ch] = w[ch * SV_M + c];
    sv_neville8(u, 4, dz, lz);
    const int8 on = (int8)(t) < N;
    const float8 tr = 1.0f - aa;
    ar = select(ar, ar + tr * u[0], on);
    ag = select(ag, ag + tr * u[1], on);
    ab = select(ab, ab + tr * u[2], on);
    aa = select(aa, aa + tr * u[3], on);
    X[0] += s_0;
    X[1] += s_1;
    X[2] += s_2;
  }
  float rr[8], gg[8], bb[8], al[8];
  vstore8(ar, 0, rr);
  vstore8(ag, 0, gg);
  vstore8(ab, 0, bb);
  vstore8(aa, 0, al);
#pragma unroll
  for (int l = 0; l < 8; ++l) {
    const int s = s0 + l;
    if (s < nseg) {
      const int p = sv_pe_of_segment(seg_off, log2p, s);
      const sv_segment g = {li[l], lj[l], lk[l], lk[l] + ln[l]};
      foot[sv_footprint_index(rects, rect_off, p, g)] = (float4)(rr[l], gg[l], bb[l], al[l]);
    }
  }
}
#endif
