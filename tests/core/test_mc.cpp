// Monte Carlo compositing references on the PE array's segments (mc.hpp):
// whole ray against the serial renderer bit for bit, exact opacity, dropped
// transparent samples, the allocation rule, and the estimators' expectations.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numeric>
#include <random>
#include <vector>

#include "simdvol/error.hpp"
#include "simdvol/local.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc.hpp"
#include "simdvol/render.hpp"

using namespace simdvol;

namespace {

// Random classified voxels, with a share of fully transparent ones.
std::vector<Rgba> random_voxels(const Dims3& d, unsigned seed, float max_alpha = 0.3f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  for (Rgba& x : v) {
    if (u(rng) < 0.3f) continue;  // transparent
    x.a = u(rng) * max_alpha;
    x.r = x.a * u(rng);
    x.g = x.a * u(rng);
    x.b = x.a * u(rng);
  }
  return v;
}

struct Case {
  Dims3 dims;
  Volume vol;
  std::vector<Rgba> voxels;
  ViewGeometry view;
  Matching m;
  std::vector<Rgba> samples;
  RaySegments rays;
  Case(Dims3 d, ViewAngles a, int64_t pes, int order, unsigned seed, int size = 24)
      : dims(d),
        vol(d, VoxelType::f32),
        voxels(random_voxels(d, seed)),
        view(make_view(vol, a, size, size, Sampling::voxel)) {
    const KdSplit split = kd_split(d, pes);
    m = balance_reference(match_reference(view, split), view, split);
    samples = resample_reference(m, voxels, d, view, order);
    rays = ray_segments(m, view.width(), view.height());
  }
  Image rendered(const CompositeParams& p, int order) const {
    RenderOptions opt;
    opt.order = order;
    opt.composite = p;
    Image inter;
    render_classified(voxels, vol, view, opt, nullptr, &inter);
    return inter;
  }
};

void expect_same(const Image& a, const Image& b) {
  ASSERT_EQ(a.pixels().size(), b.pixels().size());
  for (std::size_t q = 0; q < a.pixels().size(); ++q) {
    const Rgba &x = a.pixels()[q], &y = b.pixels()[q];
    ASSERT_EQ(x.r, y.r) << q;
    ASSERT_EQ(x.g, y.g) << q;
    ASSERT_EQ(x.b, y.b) << q;
    ASSERT_EQ(x.a, y.a) << q;
  }
}

CompositeParams mc(int n, uint64_t seed, RandomStreams st, bool exact, bool strat = false) {
  CompositeParams p;
  p.stratified = strat;
  p.mode = CompositeMode::mc;
  p.samples = n;
  p.seed = seed;
  p.streams = st;
  p.exact_opacity = exact;
  return p;
}

}  // namespace

TEST(McWhole, EqualsTheSerialRendererBitForBit) {
  for (const auto& [angles, pes, order] : {std::tuple{ViewAngles{0, 0, 0}, int64_t{64}, 1},
                                           std::tuple{ViewAngles{30, 45, 10}, int64_t{512}, 1},
                                           std::tuple{ViewAngles{10, 30, 0}, int64_t{8}, 3}}) {
    Case c({21, 17, 13}, angles, pes, order, 5);
    for (RandomStreams st : {RandomStreams::per_ray, RandomStreams::shared})
      for (bool exact : {false, true}) {
        SCOPED_TRACE(std::to_string(pes) + (exact ? " exact" : " plain") +
                     (st == RandomStreams::shared ? " shared" : " per-ray"));
        CompositeParams p = mc(7, 123, st, exact);
        const Image got = mc_whole_reference(c.m, c.samples, c.rays, p);
        if (!exact) {
          expect_same(got, c.rendered(p, order));
        } else {
          // The serial renderer has no exact-opacity mode of its own to
          // compare with; its direct alpha is the exact one.
          const Image direct = c.rendered(CompositeParams{}, order);
          for (std::size_t q = 0; q < got.pixels().size(); ++q)
            ASSERT_EQ(got.pixels()[q].a, direct.pixels()[q].a);
        }
      }
  }
}

TEST(McWhole, ExactOpacityEqualsCompositeMcWithTheOption) {
  Case c({19, 23, 11}, ViewAngles{20, 35, 5}, 256, 1, 8);
  CompositeParams p = mc(5, 77, RandomStreams::per_ray, true);
  // The serial renderer honours the new option through composite_mc.
  expect_same(mc_whole_reference(c.m, c.samples, c.rays, p), c.rendered(p, 1));
}

