/* swap.cl — binary swap, display and the final warp on the PE array
 * (thesis ch. 6, 3.5; host/include/simdvol/swap.hpp has the schedule).
 *
 * A level's buffer holds, per PE p, the pixels of its strided rectangle
 * rect[p] = (x0, y0, nx, ny, sx, sy, lx, ly) (sx = 1 << lx, sy = 1 << ly)
 * densely, row-major, from off[p] (off has P + 1 entries).
 *
 * simdvol_swap_stage: stage k, one work-item per PE p of the output level
 * (1-D, local size 64): every pixel of p's rectangle there, reading its own
 * level-k rectangle and its partner's (p ^ 2^k; 0 where absent: the
 * partner's read is the X-Net transfer) and writing over(front, back), p in
 * front when bit k of p equals `front`. (One work-item per pixel, at first,
 * spent ~13 ns per pixel on finding its PE, a division and the rectangles'
 * loads; one per 16 pixels of a PE, from a chunk table the host made and
 * uploaded per stage, after that: simdvol-bench-swap --swap-only, 2-core
 * Intel Xeon (family 6, model 167), the 13 stages one launch each, two
 * alternations: the 256^3 phantom at 256^2 10.49 / 10.31 -> 8.10 / 7.99
 * ms, at 512^2 with pixel sampling 50.15 / 50.14 -> 38.26 / 40.05,
 * brainsmall 2.42 / 2.52 -> 2.12 / 2.18; the frame's stages after the
 * fused launch 2.50 -> 2.11 ms on the phantom.) Where the output's x
 * stride is a multiple of both inputs' (in every plan of plan_swap, both
 * layouts: a level's strides never shrink), a PE's pixels go row by row
 * and step each input's column instead of indexing both rectangles per
 * pixel (the same pixels); a plan made otherwise takes the per-pixel path.
 *
 * simdvol_swap_stages: stages k0 .. k0 + m - 1 in one launch, a work-group
 * per group of 2^m PEs whose partners in those stages are all inside it
 * (below); the engine runs the first stages so, where the levels are large.
 *
 * simdvol_display: one work-item per intermediate pixel (x, y): the PE
 * xpe[x] | ype[y] holds it after the swap (0 if outside its rectangle).
 *
 * simdvol_warp: the bilinear scale of voxel sampling (render.cpp
 * warp_to_output), with the source positions precomputed on the host in
 * double (ix, tx per output column; iy, ty per row): same float expressions.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL FP_CONTRACT OFF

SV_FN float4 sv_swap_over(const float4 f, const float4 b) {
  const float t = 1.0f - f.w;
  return (float4)(f.x + t * b.x, f.y + t * b.y, f.z + t * b.z, f.w + t * b.w);
}

/* Index of pixel (x, y) in rectangle r, or -1. */
SV_FN int sv_rect_index(const int8 r, const int x, const int y) {
  const int dx = x - r.s0, dy = y - r.s1;
  const int a = dx >> r.s6, b = dy >> r.s7;
  const bool in = dx >= 0 && dy >= 0 && (dx & (r.s4 - 1)) == 0 && (dy & (r.s5 - 1)) == 0 &&
                  a < r.s2 && b < r.s3;
  return in ? b * r.s2 + a : -1;
}

/* Pixels [first, first + n) of PE p's rectangle o at level k + 1 (from
 * out_base on) from level k's buffer `in` (its rectangles rp of p and rq of
 * the partner q = p ^ 2^k at offsets offp, offq): over(front, back), p in
 * front when bit k of p equals `front`. One body for each pair of address
 * spaces (IN, OUT) the kernels need (OpenCL 1.2 has no generic pointers):
 * sv_swap_pixels global -> global, _gl global -> local, _ll local -> local,
 * _lg local -> global. */
