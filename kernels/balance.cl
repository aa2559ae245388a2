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
 * A round's pair (F, B) gives its samples in equal shares over F's list
 * along the round's axis (match.hpp, "the shares" below): one walk over the
 * entries whose share is not 0, and a second, greedy one only where some
 * ray held less than its share.
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
 * The pairs: the host lists them per (axis, parity) once per matching
 * (DeviceMatching::pairs: (the PE of cell index c, the PE of c + 1) along
 * the axis, c = 2 m + parity); a round takes its list.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

SV_FN int sv_list_start(int4 o, int axis) {
  return axis == 0 ? o.y : (axis == 1 ? o.z : o.w);
}

/* A round's pair (F, B) = (front, back) from its entry (the PE of the
 * lower cell along the round's axis, the PE of the cell above it): dir = the
 * sign of the depth step along the axis. The host lists each (axis,
 * parity)'s pairs once per matching (DeviceMatching::pairs, match_cl.hpp): the
 * pairs of cell indices (2 m + par, 2 m + 1 + par) along the axis. */
SV_FN int2 sv_balance_fb(const int2 lu, int dir) {
  return dir > 0 ? lu : (int2)(lu.y, lu.x);
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
/* A round's work-items walk their pair's links and bounds, scattered over
 * megabytes: with SV_BAL_PF > 0 the pair SV_BAL_PF ahead in the round's list
 * (each of a work-item's SV_BAL_PES pairs in turn; until 2026-12-05 a
 * work-item per PE) has its link list prefetched and the bounds the list
 * points to (all of F's and B's, below), where the pair moves samples in
 * this round (its loads, which no other pair of the round changes, differ
 * by 2 or more). A hint only.
 * Default 0 (none) since the equal shares of 2026-12-04, which visit only
 * the entries with a share where the pair moves fewer samples than it has
 * entries: simdvol-bench-options, 12-16 frames, balance 3.53 / 3.53 -> 3.29
 * / 3.32 ms at (0, 45, 0), 1.80 -> 1.49 at (20, 35, 10), ch2 4.29 -> 4.02,
 * brainsmall 0.90 -> 0.68 (8 -> 0; 4 and 16 as 8; prefetching only for the
 * pairs that visit every entry, or only the visited entries' list lines,
 * 3.8-3.9 ms at 45 deg: a 2-core Intel Xeon). With the proportional shares
 * (two walks over every entry) 8 was the faster:
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
#define SV_BAL_PF 0
#endif
SV_FN void sv_balance_prefetch(global const int2* pairs, int npairs, int dir,
                               global const int4* lofs, global const int2* llist, const int nl,
                               global const uchar* kk, int kb, global const int* loads, int i,
                               int axis) {
#if SV_BAL_PF > 0
  if (i + SV_BAL_PF >= npairs) return;
  const int2 fb = sv_balance_fb(pairs[i + SV_BAL_PF], dir);
  if ((loads[fb.x] - loads[fb.y]) / 2 == 0) return;
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

/* ---- the shares ----
 * W = the samples the pair moves, n = e1 - e0 the linked rays (F's list
 * along the axis), entry r (0-based, in F's segment order) gives min(len_r,
 * share_r) (the reference's `transfer`, match.cpp):
 * - W >= n: share_r = floor((r + 1) W / n) - floor(r W / n), W / n plus 1
 *   where the running remainder of r (W mod n) passes n (no division per
 *   entry): the extra samples spread evenly over the list;
 * - W < n: the first W entries, one sample each: a pair that moves a few
 *   samples reads a few consecutive list entries and bounds.
 * Then, where the moved samples fall short of W (a ray held less than its
 * share), the entries from the first on give what they still hold until W
 * is reached.
 * simdvol-bench-options --view 0,45,0, 12 frames, three alternations:
 * balance 3.31 / 3.27 / 3.33 ms with the shares spread evenly for every W
 * (W scattered entries where W < n), 3.00 / 3.02 / 2.89 as here; in three
 * alternations before, 3.44 / 3.37 / 3.29 spread evenly against 3.18 /
 * 3.17 / 3.26 with the first W mod n entries given the extra sample for
 * every W. The utilisation the same to 0.001 for all three (a 2-core Intel
 * Xeon, 2026-12-04). Until 2026-12-04 the shares were proportional to the
 * lengths (cumulative shares of the cap): a first walk over every entry for
 * the cap, then a second for the shares (docs/PERFORMANCE.md, "The equal
 * shares").
 * SV_BAL_GIVE: entry E gives up to SHARE samples (a macro over the round's
 * locals llist, kk, sF, sB, front_gives, moved). */
#define SV_BAL_GIVE(BT, B1, NL, E, SHARE)                 \
  {                                                       \
    const int2 st = sv_bal_link(llist, NL, (E), sF, sB);  \
    const BT g = kk[front_gives ? st.x : st.y];           \
    const int give = min((int)(SHARE), (int)(g.y - g.x)); \
    if (give > 0) {                                       \
      const int shift = front_gives ? -give : give;       \
      kk[st.x].y = (B1)(kk[st.x].y + shift);              \
      kk[st.y].x = (B1)(kk[st.y].x + shift);              \
      moved += give;                                      \
    }                                                     \
  }
#define SV_BAL_SHARES(BT, B1, NL)                 \
  if (want < n) {                                 \
    for (int e = e0; e < e0 + want; ++e) {        \
      SV_BAL_GIVE(BT, B1, NL, e, 1)               \
    }                                             \
  } else {                                        \
    const int q = want / n, dr = want % n;        \
    int acc = 0;                                  \
    for (int e = e0; e < e1; ++e) {               \
      acc += dr;                                  \
      const int over = acc >= n;                  \
      acc -= over ? n : 0;                        \
      SV_BAL_GIVE(BT, B1, NL, e, q + over)        \
    }                                             \
  }                                               \
  for (int e = e0; e < e1 && moved < want; ++e) { \
    SV_BAL_GIVE(BT, B1, NL, e, want - moved)      \
  }

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
 * parity `par` (entries first .. first + npairs - 1 of the pair list); dir
 * = sign of the depth step along the axis (non-zero). Each work-item takes
 * SV_BAL_PES consecutive pairs (simdvol_shared.h), one after the other.
 * Until the third session of 2026-12-05 each took SV_BAL_PES consecutive
 * PEs and found each PE's pair from its cell index (and skipped the PEs
 * without one, half of them): most pairs of a round move nothing, so that
 * search was most of a round. scripts/bench-ab (4 pairs), the balance:
 * the 256^3 phantom at (20, 35, 10) 1.84 -> 0.96 ms, brainsmall 0.64 ->
 * 0.29, (0, 45, 0) 3.96 -> 3.38, ch2 4.16 -> 3.48 (a 2-core Intel Xeon).
 * Before that, with one PE per work-item, those launches of 8,192
 * work-items had cost 20-30 us each. `simdvol render --frames 8 --step 0
 * --trace`, the balance from its first round to the segment order
 * (medians of 6 frames;
 * 1 -> 16 PEs per work-item): brainsmall 1.05 -> 0.65-0.76 ms, the 256^3
 * phantom at (20, 35, 10) 2.28 -> 1.97-2.13, at (0, 45, 0) 4.11 -> 3.98-4.02,
 * ch2 4.65 -> 4.26-4.63 (4 and 32 in between or worse; a 2-core Intel Xeon,
 * 2026-12-05). The sweeps after the first two in one launch of one
 * work-group (a barrier between rounds) were faster where they were settled
 * (brainsmall 0.68, the phantom 1.88 ms) and slower where they were not
 * (one core: 4.4-4.7 ms at (0, 45, 0), 5.5 on ch2): not kept.
 * _roundn, _round16n: the same on narrow link lists (one uint per entry,
 * sv_bal_link), which the host takes where the matching wrote them
 * (DeviceMatching::links_narrow).
 * _pack: before the first round, the bounds out of the segments (one
 * work-item per segment slot; slots past seg_offset[pes] hold nothing).
 * _unpack: after the last round, the bounds back into the segments. */
