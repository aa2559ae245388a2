/* mc.cl — Monte Carlo compositing on the PE array (thesis ch. 7.2-7.5).
 * References: host/core/mc.cpp and composite_mc_walks (host/core/composite.cpp);
 * the walk arithmetic below repeats theirs operation for operation (colour
 * sums in double, FP_CONTRACT off), so results agree bit for bit.
 *
 * Inputs: the segments (CSR per PE), the resample stage's samples in segment
 * order (sample_off[s] = first sample of segment s) and, for whole rays and
 * the allocation, per-pixel lists of the non-empty segments in increasing k0
 * (ray_off[W * H + 1], ray_items[]), built by the ray_* kernels below:
 *   simdvol_mc_ray_count  one work-item per segment: atomic count per pixel
 *   simdvol_mc_ray_scan   one work-item: exclusive prefix sum (W * H ints)
 *   simdvol_mc_ray_fill   one work-item per segment: atomic slot per pixel
 *   simdvol_mc_ray_sort   one work-item per pixel: insertion sort by k0 (the
 *                         atomic order is arbitrary; sorted it is unique)
 *
 *   simdvol_mc_whole      one work-item per pixel (the pixel's owner after
 *                         the swap): the walks over the ray's samples,
 *                         segment after segment in depth order -> image
 *   simdvol_mc_alpha      one work-item per segment: exact opacity; walks = 0
 *   simdvol_mc_allocate   one work-item per pixel: allocate_walks (mc.hpp)
 *   simdvol_mc_local      one work-item per segment: its walks over its own
 *                         samples -> the PE's footprint (as simdvol_local)
 *
 * Options (defines): SHARED (1: key SV_SHARED_RAY), EXACT (exact opacity),
 * STRAT (with EXACT: stratified picks, composite_mc_stratified), DROP (no
 * draw for alpha <= 0), ALLOC (mc_local reads walks[s]), SV_MC_SCALAR (the
 * walks one by one, each a pass over the samples, as the reference writes
 * them; kept for timing comparisons: the default takes 8 walks per pass,
 * with the same draws and sums).
 * stats (if STATS): one int4 per work-item (walks, draws, skipped, fallback).
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#ifndef SHARED
#define SHARED 0
#endif
#ifndef EXACT
#define EXACT 0
#endif
#ifndef DROP
#define DROP 1
#endif
#ifndef ALLOC
#define ALLOC 0
#endif
#ifndef STRAT
#define STRAT 0
#endif
#if STRAT && !EXACT
#error "STRAT (stratified picks) needs EXACT (exact opacity)"
#endif
#ifndef STATS
#define STATS 0
#endif

__kernel void simdvol_mc_ray_count(__global const sv_segment* segs, const int nseg, const int width,
                                   const int height, volatile __global int* counts) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  if (g.k1 > g.k0 && g.i >= 0 && g.j >= 0 && g.i < width && g.j < height)
    atomic_inc(&counts[g.j * width + g.i]);
}

__kernel void simdvol_mc_ray_scan(__global int* counts, const int n, __global int* off) {
  if (get_global_id(0) != 0) return;
  int acc = 0;
  for (int q = 0; q < n; ++q) {
    off[q] = acc;
    acc += counts[q];
    counts[q] = 0; /* reused as the fill cursor */
  }
  off[n] = acc;
}

__kernel void simdvol_mc_ray_fill(__global const sv_segment* segs, const int nseg, const int width,
                                  const int height, __global const int* off,
                                  volatile __global int* cursor, __global int* items) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  if (g.k1 <= g.k0 || g.i < 0 || g.j < 0 || g.i >= width || g.j >= height) return;
  const int q = g.j * width + g.i;
  items[off[q] + atomic_inc(&cursor[q])] = s;
}

__kernel void simdvol_mc_ray_sort(__global const sv_segment* segs, const int npx,
                                  __global const int* off, __global int* items) {
  const int q = (int)get_global_id(0);
  if (q >= npx) return;
  const int b = off[q], e = off[q + 1];
  for (int t = b + 1; t < e; ++t) {
    const int v = items[t];
    const int k = segs[v].k0;
    int u = t - 1;
    while (u >= b && segs[items[u]].k0 > k) {
      items[u + 1] = items[u];
      --u;
    }
    items[u + 1] = v;
  }
}

