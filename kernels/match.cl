/* match.cl — which PE resamples which viewing sample (see
 * host/include/simdvol/match.hpp and match_cl.hpp).
 *
 * Work decomposition: rows (PE p, row r) of p's candidate rectangle at
 * g = p * H + r, H = the largest candidate height rounded up to a multiple
 * of 8, so rows are independent and the segments of one row are contiguous
 * in p's (j, i)-sorted list. The row kernels take 8 rows of one PE per
 * work-item (see "8 rows per work-item" below).
 *
 *   simdvol_match_rows   per (PE, row): the exact segments of the row,
 *                        counted: rowsum = (count, load, first i, last i),
 *                        rowlk = links along x, y, z
 *   simdvol_match_pe     per PE: exclusive prefix of its rows (rowoff),
 *                        totals, load, footprint rect
 *   simdvol_match_scan   one work-item: seg_offset[P + 1], link-list offsets
 *                        (and, where `save`, each column's k0, k1 and
 *                        link axis for the fill: sv_kpack8)
 *   simdvol_match_fill   per (PE, row): the segments again (from the rows'
 *                        saved columns, or stepped again), written at
 *                        seg_offset[p] + rowoff, with the per-(PE, axis)
 *                        lists of their balance links (balance_links) and,
 *                        where fill_bounds, their (k0, k1) as the balance's
 *                        16-bit bounds. A link entry is (segment, linked
 *                        segment) as int2, or, where `narrow` (every PE's
 *                        candidate rays <= 65536: match_cl.hpp), one uint:
 *                        the segment's index within its PE's segments in
 *                        the low 16 bits, the linked one's within its PE's
 *                        in the high 16; lbase[p] = (the first segment of
 *                        p's link target along x, y, z, or -1; p's own)
 *   simdvol_match_active per PE: active[p] = some brick with reach meets
 *                        the PE's cell (empty-space skipping, below)
 *
 *   simdvol_match_rows_nolinks, simdvol_match_fill_nolinks: the same
 *                        without the links (no balancing to follow): rowlk
 *                        0, llist and bounds not written; the segments,
 *                        rects and loads are the same.
 * The links were about a third of the matching's time (SIMDVOL_CL_OPTIONS
 * switch, `simdvol render --view 20,35,10 --frames 6 --step 0
 * --balance-sweeps 0 --times`, alternated twice: the 256^3 phantom
 * 16.6-22.4 -> 9.8-11.6 ms, brainsmall 6.8-7.1 -> 4.5 ms). A run-time flag
 * instead gained nothing: the link test inside sv_row8_eval ran anyway.
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
 *   global const uchar* active  per PE: 0 = the PE takes no part (no
 *                               segments, no link into it; match.hpp:
 *                               Matching::active); all 1 for the plain
 *                               matching
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

/* Exact [k0, k1) of ray (i, j) in the box; k0 >= k1 when empty (the fill's
 * cursor over rows with holes). */
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

/* The columns [ia[l], ib[l]] of the rows j0 + l, l = 0 .. 7, that can meet
 * the cell of PE p (a superset; empty when ia[l] > ib[l], and for l >= n),
 * in float8 lanes. It replaced a scalar function of the same arithmetic
 * called per row: its 48 divisions per work-item were much of
 * simdvol_match_rows' set-up (simdvol-bench-options --frames 12, the
 * 256^3 phantom at (20, 35, 10), two alternations: match 6.80 / 6.79 ->
 * 6.12 / 6.13 ms, 2-core Intel Xeon, 2026-12-05; the same images). */
