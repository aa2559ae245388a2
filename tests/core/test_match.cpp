// Matching (floor-inverse-rotation ownership of viewing samples) and load
// balancing: the serial references.
#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstdlib>
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

TEST(Balance, OneRoundGivesEqualSharesOverTheLinkedRays) {
  // Two PEs stacked along the viewing direction (the axis view looks down
  // z, the split cuts z): every ray crosses their face, so each of the
  // giver's n segments is linked. One sweep is one round; the heavier PE
  // gives W = floor(|L0 - L1| / 2) samples, its ray r (in (j, i) order)
  // floor((r + 1) W / n) - floor(r W / n) of them where W >= n, and 1 if r
  // < W where W < n (match.hpp), every ray long enough here. Voxel sampling
  // of 4 x 4 x 13: W = 8 < n = 16 (the first 8 rays give 1, the others 0);
  // pixel sampling to 52 x 52 (4 samples per voxel along each axis): W >= n
  // (shares q or q + 1, the larger spread evenly).
  struct Case {
    Sampling sampling;
    int size;
  };
  for (const Case c : {Case{Sampling::voxel, 4}, Case{Sampling::pixel, 52}}) {
    const Dims3 dims{4, 4, 13};
    const ViewGeometry v = geometry(dims, {0, 0, 0}, c.size, c.size, c.sampling);
    const KdSplit split = kd_split(dims, 2);
    ASSERT_EQ(split.splits()[2], 2);
    const Matching m = match_reference(v, split);
    const std::vector<int32_t> link = balance_links(m, v, split);
    const int64_t giver = m.loads[0] > m.loads[1] ? 0 : 1;
    const int64_t n = m.seg_offset[giver + 1] - m.seg_offset[giver];
    const int64_t W = std::abs(m.loads[0] - m.loads[1]) / 2;
    ASSERT_GT(W, 0) << c.size;
    ASSERT_EQ(W < n, c.sampling == Sampling::voxel) << W << " " << n;
    const Matching b = balance_reference(m, v, split, 1);
    EXPECT_EQ(b.loads[giver], m.loads[giver] - W) << c.size;
    EXPECT_EQ(b.loads[1 - giver], m.loads[1 - giver] + W) << c.size;
    for (int64_t r = 0; r < n; ++r) {
      const int64_t s = m.seg_offset[giver] + r;
      ASSERT_GE(link[s], 0) << "size " << c.size << " ray " << r;
      const int64_t share = W >= n ? (r + 1) * W / n - r * W / n : (r < W ? 1 : 0);
      const int64_t got =
          (m.segments[s].k1 - m.segments[s].k0) - (b.segments[s].k1 - b.segments[s].k0);
      EXPECT_EQ(got, share) << "size " << c.size << " ray " << r;
    }
  }
}

TEST(Balance, EqualSharesNotProportionalToTheRaysLengths) {
  // An oblique view: the giver's 16 linked rays hold 2 to 6 samples, W = 28
  // (shares of 1 or 2, none longer than its ray), and each ray gives its
  // equal share all the same
  // (shares proportional to the lengths gave the long rays more, until
  // 2026-12-04).
  const Dims3 dims{17, 8, 8};
  const ViewGeometry v = geometry(dims, {0, 15, 0}, 24, 24);
  const KdSplit split = kd_split(dims, 2);
  ASSERT_EQ(split.splits()[0], 2);
  const Matching m = match_reference(v, split);
  const std::vector<int32_t> link = balance_links(m, v, split);
  const int64_t F = v.grid.step[0][2] > 0 ? 0 : 1;
  const int64_t W = std::abs(m.loads[0] - m.loads[1]) / 2;
  const int64_t giver = m.loads[0] > m.loads[1] ? 0 : 1;
  std::vector<int64_t> seg;  // the giver's linked segments, in F's order
  for (int64_t s = m.seg_offset[F]; s < m.seg_offset[F + 1]; ++s)
    if (link[s] >= 0) seg.push_back(giver == F ? s : link[s] >> 2);
  const int64_t n = static_cast<int64_t>(seg.size());
  ASSERT_GT(n, 0);
  ASSERT_GE(W, n);
  int64_t shortest = INT64_MAX, longest = 0;
  for (const int64_t s : seg) {
    shortest = std::min<int64_t>(shortest, m.segments[s].k1 - m.segments[s].k0);
    longest = std::max<int64_t>(longest, m.segments[s].k1 - m.segments[s].k0);
  }
  ASSERT_GE(shortest, (W + n - 1) / n) << "a ray shorter than a share";
  ASSERT_GE(longest, 2 * shortest) << "the lengths differ too little";
  const Matching b = balance_reference(m, v, split, 1);
  for (int64_t r = 0; r < n; ++r) {
    const int64_t s = seg[static_cast<std::size_t>(r)];
    const int64_t share = (r + 1) * W / n - r * W / n;  // W >= n
    const int64_t got =
        (m.segments[s].k1 - m.segments[s].k0) - (b.segments[s].k1 - b.segments[s].k0);
    EXPECT_EQ(got, share) << "ray " << r << " of " << n << ", W " << W;
  }
}

