/* balance.cl — load balancing by moving segment boundaries between face
 * neighbours (see host/include/simdvol/match.hpp for the scheme and
 * match_cl.hpp for the buffers). Integer only: equal to balance_reference.
 *
 * The links come from simdvol_match_fill as per-(PE, axis) lists: lofs[p]
 * (y, z, w for axis x, y, z) is the start of PE p's list of its segments
 * linked along that axis, lofs[p + 1] its end; entry (s, t) = the segment s
 * of p and the segment t of the same ray in the face neighbour, in p's
 * segment order: an int2, or in the _n rounds (narrow links) one uint of
 * the two indices within p's and the neighbour's segments (sv_bal_link).
 * A round's pair (F, B) walks F's list along the round's axis twice (cap,
 * then cumulative shares); the share's floor division uses a double
 * estimate corrected exactly.
 *
 * The rounds read and move the segments' bounds (k0, k1) in `kk`, 4 (or 8)
 * bytes per segment, not the 16-byte segments: a round touches segments all
 * over the buffer, and its time is mostly that of streaming their cache
 * lines (16-bit bounds of 2 M segments, 8 MB, stay in a 32 MB L3).
 * simdvol_balance_pack copies the bounds out of the segments before the
 * first round (for the 32-bit bounds only: simdvol_match_fill writes the
 * 16-bit ones beside the segments), simdvol_balance_unpack writes them back
 * after the last.
 *
 * Tables: cidx (int4[P], cell index of each PE), pe_of (int[P], the PE of
 * cell (ix, iy, iz) at (iz * sy + iy) * sx + ix), splits (int4, cells per
 * axis).
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

#pragma OPENCL EXTENSION cl_khr_fp64 : enable

/* floor(a / b) for 0 <= a, 0 < b, given inv ~ 1 / b. */
SV_FN long sv_floor_div(long a, long b, double inv) {
  long q = (long)((double)a * inv);
  long r = a - q * b;
  while (r < 0) {
    --q;
    r += b;
  }
  while (r >= b) {
    ++q;
    r -= b;
  }
  return q;
}

SV_FN int sv_list_start(int4 o, int axis) {
  return axis == 0 ? o.y : (axis == 1 ? o.z : o.w);
}

/* The pair of PE p in a round: F (front) and B (back), or -1 if p has none. */
SV_FN int2 sv_balance_pair(global const int4* cidx, global const int* pe_of, int4 splits, int pes,
                           int axis, int par, int dir, int p) {
  if (p >= pes) return (int2)(-1);
  int4 c = cidx[p];
  const int sa = axis == 0 ? splits.x : (axis == 1 ? splits.y : splits.z);
  const int ca = axis == 0 ? c.x : (axis == 1 ? c.y : c.z);
  if ((ca & 1) != par || ca + 1 >= sa) return (int2)(-1);
  if (axis == 0)
    c.x += 1;
  else if (axis == 1)
    c.y += 1;
  else
    c.z += 1;
  const int q = pe_of[(c.z * splits.y + c.y) * splits.x + c.x];
  return dir > 0 ? (int2)(p, q) : (int2)(q, p);
}

/* Link entry e of a list: (segment of F, linked segment of B), from an
 * int2 or, with narrow links (nl), from one uint of the two indices within
 * F's and B's segments (match.cl: simdvol_match_fill), sF and sB their
 * first segments. */
SV_FN int2 sv_bal_link(global const int2* llist, const int nl, const int e, const int sF,
                       const int sB) {
  if (!nl) return llist[e];
  const uint w = ((global const uint*)llist)[e];
  return (int2)(sF + (int)(w & 0xffffu), sB + (int)(w >> 16));
}
/* The indices of 8 entries' giving segments (front_gives: F's, else B's). */
SV_FN int8 sv_bal_give8(global const int2* llist, const int nl, const int e, const int sF,
                        const int sB, const int front_gives) {
  if (nl) {
    const uint8 w = vload8(0, (global const uint*)llist + e);
    return front_gives ? sF + convert_int8(w & 0xffffu) : sB + convert_int8(w >> 16);
  }
  const int16 L = vload16(0, (global const int*)(llist + e));
  return front_gives ? L.even : L.odd;
}