SV_FN void sv_row_range8(__constant float* geo, int4 ci, sv_rect r, int j0, int n, int* ia,
                         int* ib) {
  const float cx = geo[0] + ci.x * geo[2] + ci.y * geo[3] + ci.z * geo[4];
  const float cy = geo[1] + ci.x * geo[5] + ci.y * geo[6] + ci.z * geo[7];
  const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
  float8 lo = (float8)((float)r.i0), hi = (float8)((float)(r.i0 + r.w - 1));
  const float8 dj = convert_float8((int8)(j0) + lane) - cy;
  for (int a = 0; a < 3; ++a) {
    const float ni = geo[8 + a], nj = geo[11 + a], h = geo[14 + a];
    if (ni == 0.0f) continue;
    const float8 t = nj * dj;
    float8 x0 = (-h - t) / ni, x1 = (h - t) / ni;
    if (ni < 0.0f) {
      const float8 x = x0;
      x0 = x1;
      x1 = x;
    }
    lo = max(lo, cx + x0);
    hi = min(hi, cx + x1);
  }
  const int8 ok = (lo <= hi) & (lane < (int8)(n));
  vstore8(select((int8)(1), convert_int8(ceil(lo)), ok), 0, ia);
  vstore8(select((int8)(0), convert_int8(floor(hi)), ok), 0, ib);
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

__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_pe(
    global const sv_rect* cand, global const uchar* active, int pes, int H,
    global const int4* rowsum, global const int4* rowlk, global int4* rowoff, global int4* petot,
    global int* counts, global sv_rect* rects, global int* loads) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  /* An inactive PE's rows are not written (simdvol_match_rows): it has no
   * segments, and no fill or zero fill reads its row offsets. Its rows
   * written as zeros and walked here, as before: scripts/bench-ab, match
   * 5.78 -> 5.36 ms (0.926, 6 pairs) on the 256^3 phantom, brainsmall 2.25
   * -> 2.05 (0.902, 4 pairs) (2-core Intel Xeon, 2026-12-05). */
  const int h = active[p] ? cand[p].h : 0;
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

/* seg_offset[p] = segments before PE p; lofs[p] = (seg_offset[p], the start
 * of PE p's list of links along x, along y, along z): component a + 1 for
 * axis a (the lists of axis x, then y, then z, each PE-major). One
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

/* ---- 8 rows per work-item: simdvol_match_rows and simdvol_match_fill ----
 * Work-item w takes the rows g = 8 w ... 8 w + 7 (H a multiple of 8, so the
 * 8 rows belong to one PE) as the lanes of int8/long8 values. PoCL ran the
 * earlier one-row-per-work-item kernels as scalar code (a column loop of
 * varying trip count per work-item); here the lanes step their columns
 * together. Every lane starts its exact stepping at the group's first
 * column i0 (the recurrence holds from any column) and counts only the
 * columns of its own range. Integer arithmetic: the results equal
 * match_reference's exactly (tests/cl/test_match_cl.cpp).
 * simdvol-bench-match, 256^3, 8192 PEs, 30 / 45 deg: rows 43-47 -> 17-20
 * ms, fill 45-56 -> 34-49 ms (against the one-row kernels, alternated). */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif

typedef struct sv_row8 {
  long8 qlo[3], rlo[3], qhi[3], rhi[3], base[3];
} sv_row8;

/* Lanes with on[l] start at column i0 of row j[l] = j[0] + l (the 8 rows
 * are consecutive); the others hold zeros. Row j[0] is set up exactly
 * (sv_row_init), and each next row by one exact step along j, as
 * sv_row8_step steps along i: moving to row j + 1 adds delta = -+s_j
 * (s_j = step[a][1], the sign as for i) to N, so with delta = dq m + dr,
 * 0 <= dr < m, q grows by dq (+1 where r - dr < 0) and r becomes r - dr
 * (+ m). The same values as sv_row_init for each row, without its
 * double-precision divisions and correction loops per lane and axis. */
SV_FN void sv_row8_init(__constant sv_view* view, __constant long* stepc, const long* lo,
                        const long* hi, int i0, const int* j, const int* on, sv_row8* st) {
  long v[5][3][8];
  sv_row_state t;
  sv_row_init(view, stepc, lo, hi, i0, j[0], &t);
  for (int a = 0; a < 3; ++a) {
    const long d = view->step[a][2], sj = view->step[a][1], m = stepc[3 * a];
    long ql = t.qlo[a], rl = t.rlo[a], qh = t.qhi[a], rh = t.rhi[a], b = t.base[a];
    long dq = 0, dr = 0;
    if (d != 0) {
      const long delta = d > 0 ? -sj : sj;
      dq = delta / m;
      if (delta - dq * m < 0) --dq; /* floor: m > 0 */
      dr = delta - dq * m;
    }
    for (int l = 0; l < 8; ++l) {
      v[0][a][l] = on[l] ? ql : 0;
      v[1][a][l] = on[l] ? rl : 0;
      v[2][a][l] = on[l] ? qh : 0;
      v[3][a][l] = on[l] ? rh : 0;
      v[4][a][l] = on[l] ? b : 0;
      b += sj;
      if (d != 0) {
        long r = rl - dr;
        ql += dq + (r < 0 ? 1 : 0);
        rl = r < 0 ? r + m : r;
        r = rh - dr;
        qh += dq + (r < 0 ? 1 : 0);
        rh = r < 0 ? r + m : r;
      }
    }
  }
  for (int a = 0; a < 3; ++a) {
    st->qlo[a] = vload8(0, v[0][a]);
    st->rlo[a] = vload8(0, v[1][a]);
    st->qhi[a] = vload8(0, v[2][a]);
    st->rhi[a] = vload8(0, v[3][a]);
    st->base[a] = vload8(0, v[4][a]);
  }
}

/* One column of the 8 lanes: k0, k1 = the largest entry bound and the
 * smallest exit bound over the axes, clamped to [0, D]; act = lanes with a
 * segment inside [ia, ib]; lnk = those whose segment has a balance link
 * (one exit axis, k1 < D, the neighbour cell inside the volume), exit axis
 * in ea. */
SV_FN void sv_row8_eval(const sv_row8* st, __constant sv_view* view, const long* L, const long* Hb,
                        int4 cell, int i, int8 ia, int8 ib, int8* k0, int8* k1, int8* act,
                        int8* lnk, int8* ea) {
  const int D = view->grid[2];
  long8 lo = (long8)(0), hi = (long8)(D);
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    if (view->step[a][2] == 0) {
      hi = select(hi, (long8)(0), (st->base[a] < L[a]) | (st->base[a] >= Hb[a]));
      continue;
    }
    lo = max(lo, st->qlo[a]);
    hi = min(hi, st->qhi[a]);
  }
  *k0 = convert_int8(clamp(lo, (long8)(0), (long8)(D)));
  *k1 = convert_int8(clamp(hi, (long8)(0), (long8)(D)));
  *act = (ia <= (int8)(i)) & (ib >= (int8)(i)) & (*k0 < *k1);
  long8 n = (long8)(0), ok = (long8)(0);
  int8 e = (int8)(-1);
  const int c[3] = {cell.x, cell.y, cell.z};
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const long d = view->step[a][2];
    if (d == 0) continue;
    const long8 ex = st->qhi[a] == hi;
    n -= ex;
    e = select(e, (int8)(a), convert_int8(ex));
    /* A link needs the sample k1 inside the volume and in the next cell
     * along a (not past it). Where it counts (a the only exit axis, a
     * segment, k1 < D) k1 = qhi[a], at Hb[a] + rhi[a] along a for d > 0
     * and at L[a] - 1 - rhi[a] for d < 0 (sv_row_init: rhi = qhi m - nhi),
     * so with the box bounds multiples of SV_ONE the floor tests come down
     * to one compare of rhi with a bound of the PE: no multiply or
     * arithmetic shift of 64-bit lanes per column (AVX2 has neither; their
     * emulation was most of the link test). simdvol_match_rows went from
     * 6,089 to 5,451 instructions; the match stage of `simdvol render
     * --view 20,35,10 --frames 6 --step 0 --times` from 8.3-10.0 to
     * 7.5-8.3 ms on brainsmall and 21.0-21.9 to 18.4-20.9 ms on the 256^3
     * phantom (three alternations each). */
    const long cb = (long)c[a] << SV_FRAC_BITS;
    const long bound =
        d > 0 ? min(cb, ((long)view->dims[a] << SV_FRAC_BITS) - Hb[a]) : min(cb, L[a]);
    ok = select(ok, st->rhi[a] < (long8)(bound), ex);
  }
  *lnk = *act & (*k1 < (int8)(D)) & convert_int8((n == (long8)(1)) & ok);
  *ea = e;
}

