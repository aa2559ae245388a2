/* match.cl — which PE resamples which viewing sample (see
 * host/include/simdvol/match.hpp and match_cl.hpp).
 *
 * Work decomposition: one work-item per (PE p, row r) of p's candidate
 * rectangle (global id = p * H + r, H = the largest candidate height), so
 * rows are independent and the segments of one row are contiguous in p's
 * (j, i)-sorted list.
 *
 *   simdvol_match_rows   per (PE, row): the exact segments of the row,
 *                        counted: rowsum = (count, load, first i, last i),
 *                        rowlk = links along x, y, z
 *   simdvol_match_pe     per PE: exclusive prefix of its rows (rowoff),
 *                        totals, load, footprint rect
 *   simdvol_match_scan   one work-item: seg_offset[P + 1], link-list offsets
 *   simdvol_match_fill   per (PE, row): the segments again, written at
 *                        seg_offset[p] + rowoff, with their balance links
 *                        (balance_links) and the per-(PE, axis) link lists
 *
 * A row's columns: the row j cuts the projection of the PE's cell (a
 * zonogon, the intersection of three strips |n_a . (p - centre)| <= h_a)
 * in an interval of i (computed in float with a generous pad, so a superset
 * of the rays that meet the cell). Along the row, each slab bound
 * k = ceil(N / m) (N an affine function of i) is stepped exactly in 64-bit
 * integers (q, r with N = q m - r, 0 <= r < m), started from a double
 * estimate corrected exactly: no division in the column loop.
 *
 * Arguments shared by the kernels:
 *   __constant sv_view* view    the fixed-point viewing map
 *   __constant float* geo       row geometry (host: see match.cpp)
 *   __constant long* stepc      per axis a: m_a = |d_a|, dq_a, dr_a with
 *                               delta_a = dq_a m_a + dr_a, 0 <= dr_a < m_a
 *                               (delta_a = -s_a for d_a > 0, +s_a for
 *                               d_a < 0; s_a = step along i); 9 longs
 *   global const sv_rect* cand  candidate rectangle of each PE
 *   global const int4* cidx     cell index of each PE
 *   int4 cell                   cell extent c
 *   int4 splits                 cells per axis
 *   global const int* pe_of     PE of cell (ix, iy, iz) at (iz sy + iy) sx + ix
 *   int pes, int H
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL EXTENSION cl_khr_fp64 : enable

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

/* Exact [k0, k1) of ray (i, j) in the box; k0 >= k1 when empty (slow path). */
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

/* q = ceil(n / m) and r = q m - n in [0, m) (m > 0), exactly. */
SV_FN long sv_ceil_div(long n, long m, long* r) {
  long q = (long)ceil((double)n / (double)m);
  long rr = q * m - n;
  while (rr < 0) {
    ++q;
    rr += m;
  }
  while (rr >= m) {
    --q;
    rr -= m;
  }
  *r = rr;
  return q;
}

/* The columns [*ia, *ib] of row j that can meet the cell of PE p (a superset;
 * empty when *ia > *ib). */
SV_FN void sv_row_range(__constant float* geo, int4 ci, sv_rect r, int j, int* ia, int* ib) {
  const float cx = geo[0] + ci.x * geo[2] + ci.y * geo[3] + ci.z * geo[4];
  const float cy = geo[1] + ci.x * geo[5] + ci.y * geo[6] + ci.z * geo[7];
  float lo = (float)r.i0, hi = (float)(r.i0 + r.w - 1);
  const float dj = (float)j - cy;
  for (int a = 0; a < 3; ++a) {
    const float ni = geo[8 + a], nj = geo[11 + a], h = geo[14 + a];
    if (ni == 0.0f) continue;
    const float t = nj * dj;
    float x0 = (-h - t) / ni, x1 = (h - t) / ni;
    if (ni < 0.0f) {
      const float x = x0;
      x0 = x1;
      x1 = x;
    }
    lo = max(lo, cx + x0);
    hi = min(hi, cx + x1);
  }
  if (!(lo <= hi)) {
    *ia = 1;
    *ib = 0;
    return;
  }
  *ia = (int)ceil(lo);
  *ib = (int)floor(hi);
}

/* Stepping state of one row. */
typedef struct sv_row_state {
  long qlo[3], rlo[3], qhi[3], rhi[3];
  long base[3]; /* X_a at the current column, k = 0 */
  long m[3], dq[3], dr[3], s[3], d[3];
  long L[3], H[3];
} sv_row_state;