/* A round's work-items walk their pair's links and bounds, scattered over
 * megabytes: the work-item SV_BAL_PF ahead (8; 0: none) prefetches its
 * pair's link list and the bounds the list points to (all of F's and B's,
 * below), where the pair moves samples in this round (its loads, which no
 * other pair of the round changes, differ by 2 or more). A hint only.
 * simdvol-bench-match --repeat 3 --random 0 (every PE), alternated twice:
 * balance at 30 / 45 deg 29.2 / 55.1 and 20.9 / 40.1 -> 23.7 / 31.3 and
 * 21.4 / 30.7 ms, at 0 deg 3.0 / 2.6 against 2.2 / 3.3 ms.
 * The bounds prefetched are those of every segment of F and of B (lofs[.].x
 * = seg_offset: no load that waits), not the range between the list's first
 * and last entries (-DSV_BAL_PF_ENDS, for comparison: those two loads of
 * the list, just prefetched, had about a fifth of the round's samples in
 * perf annotate). 2-core Zen 4 EPYC, 2026-12-02: simdvol-bench-options
 * --view 0,45,0, 12 frames, both orders, balance 11.6 / 12.1 -> 11.2 / 11.6
 * ms; simdvol-bench-frame --views 30,45, alternated twice, balance (every
 * PE) 23.6 / 19.4 -> 16.7 / 17.0 ms at 30 deg, 38.5 / 40.0 -> 35.7 / 28.6
 * at 45. */
#ifndef SV_BAL_PF
#define SV_BAL_PF 8
#endif
SV_FN void sv_balance_prefetch(global const int4* cidx, global const int* pe_of, int4 splits,
                               int pes, int axis, int par, int dir, global const int4* lofs,
                               global const int2* llist, const int nl, global const uchar* kk,
                               int kb, global const int* loads, int p) {
#if SV_BAL_PF > 0
  const int2 fb = sv_balance_pair(cidx, pe_of, splits, pes, axis, par, dir, p + SV_BAL_PF);
  if (fb.x < 0 || (loads[fb.x] - loads[fb.y]) / 2 == 0) return;
  const int4 f0 = lofs[fb.x], f1 = lofs[fb.x + 1];
  const int e0 = sv_list_start(f0, axis), e1 = sv_list_start(f1, axis);
  if (e1 <= e0) return;
  const int lb = nl ? 4 : 8; /* bytes per list entry */
  for (int e = e0; e < e1; e += 64 / lb) SV_PREFETCH((global const uchar*)llist + (size_t)e * lb);
  const int step = 64 / kb; /* kb bytes per segment's bounds */
#ifdef SV_BAL_PF_ENDS
  const int2 a = sv_bal_link(llist, nl, e0, f0.x, lofs[fb.y].x),
             b = sv_bal_link(llist, nl, e1 - 1, f0.x, lofs[fb.y].x);
  for (int x = min(a.x, b.x); x <= max(a.x, b.x); x += step) SV_PREFETCH(kk + (size_t)x * kb);
  for (int y = min(a.y, b.y); y <= max(a.y, b.y); y += step) SV_PREFETCH(kk + (size_t)y * kb);
#else
  const int b0 = lofs[fb.y].x, b1 = lofs[fb.y + 1].x;
  for (int x = f0.x; x < f1.x; x += step) SV_PREFETCH(kk + (size_t)x * kb);
  for (int y = b0; y < b1; y += step) SV_PREFETCH(kk + (size_t)y * kb);
#endif
#endif
}

/* ---- the first walk (the cap), 8 entries at a time ----
 * PoCL runs a round's loops of varying trip count per work-item, in scalar
 * code. The first walk only sums the lengths k1 - k0 of the giving side's
 * segments: here 8 entries' lengths per step, from one 16-entry load of the
 * list and one 8-lane gather of their bound pairs (4 or 8 bytes each); the
 * last (e1 - e0) mod 8 entries one by one. The same integer sum, so the
 * same result. -DSV_BAL_SCALAR walks every entry one by one, for
 * comparison: simdvol-bench-options --view 0,45,0, 12 frames, alternated
 * four times, balance 17.1 / 16.1 / 16.3 / 16.2 -> 15.6 / 15.4 / 15.7 /
 * 14.7 ms; simdvol-bench-frame at 45 deg, alternated three times, every PE
 * 37.2 / 32.5 / 30.9 -> 29.6 / 27.4 / 27.4 ms, the active PEs 15.3 / 15.0 /
 * 14.1 -> 13.1 / 13.0 / 13.0 ms; at 30 deg and at (20, 35, 10) no
 * difference (a 2-core Intel Xeon, 2026-12-02). The second walk in 8 lanes too (a
 * prefix sum of the lengths, the 8 floor divisions in double8 corrected in
 * long8, the stores of the entries whose share is not 0 one by one) was
 * slower, 16.1 / 15.7 -> 21.0 / 21.1 ms: most entries of a moving pair
 * give a sample or more, so its time is that of the scattered stores. */