SV_FN void sv_row8_step(sv_row8* st, __constant sv_view* view, __constant long* stepc) {
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    st->base[a] += view->step[a][0];
    if (view->step[a][2] == 0) continue;
    const long m = stepc[3 * a], dq = stepc[3 * a + 1], dr = stepc[3 * a + 2];
    long8 r = st->rlo[a] - dr;
    long8 c = r < (long8)(0); /* -1 where r < 0 */
    st->qlo[a] += dq - c;
    st->rlo[a] = r + (c & (long8)(m));
    r = st->rhi[a] - dr;
    c = r < (long8)(0);
    st->qhi[a] += dq - c;
    st->rhi[a] = r + (c & (long8)(m));
  }
}

/* The face neighbour along each axis that the rays pass into (the sign of
 * the depth step), if it exists and is active: nq[a] = its PE, else -1. */
SV_FN void sv_link_targets(__constant sv_view* view, int4 ci, int4 splits, global const int* pe_of,
                           global const uchar* active, int* nq) {
  for (int e = 0; e < 3; ++e) {
    int idx[3] = {ci.x, ci.y, ci.z};
    const int sa = e == 0 ? splits.x : (e == 1 ? splits.y : splits.z);
    idx[e] += view->step[e][2] > 0 ? 1 : -1;
    const int q =
        idx[e] >= 0 && idx[e] < sa ? pe_of[(idx[2] * splits.y + idx[1]) * splits.x + idx[0]] : -1;
    nq[e] = q >= 0 && active[q] ? q : -1;
  }
}

/* The columns' results saved by simdvol_match_rows for simdvol_match_fill
 * (save / saved, where the grid's depth D <= 32767): per (work-item, column
 * i, lane l) one uint at koff[p] + row0 w + 8 (i - i0) + l, w and i0 the
 * PE's candidate width and first column (koff[p]: the sum of ceil8(h) w
 * over the PEs before p), bits 0-14 k0, 15-29 k1 (0, 0 where the lane has
 * no segment), 30-31 the link's exit axis (3: no link). So the fill reads
 * them instead of stepping the columns again, and a row at a time (its
 * segments, bounds and links consecutive stores). 2-core Intel Xeon,
 * 2026-12-05, the 256^3 phantom at (20, 35, 10), `simdvol render --frames 8
 * --step 0 --trace`, frames 2-7, alternated twice with SIMDVOL_MATCH_SAVED=0
 * (stepped): match_fill 5.56 / 5.64 -> 2.90 / 3.14 ms, match_rows 2.87 /
 * 3.02 -> 2.93 / 3.12; without links 2.87 / 3.00 -> 1.73 / 1.78 ms. */
