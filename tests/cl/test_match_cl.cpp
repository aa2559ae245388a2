// The match and balance stages on the device: equal to the serial references
// exactly, plus the balancing invariants and the utilisation reached.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>

#include "core/match_testing.hpp"
#include "simdvol/match_cl.hpp"
#include "stage_testing.hpp"

using namespace simdvol;
using namespace simdvol::testing;

namespace {

const ViewAngles kViews[] = {{0, 0, 0}, {0, 90, 0}, {0, 45, 0}, {30, 30, 30}};

// Three angles uniform in [-360, 360) degrees.
ViewAngles random_view(std::mt19937& rng) {
  std::uniform_real_distribution<double> ang(-360.0, 360.0);
  const double t = ang(rng), p = ang(rng);
  return {t, p, ang(rng)};
}

std::string name(ViewAngles v, int64_t pes) {
  return "view (" + std::to_string(v.theta) + "," + std::to_string(v.phi) + "," +
         std::to_string(v.varphi) + ") P=" + std::to_string(pes);
}

void expect_same(const Matching& a, const Matching& b, const std::string& what) {
  ASSERT_EQ(a.seg_offset, b.seg_offset) << what;
  ASSERT_EQ(a.loads, b.loads) << what;
  ASSERT_EQ(a.segments.size(), b.segments.size()) << what;
  for (std::size_t s = 0; s < a.segments.size(); ++s) {
    const sv_segment &x = a.segments[s], &y = b.segments[s];
    ASSERT_TRUE(x.i == y.i && x.j == y.j && x.k0 == y.k0 && x.k1 == y.k1)
        << what << " segment " << s;
  }
  for (std::size_t p = 0; p < a.rects.size(); ++p) {
    const sv_rect &x = a.rects[p], &y = b.rects[p];
    ASSERT_TRUE(x.i0 == y.i0 && x.j0 == y.j0 && x.w == y.w && x.h == y.h) << what << " pe " << p;
  }
}

// Runs match (and balance when sweeps >= 0) on the device and checks both
// against the references.
// Rows of a PE whose segments skip a ray between their first and last (the
// device fill's cursor for link targets).
int64_t rows_with_holes(const Matching& m) {
  int64_t n = 0;
  for (int64_t p = 0; p < m.pes(); ++p)
    for (int64_t s = m.seg_offset[p] + 1; s < m.seg_offset[p + 1]; ++s) {
      const sv_segment &f = m.segments[s - 1], &g = m.segments[s];
      n += f.j == g.j && g.i != f.i + 1;
    }
  return n;
}

void check_device(Device& dev, const ViewGeometry& v, const KdSplit& split, int sweeps,
                  const std::string& what, BalanceBounds bounds = BalanceBounds::automatic,
                  const std::vector<uint8_t>& active = {}) {
  const Matching ref = match_reference(v, split, active);
  DeviceMatching dm =
      active.empty() ? enqueue_match(dev, v, split) : enqueue_match(dev, v, split, active);
  const Matching got = dm.read(dev);
  ASSERT_EQ(got.active, ref.active) << what;
  expect_same(got, ref, what + " (match)");
  if (sweeps < 0) return;
  enqueue_balance(dev, dm, v, split, sweeps, bounds);
  EXPECT_EQ(dm.read_links(dev), balance_links(ref, v, split)) << what;
  const Matching bal = dm.read(dev);
  expect_same(bal, balance_reference(ref, v, split, sweeps), what + " (balance)");
}

}  // namespace

TEST(MatchCl, EqualsReferenceFixedViewsAllP) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{93, 57, 31};
  for (ViewAngles va : kViews) {
    const ViewGeometry v = geometry(dims, va, 96, 96);
    for (int64_t pes = 1; pes <= 8192; pes *= 2)
      check_device(dev, v, kd_split(dims, pes), pes % 8 == 1 || pes >= 256 ? 8 : -1, name(va, pes));
  }
}