TEST(McSub, ExactOpacityHasZeroAlphaError) {
  Case c({20, 18, 16}, ViewAngles{15, 40, 0}, 512, 1, 9);
  const std::vector<Rgba> direct = local_reference(c.m, c.voxels, c.dims, c.view, 1);
  for (bool alloc : {false, true}) {
    CompositeParams p = mc(3, 5, RandomStreams::per_ray, true);
    const std::vector<int32_t> walks =
        alloc ? allocation_reference(c.m, c.samples, c.rays, 4) : std::vector<int32_t>{};
    const std::vector<Rgba> got = mc_sub_reference(c.m, c.samples, c.rays, p, walks);
    for (std::size_t s = 0; s < got.size(); ++s) ASSERT_EQ(got[s].a, direct[s].a) << s;
    const Image a = composite_segments(c.m, got, c.view.width(), c.view.height());
    const Image b = composite_segments(c.m, direct, c.view.width(), c.view.height());
    for (std::size_t q = 0; q < a.pixels().size(); ++q)
      ASSERT_EQ(a.pixels()[q].a, b.pixels()[q].a) << q;
  }
}

TEST(Mc, DroppingTransparentSamplesChangesNothingButTheDraws) {
  Case c({22, 14, 18}, ViewAngles{0, 30, 0}, 128, 1, 3);
  for (bool exact : {false, true}) {
    CompositeParams keep = mc(6, 9, RandomStreams::per_ray, exact), drop = keep;
    keep.drop_transparent = false;
    McStats sk, sd;
    const Image a = mc_whole_reference(c.m, c.samples, c.rays, keep, &sk);
    const Image b = mc_whole_reference(c.m, c.samples, c.rays, drop, &sd);
    expect_same(a, b);
    EXPECT_GT(sd.skipped, 0);
    EXPECT_EQ(sk.skipped, 0);
    EXPECT_EQ(sk.draws, sd.draws + sd.skipped);
    EXPECT_EQ(sk.walks, sd.walks);
    McStats tk, td;
    const std::vector<Rgba> x = mc_sub_reference(c.m, c.samples, c.rays, keep, {}, &tk);
    const std::vector<Rgba> y = mc_sub_reference(c.m, c.samples, c.rays, drop, {}, &td);
    for (std::size_t s = 0; s < x.size(); ++s) {
      ASSERT_EQ(x[s].r, y[s].r);
      ASSERT_EQ(x[s].a, y[s].a);
    }
    EXPECT_EQ(tk.draws, td.draws + td.skipped);
    EXPECT_GT(td.skipped, 0);
  }
}

TEST(Allocation, KnownCases) {
  EXPECT_EQ(allocate_walks(std::vector<float>{0.5f, 0.0f, 0.25f, 0.25f}, 7),
            (std::vector<int32_t>{3, 0, 2, 2}));
  // Weights ceil(256 alpha) = {26, 52, 77}, W = 155; r = 7: 7 w / W =
  // {1.17, 2.35, 3.48}, floors 1, 2, 3, remainders 7 w mod W = {27, 54, 74};
  // one more to the largest.
  EXPECT_EQ(allocate_walks(std::vector<float>{0.1f, 0.2f, 0.3f}, 10),
            (std::vector<int32_t>{2, 3, 5}));
  // Equal remainders: the front one first.
  EXPECT_EQ(allocate_walks(std::vector<float>{0.2f, 0.2f}, 3), (std::vector<int32_t>{2, 1}));
  // Budget below the non-transparent count: one each.
  EXPECT_EQ(allocate_walks(std::vector<float>{0.2f, 0.0f, 0.1f, 0.3f}, 2),
            (std::vector<int32_t>{1, 0, 1, 1}));
  EXPECT_EQ(allocate_walks(std::vector<float>{0.0f, -0.01f}, 8), (std::vector<int32_t>{0, 0}));
  EXPECT_EQ(allocate_walks(std::vector<float>{}, 8), (std::vector<int32_t>{}));
  EXPECT_THROW(allocate_walks(std::vector<float>{0.5f}, -1), ArgumentError);
  // Not opacities: an infinite or huge one gave negative counts
  // (-2147483646), a NaN an undefined conversion.
  for (const float bad : {INFINITY, -INFINITY, NAN, 3e38f, 1.01f})
    EXPECT_THROW(allocate_walks(std::vector<float>{bad, 0.2f, 0.3f}, 10), ArgumentError) << bad;
  // A composited opacity a hair past 1 is one.
  EXPECT_EQ(allocate_walks(std::vector<float>{1.000001f, 0.0f}, 4), (std::vector<int32_t>{4, 0}));
}

