// Matching (floor-inverse-rotation ownership of viewing samples) and load
// balancing: the serial references.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "core/match_testing.hpp"
#include "simdvol/error.hpp"
#include "simdvol/match.hpp"

using namespace simdvol;
using namespace simdvol::testing;

namespace {

const ViewAngles kViews[] = {{0, 0, 0}, {0, 90, 0}, {0, 45, 0}, {30, 30, 30}};

std::string name(ViewAngles v, int64_t pes) {
  return "view (" + std::to_string(v.theta) + "," + std::to_string(v.phi) + "," +
         std::to_string(v.varphi) + ") P=" + std::to_string(pes);
}

}  // namespace

TEST(Match, BruteForceOwnershipOnTinyVolumes) {
  // Every sample (i, j, k) inside the volume is in the segment of the PE
  // owning floor(X), and no other sample is in any segment.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ang(-180.0, 180.0);
  for (int n = 0; n < 24; ++n) {
    const Dims3 dims{7 + n % 5, 5 + n % 3, 3 + n % 4};
    const ViewAngles va = n < 4 ? kViews[n] : ViewAngles{ang(rng), ang(rng), ang(rng)};
    const ViewGeometry v = geometry(dims, va, 12, 9, n % 2 ? Sampling::voxel : Sampling::pixel);
    for (int64_t pes : {1, 2, 8, 64, 512}) {
      const KdSplit split = kd_split(dims, pes);
      const Matching m = match_reference(v, split);
      expect_well_formed(m, pes, true, name(va, pes));
      std::vector<int64_t> owner(static_cast<std::size_t>(v.width()) * v.height() * v.depth(), -1);
      for (int64_t p = 0; p < pes; ++p)
        for (int64_t s = m.seg_offset[p]; s < m.seg_offset[p + 1]; ++s) {
          const sv_segment& g = m.segments[s];
          for (int k = g.k0; k < g.k1; ++k) {
            auto& o = owner[(static_cast<std::size_t>(k) * v.height() + g.j) * v.width() + g.i];
            ASSERT_EQ(o, -1) << name(va, pes);
            o = p;
          }
        }
      for (int k = 0; k < v.depth(); ++k)
        for (int j = 0; j < v.height(); ++j)
          for (int i = 0; i < v.width(); ++i) {
            int64_t expect = -1;
            if (v.inside(i, j, k)) {
              Dims3 c{};
              for (int a = 0; a < 3; ++a) c[a] = fixed_floor(v.fixed(a, i, j, k)) / split.cell[a];
              expect = split.pe_of_cell(c);
            }
            ASSERT_EQ(owner[(static_cast<std::size_t>(k) * v.height() + j) * v.width() + i], expect)
                << name(va, pes) << " sample " << i << "," << j << "," << k;
          }
    }
  }
}

TEST(Match, EveryInVolumeSampleToExactlyOnePeFixedViewsAllP) {
  const Dims3 dims{93, 57, 31};
  for (ViewAngles va : kViews) {
    const ViewGeometry v = geometry(dims, va, 96, 96);
    for (int64_t pes = 1; pes <= 8192; pes *= 2) {
      const Matching m = match_reference(v, kd_split(dims, pes));
      expect_well_formed(m, pes, true, name(va, pes));
      expect_tiles_rays(m, v, name(va, pes));
    }
  }
}

TEST(Match, EveryInVolumeSampleToExactlyOnePeRandomViews) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ang(-360.0, 360.0);
  const Dims3 dims{23, 17, 13};
  for (int n = 0; n < 200; ++n) {
    const ViewAngles va{ang(rng), ang(rng), ang(rng)};
    const int64_t pes = int64_t(1) << (n % 14);
    const ViewGeometry v = geometry(dims, va, 40, 32, n % 3 ? Sampling::voxel : Sampling::pixel);
    const Matching m = match_reference(v, kd_split(dims, pes));
    expect_well_formed(m, pes, true, name(va, pes));
    expect_tiles_rays(m, v, name(va, pes));
  }
}

TEST(Match, CandidatesContainEveryRay) {
  const Dims3 dims{31, 29, 37};
  const ViewGeometry v = geometry(dims, {17, 41, 73}, 50, 50);
  const KdSplit split = kd_split(dims, 64);
  const auto cand = match_candidates(v, split);
  const Matching m = match_reference(v, split);
  for (int64_t p = 0; p < 64; ++p) {
    const sv_rect c = cand[p], r = m.rects[p];
    EXPECT_GT(r.w, 0);
    EXPECT_LE(c.i0, r.i0);
    EXPECT_LE(c.j0, r.j0);
    EXPECT_GE(c.i0 + c.w, r.i0 + r.w);
    EXPECT_GE(c.j0 + c.h, r.j0 + r.h);
  }
}