TEST(MatchCl, BalanceBoundsWidths) {
  // The rounds move 16-bit bounds where the grid depth allows and 32-bit ones
  // otherwise: both give the reference's balance exactly.
  EXPECT_TRUE(balance_bounds16(32767));
  EXPECT_FALSE(balance_bounds16(32768));
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{93, 57, 31};
  for (ViewAngles va : {kViews[2], kViews[3]}) {
    const ViewGeometry v = geometry(dims, va, 96, 96);
    for (int64_t pes : {8, 512})
      for (BalanceBounds b : {BalanceBounds::narrow, BalanceBounds::wide})
        check_device(dev, v, kd_split(dims, pes), 8, name(va, pes), b);
  }
  // 16-bit bounds are refused for a grid deeper than they hold.
  ViewGeometry deep = geometry(dims, kViews[2], 96, 96);
  const KdSplit split = kd_split(dims, 8);
  DeviceMatching dm = enqueue_match(dev, deep, split);
  deep.grid.grid[2] = 40000;
  EXPECT_THROW(enqueue_balance(dev, dm, deep, split, 1, BalanceBounds::narrow), ArgumentError);
}

// The link lists hold 16-bit indices within each PE's segments where every
// PE has at most 65536 candidate rays (DeviceMatching::links_narrow), and
// (segment, linked segment) pairs otherwise: a 500 x 500 x 7 volume in a
// 520 x 520 grid gives each of 2 PEs more than 65536 rays and each of 16
// fewer. Both formats give the
// reference's links and balance, with either width of bounds.
TEST(MatchCl, LinkWidths) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{500, 500, 7};
  for (ViewAngles va : {kViews[2], kViews[3]}) {
    const ViewGeometry v = geometry(dims, va, 520, 520);
    for (int64_t pes : {2, 16}) {
      const KdSplit split = kd_split(dims, pes);
      int64_t most = 0;
      for (const sv_rect& r : match_candidates(v, split))
        most = std::max<int64_t>(most, int64_t(r.w) * r.h);
      ASSERT_EQ(most > 65536, pes == 2) << name(va, pes) << ": the case this test needs";
      EXPECT_EQ(enqueue_match(dev, v, split).links_narrow, pes == 16) << name(va, pes);
      for (BalanceBounds b : {BalanceBounds::narrow, BalanceBounds::wide})
        check_device(dev, v, split, 8, name(va, pes), b);
    }
  }
}

// Balancing one matching twice, with either width of bounds each time: the
// 16-bit bounds the fill wrote (kept equal to the segments by every
// 16-bit balance) or a pack of the segments (after a 32-bit balance, which
// leaves the fill's copy behind) give the reference's balance of as many
// sweeps.
TEST(MatchCl, RepeatedBalancingEqualsReference) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{93, 57, 31};
  const BalanceBounds n = BalanceBounds::narrow, w = BalanceBounds::wide;
  const BalanceBounds orders[][2] = {{n, n}, {w, n}, {n, w}, {w, w}};
  for (ViewAngles va : {kViews[2], kViews[3]})
    for (int64_t pes : {int64_t(64), int64_t(512)}) {
      const ViewGeometry v = geometry(dims, va, 96, 96);
      const KdSplit split = kd_split(dims, pes);
      const Matching ref = match_reference(v, split);
      // (two sweeps, then three: the rounds of five sweeps)
      const Matching want = balance_reference(ref, v, split, 5);
      for (const auto& o : orders) {
        DeviceMatching dm = enqueue_match(dev, v, split);
        ASSERT_TRUE(dm.bounds_filled);
        enqueue_balance(dev, dm, v, split, 2, o[0]);
        enqueue_balance(dev, dm, v, split, 3, o[1]);
        EXPECT_EQ(dm.bounds_filled, o[0] == n && o[1] == n);
        expect_same(dm.read(dev), want,
                    name(va, pes) + (o[0] == n ? " narrow" : " wide") +
                        (o[1] == n ? " then narrow" : " then wide"));
      }
    }
}