#define SV_SWAP_PIXELS(NAME, IN, OUT)                                                        \
  SV_FN void NAME(IN const float4* in, const int8 rp, const int offp, const int8 rq,         \
                  const int offq, OUT float4* out, const int8 o, const int out_base,         \
                  const int first, const int n, const int p, const int k, const int front) { \
    IN const float4* inp = in + offp;                                                        \
    IN const float4* inq = in + offq;                                                        \
    const bool p_front = ((p >> k) & 1) == front;                                            \
    const int base = out_base + first;                                                       \
    int row = first / o.s2;                                                                  \
    int col = first - row * o.s2;                                                            \
    if (o.s6 >= rp.s6 && o.s6 >= rq.s6) {                                                    \
      /* Row by row: along a row of o, x steps by 1 << o.s6, a multiple of                   \
       * each input rectangle's x stride, so a pixel's alignment with an input               \
       * rectangle is that of the row's first, and its column there steps by                 \
       * 1 << (o.s6 - r.s6): sv_rect_index's result, incrementally. */                       \
      const int ip_inc = 1 << (o.s6 - rp.s6), iq_inc = 1 << (o.s6 - rq.s6);                  \
      for (int i = 0; i < n;) {                                                              \
        const int x = o.s0 + (col << o.s6), y = o.s1 + (row << o.s7);                        \
        const int m = min(o.s2 - col, n - i);                                                \
        const int dxp = x - rp.s0, dyp = y - rp.s1, dxq = x - rq.s0, dyq = y - rq.s1;        \
        const int bp = dyp >> rp.s7, bq = dyq >> rq.s7;                                      \
        const bool okp =                                                                     \
            dyp >= 0 && (dyp & (rp.s5 - 1)) == 0 && bp < rp.s3 && (dxp & (rp.s4 - 1)) == 0;  \
        const bool okq =                                                                     \
            dyq >= 0 && (dyq & (rq.s5 - 1)) == 0 && bq < rq.s3 && (dxq & (rq.s4 - 1)) == 0;  \
        int ap = dxp >> rp.s6, aq = dxq >> rq.s6;                                            \
        IN const float4* rowp = inp + bp * rp.s2;                                            \
        IN const float4* rowq = inq + bq * rq.s2;                                            \
        for (int j = 0; j < m; ++j) {                                                        \
          const float4 vp = okp && ap >= 0 && ap < rp.s2 ? rowp[ap] : (float4)(0.0f);        \
          const float4 vq = okq && aq >= 0 && aq < rq.s2 ? rowq[aq] : (float4)(0.0f);        \
          out[base + i + j] = p_front ? sv_swap_over(vp, vq) : sv_swap_over(vq, vp);         \
          ap += ip_inc;                                                                      \
          aq += iq_inc;                                                                      \
        }                                                                                    \
        i += m;                                                                              \
        col = 0;                                                                             \
        ++row;                                                                               \
      }                                                                                      \
      return;                                                                                \
    }                                                                                        \
    for (int i = 0; i < n; ++i) {                                                            \
      const int x = o.s0 + (col << o.s6), y = o.s1 + (row << o.s7);                          \
      const int ip = sv_rect_index(rp, x, y);                                                \
      const int iq = sv_rect_index(rq, x, y);                                                \
      const float4 vp = ip >= 0 ? inp[ip] : (float4)(0.0f);                                  \
      const float4 vq = iq >= 0 ? inq[iq] : (float4)(0.0f);                                  \
      out[base + i] = p_front ? sv_swap_over(vp, vq) : sv_swap_over(vq, vp);                 \
      if (++col == o.s2) {                                                                   \
        col = 0;                                                                             \
        ++row;                                                                               \
      }                                                                                      \
    }                                                                                        \
  }
SV_SWAP_PIXELS(sv_swap_pixels, __global, __global)
SV_SWAP_PIXELS(sv_swap_pixels_gl, __global, __local)
SV_SWAP_PIXELS(sv_swap_pixels_ll, __local, __local)
SV_SWAP_PIXELS(sv_swap_pixels_lg, __local, __global)
#undef SV_SWAP_PIXELS

__kernel void simdvol_swap_stage(__global const float4* in, __global const int8* in_rect,
                                 __global const int* in_off, __global float4* out,
                                 __global const int8* out_rect, __global const int* out_off,
                                 const int pes, const int k, const int front) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const int q = p ^ (1 << k);
  const int n = out_off[p + 1] - out_off[p];
  if (n <= 0) return;
  sv_swap_pixels(in, in_rect[p], in_off[p], in_rect[q], in_off[q], out, out_rect[p], out_off[p], 0,
                 n, p, k, front);
}