TEST(Match, AxisAlignedViewGivesEachPeItsCellVolume) {
  // View 0 with voxel sampling: one sample per voxel, so each PE's load is
  // its clipped cell's voxel count.
  const Dims3 dims{32, 24, 16};
  const ViewGeometry v = geometry(dims, {0, 0, 0}, 32, 32);
  const KdSplit split = kd_split(dims, 64);
  const Matching m = match_reference(v, split);
  for (int64_t p = 0; p < 64; ++p) {
    const CellBox b = cell_box(split, p);
    EXPECT_EQ(m.loads[p], (b.hi[0] - b.lo[0]) * (b.hi[1] - b.lo[1]) * (b.hi[2] - b.lo[2]));
  }
  EXPECT_DOUBLE_EQ(m.utilisation(), 1.0);
}

TEST(Match, RejectsMismatchedSplit) {
  const ViewGeometry v = geometry({8, 8, 8}, {}, 8, 8);
  EXPECT_THROW(match_reference(v, kd_split({8, 8, 9}, 4)), ArgumentError);
}

TEST(Balance, InvariantsHoldAndLoadsImprove) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ang(-360.0, 360.0);
  const Dims3 dims{45, 39, 33};
  for (int n = 0; n < 12; ++n) {
    const ViewAngles va = n < 4 ? kViews[n] : ViewAngles{ang(rng), ang(rng), ang(rng)};
    const ViewGeometry v = geometry(dims, va, 48, 48);
    for (int64_t pes : {2, 16, 128, 1024}) {
      const KdSplit split = kd_split(dims, pes);
      const Matching m = match_reference(v, split);
      const Matching b = balance_reference(m, v, split);
      expect_balanced_invariants(m, b, v, split, name(va, pes));
      EXPECT_LE(b.max_load(), m.max_load()) << name(va, pes);
    }
  }
}

TEST(Balance, ZeroSweepsIsIdentityAndRejectsNegative) {
  const Dims3 dims{20, 20, 20};
  const ViewGeometry v = geometry(dims, {10, 20, 30}, 24, 24);
  const KdSplit split = kd_split(dims, 32);
  const Matching m = match_reference(v, split);
  const Matching b = balance_reference(m, v, split, 0);
  EXPECT_EQ(b.loads, m.loads);
  EXPECT_THROW(balance_reference(m, v, split, -1), ArgumentError);
}

TEST(Match, ActiveFromReachByVoxels) {
  // match_active_reference against a brute force over the voxels: PE p is
  // active iff some voxel it owns (split.owner) lies in a brick with reach.
  std::mt19937 rng(23);
  const int64_t brick = int64_t(1) << SV_BRICK_LOG2;
  for (const Dims3 dims : {Dims3{93, 57, 31}, Dims3{16, 16, 16}, Dims3{5, 9, 3}}) {
    Dims3 nb{};
    for (int a = 0; a < 3; ++a) nb[a] = (dims[a] + brick - 1) / brick;
    for (int64_t pes = 1; pes <= 4096; pes *= 4) {
      const KdSplit split = kd_split(dims, pes);
      std::bernoulli_distribution on(pes % 16 == 0 ? 0.01 : 0.1);
      std::vector<uint8_t> reach(static_cast<std::size_t>(nb[0] * nb[1] * nb[2]));
      for (uint8_t& r : reach) r = on(rng) ? 1 : 0;
      std::vector<uint8_t> want(static_cast<std::size_t>(pes), 0);
      for (int64_t z = 0; z < dims[2]; ++z)
        for (int64_t y = 0; y < dims[1]; ++y)
          for (int64_t x = 0; x < dims[0]; ++x)
            if (reach[static_cast<std::size_t>(((z / brick) * nb[1] + y / brick) * nb[0] +
                                               x / brick)])
              want[static_cast<std::size_t>(split.owner({x, y, z}))] = 1;
      EXPECT_EQ(match_active_reference(split, reach), want) << "P=" << pes;
    }
  }
  const KdSplit split = kd_split({16, 16, 16}, 8);
  EXPECT_THROW(match_active_reference(split, std::vector<uint8_t>(63, 1)), ArgumentError);
}