SV_FN uint8 sv_kpack8(int8 k0, int8 k1, int8 act, int8 lnk, int8 ea, const int make_links) {
  const uint8 e = make_links ? as_uint8(select((int8)(3), ea, lnk)) : (uint8)(3);
  return select((uint8)(3u << 30), as_uint8(k0) | (as_uint8(k1) << 15) | (e << 30), as_uint8(act));
}

/* The kernels' bodies take make_links as a constant (always inlined), so
 * that the _nolinks kernels leave the link test of sv_row8_eval out
 * altogether. */
#define SV_MATCH_FN static inline __attribute__((always_inline))

/* simdvol_match_fill prefetches its links' neighbour rows (1; 0: not). */
#ifndef SV_FILL_PF
#define SV_FILL_PF 1
#endif
/* ... and, at each store, the line SV_FILL_WPF x 16 bytes ahead in the
 * stream it writes (segments, bounds, link list; 0: not): a work-item
 * writes 8 rows' segments, bounds and links, up to 40 streams per core,
 * more than the hardware's stream prefetch follows. 2-core Zen 3 EPYC,
 * simdvol-bench-options --frames 16, the match stage, 0 -> 32, alternated:
 * the 256^3 phantom at (20, 35, 10) 25.1 / 23.8 -> 22.7 / 21.8 ms, at (0,
 * 45, 0) 19.8 / 17.9 / 16.7 / 19.2 -> 18.1 / 18.1 / 14.6 / 17.9, ch2 25.7 /
 * 27.7 -> 22.8 / 23.6; 16 in between. A hint: no result changes. */
#ifndef SV_FILL_WPF
#define SV_FILL_WPF 32
#endif

SV_MATCH_FN void sv_match_rows(__constant sv_view* view, __constant float* geo,
                               __constant long* stepc, global const sv_rect* cand,
                               global const int4* cidx, int4 cell, int4 splits,
                               global const int* pe_of, global const uchar* active, int pes, int H,
                               global int4* rowsum, global int4* rowlk, global uint* kscr,
                               global const int* koff, const int save, const int make_links) {
  const int g0 = (int)get_global_id(0) * 8;
  const int p = g0 / H, row0 = g0 - p * H;
  if (p >= pes) return;
  /* An inactive PE (more than half the PEs at 8,192 with empty space left
   * out) has no segments: its rows are left as they are, unwritten, and
   * simdvol_match_pe and the fill take the mask for them (no row of such a
   * PE is read: no link goes into it, and its footprint is empty).
   * Skipping its loop's set-up, simdvol-bench-options --frames 12, two
   * alternations with this as a define: match 9.23 / 9.32 -> 8.99 / 9.15
   * ms on the 256^3 phantom, 3.43 / 3.39 -> 3.25 / 3.26 on brainsmall (a
   * 2-core Intel Xeon, 2026-12-05); leaving its rows unwritten too: see
   * simdvol_match_pe. */
  if (!active[p]) return;
  const sv_rect r = cand[p];
  const int4 ci = cidx[p];
  long lo[3], hi[3];
  const int box = active[p] && sv_pe_box(view, ci, cell, lo, hi);
  int qa[3]; /* a link along axis a needs an active neighbour (and links made) */
  sv_link_targets(view, ci, splits, pe_of, active, qa);
  if (!make_links) qa[0] = qa[1] = qa[2] = -1;
  int ia[8], ib[8], jj[8], on[8];
  int i0 = INT_MAX, i1 = INT_MIN;
  sv_row_range8(geo, ci, r, r.j0 + row0, box ? r.h - row0 : 0, ia, ib);
  for (int l = 0; l < 8; ++l) {
    jj[l] = r.j0 + row0 + l;
    on[l] = ia[l] <= ib[l];
    if (on[l]) {
      i0 = min(i0, ia[l]);
      i1 = max(i1, ib[l]);
    }
  }
  int8 cnt = (int8)(0), load = (int8)(0), first = (int8)(0), last = (int8)(-1);
  int8 lk[3] = {(int8)(0), (int8)(0), (int8)(0)};
  if (i0 <= i1) {
    sv_row8 st;
    sv_row8_init(view, stepc, lo, hi, i0, jj, on, &st);
    const int8 IA = vload8(0, ia), IB = vload8(0, ib);
    const int kb = save ? koff[p] + row0 * r.w : 0;
    for (int i = i0; i <= i1; ++i) {
      int8 k0, k1, act, lnk, ea;
      sv_row8_eval(&st, view, lo, hi, cell, i, IA, IB, &k0, &k1, &act, &lnk, &ea);
      if (save) vstore8(sv_kpack8(k0, k1, act, lnk, ea, make_links), 0, kscr + kb + 8 * (i - r.i0));
      first = select(first, (int8)(i), act & (cnt == (int8)(0)));
      cnt -= act;
      load += select((int8)(0), k1 - k0, act);
      last = select(last, (int8)(i), act);
#pragma unroll
      for (int a = 0; a < 3; ++a)
        if (make_links && qa[a] >= 0) lk[a] -= lnk & (ea == (int8)(a));
      sv_row8_step(&st, view, stepc);
    }
  }
  int c[8], s[8], f[8], w[8], x[8], y[8], z[8];
  vstore8(cnt, 0, c);
  vstore8(load, 0, s);
  vstore8(first, 0, f);
  vstore8(last, 0, w);
  vstore8(lk[0], 0, x);
  vstore8(lk[1], 0, y);
  vstore8(lk[2], 0, z);
  for (int l = 0; l < 8; ++l) {
    rowsum[g0 + l] = (int4)(c[l], s[l], f[l], w[l]);
    rowlk[g0 + l] = (int4)(x[l], y[l], z[l], 0);
  }
}

