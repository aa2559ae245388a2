// The match and balance stages on the device (kernels/match.cl,
// kernels/balance.cl); the serial references and the definitions are in
// match.hpp.
//
// enqueue_match(device, view, split) enqueues, with no host synchronisation
// (kernels/match.cl; one work-item per 8 rows of a PE's candidate rectangle,
// H = the largest candidate height rounded up to a multiple of 8, except
// where noted):
//   1. simdvol_match_rows  the exact segments of each row, counted (count,
//                          load, first and last i; links per axis), and
//                          each column's bounds and link axis saved for
//                          the fill (DeviceMatching::columns_saved)
//   2. simdvol_match_pe    one work-item per PE: row offsets, totals, load,
//                          footprint rect
//   3. simdvol_match_scan  one work-item: seg_offset[P + 1] and the link-list
//                          offsets (a serial scan of P entries: microseconds)
//   4. simdvol_match_fill  the segments again (from the saved columns, not
//                          stepped again), written in place, with the
//                          per-(PE, axis) lists of their balance links and,
//                          where 16-bit balance bounds will do, the bounds
//                          the balance rounds move (so no pack reads the
//                          segments back)
// (with MatchLinks::skip, simdvol_match_rows_nolinks and _fill_nolinks: the
// same without the links, their test compiled out)
// With a PE mask (enqueue_match's `active`, or its `reach`: first
//   0. simdvol_match_active  one work-item per PE: the mask from the brick
//                            reach, as match_active_reference)
// an inactive PE has no rows (no segments, an empty rect, load 0) and no
// link goes into it: the result equals match_reference(view, split, mask).
// Each row's columns are those where the row cuts the projection of the cell
// (a zonogon: three strips); along the row the slab bounds are stepped
// exactly in integers (no division per column). The segment buffer is
// allocated at an upper bound known on the host before anything runs, the
// sum of the candidate rectangles' areas (`capacity`); only the first
// seg_offset[P] entries are written.
//
// enqueue_balance(device, matching, view, split, sweeps) enqueues
// sweeps x (axis x, y, z with a non-zero depth step and >= 2 cells) x
// (parity 0, 1) launches of simdvol_balance_round (kernels/balance.cl), one
// work-item per PE (the lower PE of each pair does the pair's work, walking
// the front PE's link list along the axis), between simdvol_balance_pack and
// simdvol_balance_unpack. The rounds move the bounds (k0, k1) of the
// segments in a compact copy, 16-bit when the grid depth allows
// (balance_bounds16; the kernels named ...16) and 32-bit otherwise, and
// update loads in place; the
// unpack writes the bounds back into segments. The 16-bit copy is the one
// the matching's fill wrote (DeviceMatching::bounds_filled), so no pack
// runs; the 32-bit one is packed from the segments. The rounds are bound by
// streaming the segments they touch: 4-byte bounds instead of 16-byte
// segments keep 2 M segments' bounds in the L3 (simdvol-bench-match,
// 256^3 at 45 deg, 8192 PEs: balance 112-132 -> 64-76 ms). The result
// equals balance_reference(read(), view, split, sweeps) exactly, for either
// width.
//
// Buffers of DeviceMatching, consumed by the resample/local stages:
//   seg_offset  cl_int[P + 1]    CSR offsets (int32: at most INT_MAX segments)
//   segments    sv_segment[capacity], PE p's at [seg_offset[p], seg_offset[p+1]),
//               sorted by (j, i); after balancing some may be empty (k0 == k1)
//   rects       sv_rect[P]       footprint = bbox of the PE's rays (not changed
//               by balancing)
//   loads       cl_int[P]        sum of k1 - k0 (updated by balancing)
//   link_list   cl_int2[capacity] the balance links per (axis, PE), at
//               link_offset (written by enqueue_match with MatchLinks::make,
//               the default; with skip, no link buffers); read_links gives
//               them in balance_links()'s format. Narrow (links_narrow,
//               where every PE has at most 65536 candidate rays): one
//               cl_uint per link, the two segments' indices within their
//               PEs' segments (16 bits each), half the bytes for the fill
//               to write and the rounds to read; link_base then holds each
//               PE's link targets' first segments (simdvol-bench-options,
//               the 256^3 phantom at (0, 45, 0), 8192 PEs: balance 6.6-6.8
//               -> 5.9-6.0 ms; ch2 the same)
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/match.hpp"