// A balance with its unpack deferred (BalanceUnpack::deferred, the engine's
// direct frames) leaves the balanced bounds in the fill's 16-bit copy only:
// read() still returns the reference's balance, and enqueue_balance_unpack
// writes them into the segments (then the segments are those of a balance
// that unpacked at once). Rounds of either width may follow: a 16-bit
// balance keeps the unpack pending where asked, a 32-bit one (packed from
// the segments) unpacks first; both give the reference's balance of all
// the sweeps.
TEST(MatchCl, DeferredUnpackEqualsReference) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{93, 57, 31};
  const BalanceBounds n = BalanceBounds::narrow, w = BalanceBounds::wide;
  const BalanceUnpack later = BalanceUnpack::deferred, now = BalanceUnpack::now;
  for (ViewAngles va : {kViews[2], kViews[3]})
    for (int64_t pes : {int64_t(64), int64_t(8192)}) {
      const ViewGeometry v = geometry(dims, va, 96, 96);
      const KdSplit split = kd_split(dims, pes);
      const Matching ref = match_reference(v, split);
      const Matching want2 = balance_reference(ref, v, split, 2);
      const Matching want5 = balance_reference(ref, v, split, 5);
      EXPECT_NE(want2.loads, ref.loads) << name(va, pes);  // the sweeps move samples
      DeviceMatching dm = enqueue_match(dev, v, split);
      enqueue_balance(dev, dm, v, split, 2, n, later);
      ASSERT_TRUE(dm.unpack_pending);
      expect_same(dm.read(dev), want2, name(va, pes) + " pending");
      // the segments themselves still hold the matching's bounds
      std::vector<sv_segment> raw(want2.segments.size());
      cl_check(dev.queue().enqueueReadBuffer(dm.segments, CL_TRUE, 0,
                                             raw.size() * sizeof(sv_segment), raw.data()),
               "read segments");
      bool stale = false;
      for (std::size_t s = 0; s < raw.size(); ++s)
        stale |= raw[s].k0 != ref.segments[s].k0 || raw[s].k1 != ref.segments[s].k1;
      EXPECT_FALSE(stale) << name(va, pes);
      enqueue_balance_unpack(dev, dm);
      EXPECT_FALSE(dm.unpack_pending);
      enqueue_balance_unpack(dev, dm);  // nothing pending: nothing done
      expect_same(dm.read(dev), want2, name(va, pes) + " unpacked");
      cl_check(dev.queue().enqueueReadBuffer(dm.segments, CL_TRUE, 0,
                                             raw.size() * sizeof(sv_segment), raw.data()),
               "read segments");
      for (std::size_t s = 0; s < raw.size(); ++s)
        ASSERT_TRUE(raw[s].k0 == want2.segments[s].k0 && raw[s].k1 == want2.segments[s].k1)
            << name(va, pes) << " segment " << s;
      // Deferred, then three more sweeps of each width and either unpack.
      const std::pair<BalanceBounds, BalanceUnpack> then[] = {
          {n, later}, {n, now}, {w, later}, {w, now}};
      for (const auto& [b, u] : then) {
        DeviceMatching d2 = enqueue_match(dev, v, split);
        enqueue_balance(dev, d2, v, split, 2, n, later);
        enqueue_balance(dev, d2, v, split, 3, b, u);
        EXPECT_EQ(d2.unpack_pending, b == n && u == later) << name(va, pes);
        const std::string what = name(va, pes) + (b == n ? " then narrow" : " then wide") +
                                 (u == later ? " deferred" : "");
        expect_same(d2.read(dev), want5, what);
        enqueue_balance_unpack(dev, d2);
        expect_same(d2.read(dev), want5, what + ", unpacked");
      }
    }
}

TEST(MatchCl, EqualsReferenceRandomViews) {
  SIMDVOL_TEST_DEVICE(dev);
  std::mt19937 rng(9);
  const Dims3 dims{23, 17, 13};
  int64_t holes = 0;
  for (int n = 0; n < 200; ++n) {
    const ViewAngles va = random_view(rng);
    const int64_t pes = int64_t(1) << (n % 14);
    const ViewGeometry v = geometry(dims, va, 40, 32, n % 3 ? Sampling::voxel : Sampling::pixel);
    check_device(dev, v, kd_split(dims, pes), n % 4 == 0 ? 4 : -1, name(va, pes));
    holes += rows_with_holes(match_reference(v, kd_split(dims, pes)));
  }
  // The random views include rows with holes, so the cursor is covered.
  EXPECT_GT(holes, 0);
}

