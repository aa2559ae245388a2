// Matching and load balancing on the PE array (thesis ch. 5.4, 5.5; eq
// 5.5–5.9): which PE resamples which viewing-space sample, as per-PE lists of
// depth segments of rays. Serial references; the device stages live in
// host/cl/match.cpp (kernels/match.cl, kernels/balance.cl, match_cl.hpp).
//
// Matching. PE p's box B_p = [o_a, min(o_a + c_a, n_a)) per axis (empty if
// o_a >= n_a). Sample (i, j, k) belongs to p iff floor(X(i, j, k)) lies in
// B_p, so every in-volume sample belongs to exactly one PE. For each PE the
// rays to look at are those in its candidate rectangle (match_candidates: the
// 8 vertices of B_p mapped back to the viewing grid in double precision,
// padded by 1 pixel, clipped to the grid; a superset of the rays that meet
// B_p); per ray the exact [k0, k1) comes from the slab intersection in
// integer arithmetic (box_ray_range). Rays with k0 < k1 are p's segments,
// sorted by (j, i). The set of segments does not depend on the candidate
// rectangle (only that it is a superset), so any exact implementation gives
// the same result.
//
// Balancing (balance_reference). Samples move only between face neighbours
// and only across the face through which the ray passes from one to the
// other: for a ray whose segment in PE F ends at k1 where its segment in the
// face neighbour B begins (the "link" F -> B), the boundary k1 may move. F
// gives its last s samples to B (boundary -= s) or B gives its first s
// samples to F (boundary += s). Segments are never created or removed; they
// may become empty (k0 == k1, kept in place); rects stay those of the
// matching. The schedule is a fixed number of sweeps; each sweep is 6 rounds
// (axis x, y, z) x (parity 0, 1); in round (a, par) the pairs are the face
// neighbours along a with cell indices (2m + par, 2m + 1 + par). A pair with
// loads L_F, L_B and d = L_F - L_B transfers W = floor(|d| / 2) samples from
// the heavier to the lighter PE, capped by what the giver holds on the
// linked rays, in equal shares: with n linked rays in F's segment order,
// ray r gives min(len_r, share_r), share_r = floor((r + 1) W / n) -
// floor(r W / n) where W >= n (the shares sum to W and differ by at most 1,
// the larger ones spread evenly), and where W < n the first W rays one
// sample each (a pair moving a few samples touches a few consecutive
// links); where some rays held less than their share, the shortfall is then
// taken greedily in the same order, each ray giving what it still holds,
// until W is reached or the rays are empty.
// (Until 2026-12-04 the shares were proportional to the rays' lengths,
// floor(W' C_r / cap) - floor(W' C_{r-1} / cap): the same amounts moved,
// W' = min(W, cap), but two walks over the links per pair; the utilisation
// after 8 sweeps is the same to 3 decimals, docs/PERFORMANCE.md.) Integer
// only: the device result is identical.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "simdvol/pe_array.hpp"
#include "simdvol/view.hpp"
#include "simdvol_shared.h"

namespace simdvol {

/// Segments of every PE (CSR), their footprints and loads.
struct Matching {
  std::vector<int64_t> seg_offset;   ///< P + 1 entries
  std::vector<sv_segment> segments;  ///< per PE sorted by (j, i)
  std::vector<sv_rect> rects;        ///< P footprints (bbox of the PE's rays)
  std::vector<int64_t> loads;        ///< P sample counts (sum of k1 - k0)
  /// Empty: every PE takes part. Else P flags (match_reference's `active`):
  /// a PE with 0 has no segments, and no balance link goes into it.
  std::vector<uint8_t> active;