/* Row j of the face neighbour q, as the fill's links take it: (its first
 * segment's index b, that segment's column, whether the row has holes). */
SV_FN_INLINE int4 sv_fill_row(global const sv_rect* cand, global const int4* rowsum,
                              global const int4* rowoff, global const int* seg_offset, const int H,
                              const int q, const int j) {
  const int gq = q * H + (j - cand[q].j0);
  const int4 s = rowsum[gq];
  return (int4)(seg_offset[q] + rowoff[gq].x, s.z, s.x != s.w - s.z + 1, 0);
}

SV_MATCH_FN void sv_match_fill(__constant sv_view* view, __constant float* geo,
                               __constant long* stepc, global const sv_rect* cand,
                               global const int4* cidx, int4 cell, int4 splits,
                               global const int* pe_of, global const uchar* active, int pes, int H,
                               global const int4* rowsum, global const int4* rowlk,
                               global const int4* rowoff, global const int* seg_offset,
                               global const int4* lofs, global sv_segment* segments,
                               global short2* bounds, const int fill_bounds, global int2* llist,
                               const int narrow, global int4* lbase, global const uint* kscr,
                               global const int* koff, const int saved, const int make_links) {
  const int g0 = (int)get_global_id(0) * 8;
  const int p = g0 / H, row0 = g0 - p * H;
  if (p >= pes) return;
  const sv_rect r = cand[p];
  const int4 ci = cidx[p];
  long lo[3], hi[3];
  sv_pe_box(view, ci, cell, lo, hi);
  const int4 lb = lofs[p];
  const int base = seg_offset[p];
  int ia[8], ib[8], jj[8], on[8], at[8], la[3][8];
  int i0 = INT_MAX, i1 = INT_MIN;
  const int live = active[p]; /* (an inactive PE's rows are not written) */
  for (int l = 0; l < 8; ++l) {
    const int4 sum = live ? rowsum[g0 + l] : (int4)(0, 0, 0, -1);
    const int4 ro = live ? rowoff[g0 + l] : (int4)(0);
    jj[l] = r.j0 + row0 + l;
    on[l] = sum.x > 0;
    ia[l] = on[l] ? sum.z : 1;
    ib[l] = on[l] ? sum.w : 0;
    at[l] = base + ro.x;
    la[0][l] = lb.y + ro.y;
    la[1][l] = lb.z + ro.z;
    la[2][l] = lb.w + ro.w;
    if (on[l]) {
      i0 = min(i0, ia[l]);
      i1 = max(i1, ib[l]);
    }
  }
  /* The link targets; with narrow links (16-bit indices within each PE's
   * segments, below), their first segments, which the PE's first
   * work-item also leaves in lbase[p] for DeviceMatching::read_links (so
   * that one runs on even where its rows are empty). */
  const int writes_base = make_links && narrow && row0 == 0;
  if (i0 > i1 && !writes_base) return;
  int nq[3], qb[3];
  sv_link_targets(view, ci, splits, pe_of, active, nq);
  if (!make_links) nq[0] = nq[1] = nq[2] = -1;
  for (int e = 0; e < 3; ++e) qb[e] = narrow && nq[e] >= 0 ? seg_offset[nq[e]] : -1;
  if (writes_base) lbase[p] = (int4)(qb[0], qb[1], qb[2], base);
  if (i0 > i1) return;
#if SV_FILL_PF
  /* A lane's first link along e reads the neighbour's row sums and offsets
   * (rows j of PE nq[e], 16 bytes each, far from this PE's): prefetched
   * here, the column loop runs before the first link needs them. */
  for (int e = 0; e < 3; ++e)
    if (nq[e] >= 0) {
      const int q = nq[e], gq = q * H + (jj[0] - cand[q].j0);
      SV_PREFETCH(rowsum + gq);
      SV_PREFETCH(rowsum + gq + 7);
      SV_PREFETCH(rowoff + gq);
      SV_PREFETCH(rowoff + gq + 7);
      SV_PREFETCH(seg_offset + q);
    }
#endif
  const int kb = saved ? koff[p] + row0 * r.w : 0;
  /* The stores and the holes' count, the same in both fills below (macros:
   * as functions they cost the saved fill 3-4 %, scripts/bench-ab).
   * SV_FILL_STORE: segment (I, J, KA, KZ) at position A, with its 16-bit
   * bounds beside it where the balance asks for them (fill_bounds: its pack
   * would otherwise read the segments back). SV_FILL_LINK: a link entry at
   * LP of its list, (A, T) or, narrow, the two indices within the PEs'
   * segments (A - base, T - QB). Each store with the line SV_FILL_WPF
   * entries ahead prefetched.
   * A link along axis e goes to the face neighbour nq[e] (one per axis for
   * the whole work-item), into the same row j (sv_fill_row: its first
   * segment b, at column `first`). Where that row's segments are
   * contiguous (no holes) column i's is b - first + i; else b + n, n its
   * segments in the columns before i, which SV_FILL_HOLES counts with
   * sv_box_ray (qlo, qhi: the neighbour's cell) from a cursor (HC, HN: HN
   * segments in the columns before HC) that grows with the columns, so that
   * a row's holes are counted once, not from its start at every link. */
#define SV_FILL_STORE(A, I, J, KA, KZ)                                             \
  {                                                                                \
    sv_segment sg;                                                                 \
    sg.i = (I);                                                                    \
    sg.j = (J);                                                                    \
    sg.k0 = (KA);                                                                  \
    sg.k1 = (KZ);                                                                  \
    segments[A] = sg;                                                              \
    if (SV_FILL_WPF > 0) {                                                         \
      SV_PREFETCH(segments + (A) + SV_FILL_WPF);                                   \
      if (make_links && fill_bounds) SV_PREFETCH(bounds + (A) + 4 * SV_FILL_WPF);  \
    }                                                                              \
    if (make_links && fill_bounds) bounds[A] = (short2)((short)(KA), (short)(KZ)); \
  }
#define SV_FILL_LINK(LP, A, T, QB)                                                    \
  {                                                                                   \
    if (narrow) {                                                                     \
      if (SV_FILL_WPF > 0) SV_PREFETCH((global uint*)llist + (LP) + 4 * SV_FILL_WPF); \
      ((global uint*)llist)[LP] = (uint)((A)-base) | ((uint)((T) - (QB)) << 16);      \
    } else {                                                                          \
      if (SV_FILL_WPF > 0) SV_PREFETCH(llist + (LP) + 2 * SV_FILL_WPF);               \
      llist[LP] = (int2)((A), (T));                                                   \
    }                                                                                 \
  }
#define SV_FILL_HOLES(HC, HN, I, J)                        \
  for (; (HC) < (I); ++(HC)) {                             \
    const int2 k_ = sv_box_ray(view, qlo, qhi, (HC), (J)); \
    (HN) += k_.x < k_.y;                                   \
  }
  if (saved) {
    /* From the rows' saved columns, a row at a time: its segments and
     * bounds, then its links along each axis that has some (rowlk), each in
     * a loop over the row's columns with its state in registers (the
     * columns' words stay in the L1); the stores of each loop consecutive.
     * scripts/bench-ab against one loop with the links' state in arrays
     * (the stepping fill's): match 5.87 -> 5.66 ms (0.964, 6 pairs) on the
     * 256^3 phantom, ch2 6.08 -> 5.83 (0.968, 4 pairs). Non-temporal
     * segment stores (-DSV_FILL_NT, a probe): 5.61 -> 5.80 ms, not kept. */
    for (int l = 0; l < 8; ++l) {
      if (!on[l]) continue;
      const int j = jj[l], c0 = ia[l], n = ib[l] - ia[l] + 1;
      global const uint* kc = kscr + kb + l + 8 * (c0 - r.i0);
      int a = at[l];
      for (int c = 0; c < n; ++c) {
        const uint v = kc[8 * c];
        const int ka = (int)(v & 0x7fffu), kz = (int)((v >> 15) & 0x7fffu);
        if (ka >= kz) continue;
        SV_FILL_STORE(a, c0 + c, j, ka, kz)
        ++a;
      }
      if (!make_links) continue;
      const int4 lk = rowlk[g0 + l];
      for (int e = 0; e < 3; ++e) {
        const int q = nq[e];
        if (q < 0 || (e == 0 ? lk.x : e == 1 ? lk.y : lk.z) == 0) continue;
        const int4 nr = sv_fill_row(cand, rowsum, rowoff, seg_offset, H, q, j);
        long qlo[3], qhi[3];
        if (nr.z) sv_pe_box(view, cidx[q], cell, qlo, qhi);
        int hc = nr.y, hn = 0, at2 = at[l], lp = la[e][l];
        for (int c = 0; c < n; ++c) {
          const uint v = kc[8 * c];
          if ((int)(v & 0x7fffu) >= (int)((v >> 15) & 0x7fffu)) continue;
          if ((int)(v >> 30) == e) {
            const int i = c0 + c;
            int t = nr.x - nr.y + i;
            if (nr.z) {
              SV_FILL_HOLES(hc, hn, i, j)
              t = nr.x + hn;
            }
            SV_FILL_LINK(lp, at2, t, qb[e])
            ++lp;
          }
          ++at2;
        }
      }
    }
  } else {
    /* The per-(axis, lane) link state, set at the lane's first link along
     * the axis (hb = SV_UNSET before): the neighbour row's first segment hb
     * at column hf, whether it has holes, and SV_FILL_HOLES' cursor. */
#define SV_UNSET INT_MAX
    int hb[3][8], hf[3][8], hh[3][8], hc[3][8], hn[3][8];
    for (int e = 0; e < 3; ++e)
      for (int l = 0; l < 8; ++l) hb[e][l] = SV_UNSET;
    sv_row8 st;
    sv_row8_init(view, stepc, lo, hi, i0, jj, on, &st);
    const int8 IA = vload8(0, ia), IB = vload8(0, ib);
    for (int i = i0; i <= i1; ++i) {
      int8 k0, k1, act, lnk, ea;
      sv_row8_eval(&st, view, lo, hi, cell, i, IA, IB, &k0, &k1, &act, &lnk, &ea);
      if (any(act)) {
        int K0[8], K1[8], A[8], LK[8], E[8];
        vstore8(k0, 0, K0);
        vstore8(k1, 0, K1);
        vstore8(act, 0, A);
        vstore8(lnk, 0, LK);
        vstore8(ea, 0, E);
        for (int l = 0; l < 8; ++l) {
          if (!A[l]) continue;
          SV_FILL_STORE(at[l], i, jj[l], K0[l], K1[l])
          if (make_links && LK[l] && nq[E[l]] >= 0) {
            const int e = E[l], q = nq[e];
            if (hb[e][l] == SV_UNSET) {
              const int4 nr = sv_fill_row(cand, rowsum, rowoff, seg_offset, H, q, jj[l]);
              hb[e][l] = nr.x;
              hf[e][l] = nr.y;
              hh[e][l] = nr.z;
              hc[e][l] = nr.y;
              hn[e][l] = 0;
            }
            long qlo[3], qhi[3];
            if (hh[e][l]) sv_pe_box(view, cidx[q], cell, qlo, qhi);
            int t = hb[e][l] - hf[e][l] + i;
            if (hh[e][l]) {
              SV_FILL_HOLES(hc[e][l], hn[e][l], i, jj[l])
              t = hb[e][l] + hn[e][l];
            }
            SV_FILL_LINK(la[e][l], at[l], t, qb[e])
            ++la[e][l];
          }
          ++at[l];
        }
      }
      sv_row8_step(&st, view, stepc);
    }
  }
#undef SV_UNSET
#undef SV_FILL_STORE
#undef SV_FILL_LINK
#undef SV_FILL_HOLES
}