SV_FN void sv_row_init(__constant sv_view* view, __constant long* stepc, const long* lo,
                       const long* hi, int i, int j, sv_row_state* st) {
  for (int a = 0; a < 3; ++a) {
    const long base = view->origin[a] + (long)i * view->step[a][0] + (long)j * view->step[a][1];
    const long d = view->step[a][2];
    st->base[a] = base;
    st->s[a] = view->step[a][0];
    st->d[a] = d;
    st->L[a] = lo[a];
    st->H[a] = hi[a];
    st->m[a] = stepc[3 * a];
    st->dq[a] = stepc[3 * a + 1];
    st->dr[a] = stepc[3 * a + 2];
    if (d == 0) {
      st->qlo[a] = st->qhi[a] = 0;
      st->rlo[a] = st->rhi[a] = 0;
      continue;
    }
    const long nlo = d > 0 ? lo[a] - base : base - hi[a] + 1;
    const long nhi = d > 0 ? hi[a] - base : base - lo[a] + 1;
    st->qlo[a] = sv_ceil_div(nlo, st->m[a], &st->rlo[a]);
    st->qhi[a] = sv_ceil_div(nhi, st->m[a], &st->rhi[a]);
  }
}

/* The exact [k0, k1) of the current column (k0 >= k1 when empty) and the
 * number of axes whose bound is k1 (exit axes) with the last such axis. */
SV_FN void sv_row_eval(const sv_row_state* st, int D, int* k0, int* k1, int* nexit, int* exit_axis) {
  long lo = 0, hi = D;
  for (int a = 0; a < 3; ++a) {
    if (st->d[a] == 0) {
      if (st->base[a] < st->L[a] || st->base[a] >= st->H[a]) hi = 0;
      continue;
    }
    lo = max(lo, st->qlo[a]);
    hi = min(hi, st->qhi[a]);
  }
  *k0 = (int)clamp(lo, (long)0, (long)D);
  *k1 = (int)clamp(hi, (long)0, (long)D);
  int n = 0, e = -1;
  for (int a = 0; a < 3; ++a)
    if (st->d[a] != 0 && st->qhi[a] == hi) {
      ++n;
      e = a;
    }
  *nexit = n;
  *exit_axis = e;
}

SV_FN void sv_row_step(sv_row_state* st) {
  for (int a = 0; a < 3; ++a) {
    st->base[a] += st->s[a];
    if (st->d[a] == 0) continue;
    long r = st->rlo[a] - st->dr[a];
    long c = r < 0;
    st->qlo[a] += st->dq[a] + c;
    st->rlo[a] = r + (c ? st->m[a] : 0);
    r = st->rhi[a] - st->dr[a];
    c = r < 0;
    st->qhi[a] += st->dq[a] + c;
    st->rhi[a] = r + (c ? st->m[a] : 0);
  }
}

/* The face neighbour along the exit axis that owns sample k1 of the column,
 * or -1 (sample outside the volume, or past the neighbour cell). */
SV_FN int sv_link_pe(const sv_row_state* st, int a, int k1, int4 ci, int4 cell, int4 splits,
                     __constant sv_view* view, global const int* pe_of) {
  const long x = st->base[a] + (long)k1 * st->d[a];
  const long f = x >> SV_FRAC_BITS;
  const int c = a == 0 ? cell.x : (a == 1 ? cell.y : cell.z);
  int idx[3] = {ci.x, ci.y, ci.z};
  if (st->d[a] > 0) {
    if (f >= view->dims[a] || f >= (st->H[a] >> SV_FRAC_BITS) + c) return -1;
    idx[a] += 1;
  } else {
    if (f < 0 || f < (st->L[a] >> SV_FRAC_BITS) - c) return -1;
    idx[a] -= 1;
  }
  return pe_of[(idx[2] * splits.y + idx[1]) * splits.x + idx[0]];
}

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_rows(
    __constant sv_view* view, __constant float* geo, __constant long* stepc,
    global const sv_rect* cand, global const int4* cidx, int4 cell, int4 splits,
    global const int* pe_of, int pes, int H, global int4* rowsum, global int4* rowlk) {
  const int g = (int)get_global_id(0);
  const int p = g / H, row = g - p * H;
  if (p >= pes) return;
  const sv_rect r = cand[p];
  int4 sum = (int4)(0, 0, 0, -1);
  int lk[3] = {0, 0, 0};
  long lo[3], hi[3];
  const int4 ci = cidx[p];
  if (row < r.h && sv_pe_box(view, ci, cell, lo, hi)) {
    const int j = r.j0 + row;
    int ia, ib;
    sv_row_range(geo, ci, r, j, &ia, &ib);
    if (ia <= ib) {
      const int D = view->grid[2];
      sv_row_state st;
      sv_row_init(view, stepc, lo, hi, ia, j, &st);
      for (int i = ia; i <= ib; ++i) {
        int k0, k1, ne, ea;
        sv_row_eval(&st, D, &k0, &k1, &ne, &ea);
        if (k0 < k1) {
          if (sum.x == 0) sum.z = i;
          sum.x += 1;
          sum.y += k1 - k0;
          sum.w = i;
          if (k1 < D && ne == 1 && sv_link_pe(&st, ea, k1, ci, cell, splits, view, pe_of) >= 0)
            lk[ea] += 1;
        }
        sv_row_step(&st);
      }
    }
  }
  rowsum[g] = sum;
  rowlk[g] = (int4)(lk[0], lk[1], lk[2], 0);
}

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_pe(
    global const sv_rect* cand, int pes, int H, global const int4* rowsum,
    global const int4* rowlk, global int4* rowoff, global int4* petot, global int* counts,
    global sv_rect* rects, global int* loads) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const int h = cand[p].h;
  int4 acc = (int4)(0, 0, 0, 0);
  int load = 0, i0 = INT_MAX, i1 = -1, j0 = -1, j1 = -1;
  for (int row = 0; row < h; ++row) {
    const int g = p * H + row;
    rowoff[g] = acc;
    const int4 s = rowsum[g];
    const int4 l = rowlk[g];
    acc += (int4)(s.x, l.x, l.y, l.z);
    if (s.x > 0) {
      load += s.y;
      i0 = min(i0, s.z);
      i1 = max(i1, s.w);
      if (j0 < 0) j0 = row;
      j1 = row;
    }
  }
  petot[p] = acc;
  counts[p] = acc.x;
  loads[p] = load;
  sv_rect out;
  if (i1 >= 0) {
    out.i0 = i0;
    out.j0 = cand[p].j0 + j0;
    out.w = i1 - i0 + 1;
    out.h = j1 - j0 + 1;
  } else {
    out.i0 = out.j0 = out.w = out.h = 0;
  }
  rects[p] = out;
}