/* simdvol_swap_stages: stages k0 .. k0 + m - 1 (1 <= m <= 7) in one launch.
 * Work-group g (local size 2^m) takes the 2^m PEs that differ only in bits
 * k0 .. k0 + m - 1, p = base | (lid << k0) with base = (g's low k0 bits) |
 * (the rest of g << (k0 + m)), one work-item per PE: every partner of those
 * stages lies in the group, so a barrier between stages is all the
 * synchronisation they need. Stage k0 + s reads level k0 + s (s = 0: `in`)
 * and writes level k0 + s + 1; the levels between, k0 + 1 .. k0 + m - 1,
 * are the group's alone and live in local memory: level k0 + s in la for
 * odd s, lb for even s, the group's PEs one after the other in lid order
 * (each PE's offset there the sum of the sizes before it), so they never
 * go out to memory; only level k0 + m is written to `out`. la and lb must
 * hold the largest group's pixels of their levels (the host sizes them).
 * fronts bit s = stage k0 + s's `front`. Levels k0 .. k0 + m: rectangles
 * r0 .. r7, offsets o0 .. o7 (the ones past m are not read). Each pixel is
 * the same over() as simdvol_swap_stage's. The engine's launch takes 7
 * stages (6 before 2026-12-05: stage 6, 64 PEs apart, went alone):
 * scripts/bench-ab against that build (with the prefix sums below),
 * column swap, 4 pairs, 2-core Intel Xeon (family 6, model 167): the
 * 256^3 phantom 6.31 -> 6.21 ms (0.977), at 512^2 0.979, ch2 0.956,
 * brainsmall 0.931; 8 stages in one launch against 7: 1.024 / 1.000. */