#define SV_BALANCE_ROUND(SFX, NSFX, BT, B1, NL)                                                    \
  __kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_round##SFX##NSFX( \
      global const int2* pair_list, int first, int npairs, int axis, int dir,                      \
      global const int4* lofs, global const int2* llist, global BT* kk, global int* loads,         \
      global int* moves, int sweep) {                                                              \
    /* A sweep that moved nothing left a state no later sweep changes. */                          \
    if (SV_BAL_SETTLED(moves, sweep)) return;                                                      \
    global const int2* pairs = pair_list + first;                                                  \
    const int i0 = (int)get_global_id(0) * SV_BAL_PES;                                             \
    for (int i = i0; i < i0 + SV_BAL_PES && i < npairs; ++i) {                                     \
      sv_balance_prefetch(pairs, npairs, dir, lofs, llist, NL, (global const uchar*)kk,            \
                          (int)sizeof(BT), loads, i, axis);                                        \
      const int2 fb = sv_balance_fb(pairs[i], dir);                                                \
      const int F = fb.x, B = fb.y;                                                                \
      const int diff = loads[F] - loads[B];                                                        \
      const int t = diff / 2; /* truncates towards 0 */                                            \
      if (t == 0) continue;                                                                        \
      const int front_gives = t > 0;                                                               \
      const int want = front_gives ? t : -t;                                                       \
      const int sF = lofs[F].x, sB = lofs[B].x; /* (narrow links: their first segments) */         \
      const int e0 = sv_list_start(lofs[F], axis), e1 = sv_list_start(lofs[F + 1], axis);          \
      const int n = e1 - e0;                                                                       \
      if (n <= 0) continue;                                                                        \
      int moved = 0;                                                                               \
      SV_BAL_SHARES(BT, B1, NL)                                                                    \
      if (moved == 0) continue;                                                                    \
      loads[F] -= front_gives ? moved : -moved;                                                    \
      loads[B] += front_gives ? moved : -moved;                                                    \
      SV_BAL_MOVED(moves, sweep);                                                                  \
    }                                                                                              \
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