/* sv_uniform (simdvol_shared.h) for 8 walks at 4 steps at once: one
 * Philox4x32-10 in uint8 lanes, the same bits per draw. Lane L = 4h + i
 * takes the counter (ray, q0 + h, kb + i, "simd"); its four words are the
 * draws of walks 4 (q0 + h) .. 4 (q0 + h) + 3 at step kb + i. Word 0 of the
 * counter (the ray) and word 3 ("simd") are the same in every lane, so
 * round 1's product of word 0 and round 2's of word 2 depend on the ray
 * alone: sv_philox_ray makes them once per ray, and a block takes 18
 * lane-wide high-low multiplication pairs for 32 draws (one pair per draw
 * as 8 walks at one step took 16 for 8). */
typedef struct {
  uint lo0, c2, lo1, hi1; /* round 1: lo(K0 * ray), word 2; round 2: lo, hi(K1 * word 2) */
  uint k0, k1;            /* the key */
} sv_philox_ray;

SV_FN sv_philox_ray sv_philox_ray_init(const ulong seed, const uint ray) {
  sv_philox_ray R;
  R.k0 = (uint)seed;
  R.k1 = (uint)(seed >> 32);
  const uint lo0 = ray * 0xD2511F53u, hi0 = mul_hi(ray, 0xD2511F53u);
  R.lo0 = lo0;
  R.c2 = hi0 ^ 0x73696d64u ^ R.k1; /* round 1's word 2 (counter word 3 is "simd") */
  R.lo1 = R.c2 * 0xCD9E8D57u;      /* round 2 on it */
  R.hi1 = mul_hi(R.c2, 0xCD9E8D57u);
  return R;
}

/* U[i] lane w = sv_uniform(seed, ray, 4 q0 + w, kb + i), i = 0..3, w = 0..7. */
SV_FN void sv_uniform8x4(const sv_philox_ray* R, const uint q0, const uint kb, float8* U) {
  const uint w0 = 0x9E3779B9u, w1 = 0xBB67AE85u;
  const uint8 L = (uint8)(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u);
  const uint8 c1 = q0 + (L >> 2), c2 = kb + (L & 3u);
  /* Round 1, key (k0, k1): word 0 = ray (R), word 2 = the step. */
  const uint8 lo1 = c2 * 0xCD9E8D57u, hi1 = mul_hi(c2, (uint8)(0xCD9E8D57u));
  const uint8 n0 = hi1 ^ c1 ^ R->k0; /* n1 = lo1, n2 = R->c2, n3 = R->lo0 */
  /* Round 2, key + w: word 2 = R->c2 (R->lo1, R->hi1). */
  const uint8 lo0 = n0 * 0xD2511F53u, hi0 = mul_hi(n0, (uint8)(0xD2511F53u));
  uint8 c0 = R->hi1 ^ lo1 ^ (R->k0 + w0);
  uint8 d1 = (uint8)(R->lo1);
  uint8 d2 = hi0 ^ R->lo0 ^ (R->k1 + w1);
  uint8 d3 = lo0;
  uint k0 = R->k0 + 2u * w0, k1 = R->k1 + 2u * w1;
#pragma unroll
  for (int q = 2; q < 10; ++q) {
    const uint8 a0 = c0 * 0xD2511F53u, b0 = mul_hi(c0, (uint8)(0xD2511F53u));
    const uint8 a1 = d2 * 0xCD9E8D57u, b1 = mul_hi(d2, (uint8)(0xCD9E8D57u));
    c0 = b1 ^ d1 ^ k0;
    d1 = a1;
    d2 = b0 ^ d3 ^ k1;
    d3 = a0;
    k0 += w0;
    k1 += w1;
  }
  const float s = 1.0f / 16777216.0f;
  const float8 f0 = convert_float8(c0 >> 8) * s, f1 = convert_float8(d1 >> 8) * s;
  const float8 f2 = convert_float8(d2 >> 8) * s, f3 = convert_float8(d3 >> 8) * s;
  /* Walk 4h + w at step kb + i is word w of lane 4h + i: a 4 x 4 transpose
   * in each half. */
  U[0] = (float8)(f0.s0, f1.s0, f2.s0, f3.s0, f0.s4, f1.s4, f2.s4, f3.s4);
  U[1] = (float8)(f0.s1, f1.s1, f2.s1, f3.s1, f0.s5, f1.s5, f2.s5, f3.s5);
  U[2] = (float8)(f0.s2, f1.s2, f2.s2, f3.s2, f0.s6, f1.s6, f2.s6, f3.s6);
  U[3] = (float8)(f0.s3, f1.s3, f2.s3, f3.s3, f0.s7, f1.s7, f2.s7, f3.s7);
}