TEST(Allocation, SumsToTheBudget) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int t = 0; t < 20000; ++t) {
    const int S = 1 + static_cast<int>(rng() % 40);
    std::vector<float> a(static_cast<std::size_t>(S));
    int c = 0;
    for (float& x : a) {
      x = u(rng) < 0.3f ? 0.0f : std::pow(u(rng), 1.0f + 6.0f * u(rng));
      if (x > 0.0f) ++c;
    }
    const int budget = static_cast<int>(rng() % 200);
    const std::vector<int32_t> n = allocate_walks(a, budget);
    const int64_t sum = std::accumulate(n.begin(), n.end(), int64_t{0});
    if (c == 0) {
      ASSERT_EQ(sum, 0);
    } else {
      ASSERT_EQ(sum, std::max(budget, c)) << t;
    }
    for (int s = 0; s < S; ++s) {
      if (a[static_cast<std::size_t>(s)] > 0.0f) {
        ASSERT_GE(n[static_cast<std::size_t>(s)], 1);
      } else {
        ASSERT_EQ(n[static_cast<std::size_t>(s)], 0);
      }
    }
  }
}

TEST(Allocation, OfAMatchingSumsToTheBudgetPerRay) {
  Case c({20, 18, 16}, ViewAngles{15, 40, 0}, 512, 1, 9);
  const std::vector<float> alpha = segment_alphas(c.m, c.samples);
  const std::vector<int32_t> w = allocation_reference(c.m, c.samples, c.rays, 16);
  int rays_checked = 0;
  for (std::size_t q = 0; q + 1 < c.rays.offset.size(); ++q) {
    int64_t sum = 0, nonzero = 0;
    for (int64_t t = c.rays.offset[q]; t < c.rays.offset[q + 1]; ++t) {
      const auto s = static_cast<std::size_t>(c.rays.items[static_cast<std::size_t>(t)]);
      sum += w[s];
      if (alpha[s] > 0.0f) ++nonzero;
    }
    if (nonzero == 0) continue;
    ASSERT_EQ(sum, std::max<int64_t>(16, nonzero)) << q;
    ++rays_checked;
  }
  EXPECT_GT(rays_checked, 100);
}

// The estimators' expectation is the direct composite: the mean over many
// seeds lies within 5 standard errors (estimated from the seeds) of it, for
// every channel (a false alarm has probability ~6e-7 per comparison). Single rays first (many seeds
// are cheap).
TEST(McStatistics, SingleRayMeanIsTheDirectComposite) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 6; ++trial) {
    std::vector<Rgba> ray(static_cast<std::size_t>(5 + trial * 7));
    for (Rgba& s : ray) {
      s.a = trial % 2 ? 0.4f * u(rng) : 0.08f * u(rng);
      s.r = s.a * u(rng);
      s.g = s.a * u(rng);
      s.b = s.a * u(rng);
    }
    const Rgba direct = composite_direct(RaySamples{ray, 3});
    for (int variant : {0, 1, 2})  // plain, exact opacity, exact + stratified
      for (int walks : {1, 4}) {
        const bool exact = variant >= 1, strat = variant == 2;
        const int seeds = 6000;
        double sum[4] = {0, 0, 0, 0}, sq[4] = {0, 0, 0, 0};
        for (int s = 0; s < seeds; ++s) {
          CompositeParams p =
              mc(walks, 1000 + static_cast<uint64_t>(s), RandomStreams::per_ray, exact, strat);
          const Rgba e = composite_mc_walks(RaySamples{ray, 3}, 42, walks, p);
          const double v[4] = {e.r, e.g, e.b, e.a};
          for (int ch = 0; ch < 4; ++ch) {
            sum[ch] += v[ch];
            sq[ch] += v[ch] * v[ch];
          }
        }
        const double want[4] = {direct.r, direct.g, direct.b, direct.a};
        for (int ch = 0; ch < 4; ++ch) {
          const double mean = sum[ch] / seeds;
          const double var = std::max(0.0, sq[ch] / seeds - mean * mean);
          const double se = std::sqrt(var / seeds);
          // + 3 / seeds: an outcome of probability p <= 3 / seeds may never
          // show in the seeds (then the sample variance misses it); every
          // estimate lies in [0, 1] here, so it moves the mean by at most p.
          EXPECT_LE(std::fabs(mean - want[ch]), 5.0 * se + 3.0 / seeds)
              << "trial " << trial << " variant " << variant << " walks " << walks << " ch " << ch;
        }
      }
  }
}

