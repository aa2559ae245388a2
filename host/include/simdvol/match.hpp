// Matching and load balancing on the PE array (thesis ch. 5.4, 5.5; eq
// 5.5–5.9): which PE resamples which viewing-space sample, as per-PE lists of
// depth segments of rays. Serial references; the device stages live in
// host/cl (kernels/match.cl, kernels/balance.cl).
#pragma once

#include <cstdint>
#include <vector>

#include "simdvol/pe_array.hpp"
#include "simdvol/view.hpp"
#include "simdvol_shared.h"

namespace simdvol {

/// Segments of every PE (CSR), their footprints and loads.
struct Matching {
  std::vector<int64_t> seg_offset;    ///< P + 1 entries
  std::vector<sv_segment> segments;   ///< per PE sorted by (j, i)
  std::vector<sv_rect> rects;         ///< P footprints (bbox of the PE's rays)
  std::vector<int64_t> loads;         ///< P sample counts (sum of k1 - k0)

  int64_t pes() const { return static_cast<int64_t>(rects.size()); }
  /// SIMD utilisation: mean load / max load (1 when every PE is idle).
  double utilisation() const;
};

/// Sample (i, j, k) belongs to PE p iff floor(X(i, j, k)) lies in p's cell
/// clipped to the volume. Exact (integer arithmetic).
Matching match_reference(const ViewGeometry& view, const KdSplit& split);

}  // namespace simdvol