/* Exact opacity of `count` segments in depth order (over's alpha
 * recurrence); *k_first = the depth of the first sample with alpha > 0 (the
 * first segment's k0 if none), which keys the exact-opacity draws
 * (composite.cpp: first_opaque_step). */
SV_FN float sv_mc_alpha(__global const sv_segment* segs, __global const int* sample_off,
                        __global const float4* samples, __global const int* items, const int first,
                        const int count, int* k_first) {
  float acc = 0.0f;
  int found = 0;
  for (int t = 0; t < count; ++t) {
    const int s = items ? items[first + t] : first + t;
    const sv_segment sg = segs[s];
    if (t == 0) *k_first = sg.k0;
    __global const float4* in = samples + sample_off[s];
    for (int k = sg.k0; k < sg.k1; ++k) {
      const float a = in[k - sg.k0].w;
      if (!found && a > 0.0f) {
        *k_first = k;
        found = 1;
      }
      acc = acc + (1.0f - acc) * a;
    }
  }
  return acc;
}

/* The estimator over `count` segments (indices items[first + t], or
 * first + t when items is 0) in depth order: composite_mc_walks. */
SV_FN float4 sv_mc_estimate(__global const sv_segment* segs, __global const int* sample_off,
                            __global const float4* samples, __global const int* items,
                            const int first, const int count, const uint key, const int walks,
                            const ulong seed, int4* st) {
#if STRAT
  /* Stratified picks (composite_mc_stratified in composite.cpp): exact
   * opacity, then one pass in which walk m picks the first sample with
   * alpha > 0 whose cumulative opacity exceeds ((m + u_m) / n) * alpha. */
  int k_first = 0;
  const float acc = sv_mc_alpha(segs, sample_off, samples, items, first, count, &k_first);
  float4 out = (float4)(0.0f, 0.0f, 0.0f, acc);
  int skipped = 0, fallback = 0, draws = 0;
  if (walks > 0 && acc > 0.0f) {
    const float inv_n = 1.0f / (float)walks;
    double r = 0.0, g = 0.0, b = 0.0;
    int m = 0;
    float ub[4]; /* the draws of walks 4q .. 4q + 3: one Philox block */
    sv_uniform4(seed, key, 0u, (uint)k_first, ub);
    float tt = (((float)0 + ub[0]) * inv_n) * acc;
    float c = 0.0f;
    float4 last = (float4)(0.0f);
    for (int t = 0; t < count && m < walks; ++t) {
      const int s = items ? items[first + t] : first + t;
      const sv_segment sg = segs[s];
      __global const float4* in = samples + sample_off[s];
      for (int k = sg.k0; k < sg.k1 && m < walks; ++k) {
        const float4 v = in[k - sg.k0];
        if (v.w <= 0.0f) {
          ++skipped;
          continue;
        }
        last = v;
        c = c + (1.0f - c) * v.w;
        while (m < walks && c > tt) {
          r += (double)(v.x / v.w);
          g += (double)(v.y / v.w);
          b += (double)(v.z / v.w);
          ++m;
          if (m < walks) {
            if ((m & 3) == 0) sv_uniform4(seed, key, (uint)m >> 2, (uint)k_first, ub);
            tt = (((float)m + ub[m & 3]) * inv_n) * acc;
          }
        }
      }
    }
    if (m < walks) {
      fallback = 1;
      for (; m < walks; ++m) {
        r += (double)(last.x / last.w);
        g += (double)(last.y / last.w);
        b += (double)(last.z / last.w);
      }
    }
    draws = walks;
    const double a = (double)acc;
    const double inv = 1.0 / (double)walks;
    out.x = (float)(a * (r * inv));
    out.y = (float)(a * (g * inv));
    out.z = (float)(a * (b * inv));
  }
  *st = (int4)(walks, draws, skipped, fallback);
  return out;
#else
  double r = 0.0, g = 0.0, b = 0.0;
  int stopped = 0, draws = 0, skipped = 0;
#ifndef SV_MC_SCALAR
  /* The walks 8 at a time, one pass over the samples per 8: each sample is
   * read once for the 8, and their draws come 4 steps at a time from one
   * 8-lane Philox (sv_uniform8x4; drawn again when a step falls outside the
   * 4). Walk m stops at the first sample k with u(m, k) < alpha, as in the
   * walk-by-walk loop (SV_MC_SCALAR), and the stopped walks' colours are
   * summed afterwards in walk order: the same sums bit for bit. */
  const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
  const sv_philox_ray R = sv_philox_ray_init(seed, key);
  for (int m0 = 0; m0 < walks; m0 += 8) {
    const int8 real = (m0 + lane) < (int8)(walks);
    int8 live = real;
    int nlive = min(walks - m0, 8);
    float8 cr = (float8)(0.0f), cg = cr, cb = cr;
    float8 U[4];
    int kb = 0, drawn = 0; /* U holds the draws of steps kb .. kb + 3 */
    for (int t = 0; t < count && nlive > 0; ++t) {
      const int s = items ? items[first + t] : first + t;
      const sv_segment sg = segs[s];
      __global const float4* in = samples + sample_off[s];
      for (int k = sg.k0; k < sg.k1; ++k) {
        const float4 v = in[k - sg.k0];
        if (v.w <= 0.0f && DROP) {
          skipped += nlive;
          continue;
        }
        draws += nlive;
        if (!drawn || (uint)(k - kb) >= 4u) {
          kb = k;
          drawn = 1;
          sv_uniform8x4(&R, (uint)m0 >> 2, (uint)k, U);
        }
        const int8 h = live & (U[k - kb] < (float8)(v.w));
        if (any(h)) {
          cr = select(cr, (float8)(v.x / v.w), h);
          cg = select(cg, (float8)(v.y / v.w), h);
          cb = select(cb, (float8)(v.z / v.w), h);
          live &= ~h;
          nlive = -(live.s0 + live.s1 + live.s2 + live.s3 + live.s4 + live.s5 + live.s6 + live.s7);
          if (nlive == 0) break;
        }
      }
    }
    const int8 done = real & ~live;
    float fr[8], fg[8], fb[8];
    int fd[8];
    vstore8(cr, 0, fr);
    vstore8(cg, 0, fg);
    vstore8(cb, 0, fb);
    vstore8(done, 0, fd);
    for (int l = 0; l < 8; ++l)
      if (fd[l]) {
        r += (double)fr[l];
        g += (double)fg[l];
        b += (double)fb[l];
        ++stopped;
      }
  }
#else
  for (int m = 0; m < walks; ++m) {
    int done = 0;
    for (int t = 0; t < count && !done; ++t) {
      const int s = items ? items[first + t] : first + t;
      const sv_segment sg = segs[s];
      __global const float4* in = samples + sample_off[s];
      for (int k = sg.k0; k < sg.k1; ++k) {
        const float4 v = in[k - sg.k0];
        if (v.w <= 0.0f && DROP) {
          ++skipped;
          continue;
        }
        ++draws;
        const float u = sv_uniform(seed, key, (uint)m, (uint)k);
        if (u < v.w) {
          r += (double)(v.x / v.w);
          g += (double)(v.y / v.w);
          b += (double)(v.z / v.w);
          ++stopped;
          done = 1;
          break;
        }
      }
    }
  }
#endif
  float4 out = (float4)(0.0f);
  int fallback = 0;
#if !EXACT
  if (walks > 0) {
    const double inv = 1.0 / (double)walks;
    out = (float4)((float)(r * inv), (float)(g * inv), (float)(b * inv),
                   (float)((double)stopped * inv));
  }
#else
  /* Exact opacity: over's alpha recurrence; when no walk stopped, one pick
   * from p_s / alpha by inverting the cumulative opacity (composite.cpp). */
  int k_first = 0;
  const float acc = sv_mc_alpha(segs, sample_off, samples, items, first, count, &k_first);
  out.w = acc;
  if (stopped > 0) {
    const double a = (double)acc;
    out.x = (float)(a * (r / (double)stopped));
    out.y = (float)(a * (g / (double)stopped));
    out.z = (float)(a * (b / (double)stopped));
  } else if (acc > 0.0f) {
    fallback = 1;
    ++draws;
    const float u = sv_uniform(seed, key, (uint)walks, (uint)k_first);
    const float tt = u * acc;
    float c = 0.0f;
    float4 pick = (float4)(0.0f);
    int found = 0, done = 0;
    for (int t = 0; t < count && !done; ++t) {
      const int s = items ? items[first + t] : first + t;
      const sv_segment sg = segs[s];
      __global const float4* in = samples + sample_off[s];
      for (int k = sg.k0; k < sg.k1; ++k) {
        const float4 v = in[k - sg.k0];
        if (v.w > 0.0f) {
          pick = v;
          found = 1;
        }
        c = c + (1.0f - c) * v.w;
        if (c > tt && v.w > 0.0f) {
          done = 1;
          break;
        }
      }
    }
    if (found) {
      const double a = (double)acc;
      out.x = (float)(a * (double)(pick.x / pick.w));
      out.y = (float)(a * (double)(pick.y / pick.w));
      out.z = (float)(a * (double)(pick.z / pick.w));
    }
  } else {
    fallback = 1;
  }
#endif
  *st = (int4)(walks, draws, skipped, fallback);
  return out;
#endif
}