/* seg_offset[p] = segments before PE p; lofs[p].a = start of PE p's list of
 * links along a (the lists of axis x, then y, then z, each PE-major). One
 * work-item. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_scan(
    global const int4* petot, int pes, global int* seg_offset, global int4* lofs) {
  if (get_global_id(0) != 0) return;
  int4 s = (int4)(0, 0, 0, 0);
  for (int p = 0; p < pes; ++p) s += petot[p];
  int4 at = (int4)(0, 0, s.y, s.y + s.z);
  for (int p = 0; p < pes; ++p) {
    seg_offset[p] = at.x;
    lofs[p] = at;
    at += petot[p];
  }
  seg_offset[pes] = at.x;
  lofs[pes] = at;
}

/* Index of the segment of ray (i, j) in PE q (which has one). */
SV_FN int sv_segment_index(__constant sv_view* view, global const sv_rect* cand,
                           global const int4* cidx, int4 cell, int H,
                           global const int4* rowsum, global const int4* rowoff,
                           global const int* seg_offset, int q, int i, int j) {
  const int g = q * H + (j - cand[q].j0);
  const int4 s = rowsum[g];
  int n = 0;
  if (s.x == s.w - s.z + 1) {
    n = i - s.z;
  } else { /* the row has holes: count its segments left of i */
    long lo[3], hi[3];
    sv_pe_box(view, cidx[q], cell, lo, hi);
    for (int c = s.z; c < i; ++c) {
      const int2 k = sv_box_ray(view, lo, hi, c, j);
      n += k.x < k.y;
    }
  }
  return seg_offset[q] + rowoff[g].x + n;
}

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_fill(
    __constant sv_view* view, __constant float* geo, __constant long* stepc,
    global const sv_rect* cand, global const int4* cidx, int4 cell, int4 splits,
    global const int* pe_of, int pes, int H, global const int4* rowsum,
    global const int4* rowoff, global const int* seg_offset, global const int4* lofs,
    global sv_segment* segments, global int* links, global int2* llist) {
  const int g = (int)get_global_id(0);
  const int p = g / H, row = g - p * H;
  if (p >= pes) return;
  const int4 sum = rowsum[g];
  if (sum.x == 0) return;
  const sv_rect r = cand[p];
  long lo[3], hi[3];
  const int4 ci = cidx[p];
  sv_pe_box(view, ci, cell, lo, hi);
  const int j = r.j0 + row;
  const int4 ro = rowoff[g];
  int at = seg_offset[p] + ro.x;
  const int4 lb = lofs[p];
  int la[3] = {lb.y + ro.y, lb.z + ro.z, lb.w + ro.w};
  const int D = view->grid[2];
  sv_row_state st;
  sv_row_init(view, stepc, lo, hi, sum.z, j, &st);
  for (int i = sum.z; i <= sum.w; ++i) {
    int k0, k1, ne, ea;
    sv_row_eval(&st, D, &k0, &k1, &ne, &ea);
    if (k0 < k1) {
      sv_segment sg;
      sg.i = i;
      sg.j = j;
      sg.k0 = k0;
      sg.k1 = k1;
      segments[at] = sg;
      int link = -1;
      if (k1 < D && ne == 1) {
        const int q = sv_link_pe(&st, ea, k1, ci, cell, splits, view, pe_of);
        if (q >= 0) {
          const int t =
              sv_segment_index(view, cand, cidx, cell, H, rowsum, rowoff, seg_offset, q, i, j);
          link = t * 4 + ea;
          llist[la[ea]++] = (int2)(at, t);
        }
      }
      links[at] = link;
      ++at;
    }
    sv_row_step(&st);
  }
}
