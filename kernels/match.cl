/* match.cl — which PE resamples which viewing sample (see
 * host/include/simdvol/match.hpp and match_cl.hpp).
 *
 * Arguments shared by the kernels:
 *   __constant sv_view* view   the fixed-point viewing map
 *   global const sv_rect* cand candidate rectangle of each PE (host-computed)
 *   global const int4* cidx    cell index of each PE (w unused)
 *   int4 cell                  cell extent c (w unused)
 *   int pes
 * A PE's box is [cidx * c, min(cidx * c + c, dims)). Per ray the exact depth
 * range comes from a float estimate of each slab bound, corrected with exact
 * 64-bit checks (the predicate is monotonic in k, and the estimate is
 * clamped to [0, D] first, so the corrections take a step or two).
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

/* Smallest k in [0, D] with base + k d >= v (d > 0), or D if none. */
SV_FN int sv_first_at_least(long base, long d, long v, int D) {
  float e = ceil((float)(v - base) / (float)d);
  int k = (int)clamp(e, 0.0f, (float)D);
  while (k < D && base + (long)k * d < v) ++k;
  while (k > 0 && base + (long)(k - 1) * d >= v) --k;
  return k;
}

/* Smallest k in [0, D] with base + k d < v (d < 0), or D if none. */
SV_FN int sv_first_below(long base, long d, long v, int D) {
  float e = floor((float)(base - v) / (float)(-d)) + 1.0f;
  int k = (int)clamp(e, 0.0f, (float)D);
  while (k < D && base + (long)k * d >= v) ++k;
  while (k > 0 && base + (long)(k - 1) * d < v) --k;
  return k;
}

/* The PE's box in fixed point: lo/hi per axis; returns 0 if empty. */
SV_FN int sv_pe_box(__constant sv_view* view, int4 ci, int4 cell, long* lo, long* hi) {
  int c[3] = {cell.x, cell.y, cell.z};
  int i[3] = {ci.x, ci.y, ci.z};
  for (int a = 0; a < 3; ++a) {
    long l = (long)i[a] * c[a];
    long h = min(l + c[a], (long)view->dims[a]);
    if (l >= h) return 0;
    lo[a] = l << SV_FRAC_BITS;
    hi[a] = h << SV_FRAC_BITS;
  }
  return 1;
}

/* Exact [k0, k1) of ray (i, j) in the box; k0 >= k1 when empty. */
SV_FN int2 sv_box_ray(__constant sv_view* view, const long* lo, const long* hi, int i, int j) {
  const int D = view->grid[2];
  int k0 = 0, k1 = D;
  for (int a = 0; a < 3; ++a) {
    const long base = view->origin[a] + (long)i * view->step[a][0] + (long)j * view->step[a][1];
    const long d = view->step[a][2];
    if (d == 0) {
      if (base < lo[a] || base >= hi[a]) return (int2)(0, 0);
    } else if (d > 0) {
      k0 = max(k0, sv_first_at_least(base, d, lo[a], D));
      k1 = min(k1, sv_first_at_least(base, d, hi[a], D));
    } else {
      k0 = max(k0, sv_first_below(base, d, hi[a], D));
      k1 = min(k1, sv_first_below(base, d, lo[a], D));
    }
  }
  return (int2)(k0, k1);
}

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_count(
    __constant sv_view* view, global const sv_rect* cand, global const int4* cidx, int4 cell,
    int pes, global int* counts) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const sv_rect r = cand[p];
  long lo[3], hi[3];
  int n = 0;
  if (sv_pe_box(view, cidx[p], cell, lo, hi)) {
    for (int j = r.j0; j < r.j0 + r.h; ++j)
      for (int i = r.i0; i < r.i0 + r.w; ++i) {
        const int2 k = sv_box_ray(view, lo, hi, i, j);
        n += k.x < k.y;
      }
  }
  counts[p] = n;
}

/* Exclusive prefix sum: seg_offset[0] = 0, seg_offset[p + 1] = sum of counts
 * up to p. One work-item (launched as one group of WGS, the others idle). */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_scan(
    global const int* counts, int pes, global int* seg_offset) {
  if (get_global_id(0) != 0) return;
  int s = 0;
  seg_offset[0] = 0;
  for (int p = 0; p < pes; ++p) {
    s += counts[p];
    seg_offset[p + 1] = s;
  }
}

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_fill(
    __constant sv_view* view, global const sv_rect* cand, global const int4* cidx, int4 cell,
    int pes, global const int* seg_offset, global sv_segment* segments, global sv_rect* rects,
    global int* loads) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const sv_rect r = cand[p];
  long lo[3], hi[3];
  int at = seg_offset[p];
  int load = 0, i0 = INT_MAX, j0 = INT_MAX, i1 = -1, j1 = -1;
  if (sv_pe_box(view, cidx[p], cell, lo, hi)) {
    for (int j = r.j0; j < r.j0 + r.h; ++j)
      for (int i = r.i0; i < r.i0 + r.w; ++i) {
        const int2 k = sv_box_ray(view, lo, hi, i, j);
        if (k.x >= k.y) continue;
        sv_segment g;
        g.i = i;
        g.j = j;
        g.k0 = k.x;
        g.k1 = k.y;
        segments[at++] = g;
        load += k.y - k.x;
        i0 = min(i0, i);
        i1 = max(i1, i);
        j0 = min(j0, j);
        j1 = max(j1, j);
      }
  }
  sv_rect out;
  if (i1 >= 0) {
    out.i0 = i0;
    out.j0 = j0;
    out.w = i1 - i0 + 1;
    out.h = j1 - j0 + 1;
  } else {
    out.i0 = out.j0 = out.w = out.h = 0;
  }
  rects[p] = out;
  loads[p] = load;
}