__kernel void simdvol_mc_whole(__global const sv_segment* segs, __global const int* sample_off,
                               __global const float4* samples, __global const int* ray_off,
                               __global const int* ray_items, const int width, const int npx,
                               const int walks, const ulong seed, __global float4* image,
                               __global int4* stats) {
  const int q = (int)get_global_id(0);
  if (q >= npx) return;
  const uint key = SHARED ? SV_SHARED_RAY : (uint)q; /* q = j * width + i */
  int4 st;
  const int b = ray_off[q];
  image[q] = sv_mc_estimate(segs, sample_off, samples, ray_items, b, ray_off[q + 1] - b, key, walks,
                            seed, &st);
#if STATS
  stats[q] = st;
#endif
}

__kernel void simdvol_mc_alpha(__global const sv_segment* segs, const int nseg,
                               __global const int* sample_off, __global const float4* samples,
                               __global float* alpha, __global int* walks) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment sg = segs[s];
  __global const float4* in = samples + sample_off[s];
  float acc = 0.0f;
  for (int k = sg.k0; k < sg.k1; ++k) acc = acc + (1.0f - acc) * in[k - sg.k0].w;
  alpha[s] = acc;
  walks[s] = 0;
}

/* allocation_weight (mc.hpp): an opacity in 256 steps, at least 1 */
inline int sv_alloc_weight(const float a) {
  return a > 0.0f ? (int)ceil(fmin(a, 1.0f) * 256.0f) : 0;
}