namespace simdvol {

/// Whether enqueue_match makes the balance links (links, link_offset,
/// link_list): balancing needs them; without balancing (sweeps 0) they can
/// be left out, about a third of the matching's time. The segments, rects
/// and loads are the same either way.
enum class MatchLinks { make, skip };

/// A named profiling event of one enqueued kernel.
struct StageEvent {
  std::string name;
  cl::Event event;
};
/// Sum of the events' durations (ns); 0 without profiling.
std::uint64_t events_ns(const std::vector<StageEvent>& events);

/// The device matching (see the file comment for the buffers).
struct DeviceMatching {
  int64_t pes = 0;
  int64_t capacity = 0;  ///< segments allocated (>= the segment count)
  int64_t rows =
      0;  ///< H, rows per PE in the row tables (largest candidate height, rounded up to 8)
  cl::Buffer candidates;  ///< sv_rect[P], match_candidates()
  cl::Buffer cidx;        ///< cl_int4[P] cell index of each PE (w = 0)
  cl::Buffer pe_of;       ///< cl_int[P] PE of cell (ix, iy, iz) at (iz * sy + iy) * sx + ix
  /// cl_int2 per balance pair: (the PE of cell index c, the PE of c + 1)
  /// along an axis, c = 2 m + parity; the pairs of (axis a, parity par) are
  /// entries pair_first[2 a + par] .. pair_first[2 a + par + 1] - 1.
  cl::Buffer pairs;
  std::array<cl_int, 7> pair_first{};
  cl::Buffer view;      ///< sv_view
  cl::Buffer geometry;  ///< float[20] row geometry (zonogon strips)
  cl::Buffer steps;     ///< cl_long[9] exact stepping constants per axis
  cl::Buffer rowsum;    ///< cl_int4[P * H] (count, load, first i, last i) per row
  cl::Buffer rowlinks;  ///< cl_int4[P * H] links along x, y, z per row
  cl::Buffer rowoff;    ///< cl_int4[P * H] exclusive prefix within the PE of (count, links)
  /// cl_uint per (row, candidate column) where columns_saved: the rows'
  /// (k0, k1, link axis) per column for the fill (match.cl: sv_kpack8)
  cl::Buffer column_scratch;
  cl::Buffer column_offsets;  ///< cl_int[P]: PE p's first entry in column_scratch
  cl::Buffer petot;           ///< cl_int4[P] (segments, links x, y, z) per PE
  cl::Buffer counts;          ///< cl_int[P] segment counts
  cl::Buffer seg_offset;      ///< cl_int[P + 1]
  cl::Buffer segments;        ///< sv_segment[capacity]
  cl::Buffer rects;           ///< sv_rect[P]
  cl::Buffer loads;           ///< cl_int[P]
  cl::Buffer bounds;          ///< cl_short2[capacity]: (k0, k1) per segment, see bounds_filled
  cl::Buffer link_offset;     ///< cl_int4[P + 1]: y, z, w = start of PE p's list along x, y, z
  cl::Buffer link_list;       ///< cl_int2[capacity]: (segment, linked segment), per (axis, PE);
                              ///< cl_uint[capacity] where links_narrow
  /// cl_int4[P] where links_narrow: the first segment of PE p's link target
  /// along x, y, z (-1: none) and p's own (w).
  cl::Buffer link_base;
  cl::Buffer active;    ///< cl_uchar[P]: the PE mask (all 1 without one)
  bool masked = false;  ///< made with a mask (read() then returns it in Matching::active)
  bool linked = true;   ///< made with MatchLinks::make (link lists written)
  /// The fill read the rows' saved columns instead of stepping them again.
  bool columns_saved = false;
  /// The link entries are 16-bit pairs of indices within the PEs' segments
  /// (every PE has at most 65536 candidate rays; the rounds named ...n).
  bool links_narrow = false;
  /// `bounds` holds the segments' 16-bit (k0, k1) (written by the fill, kept
  /// by balancing with 16-bit bounds): enqueue_balance then needs no pack.
  bool bounds_filled = false;
  /// Left by enqueue_balance with BalanceUnpack::deferred: the balanced
  /// (k0, k1) are in `bounds` (16-bit) only, the segments still hold the
  /// matching's. read() returns the balanced ones either way; the kernels
  /// that take them from `bounds` are the frame's (LocalSegments::bounds).
  bool unpack_pending = false;
  std::vector<StageEvent> match_events;    ///< (active,) rows, pe, scan, fill
  std::vector<StageEvent> balance_events;  ///< pack, every round, unpack