#define SV_SWAP_GROUP 128 /* 2^7: kSwapFusedStages in swap_cl.hpp */
__kernel void simdvol_swap_stages(
    __global const float4* in, __global float4* out, __local float4* la, __local float4* lb,
    __global const int8* r0, __global const int8* r1, __global const int8* r2,
    __global const int8* r3, __global const int8* r4, __global const int8* r5,
    __global const int8* r6, __global const int8* r7, __global const int* o0,
    __global const int* o1, __global const int* o2, __global const int* o3, __global const int* o4,
    __global const int* o5, __global const int* o6, __global const int* o7, const int k0,
    const int m, const int fronts) {
  __global const int8* R[8] = {r0, r1, r2, r3, r4, r5, r6, r7};
  __global const int* O[8] = {o0, o1, o2, o3, o4, o5, o6, o7};
  /* Level k0 + s's pixel count and local offset of each PE of the group
   * (index s - 1, lid). */
  __local int size[6][SV_SWAP_GROUP];
  __local int start[6][SV_SWAP_GROUP];
  const int lid = (int)get_local_id(0), g = (int)get_group_id(0);
  const int low = g & ((1 << k0) - 1);
  const int p = low | ((g >> k0) << (k0 + m)) | (lid << k0);
  for (int s = 1; s < m; ++s) size[s - 1][lid] = O[s][p + 1] - O[s][p];
  barrier(CLK_LOCAL_MEM_FENCE);
  /* The group's offsets in local memory: prefix sums of the sizes, one
   * work-item summing each level's 2^m sizes in turn (-DSV_SWAP_SCAN_ALL:
   * each work-item its own sum over the sizes before it, 2^m (2^m - 1) / 2
   * additions a level instead of 2^m; simdvol-bench-options --frames 12,
   * two alternations: swap 6.31 / 6.24 -> 6.23 / 6.15 ms). */
#ifdef SV_SWAP_SCAN_ALL
  for (int s = 1; s < m; ++s) {
    int a = 0;
    for (int j = 0; j < lid; ++j) a += size[s - 1][j];
    start[s - 1][lid] = a;
  }
#else
  if (lid == 0)
    for (int s = 1; s < m; ++s) {
      int a = 0;
      for (int j = 0; j < (1 << m); ++j) {
        start[s - 1][j] = a;
        a += size[s - 1][j];
      }
    }
#endif
  barrier(CLK_LOCAL_MEM_FENCE);
  /* The seven stage slots unrolled, each barrier outside any loop or branch
   * (PoCL ran the loop with a barrier inside at several times the cost
   * per work-item); slots past m do nothing. Slot S reads level k0 + S
   * (global for S = 0, else local) and writes level k0 + S + 1 (global for
   * S = m - 1, else local). */
#define SV_SWAP_SLOT(S)                                                                        \
  if (S < m) {                                                                                 \
    const int k = k0 + S, q = p ^ (1 << k), lq = lid ^ (1 << S), fr = (fronts >> S) & 1;       \
    __local float4* lin = (S & 1) ? la : lb;                                                   \
    __local float4* lout = (S & 1) ? lb : la;                                                  \
    const int8 rp = R[S][p], rq = R[S][q], ro = R[S + 1][p];                                   \
    const int n = O[S + 1][p + 1] - O[S + 1][p];                                               \
    if (S == m - 1) {                                                                          \
      if (S == 0)                                                                              \
        sv_swap_pixels(in, rp, O[0][p], rq, O[0][q], out, ro, O[S + 1][p], 0, n, p, k, fr);    \
      else                                                                                     \
        sv_swap_pixels_lg(lin, rp, start[S > 0 ? S - 1 : 0][lid], rq,                          \
                          start[S > 0 ? S - 1 : 0][lq], out, ro, O[S + 1][p], 0, n, p, k, fr); \
    } else {                                                                                   \
      const int base = start[S < 6 ? S : 0][lid];                                              \
      if (S == 0)                                                                              \
        sv_swap_pixels_gl(in, rp, O[0][p], rq, O[0][q], lout, ro, base, 0, n, p, k, fr);       \
      else                                                                                     \
        sv_swap_pixels_ll(lin, rp, start[S > 0 ? S - 1 : 0][lid], rq,                          \
                          start[S > 0 ? S - 1 : 0][lq], lout, ro, base, 0, n, p, k, fr);       \
    }                                                                                          \
  }                                                                                            \
  barrier(CLK_LOCAL_MEM_FENCE);
  SV_SWAP_SLOT(0)
  SV_SWAP_SLOT(1)
  SV_SWAP_SLOT(2)
  SV_SWAP_SLOT(3)
  SV_SWAP_SLOT(4)
  SV_SWAP_SLOT(5)
  SV_SWAP_SLOT(6)
#undef SV_SWAP_SLOT
}

__kernel void simdvol_display(__global const float4* last, __global const int8* rect,
                              __global const int* off, __global const int* xpe,
                              __global const int* ype, const int width, const int height,
                              __global float4* image) {
  const int x = (int)get_global_id(0), y = (int)get_global_id(1);
  if (x >= width || y >= height) return;
  const int p = xpe[x] | ype[y];
  const int i = sv_rect_index(rect[p], x, y);
  image[y * width + x] = i >= 0 ? last[off[p] + i] : (float4)(0.0f);
}

SV_FN float4 sv_warp_px(__global const float4* im, const int w, const int h, const int x,
                        const int y) {
  const bool in = x >= 0 && y >= 0 && x < w && y < h;
  return in ? im[y * w + x] : (float4)(0.0f);
}

__kernel void simdvol_warp(__global const float4* im, const int w, const int h,
                           __global const int* ix, __global const float* tx, __global const int* iy,
                           __global const float* ty, const int ow, const int oh,
                           __global float4* out) {
  const int x = (int)get_global_id(0), y = (int)get_global_id(1);
  if (x >= ow || y >= oh) return;
  const int x0 = ix[x], y0 = iy[y];
  const float fx = tx[x], fy = ty[y];
  const float4 a = sv_warp_px(im, w, h, x0, y0), b = sv_warp_px(im, w, h, x0 + 1, y0);
  const float4 c = sv_warp_px(im, w, h, x0, y0 + 1), d = sv_warp_px(im, w, h, x0 + 1, y0 + 1);
  const float4 top = a + fx * (b - a);
  const float4 bot = c + fx * (d - c);
  out[y * ow + x] = top + fy * (bot - top);
}