#ifndef SV_BAL_SCALAR
#define SV_BAL_VEC 1
#else
#define SV_BAL_VEC 0
#endif

#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif

/* The lengths k1 - k0 of the segments idx: 16-bit bounds (short2, x = k0 in
 * the low half of each 32-bit pair) and 32-bit bounds (int2). */
SV_FN int8 sv_bal_len8_16(global const short2* kk, const int8 idx) {
  global const uint* w = (global const uint*)kk;
  const uint8 g = (uint8)(w[idx.s0], w[idx.s1], w[idx.s2], w[idx.s3], w[idx.s4], w[idx.s5],
                          w[idx.s6], w[idx.s7]);
  const short16 h = as_short16(g);
  return convert_int8(h.odd) - convert_int8(h.even);
}
SV_FN int8 sv_bal_len8_(global const int2* kk, const int8 idx) {
  global const ulong* w = (global const ulong*)kk;
  const ulong8 g = (ulong8)(w[idx.s0], w[idx.s1], w[idx.s2], w[idx.s3], w[idx.s4], w[idx.s5],
                            w[idx.s6], w[idx.s7]);
  const int16 h = as_int16(g);
  return h.odd - h.even;
}

/* The sum of 8 lengths, in 64 bits. */
SV_FN long sv_bal_sum8(const int8 n8) {
  const int4 n4 = n8.lo + n8.hi;
  return (long)(n4.x + n4.y) + (long)(n4.z + n4.w);
}

/* The second walk: each entry's share of `moved`, floor(moved C_r / cap) -
 * floor(moved C_{r-1} / cap) with C_r the lengths' running sum, moved to
 * the pair's other segment. The floors by their remainder: r = moved C_r -
 * cap floor(moved C_r / cap) in [0, cap), so an entry adds moved times its
 * length to r and gives floor(r / cap) (1 where r < 2 cap, else the
 * division), keeping r below cap: the same integers, without a division
 * per entry (moved C_r < 2^62 as before). A macro over the round's locals
 * (e0, e1, llist, kk, front_gives, moved, cap, inv). -DSV_BAL_DIVIDE takes
 * each floor by its division, for comparison: simdvol-bench-options, 12
 * frames, both orders, balance at (0, 45, 0) 10.7 / 11.2 -> 8.6 / 8.9 ms,
 * ch2 at (20, 35, 10) 9.4 / 9.3 -> 8.3 / 8.3 ms, the phantom there 3.1 /
 * 3.0 -> 3.0 / 2.9 ms (a 2-core Intel Xeon).
 * Where the pair moves few samples for its list (more than SV_BAL_SPARSE_K
 * = 32 entries per sample moved), most entries give nothing: the walk then
 * steps 8 entries at a time (their lengths as in the first walk) while r
 * stays below cap, and only a chunk in which r reaches cap is walked entry
 * by entry. r takes the same values at the chunks' ends, so the shares are
 * the same integers. -DSV_BAL_NO_SKIP walks every entry one by one, for
 * comparison: simdvol-bench-options, 12 frames, the phantom at (0, 45, 0),
 * balance 7.87 / 8.07 -> 7.34 / 7.40 ms (K = 32 / 16); ch2 at (20, 35, 10)
 * 7.50 / 7.58 against 7.57 / 7.51 (K = 32, the same; K = 8 was 0.3-0.45 ms
 * slower there: a chunk that gives is walked twice); a 2-core Intel Xeon,
 * 2026-12-02. */