  /// Blocking read-back as a Matching (loads as int64).
  Matching read(Device& device) const;
  /// Blocking read-back of the links in balance_links()'s format
  /// (seg_offset[P] entries, from the link lists written by enqueue_match).
  /// ArgumentError if made with MatchLinks::skip; Error if the lists link a
  /// segment twice or out of range.
  std::vector<int32_t> read_links(Device& device) const;
};

/// Enqueues the matching. Throws ArgumentError if the split does not fit the
/// view or the sizes exceed 32-bit indexing.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             MatchLinks links = MatchLinks::make);
/// The matching of the PEs flagged in `active` (P flags, uploaded; see the
/// file comment); ArgumentError if it has another size.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const std::vector<uint8_t>& active,
                             MatchLinks links = MatchLinks::make);
/// The brick reach of empty-space skipping (local_cl.hpp: DeviceOccupancy):
/// cl_uchar per brick, `bricks` per axis.
struct BrickReach {
  const cl::Buffer* reach = nullptr;
  std::array<cl_int, 3> bricks{0, 0, 0};
};
/// The matching of the PEs whose cell meets a brick with reach, the mask
/// made on the device (simdvol_match_active, equal to
/// match_active_reference). ArgumentError if the bricks do not tile the
/// split's volume.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const BrickReach& reach, MatchLinks links = MatchLinks::make);

/// The PE tables of a split, as DeviceMatching holds them: the cell index
/// of each PE (cidx), the PE of each cell (pe_of) and the balance rounds'
/// pairs (pairs, pair_first). They depend on the split alone, so a caller
/// that matches frame after frame under one split makes them once and
/// passes them to enqueue_match (the engine's way: at 8,192 PEs about a
/// quarter of a millisecond of host work a frame otherwise, beside the
/// kernels that share the CPU). They also hold the every-PE mask (P bytes
/// of 1) that the matching without a mask reads, so that it too is made
/// once rather than uploaded every frame.
struct DevicePeTables {
  KdSplit split;  ///< the split they were made for
  cl::Buffer cidx, pe_of, pairs;
  std::array<cl_int, 7> pair_first{};
  cl::Buffer every_pe;  ///< cl_uchar[max(P, 1)], all 1: the mask of the every-PE matching
};
/// Makes and uploads the PE tables of `split`.
DevicePeTables upload_pe_tables(Device& device, const KdSplit& split);
/// enqueue_match(device, view, split, reach, links) with the split's tables
/// made before; ArgumentError if they were made for another split.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const BrickReach& reach, const DevicePeTables& tables,
                             MatchLinks links = MatchLinks::make);
/// enqueue_match(device, view, split, links) (every PE) with the split's
/// tables made before; ArgumentError if they were made for another split.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const DevicePeTables& tables, MatchLinks links = MatchLinks::make);

/// The width of the bounds the balance rounds move: 16-bit where every k of
/// the grid fits (automatic: balance_bounds16), or as asked.
enum class BalanceBounds { automatic, narrow, wide };
/// Whether 16-bit bounds hold every k of a grid `depth` samples deep.
bool balance_bounds16(int64_t depth);

/// Whether the balanced bounds go back into the segments at the end of
/// enqueue_balance (now: simdvol_balance_unpack), or, with 16-bit bounds,
/// stay in DeviceMatching::bounds for the kernels that read them there
/// (deferred: unpack_pending; the frame's segment order and fused resample
/// + local, which saves the unpack's pass over every segment, about a third
/// of the balance stage). With 32-bit bounds both unpack now.
enum class BalanceUnpack { now, deferred };

/// Enqueues `sweeps` sweeps of balancing on `m` (made by enqueue_match with
/// the same view and split). Throws ArgumentError for sweeps < 0, for
/// BalanceBounds::narrow where the grid is too deep for it, or for sweeps > 0
/// on a matching made with MatchLinks::skip. A pending unpack of an earlier
/// balance is done first where these rounds take 32-bit bounds (packed from
/// the segments).
void enqueue_balance(Device& device, DeviceMatching& m, const ViewGeometry& view,
                     const KdSplit& split, int sweeps = kBalanceSweeps,
                     BalanceBounds bounds = BalanceBounds::automatic,
                     BalanceUnpack unpack = BalanceUnpack::now);
/// Writes the balanced bounds of a deferred unpack into the segments
/// (simdvol_balance_unpack16); nothing where none is pending.
void enqueue_balance_unpack(Device& device, DeviceMatching& m);

}  // namespace simdvol