TEST(MatchCl, BalanceInvariantsOnDevice) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{61, 47, 39};
  std::mt19937 rng(2);
  for (int n = 0; n < 8; ++n) {
    const ViewAngles va = n < 4 ? kViews[n] : random_view(rng);
    const ViewGeometry v = geometry(dims, va, 64, 64);
    for (int64_t pes : {64, 512, 4096}) {
      const KdSplit split = kd_split(dims, pes);
      DeviceMatching dm = enqueue_match(dev, v, split);
      const Matching m = dm.read(dev);
      enqueue_balance(dev, dm, v, split, 8);
      const Matching b = dm.read(dev);
      expect_balanced_invariants(m, b, v, split, name(va, pes));
      EXPECT_LE(b.max_load(), m.max_load()) << name(va, pes);
    }
  }
}

TEST(MatchCl, UtilisationAfterBalancing256) {
  // The 256^3 volume at 256^2 voxel sampling. Goal (issue 4): >= 0.95 after
  // balancing for every view. Reached for the axis views and for 45 deg at
  // 512 PEs; not for the oblique views: the 258^2 viewing grid clips the
  // rotated volume's corners, so some PEs have no sample at all, and
  // balancing never creates segments, so mean / max stays below the fraction
  // of PEs with work (0.89-0.97 here; see simdvol-bench-match). The floors
  // below are what 8 sweeps reach (measured, minus 0.005).
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{256, 256, 256};
  struct Case {
    ViewAngles view;
    int64_t pes;
    double floor;
  };
  const Case cases[] = {
      {{0, 0, 0}, 512, 1.0},
      {{0, 0, 0}, 8192, 1.0},
      {{0, 90, 0}, 512, 1.0},
      {{0, 90, 0}, 8192, 1.0},
      {{0, 45, 0}, 512, 0.95},
      {{0, 45, 0}, 8192, 0.904},
      {{30, 30, 30}, 512, 0.879},
      {{30, 30, 30}, 8192, 0.834},
      {{37.3, 112.9, -61.4}, 512, 0.92},
      {{37.3, 112.9, -61.4}, 8192, 0.866},
  };
  for (const Case& c : cases) {
    const ViewGeometry v = geometry(dims, c.view, 256, 256);
    const KdSplit split = kd_split(dims, c.pes);
    DeviceMatching dm = enqueue_match(dev, v, split);
    const Matching before = dm.read(dev);
    enqueue_balance(dev, dm, v, split);
    const Matching after = dm.read(dev);
    EXPECT_GE(after.utilisation(), c.floor) << name(c.view, c.pes);
    EXPECT_GE(after.utilisation(), before.utilisation()) << name(c.view, c.pes);
    EXPECT_EQ(after.total_load(), before.total_load()) << name(c.view, c.pes);
  }
}

TEST(MatchCl, UtilisationGoalWithTheWholeVolumeInView) {
  // The same 256^3 volume framed by its diagonal (render --fit diagonal):
  // the viewing grid holds the whole rotated volume, every PE has samples,
  // and 8 sweeps reach the goal (>= 0.95) for every view. Measured (the
  // device kernels, 200 random views plus 45, 30 and (30, 30, 30) deg, P =
  // 512, 2048, 8192): at least 0.991 after balancing; before it 0.932 at
  // 8192 PEs.
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{256, 256, 256};
  std::vector<ViewAngles> views = {{0, 0, 0},  {0, 90, 0},   {0, 45, 0},
                                   {0, 30, 0}, {30, 30, 30}, {37.3, 112.9, -61.4}};
  std::mt19937 rng(11);
  for (int n = 0; n < 4; ++n) views.push_back(random_view(rng));
  for (const int64_t pes : {int64_t{512}, int64_t{8192}}) {
    const KdSplit split = kd_split(dims, pes);
    for (const ViewAngles& va : views) {
      const ViewGeometry v = geometry(dims, va, 256, 256, Sampling::voxel, Framing::diagonal);
      DeviceMatching dm = enqueue_match(dev, v, split);
      const Matching before = dm.read(dev);
      enqueue_balance(dev, dm, v, split);
      const Matching after = dm.read(dev);
      int64_t idle = 0;
      for (const int64_t l : before.loads) idle += l == 0;
      EXPECT_EQ(idle, 0) << name(va, pes);
      EXPECT_GE(after.utilisation(), 0.95) << name(va, pes);
      EXPECT_EQ(after.total_load(), before.total_load()) << name(va, pes);
      // Balancing does the work: 45 deg at 8,192 PEs starts below the goal.
      if (pes == 8192 && va.theta == 0 && va.phi == 45) {
        EXPECT_LT(before.utilisation(), 0.95) << name(va, pes);
      }
    }
  }
}