#ifndef SV_BAL_DIVIDE
#if SV_BAL_VEC && !defined(SV_BAL_NO_SKIP)
#ifndef SV_BAL_SPARSE_K
#define SV_BAL_SPARSE_K 32
#endif
#define SV_BAL_SPARSE (e1 - e0 > SV_BAL_SPARSE_K * moved)
#else
#define SV_BAL_SPARSE 0
#endif
#define SV_BAL_SHARES(BT, B1, SFX, NL)                                                         \
  long r = 0;                                                                                  \
  const int sparse = SV_BAL_SPARSE;                                                            \
  for (int e = e0; e < e1;) {                                                                  \
    int stop = e1;                                                                             \
    if (sparse) {                                                                              \
      for (; e + 8 <= e1; e += 8) {                                                            \
        const long nr = r + moved * sv_bal_sum8(sv_bal_len8_##SFX(                             \
                                        kk, sv_bal_give8(llist, NL, e, sF, sB, front_gives))); \
        if (nr >= cap) break;                                                                  \
        r = nr;                                                                                \
      }                                                                                        \
      stop = min(e + 8, e1);                                                                   \
    }                                                                                          \
    for (; e < stop; ++e) {                                                                    \
      const int2 st = sv_bal_link(llist, NL, e, sF, sB);                                       \
      const BT g = kk[front_gives ? st.x : st.y];                                              \
      r += moved * (long)(g.y - g.x);                                                          \
      if (r < cap) continue;                                                                   \
      const int give = r < 2 * cap ? 1 : (int)sv_floor_div(r, cap, inv);                       \
      r -= (long)give * cap;                                                                   \
      const int shift = front_gives ? -give : give;                                            \
      kk[st.x].y = (B1)(kk[st.x].y + shift);                                                   \
      kk[st.y].x = (B1)(kk[st.y].x + shift);                                                   \
    }                                                                                          \
  }
#else
#define SV_BAL_SHARES(BT, B1, SFX, NL)                  \
  long cum = 0, prev = 0;                               \
  for (int e = e0; e < e1; ++e) {                       \
    const int2 st = sv_bal_link(llist, NL, e, sF, sB);  \
    const BT g = kk[front_gives ? st.x : st.y];         \
    cum += g.y - g.x;                                   \
    const long f = sv_floor_div(moved * cum, cap, inv); \
    const int give = (int)(f - prev);                   \
    prev = f;                                           \
    if (give == 0) continue;                            \
    const int shift = front_gives ? -give : give;       \
    kk[st.x].y = (B1)(kk[st.x].y + shift);              \
    kk[st.y].x = (B1)(kk[st.y].x + shift);              \
  }
#endif

/* The rounds of sweep s > 0 do nothing where sweep s - 1 moved no sample:
 * a sweep is the same rounds in the same order, so from a state one sweep
 * leaves as it is every later sweep leaves it too (the result is the same,
 * exactly). moves[s] = 1 once a pair of sweep s moved samples (moves zero
 * before the first round). -DSV_BAL_EVERY_SWEEP runs every round, for
 * comparison. */
/* A pair that moved samples sets its sweep's flag (every writer stores
 * the same 1). The flags lie a cache line apart (SV_BAL_MOVES_STRIDE): the
 * load of the sweep before's flag, in every work-item, had about a seventh
 * of the round's samples in perf annotate while it shared its line with
 * the flag the other core's pairs were storing. simdvol-bench-options, 12
 * frames, against the flags side by side (a worktree, alternated): balance
 * at (0, 45, 0) 7.61 / 7.61 / 8.64 -> 7.02 / 7.49 / 6.78 ms, ch2 at (20,
 * 35, 10) 7.32 / 7.15 -> 6.78 / 6.90, the phantom at (0, 30, 0) 2.11 /
 * 2.09 -> 1.93 / 2.06 (a 2-core Intel Xeon, 2026-12-02). Storing only where
 * the flag was still 0 measured the same, so the store stays plain. */
#define SV_BAL_MOVED(moves, sweep) ((moves)[(sweep)*SV_BAL_MOVES_STRIDE] = 1)
#ifndef SV_BAL_EVERY_SWEEP
#define SV_BAL_SETTLED(moves, sweep) \
  ((sweep) > 0 && (moves)[((sweep)-1) * SV_BAL_MOVES_STRIDE] == 0)
#else
#define SV_BAL_SETTLED(moves, sweep) 0
#endif

/* The kernels, once for each width of the bounds (BT = the pair, B1 = one
 * bound): simdvol_balance_pack, _round and _unpack with int2 bounds, and
 * simdvol_balance_pack16, _round16 and _unpack16 with short2 bounds, which
 * the host takes when every k fits in 16 bits (balance_bounds16: grid depth
 * <= 32767). Both in one program (it joins the frame's program of layout,
 * match and swap): a BOUNDS16 define made the balance a program of its own,
 * one more build of 40-60 ms per render.
 *
 * _round: one round, the pairs along `axis` whose lower cell index has
 * parity `par`; dir = sign of the depth step along the axis (non-zero).
 * _roundn, _round16n: the same on narrow link lists (one uint per entry,
 * sv_bal_link), which the host takes where the matching wrote them
 * (DeviceMatching::links_narrow).
 * _pack: before the first round, the bounds out of the segments (one
 * work-item per segment slot; slots past seg_offset[pes] hold nothing).
 * _unpack: after the last round, the bounds back into the segments. */