__kernel void simdvol_mc_allocate(__global const int* ray_off, __global const int* ray_items,
                                  const int npx, __global const float* alpha, const int budget,
                                  __global int* walks) {
  const int q = (int)get_global_id(0);
  if (q >= npx) return;
  const int b = ray_off[q], e = ray_off[q + 1];
  int c = 0;
  long W = 0;
  for (int t = b; t < e; ++t) {
    const float a = alpha[ray_items[t]];
    if (a > 0.0f) {
      ++c;
      W += sv_alloc_weight(a);
    }
  }
  if (c == 0) return; /* walks stay 0 */
  if (budget <= c) {
    for (int t = b; t < e; ++t) walks[ray_items[t]] = alpha[ray_items[t]] > 0.0f ? 1 : 0;
    return;
  }
  /* integers throughout (allocate_walks): floors into walks, then one more
   * to the L largest remainders (ties: the front one) */
  const long r = budget - c;
  long sum_f = 0;
  for (int t = b; t < e; ++t) {
    const long f = r * sv_alloc_weight(alpha[ray_items[t]]) / W;
    walks[ray_items[t]] = (int)f;
    sum_f += f;
  }
  const long L = r - sum_f;
  for (int t = b; t < e; ++t) {
    const float a = alpha[ray_items[t]];
    if (!(a > 0.0f)) continue;
    const long rs = r * sv_alloc_weight(a) % W;
    long rank = 0;
    for (int u = b; u < e; ++u) {
      const float au = alpha[ray_items[u]];
      if (!(au > 0.0f)) continue;
      const long ru = r * sv_alloc_weight(au) % W;
      if (ru > rs || (ru == rs && u < t)) ++rank;
    }
    walks[ray_items[t]] = 1 + walks[ray_items[t]] + (rank < L ? 1 : 0);
  }
}

__kernel void simdvol_mc_local(__global const sv_segment* segs, const int nseg,
                               __global const int* seg_off, const int log2p,
                               __global const int* sample_off, __global const float4* samples,
                               const int width, const int walks, __global const int* alloc,
                               const ulong seed, __global const sv_rect* rects,
                               __global const int* rect_off, __global float4* foot,
                               __global int4* stats) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  int4 st = (int4)(0);
  float4 v = (float4)(0.0f);
  if (g.k1 > g.k0) {
    const uint key = SHARED ? SV_SHARED_RAY : (uint)(g.j * width + g.i);
    const int n = ALLOC ? alloc[s] : walks;
    v = sv_mc_estimate(segs, sample_off, samples, 0, s, 1, key, n, seed, &st);
  }
  const int p = sv_pe_of_segment(seg_off, log2p, s);
  const sv_rect r = rects[p];
  foot[rect_off[p] + (g.j - r.j0) * r.w + (g.i - r.i0)] = v;
#if STATS
  stats[s] = st;
#endif
}