// Whole images: the mean over seeds of the image's channel sums, whole ray
// and per sub-ray (plain, exact, allocated), both streams.
TEST(McStatistics, ImageMeanIsTheDirectComposite) {
  Case c({16, 14, 12}, ViewAngles{10, 30, 0}, 256, 1, 13, 16);
  const std::vector<Rgba> direct_seg = local_reference(c.m, c.voxels, c.dims, c.view, 1);
  const Image direct = composite_segments(c.m, direct_seg, c.view.width(), c.view.height());
  auto sums = [](const Image& im) {
    std::array<double, 4> s{0, 0, 0, 0};
    for (const Rgba& p : im.pixels()) {
      s[0] += p.r;
      s[1] += p.g;
      s[2] += p.b;
      s[3] += p.a;
    }
    return s;
  };
  const auto want = sums(direct);
  enum Kind { whole, sub, sub_alloc };
  for (Kind kind : {whole, sub, sub_alloc})
    for (RandomStreams st : {RandomStreams::per_ray, RandomStreams::shared})
      for (int variant : {0, 1, 2}) {  // plain, exact opacity, exact + stratified
        const bool exact = variant >= 1, strat = variant == 2;
        if (kind == sub_alloc && !exact) continue;
        const int seeds = 300;
        std::array<double, 4> sum{0, 0, 0, 0}, sq{0, 0, 0, 0};
        const std::vector<int32_t> walks = kind == sub_alloc
                                               ? allocation_reference(c.m, c.samples, c.rays, 4)
                                               : std::vector<int32_t>{};
        for (int s = 0; s < seeds; ++s) {
          const CompositeParams p = mc(2, 500 + static_cast<uint64_t>(s), st, exact, strat);
          const Image im =
              kind == whole
                  ? mc_whole_reference(c.m, c.samples, c.rays, p)
                  : composite_segments(c.m, mc_sub_reference(c.m, c.samples, c.rays, p, walks),
                                       c.view.width(), c.view.height());
          const auto v = sums(im);
          for (int ch = 0; ch < 4; ++ch) {
            sum[ch] += v[ch];
            sq[ch] += v[ch] * v[ch];
          }
        }
        for (int ch = 0; ch < 4; ++ch) {
          const double mean = sum[ch] / seeds;
          const double se = std::sqrt(std::max(0.0, sq[ch] / seeds - mean * mean) / seeds);
          EXPECT_LE(std::fabs(mean - want[ch]), 5.0 * se + 1e-4)
              << "kind " << kind << " variant " << variant << " shared "
              << (st == RandomStreams::shared) << " ch " << ch;
        }
      }
}

// Stratified picks (CompositeParams::stratified): one draw per walk, every
// walk picks (none passes the ray), and with n walks each stratum of the
// cumulative opacity gets one pick. On rays whose colour changes along the
// depth, its mean squared error over seeds must be well below that of the
// exact-opacity walks (which pick independently): asserted below half, at
// 8 walks (measured ratios are printed).
TEST(McStratified, OneDrawPerWalkAndLowerErrorThanIndependentWalks) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 4; ++trial) {
    std::vector<Rgba> ray(40);
    for (std::size_t k = 0; k < ray.size(); ++k) {
      Rgba& s = ray[k];
      s.a = k % 5 == 3 ? 0.0f : 0.1f * u(rng);  // some transparent samples
      const float depth = static_cast<float>(k) / static_cast<float>(ray.size());
      s.r = s.a * depth;
      s.g = s.a * (1.0f - depth);
      s.b = s.a * u(rng);
    }
    const Rgba direct = composite_direct(RaySamples{ray, 7});
    double se_exact = 0, se_strat = 0;
    const int seeds = 2000, walks = 8;
    for (int s = 0; s < seeds; ++s) {
      McStats st;
      const Rgba a = composite_mc_walks(RaySamples{ray, 7}, 9, walks,
                                        mc(walks, 77 + s, RandomStreams::per_ray, true));
      const Rgba b = composite_mc_walks(RaySamples{ray, 7}, 9, walks,
                                        mc(walks, 77 + s, RandomStreams::per_ray, true, true), &st);
      EXPECT_EQ(st.walks, walks);
      EXPECT_EQ(st.draws, walks);
      EXPECT_EQ(b.a, direct.a);  // exact opacity: over's recurrence, bit for bit
      auto sq = [](float x) { return static_cast<double>(x) * x; };
      se_exact += sq(a.r - direct.r) + sq(a.g - direct.g) + sq(a.b - direct.b);
      se_strat += sq(b.r - direct.r) + sq(b.g - direct.g) + sq(b.b - direct.b);
    }
    std::printf("trial %d: MSE exact-opacity walks %.3g, stratified %.3g (ratio %.3f)\n", trial,
                se_exact / seeds, se_strat / seeds, se_strat / se_exact);
    EXPECT_LT(se_strat, 0.5 * se_exact) << "trial " << trial;
  }
}

TEST(McStratified, NeedsExactOpacity) {
  const std::vector<Rgba> ray{{0.1f, 0.1f, 0.1f, 0.2f}};
  CompositeParams p = mc(4, 1, RandomStreams::per_ray, false, true);
  EXPECT_THROW(composite_mc_walks(RaySamples{ray, 0}, 0, 4, p), ArgumentError);
  RenderOptions opt;
  opt.composite = p;
  EXPECT_THROW(validate(opt), ArgumentError);
  p.exact_opacity = true;
  opt.composite = p;
  EXPECT_NO_THROW(validate(opt));
}
