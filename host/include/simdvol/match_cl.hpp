// The match and balance stages on the device (kernels/match.cl,
// kernels/balance.cl); the serial references and the definitions are in
// match.hpp.
//
// enqueue_match(device, view, split) enqueues, with no host synchronisation:
//   1. simdvol_match_count  one work-item per PE: segments in its candidate
//                           rectangle (match_candidates, computed on the host
//                           and uploaded: P x 8 vertex transforms)
//   2. simdvol_match_scan   one work-item: the exclusive prefix sum of the
//                           counts into seg_offset[P + 1] (P <= 2^20 ints: a
//                           serial scan is a few microseconds; a host scan
//                           would need a read-back and a clFinish)
//   3. simdvol_match_fill   one work-item per PE: writes its segments at
//                           seg_offset[p], its rect and its load
// The segment buffer is allocated at the exact upper bound known on the host
// before anything runs, the sum of the candidate rectangles' areas
// (`capacity`); only the first seg_offset[P] entries are written (and only
// they are ever touched, so the extra capacity costs no page faults).
//
// enqueue_balance(device, matching, view, split, sweeps) enqueues
//   1. simdvol_balance_links  one work-item per PE: balance_links()
//   2. sweeps x (axis x, y, z with a non-zero depth step) x (parity 0, 1)
//      launches of simdvol_balance_round, one work-item per PE (the lower PE
//      of each pair does the pair's work)
// and updates segments (k0/k1 only) and loads in place. The result equals
// balance_reference(read(), view, split, sweeps) exactly.
//
// Buffers of DeviceMatching, consumed by the resample/local stages:
//   seg_offset  cl_int[P + 1]    CSR offsets (int32: at most INT_MAX segments)
//   segments    sv_segment[capacity], PE p's at [seg_offset[p], seg_offset[p+1]),
//               sorted by (j, i); after balancing some may be empty (k0 == k1)
//   rects       sv_rect[P]       footprint = bbox of the PE's rays (not changed
//               by balancing)
//   loads       cl_int[P]        sum of k1 - k0 (updated by balancing)
//   links       cl_int[capacity] balance_links() (valid after enqueue_balance)
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/match.hpp"

namespace simdvol {

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
  int64_t capacity = 0;   ///< segments allocated (>= the segment count)
  cl::Buffer candidates;  ///< sv_rect[P], match_candidates()
  cl::Buffer cidx;        ///< cl_int4[P] cell index of each PE (w = 0)
  cl::Buffer pe_of;       ///< cl_int[P] PE of cell (ix, iy, iz) at (iz * sy + iy) * sx + ix
  cl::Buffer view;        ///< sv_view
  cl::Buffer counts;      ///< cl_int[P] segment counts
  cl::Buffer seg_offset;  ///< cl_int[P + 1]
  cl::Buffer segments;    ///< sv_segment[capacity]
  cl::Buffer rects;       ///< sv_rect[P]
  cl::Buffer loads;       ///< cl_int[P]
  cl::Buffer links;       ///< cl_int[capacity], after enqueue_balance
  std::vector<StageEvent> match_events;    ///< count, scan, fill
  std::vector<StageEvent> balance_events;  ///< links, then every round

  /// Blocking read-back as a Matching (loads as int64).
  Matching read(Device& device) const;
  /// Blocking read-back of the links (seg_offset[P] entries).
  std::vector<int32_t> read_links(Device& device) const;
};

/// Enqueues the matching. Throws ArgumentError if the split does not fit the
/// view or the sizes exceed 32-bit indexing.
DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split);

/// Enqueues `sweeps` sweeps of balancing on `m` (made by enqueue_match with
/// the same view and split). Throws ArgumentError for sweeps < 0.
void enqueue_balance(Device& device, DeviceMatching& m, const ViewGeometry& view,
                     const KdSplit& split, int sweeps = kBalanceSweeps);

}  // namespace simdvol