#define SV_MATCH_ROWS_KERNEL(NAME, LINKS)                                                       \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void NAME(                          \
      __constant sv_view* view, __constant float* geo, __constant long* stepc,                  \
      global const sv_rect* cand, global const int4* cidx, int4 cell, int4 splits,              \
      global const int* pe_of, global const uchar* active, int pes, int H, global int4* rowsum, \
      global int4* rowlk, global uint* kscr, global const int* koff, int save) {                \
    sv_match_rows(view, geo, stepc, cand, cidx, cell, splits, pe_of, active, pes, H, rowsum,    \
                  rowlk, kscr, koff, save, LINKS);                                              \
  }
SV_MATCH_ROWS_KERNEL(simdvol_match_rows, 1)
SV_MATCH_ROWS_KERNEL(simdvol_match_rows_nolinks, 0)

#define SV_MATCH_FILL_KERNEL(NAME, LINKS)                                                         \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void NAME(                            \
      __constant sv_view* view, __constant float* geo, __constant long* stepc,                    \
      global const sv_rect* cand, global const int4* cidx, int4 cell, int4 splits,                \
      global const int* pe_of, global const uchar* active, int pes, int H,                        \
      global const int4* rowsum, global const int4* rowlk, global const int4* rowoff,             \
      global const int* seg_offset, global const int4* lofs, global sv_segment* segments,         \
      global short2* bounds, int fill_bounds, global int2* llist, int narrow, global int4* lbase, \
      global const uint* kscr, global const int* koff, int saved) {                               \
    sv_match_fill(view, geo, stepc, cand, cidx, cell, splits, pe_of, active, pes, H, rowsum,      \
                  rowlk, rowoff, seg_offset, lofs, segments, bounds, fill_bounds, llist, narrow,  \
                  lbase, kscr, koff, saved, LINKS);                                               \
  }
