// Checks shared by the match/balance tests (tests/core/test_match.cpp and
// tests/cl/test_match_cl.cpp).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "simdvol/match.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/view.hpp"

namespace simdvol::testing {

inline ViewGeometry geometry(const Dims3& dims, ViewAngles v, int w, int h,
                             Sampling s = Sampling::voxel, Framing f = Framing::longest) {
  return make_view(dims, {1.0, 1.0, 1.0}, v, w, h, s, f);
}

/// CSR shape, (j, i) order, rects = bbox of the rays, loads = sums; every
/// segment non-empty when `nonempty`.
inline void expect_well_formed(const Matching& m, int64_t pes, bool nonempty,
                               const std::string& what) {
  ASSERT_EQ(m.pes(), pes) << what;
  ASSERT_EQ(m.seg_offset.size(), static_cast<std::size_t>(pes + 1)) << what;
  ASSERT_EQ(m.loads.size(), static_cast<std::size_t>(pes)) << what;
  ASSERT_EQ(m.seg_offset.front(), 0) << what;
  ASSERT_EQ(m.seg_offset.back(), static_cast<int64_t>(m.segments.size())) << what;
  for (int64_t p = 0; p < pes; ++p) {
    ASSERT_LE(m.seg_offset[p], m.seg_offset[p + 1]) << what;
    int64_t load = 0, i0 = INT64_MAX, j0 = INT64_MAX, i1 = -1, j1 = -1;
    for (int64_t s = m.seg_offset[p]; s < m.seg_offset[p + 1]; ++s) {
      const sv_segment& g = m.segments[s];
      if (nonempty) {
        ASSERT_LT(g.k0, g.k1) << what << " pe " << p;
      }
      ASSERT_LE(g.k0, g.k1) << what << " pe " << p;
      if (s > m.seg_offset[p]) {
        const sv_segment& f = m.segments[s - 1];
        ASSERT_TRUE(f.j < g.j || (f.j == g.j && f.i < g.i)) << what << " pe " << p;
      }
      load += g.k1 - g.k0;
      i0 = std::min<int64_t>(i0, g.i), i1 = std::max<int64_t>(i1, g.i);
      j0 = std::min<int64_t>(j0, g.j), j1 = std::max<int64_t>(j1, g.j);
    }
    ASSERT_EQ(m.loads[p], load) << what << " pe " << p;
    const sv_rect r = m.rects[p];
    if (i1 < 0) {
      ASSERT_EQ(r.w, 0) << what;
      ASSERT_EQ(r.h, 0) << what;
    } else {
      ASSERT_EQ(r.i0, i0) << what;
      ASSERT_EQ(r.j0, j0) << what;
      ASSERT_EQ(r.w, i1 - i0 + 1) << what;
      ASSERT_EQ(r.h, j1 - j0 + 1) << what;
    }
  }
}

struct RayPiece {
  int32_t k0, k1;
  int64_t pe;
};

/// The pieces of every ray (index j * width + i), sorted by k0 (then k1).
inline std::vector<std::vector<RayPiece>> pieces_by_ray(const Matching& m, const ViewGeometry& v) {
  std::vector<std::vector<RayPiece>> rays(static_cast<std::size_t>(v.width()) * v.height());
  for (int64_t p = 0; p < m.pes(); ++p)
    for (int64_t s = m.seg_offset[p]; s < m.seg_offset[p + 1]; ++s) {
      const sv_segment& g = m.segments[s];
      rays[static_cast<std::size_t>(g.j) * v.width() + g.i].push_back({g.k0, g.k1, p});
    }
  for (auto& r : rays)
    std::sort(r.begin(), r.end(), [](const RayPiece& a, const RayPiece& b) {
      return a.k0 != b.k0 ? a.k0 < b.k0 : a.k1 < b.k1;
    });
  return rays;
}

/// Every ray's non-empty pieces tile ray_range exactly (disjoint, no gaps),
/// i.e. every in-volume sample belongs to exactly one PE.
inline void expect_tiles_rays(const Matching& m, const ViewGeometry& v, const std::string& what) {
  const auto rays = pieces_by_ray(m, v);
  for (int j = 0; j < v.height(); ++j)
    for (int i = 0; i < v.width(); ++i) {
      const auto range = v.ray_range(i, j);
      int64_t at = range[0];
      for (const RayPiece& r : rays[static_cast<std::size_t>(j) * v.width() + i]) {
        if (r.k0 == r.k1) continue;
        ASSERT_EQ(r.k0, at) << what << " ray " << i << "," << j;
        at = r.k1;
      }
      ASSERT_EQ(at, range[0] < range[1] ? range[1] : range[0]) << what << " ray " << i << "," << j;
    }
}

/// After balancing: the same segments (rays, per-PE order), rects unchanged,
/// total load unchanged, every ray still tiled, the PE order along each ray
/// unchanged, and every moved boundary one between a PE and a face neighbour.
inline void expect_balanced_invariants(const Matching& before, const Matching& after,
                                       const ViewGeometry& v, const KdSplit& split,
                                       const std::string& what) {
  expect_well_formed(after, before.pes(), false, what);
  ASSERT_EQ(after.seg_offset, before.seg_offset) << what;
  ASSERT_EQ(after.segments.size(), before.segments.size()) << what;
  for (std::size_t s = 0; s < before.segments.size(); ++s) {
    ASSERT_EQ(after.segments[s].i, before.segments[s].i) << what;
    ASSERT_EQ(after.segments[s].j, before.segments[s].j) << what;
  }
  for (int64_t p = 0; p < before.pes(); ++p) {
    ASSERT_EQ(after.rects[p].i0, before.rects[p].i0) << what;
    ASSERT_EQ(after.rects[p].j0, before.rects[p].j0) << what;
    ASSERT_EQ(after.rects[p].w, before.rects[p].w) << what;
    ASSERT_EQ(after.rects[p].h, before.rects[p].h) << what;
  }
  ASSERT_EQ(after.total_load(), before.total_load()) << what;
  expect_tiles_rays(after, v, what);
  // Order of PEs along each ray: compare the original order (by k0) with the
  // balanced one, where empty pieces sit at their boundary.
  const auto rb = pieces_by_ray(before, v);
  std::vector<std::vector<RayPiece>> ra(rb.size());
  for (int64_t p = 0; p < after.pes(); ++p)
    for (int64_t s = after.seg_offset[p]; s < after.seg_offset[p + 1]; ++s) {
      const sv_segment& g = after.segments[s];
      ra[static_cast<std::size_t>(g.j) * v.width() + g.i].push_back({g.k0, g.k1, p});
    }
  for (std::size_t r = 0; r < rb.size(); ++r) {
    std::vector<RayPiece> a = ra[r];
    // Put a's pieces in the original PE order and check they are contiguous.
    std::vector<RayPiece> ordered;
    for (const RayPiece& b : rb[r])
      for (const RayPiece& x : a)
        if (x.pe == b.pe) ordered.push_back(x);
    ASSERT_EQ(ordered.size(), rb[r].size()) << what;
    for (std::size_t n = 0; n + 1 < ordered.size(); ++n) {
      ASSERT_EQ(ordered[n].k1, ordered[n + 1].k0) << what << " ray " << r;
      const bool moved = ordered[n].k1 != rb[r][n].k1;
      if (moved) {
        const Dims3 ca = split.cell_index(ordered[n].pe), cb = split.cell_index(ordered[n + 1].pe);
        int64_t dist = 0;
        for (int a = 0; a < 3; ++a) dist += std::abs(ca[a] - cb[a]);
        ASSERT_EQ(dist, 1) << what << ": boundary moved between non-face neighbours";
      }
    }
  }
}

}  // namespace simdvol::testing