// ---- the PE mask (empty-space skipping of whole PEs) ----

namespace {

std::vector<uint8_t> random_mask(int64_t pes, double p_on, std::mt19937& rng) {
  std::bernoulli_distribution on(p_on);
  std::vector<uint8_t> m(static_cast<std::size_t>(pes));
  for (uint8_t& x : m) x = on(rng) ? 1 : 0;
  return m;
}

}  // namespace

// The fill reads the columns simdvol_match_rows saved (15-bit bounds and
// the link's axis per candidate ray) where every k fits 15 bits, and steps
// the columns again otherwise (a grid over 32,767 samples deep, which
// make_view never makes) or with SIMDVOL_MATCH_SAVED=0: each gives the
// reference's matching, links and balance. A grid over 16,384 samples deep
// sets the bounds' top bit.
TEST(MatchCl, SavedColumnsAndSteppedFill) {
  SIMDVOL_TEST_DEVICE(dev);
  const Dims3 dims{93, 57, 31};
  for (const char* env : {"0", "1"}) {
    ScopedEnv saved("SIMDVOL_MATCH_SAVED", env);
    for (ViewAngles va : {kViews[0], kViews[2], kViews[3]})
      for (int64_t pes : {8, 512, 8192}) {
        const ViewGeometry v = geometry(dims, va, 96, 96);
        const std::string what = name(va, pes) + " SIMDVOL_MATCH_SAVED=" + env;
        EXPECT_EQ(enqueue_match(dev, v, kd_split(dims, pes)).columns_saved, env[0] == '1') << what;
        check_device(dev, v, kd_split(dims, pes), 8, what);
        DeviceMatching dm = enqueue_match(dev, v, kd_split(dims, pes), MatchLinks::skip);
        expect_same(dm.read(dev), match_reference(v, kd_split(dims, pes)), what + " without links");
      }
  }
  // A slab seen nearly edge-on: about 17,000 samples deep (make_view's
  // limits keep every grid under 32,768: sqrt(3) x 16,384 at most).
  const Dims3 deep{12000, 2, 12000};
  for (ViewAngles va : {ViewAngles{0, 45, 0}, ViewAngles{0, 44.5, 0.01}}) {
    const ViewGeometry v = geometry(deep, va, 64, 64);
    ASSERT_GT(v.grid.grid[2], 16384) << "the case this test needs";
    const KdSplit split = kd_split(deep, 16);
    const Matching ref = match_reference(v, split);
    int64_t top = 0;  // segments whose k1 sets bit 14
    for (const sv_segment& g : ref.segments) top += g.k1 >= 16384;
    ASSERT_GT(top, 0) << "the case this test needs";
    EXPECT_TRUE(enqueue_match(dev, v, split).columns_saved);
    check_device(dev, v, split, 2, name(va, 16) + " depth " + std::to_string(v.grid.grid[2]));
  }
}