SV_MATCH_FILL_KERNEL(simdvol_match_fill, 1)
SV_MATCH_FILL_KERNEL(simdvol_match_fill_nolinks, 0)

/* ---- simdvol_match_active: the PEs that take part (empty-space skipping) ----
 * One work-item per PE: active[p] = 1 if some brick b with reach[b] != 0
 * (resample.cl: simdvol_occupancy_reach; bricks of SV_BRICK^3 voxels,
 * `bricks` per axis) meets the PE's cell clipped to the volume, else 0.
 * Every sample the matching gives p has floor(X) in that cell, so in such a
 * brick; where none has reach, every sample of p is +-0 in every channel
 * (the fused kernel would skip them all) and p's footprint stays 0. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_match_active(
    global const int4* cidx, int4 cell, int4 dims, int pes, global const uchar* reach, int4 bricks,
    global uchar* active) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const int4 ci = cidx[p];
  const int c[3] = {cell.x, cell.y, cell.z}, i[3] = {ci.x, ci.y, ci.z};
  const int n[3] = {dims.x, dims.y, dims.z};
  int b0[3], b1[3];
  for (int a = 0; a < 3; ++a) {
    const int lo = i[a] * c[a], hi = min(lo + c[a], n[a]);
    if (lo >= hi) {
      active[p] = 0;
      return;
    }
    b0[a] = lo >> SV_BRICK_LOG2;
    b1[a] = (hi - 1) >> SV_BRICK_LOG2;
  }
  uchar r = 0;
  for (int z = b0[2]; z <= b1[2]; ++z)
    for (int y = b0[1]; y <= b1[1]; ++y)
      for (int x = b0[0]; x <= b1[0]; ++x) r |= reach[(z * bricks.y + y) * bricks.x + x];
  active[p] = r != 0;
}

/* ---- simdvol_zero_uncovered: the footprint pixels no segment covers ----
 * The direct local kernels (local.cl) write every segment's pixel, an empty
 * segment's too, so before them only the pixels of a footprint without a
 * segment need zeros (simdvol_zero4 zeroes them all). Per work-item the 8
 * candidate rows g = 8 w ... 8 w + 7 of one PE (as simdvol_match_rows):
 * rowsum[g] = (count, load, first i, last i) of the row's segments; a row
 * whose segments are contiguous (count = last - first + 1) gets zeros left
 * of first and right of last within the footprint rects[p], any other row
 * (none, or holes) zeros throughout. rect_off[p]: the footprint's first
 * pixel (local.cl). Balancing moves no segment's (i, j), so the rows of the
 * matching are those of the balanced segments. At 0, 30 and 45 deg about y
 * every footprint pixel of the 256^3 phantom has a segment; at (20, 35, 10)
 * 30 % have none. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_zero_uncovered(
    global const sv_rect* cand, global const sv_rect* rects, global const int4* rowsum, int pes,
    int H, global const int* rect_off, global float4* foot) {
  const int g0 = (int)get_global_id(0) * 8;
  const int p = g0 / H, row0 = g0 - p * H;
  if (p >= pes) return;
  const sv_rect r = rects[p];
  if (r.w <= 0 || r.h <= 0) return;
  const int j0 = cand[p].j0 + row0;
  if (j0 + 7 < r.j0 || j0 >= r.j0 + r.h) return;
  global float4* base = foot + rect_off[p];
  int A[8], B[8];
  for (int l = 0; l < 8; ++l) {
    const int j = j0 + l;
    A[l] = 0;
    B[l] = r.w;
    if (j < r.j0 || j >= r.j0 + r.h) continue;
    const int4 s = rowsum[g0 + l];
#ifndef SV_ZERO_ALL
    const int whole = s.x <= 0 || s.x != s.w - s.z + 1;
#else
    const int whole = 1; /* every pixel, for comparison */