  int64_t pes() const { return static_cast<int64_t>(rects.size()); }
  /// SIMD utilisation: mean load / max load (1 when every PE is idle).
  double utilisation() const;
  /// Largest load.
  int64_t max_load() const;
  /// Sum of the loads.
  int64_t total_load() const;
};

/// PE p's cell clipped to the volume: [lo, hi) per axis.
struct CellBox {
  std::array<int64_t, 3> lo{0, 0, 0};
  std::array<int64_t, 3> hi{0, 0, 0};
  bool empty() const { return lo[0] >= hi[0] || lo[1] >= hi[1] || lo[2] >= hi[2]; }
};
CellBox cell_box(const KdSplit& split, int64_t pe);
/// Candidate rectangle of every PE (see the file comment): a superset of the
/// rays (i, j) that have a sample in the PE's box (w = h = 0 when none can).
std::vector<sv_rect> match_candidates(const ViewGeometry& view, const KdSplit& split);
/// The exact depth range [k0, k1) of ray (i, j) whose samples have
/// floor(X) in `box`, clipped to [0, depth()); {0, 0} when empty.
std::array<int64_t, 2> box_ray_range(const ViewGeometry& view, const CellBox& box, int64_t i,
                                     int64_t j);

/// Sample (i, j, k) belongs to PE p iff floor(X(i, j, k)) lies in p's cell
/// clipped to the volume. Exact (integer arithmetic). Throws ArgumentError if
/// the split's dims differ from the view's.
///
/// With `active` (P flags; empty: all), only the PEs flagged take part: the
/// others get no segments (their samples are nobody's), and balancing moves
/// nothing into or out of them (balance_links gives no link into them).
/// ArgumentError if `active` has another size.
Matching match_reference(const ViewGeometry& view, const KdSplit& split,
                         const std::vector<uint8_t>& active = {});

/// Empty-space skipping of whole PEs (match_active): active[p] = 1 iff some
/// brick b with reach[b] != 0 meets p's cell clipped to the volume; bricks
/// of 2^SV_BRICK_LOG2 voxels, ceil(dims / brick) per axis, b = (bz * nby +
/// by) * nbx + bx (local_cl.hpp: DeviceOccupancy::reach). Every sample the
/// matching gives p has floor(X) in its cell, so where this is 0 every
/// sample of p reads only zero voxels and p's footprint is 0: leaving p out
/// changes no pixel (with balancing, only the grouping of the other
/// samples). ArgumentError if `reach` has another size.
std::vector<uint8_t> match_active_reference(const KdSplit& split,
                                            const std::vector<uint8_t>& reach);

/// Throws ArgumentError ("matching: ...") where `m` cannot be read as a
/// matching: seg_offset not P + 1 non-decreasing offsets from 0 to the
/// segment count, or (with `view`) a segment outside the viewing grid. The
/// references that walk a caller's matching (balance, resample, local,
/// Monte Carlo, footprints) check it first.
void check_matching(const Matching& m);
void check_matching(const Matching& m, const ViewGeometry& view);

/// Default number of balancing sweeps.
inline constexpr int kBalanceSweeps = 8;
/// The largest number of balancing sweeps the engine and the bench tools
/// take (EngineOptions::balance_sweeps; each sweep is 6 launches).
inline constexpr int kMaxBalanceSweeps = 64;

/// The link of every segment s (same order as m.segments): -1, or
/// next * 4 + axis where `next` is the index in m.segments of the segment of
/// the same ray in the face neighbour along `axis` that owns sample k1 of s
/// (that segment starts at k1). Computed from the matching before balancing.
std::vector<int32_t> balance_links(const Matching& m, const ViewGeometry& view,
                                   const KdSplit& split);

/// Load balancing (see the file comment) of a matching made by
/// match_reference(view, split): `sweeps` sweeps of 6 rounds. Throws
/// ArgumentError for sweeps outside 0 .. kMaxBalanceSweeps or a matching of
/// another PE count.
Matching balance_reference(const Matching& m, const ViewGeometry& view, const KdSplit& split,
                           int sweeps = kBalanceSweeps);

}  // namespace simdvol