// Without the balance links (MatchLinks::skip, the engine's matching when
// no balancing follows): the same segments, rects and loads as the
// reference, with and without a mask; balancing and reading the links are
// refused, sweeps 0 is not.
TEST(MatchCl, WithoutLinksSameMatching) {
  SIMDVOL_TEST_DEVICE(dev);
  std::mt19937 rng(23);
  const Dims3 dims{93, 57, 31};
  for (int n = 0; n < 12; ++n) {
    const ViewAngles va = n < 4 ? kViews[n] : random_view(rng);
    const int64_t pes = int64_t(1) << (n + 2) % 14;
    const ViewGeometry v = geometry(dims, va, 96, 96);
    const KdSplit split = kd_split(dims, pes);
    const std::vector<uint8_t> mask = n % 2 ? random_mask(pes, 0.6, rng) : std::vector<uint8_t>{};
    DeviceMatching dm = enqueue_match(dev, v, split, mask, MatchLinks::skip);
    EXPECT_FALSE(dm.linked);
    expect_same(dm.read(dev), match_reference(v, split, mask), name(va, pes) + " without links");
    EXPECT_THROW(dm.read_links(dev), ArgumentError);
    EXPECT_NO_THROW(enqueue_balance(dev, dm, v, split, 0));
    EXPECT_THROW(enqueue_balance(dev, dm, v, split, 1), ArgumentError);
  }
  const ViewGeometry v = geometry(dims, kViews[2], 96, 96);
  EXPECT_TRUE(enqueue_match(dev, v, kd_split(dims, 8)).linked);
}

TEST(MatchCl, MaskedEqualsReference) {
  // Random masks: the device's segments, links and balance equal the
  // reference's with the same mask exactly; the mask removes whole PEs and
  // every link into them (a device that linked into an inactive PE, or kept
  // its rows, differs here).
  SIMDVOL_TEST_DEVICE(dev);
  std::mt19937 rng(5);
  const Dims3 dims{61, 47, 39};
  int64_t dropped_links = 0;
  for (int n = 0; n < 24; ++n) {
    const ViewAngles va = n < 4 ? kViews[n] : random_view(rng);
    const int64_t pes = int64_t(1) << (3 + n % 11);
    const ViewGeometry v = geometry(dims, va, 64, 64);
    const KdSplit split = kd_split(dims, pes);
    const std::vector<uint8_t> mask = random_mask(pes, n % 3 == 0 ? 0.9 : 0.5, rng);
    check_device(dev, v, split, 4, name(va, pes) + " masked", BalanceBounds::automatic, mask);
    // What the mask changed against the plain matching: the active PEs keep
    // their segments, the others have none, and links into them are gone.
    const Matching all = match_reference(v, split), some = match_reference(v, split, mask);
    for (int64_t p = 0; p < pes; ++p) {
      const int64_t na = all.seg_offset[p + 1] - all.seg_offset[p];
      const int64_t ns = some.seg_offset[p + 1] - some.seg_offset[p];
      ASSERT_EQ(ns, mask[p] ? na : 0) << name(va, pes) << " pe " << p;
      EXPECT_EQ(some.loads[p], mask[p] ? all.loads[p] : 0);
    }
    const auto count = [](const std::vector<int32_t>& l) {
      return std::count_if(l.begin(), l.end(), [](int32_t x) { return x >= 0; });
    };
    dropped_links += count(balance_links(all, v, split)) - count(balance_links(some, v, split));
  }
  EXPECT_GT(dropped_links, 0);
  // A mask of another size is refused, naming it.
  const ViewGeometry v = geometry(dims, kViews[2], 64, 64);
  EXPECT_THROW(enqueue_match(dev, v, kd_split(dims, 64), std::vector<uint8_t>(63, 1)),
               ArgumentError);
  EXPECT_THROW(match_reference(v, kd_split(dims, 64), std::vector<uint8_t>(65, 1)), ArgumentError);
}