#endif
    A[l] = whole ? r.w : s.z - r.i0;
    B[l] = whole ? r.w : s.w + 1 - r.i0;
#ifndef SV_ZERO_NO_PF
    /* The lines to zero asked for first (for writing), the 8 rows' at
     * once: the footprints come from memory (the frame's voxel cells went
     * through the cache since the last swap read them), and the stores
     * then wait for one line after another. 2026-12-05, 2-core Intel Xeon,
     * `simdvol render --view 20,35,10 --frames 10 --step 0 --trace`,
     * frames 2-9, two alternations with -DSV_ZERO_NO_PF (not asked):
     * 0.98 / 1.12 -> 0.84 / 0.84 ms on the 256^3 phantom. */
    global float4* row = base + (size_t)(j - r.j0) * r.w;
    if (A[l] > 0) {
      SV_PREFETCHW(row);
      SV_PREFETCHW(row + A[l] - 1);
    }
    if (B[l] < r.w) {
      SV_PREFETCHW(row + B[l]);
      SV_PREFETCHW(row + r.w - 1);
    }
#endif
  }
  for (int l = 0; l < 8; ++l) {
    const int j = j0 + l;
    if (j < r.j0 || j >= r.j0 + r.h) continue;
    global float4* row = base + (size_t)(j - r.j0) * r.w;
    for (int x = 0; x < A[l]; ++x) row[x] = (float4)(0.0f);
    for (int x = B[l]; x < r.w; ++x) row[x] = (float4)(0.0f);
  }
}