TEST(Balance, ShortRaysGiveWhatTheyHoldAndTheRestMakeUpTheShortfall) {
  // Sweeps until no pair moves: the loads of face neighbours then differ by
  // at most 1, or the heavier one's linked rays are empty (it gave all it
  // could). Oblique views on a small volume, where many rays are short.
  const Dims3 dims{9, 7, 11};
  for (const ViewAngles va : {ViewAngles{0, 40, 0}, ViewAngles{25, 60, 10}}) {
    const ViewGeometry v = geometry(dims, va, 16, 16);
    const KdSplit split = kd_split(dims, 8);
    const Matching m = match_reference(v, split);
    // (kMaxBalanceSweeps = 64, the most balance_reference takes.)
    const Matching b = balance_reference(m, v, split, 63);
    const Matching c = balance_reference(m, v, split, 64);
    EXPECT_EQ(c.loads, b.loads) << name(va, 8) << ": 63 sweeps did not settle";
    const std::vector<int32_t> link = balance_links(m, v, split);
    for (int64_t p = 0; p < 8; ++p)
      for (int a = 0; a < 3; ++a) {
        const int64_t dir = v.grid.step[a][2];
        Dims3 cp = split.cell_index(p);
        if (dir == 0 || cp[a] + 1 >= split.splits()[a]) continue;
        cp[a] += 1;
        const int64_t q = split.pe_of_cell(cp);
        const int64_t F = dir > 0 ? p : q, B = dir > 0 ? q : p;
        // what each side holds on the rays F's list links across this face
        int64_t holdF = 0, holdB = 0;
        for (int64_t s = m.seg_offset[F]; s < m.seg_offset[F + 1]; ++s)
          if (link[s] >= 0 && (link[s] & 3) == a) {
            holdF += b.segments[s].k1 - b.segments[s].k0;
            holdB += b.segments[link[s] >> 2].k1 - b.segments[link[s] >> 2].k0;
          }
        const int64_t d = b.loads[F] - b.loads[B];
        if (d >= 2) {
          EXPECT_EQ(holdF, 0) << name(va, 8) << " F " << F << " B " << B;
        }
        if (d <= -2) {
          EXPECT_EQ(holdB, 0) << name(va, 8) << " F " << F << " B " << B;
        }
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
  // INT_MAX sweeps ran on for hours: the engine's bound holds here too.
  EXPECT_NO_THROW(balance_reference(m, v, split, kMaxBalanceSweeps));
  EXPECT_THROW(balance_reference(m, v, split, kMaxBalanceSweeps + 1), ArgumentError);
  EXPECT_THROW(balance_reference(m, v, split, INT_MAX), ArgumentError);
}

// A caller's matching that cannot be one is refused before balance_links
// reads it (an offset or a k1 far outside read wild memory).
TEST(Balance, RejectsAnInconsistentMatching) {
  const Dims3 dims{20, 20, 20};
  const ViewGeometry v = geometry(dims, {10, 20, 30}, 24, 24);
  const KdSplit split = kd_split(dims, 32);
  const Matching m = match_reference(v, split);
  Matching bad = m;
  bad.seg_offset.back() = int64_t{1} << 30;
  EXPECT_THROW(balance_links(bad, v, split), ArgumentError);
  EXPECT_THROW(balance_reference(bad, v, split), ArgumentError);
  bad = m;
  ASSERT_FALSE(bad.segments.empty());
  bad.segments[0].k1 = 1 << 30;
  EXPECT_THROW(balance_reference(bad, v, split), ArgumentError);
  bad = m;
  bad.seg_offset[1] = bad.seg_offset[2] + 1;
  EXPECT_THROW(balance_reference(bad, v, split), ArgumentError);
  EXPECT_NO_THROW(check_matching(m, v));
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