#define SV_BALANCE_ROUND(SFX, NSFX, BT, B1, NL)                                                    \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_round##SFX##NSFX( \
      global const int4* cidx, global const int* pe_of, int4 splits, int pes, int axis, int par,   \
      int dir, global const int4* lofs, global const int2* llist, global BT* kk,                   \
      global int* loads, global int* moves, int sweep) {                                           \
    /* A sweep that moved nothing left a state no later sweep changes. */                          \
    if (SV_BAL_SETTLED(moves, sweep)) return;                                                      \
    const int p = (int)get_global_id(0);                                                           \
    sv_balance_prefetch(cidx, pe_of, splits, pes, axis, par, dir, lofs, llist, NL,                 \
                        (global const uchar*)kk, (int)sizeof(BT), loads, p);                       \
    const int2 fb = sv_balance_pair(cidx, pe_of, splits, pes, axis, par, dir, p);                  \
    if (fb.x < 0) return;                                                                          \
    const int F = fb.x, B = fb.y;                                                                  \
    const int diff = loads[F] - loads[B];                                                          \
    const int t = diff / 2; /* truncates towards 0 */                                              \
    if (t == 0) return;                                                                            \
    const int front_gives = t > 0;                                                                 \
    const int want = front_gives ? t : -t;                                                         \
    const int sF = lofs[F].x, sB = lofs[B].x; /* (narrow links: their first segments) */           \
    const int e0 = sv_list_start(lofs[F], axis), e1 = sv_list_start(lofs[F + 1], axis);            \
    const int ev = SV_BAL_VEC ? e0 + ((e1 - e0) & ~7) : e0; /* the 8-entry chunks' end */          \
    long cap = 0;                                                                                  \
    if (SV_BAL_VEC) {                                                                              \
      int8 c8 = (int8)(0);                                                                         \
      for (int e = e0; e < ev; e += 8) {                                                           \
        c8 += sv_bal_len8_##SFX(kk, sv_bal_give8(llist, NL, e, sF, sB, front_gives));              \
      }                                                                                            \
      cap = sv_bal_sum8(c8);                                                                       \
    }                                                                                              \
    for (int e = ev; e < e1; ++e) {                                                                \
      const int2 st = sv_bal_link(llist, NL, e, sF, sB);                                           \
      const BT g = kk[front_gives ? st.x : st.y];                                                  \
      cap += g.y - g.x;                                                                            \
    }                                                                                              \
    const long moved = min(cap, (long)want);                                                       \
    if (moved <= 0) return; /* (cap < 0 only from bounds not as matched: no hang) */               \
    /* Cumulative shares: floor(moved C_r / cap) - floor(moved C_{r-1} / cap). */                  \
    const double inv = 1.0 / (double)cap;                                                          \
    SV_BAL_SHARES(BT, B1, SFX, NL)                                                                 \
    loads[F] -= front_gives ? (int)moved : -(int)moved;                                            \
    loads[B] += front_gives ? (int)moved : -(int)moved;                                            \
    SV_BAL_MOVED(moves, sweep);                                                                    \
  }

#define SV_BALANCE_PACK(SFX, BT, B1)                                                             \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_pack##SFX(      \
      global const int* seg_offset, int pes, global const sv_segment* segments, global BT* kk) { \
    const int s = (int)get_global_id(0);                                                         \
    if (s >= seg_offset[pes]) return;                                                            \
    const sv_segment g = segments[s];                                                            \
    kk[s] = (BT)((B1)g.k0, (B1)g.k1);                                                            \
  }                                                                                              \
                                                                                                 \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_unpack##SFX(    \
      global const int* seg_offset, int pes, global const BT* kk, global sv_segment* segments) { \
    const int s = (int)get_global_id(0);                                                         \
    if (s >= seg_offset[pes]) return;                                                            \
    const BT g = kk[s];                                                                          \
    segments[s].k0 = g.x;                                                                        \
    segments[s].k1 = g.y;                                                                        \
  }

SV_BALANCE_ROUND(, , int2, int, 0)
SV_BALANCE_ROUND(16, , short2, short, 0)
SV_BALANCE_ROUND(, n, int2, int, 1)
SV_BALANCE_ROUND(16, n, short2, short, 1)
SV_BALANCE_PACK(, int2, int)
SV_BALANCE_PACK(16, short2, short)