TEST(MatchCl, ActiveFromReachEqualsReference) {
  // simdvol_match_active against match_active_reference on random brick
  // reach (sparse and dense), odd dims and P from 1 to 8192; then the whole
  // matching made from the reach equals the reference's with that mask.
  SIMDVOL_TEST_DEVICE(dev);
  std::mt19937 rng(17);
  const Dims3 dims{93, 57, 31};
  const int64_t brick = int64_t(1) << SV_BRICK_LOG2;
  const std::array<cl_int, 3> nb = {static_cast<cl_int>((dims[0] + brick - 1) / brick),
                                    static_cast<cl_int>((dims[1] + brick - 1) / brick),
                                    static_cast<cl_int>((dims[2] + brick - 1) / brick)};
  const std::size_t nbricks = static_cast<std::size_t>(nb[0]) * nb[1] * nb[2];
  const ViewGeometry v = geometry(dims, kViews[3], 96, 96);
  int64_t on = 0, off = 0;
  for (int64_t pes = 1; pes <= 8192; pes *= 2) {
    const std::vector<uint8_t> reach =
        random_mask(static_cast<int64_t>(nbricks), pes % 4 == 0 ? 0.002 : 0.05, rng);
    const cl::Buffer rb = dev.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, nbricks,
                                     const_cast<uint8_t*>(reach.data()), "reach");
    const KdSplit split = kd_split(dims, pes);
    const std::vector<uint8_t> want = match_active_reference(split, reach);
    DeviceMatching dm = enqueue_match(dev, v, split, BrickReach{&rb, nb});
    const Matching got = dm.read(dev);
    ASSERT_EQ(got.active, want) << "P=" << pes;
    expect_same(got, match_reference(v, split, want), "reach P=" + std::to_string(pes));
    // The same with the split's PE tables made before (the engine's), and
    // their links too.
    const DevicePeTables tables = upload_pe_tables(dev, split);
    DeviceMatching dt = enqueue_match(dev, v, split, BrickReach{&rb, nb}, tables);
    expect_same(dt.read(dev), got, "tables P=" + std::to_string(pes));
    EXPECT_EQ(dt.read_links(dev), dm.read_links(dev)) << "P=" << pes;
    // Every PE, with the tables and without, and the reference's.
    DeviceMatching da = enqueue_match(dev, v, split, tables);
    DeviceMatching d0 = enqueue_match(dev, v, split);
    const Matching all = da.read(dev);
    expect_same(all, d0.read(dev), "all PEs, tables P=" + std::to_string(pes));
    expect_same(all, match_reference(v, split), "all PEs P=" + std::to_string(pes));
    EXPECT_EQ(da.read_links(dev), d0.read_links(dev)) << "P=" << pes;
    // The tables' every-PE mask (the one those matchings read, not uploaded
    // each time) is P ones, and a second matching with them, after the
    // masked one above, matches the same.
    std::vector<uint8_t> every(static_cast<std::size_t>(pes), 0);
    cl_check(dev.queue().enqueueReadBuffer(tables.every_pe, CL_TRUE, 0, every.size(), every.data()),
             "read every_pe");
    EXPECT_EQ(std::count(every.begin(), every.end(), 1), pes) << "P=" << pes;
    expect_same(enqueue_match(dev, v, split, tables).read(dev), all,
                "all PEs again P=" + std::to_string(pes));
    on += std::count(want.begin(), want.end(), 1);
    off += std::count(want.begin(), want.end(), 0);
  }
  EXPECT_GT(on, 0);
  EXPECT_GT(off, 0);
  // Bricks that do not tile the split's volume are refused.
  const cl::Buffer rb = dev.buffer(CL_MEM_READ_WRITE, nbricks, nullptr, "reach");
  EXPECT_THROW(enqueue_match(dev, v, kd_split(dims, 8), BrickReach{&rb, {nb[0] + 1, nb[1], nb[2]}}),
               ArgumentError);
  // PE tables of another split are refused.
  EXPECT_THROW(enqueue_match(dev, v, kd_split(dims, 8), BrickReach{&rb, nb},
                             upload_pe_tables(dev, kd_split(dims, 16))),
               ArgumentError);
  EXPECT_THROW(enqueue_match(dev, v, kd_split(dims, 8), BrickReach{&rb, nb},
                             upload_pe_tables(dev, kd_split({93, 57, 32}, 8))),
               ArgumentError);
  EXPECT_THROW(enqueue_match(dev, v, kd_split(dims, 8), upload_pe_tables(dev, kd_split(dims, 16))),
               ArgumentError);
}
