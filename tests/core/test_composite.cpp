// Compositing along one ray: over, direct, adaptive and the Monte Carlo
// estimator (thesis ch. 7).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "simdvol/composite.hpp"
#include "simdvol/error.hpp"
#include "simdvol/phantom.hpp"
#ifdef SIMDVOL_FMA_CALLER
#include "fma_caller.hpp"
#endif

using namespace simdvol;

namespace {

Rgba random_premultiplied(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float a = u(rng);
  return {a * u(rng), a * u(rng), a * u(rng), a};
}

std::vector<Rgba> random_ray(std::mt19937& rng, int n, float max_alpha) {
  std::vector<Rgba> r(n);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (auto& s : r) {
    const float a = max_alpha * u(rng);
    s = {a * u(rng), a * u(rng), a * u(rng), a};
  }
  return r;
}

}  // namespace

TEST(Over, IsAssociative) {
  std::mt19937 rng(11);
  for (int n = 0; n < 100000; ++n) {
    const Rgba a = random_premultiplied(rng), b = random_premultiplied(rng),
               c = random_premultiplied(rng);
    const Rgba l = over(over(a, b), c), r = over(a, over(b, c));
    ASSERT_NEAR(l.r, r.r, 1e-6f);
    ASSERT_NEAR(l.g, r.g, 1e-6f);
    ASSERT_NEAR(l.b, r.b, 1e-6f);
    ASSERT_NEAR(l.a, r.a, 1e-6f);
  }
}

TEST(Over, IsNotCommutative) {
  const Rgba red{1, 0, 0, 1}, blue{0, 0, 0.5f, 0.5f};
  EXPECT_EQ(over(red, blue).r, 1.0f);
  EXPECT_EQ(over(blue, red).r, 0.5f);
}

// The references round each product and sum on its own, as the kernels do
// under FP_CONTRACT OFF, so that the tests can compare the two bit for bit:
// the build passes -ffp-contract=off. Without it a build for a target with
// FMA (-march=native) fused 0.1 + 0.9 * 0.6 into one rounding (0x1.47ae14p-1
// against 0x1.47ae16p-1). The inputs are volatile: computed at run time.
TEST(Over, RoundsProductAndSumApart) {
  volatile float front = 0.1f, alpha = 0.1f, back = 0.6f;
  const Rgba f{front, front, front, alpha}, b{back, back, back, back};
  const volatile float product = (1.0f - alpha) * back;
  const float apart = front + product;
  ASSERT_NE(apart,
            std::fma(1.0f - alpha, float(back), float(front)));  // the inputs tell them apart
  const Rgba o = over(f, b);
  EXPECT_EQ(o.r, apart);
  EXPECT_EQ(o.g, apart);
  EXPECT_EQ(o.b, apart);
}

// The public headers hold no float code that a caller's build could
// contract: over() and phantom_subsample() are compiled in the library. An
// embedding program built with -march=native (FMA; GCC contracts by default)
// got over() inline from composite.hpp and fused 0.1 + 0.9 * 0.6 into
// 0x1.47ae14p-1, where the library's composite() and the kernels give
// 0x1.47ae16p-1; phantom_subsample(1, 4, 3, 4) -0x1.5555555555559p-4 for
// -0x1.5555555555558p-4. fma_caller.cpp is built with -mfma
// -ffp-contract=fast (x86-64, GCC or Clang; skipped elsewhere and on a CPU
// without FMA).
TEST(PublicHeaders, SameBitsInACallerBuiltWithFma) {
#ifndef SIMDVOL_FMA_CALLER
  GTEST_SKIP() << "fma_caller.cpp is built only for x86-64 with GCC or Clang";
#else
  if (!__builtin_cpu_supports("fma")) GTEST_SKIP() << "this CPU has no FMA";
  volatile float front = 0.1f, alpha = 0.1f, back = 0.6f;
  const Rgba f{front, front, front, alpha}, b{back, back, back, back};
  const Rgba o = simdvol_test::over_in_fma_caller(f, b);
  const std::vector<Rgba> ray{f, b};
  const Rgba c = composite({ray, 0}, 0, CompositeParams{});
  EXPECT_EQ(c.r, 0x1.47ae16p-1f);
  EXPECT_EQ(o.r, c.r);
  EXPECT_EQ(o.g, c.g);
  EXPECT_EQ(o.b, c.b);
  EXPECT_EQ(o.a, c.a);
  volatile int64_t i = 1, n = 4;
  volatile int m = 3, s = 4;
  const double h = 2.0 / 3.0, q = (3.0 + 0.5) / 4.0 - 0.5;
  ASSERT_NE(phantom_coord(1, 4) + h * q, std::fma(h, q, phantom_coord(1, 4)));  // tells them apart
  EXPECT_EQ(simdvol_test::phantom_subsample_in_fma_caller(i, n, m, s), phantom_coord(1, 4) + h * q);
  EXPECT_EQ(simdvol_test::phantom_subsample_in_fma_caller(i, n, m, s), -0x1.5555555555558p-4);
#endif
}

TEST(Composite, TransparentRayIsBlack) {
  const std::vector<Rgba> ray(100, Rgba{0, 0, 0, 0});
  for (CompositeMode m : {CompositeMode::direct, CompositeMode::adaptive, CompositeMode::mc}) {
    CompositeParams p;
    p.mode = m;
    const Rgba c = composite({ray, 0}, 0, p);
    EXPECT_EQ(c.r, 0.0f);
    EXPECT_EQ(c.g, 0.0f);
    EXPECT_EQ(c.b, 0.0f);
    EXPECT_EQ(c.a, 0.0f);
  }
}

TEST(Composite, OpaqueFirstSampleShowsItsOwnColour) {
  std::mt19937 rng(5);
  std::vector<Rgba> ray = random_ray(rng, 50, 1.0f);
  ray[0] = {0.2f, 0.5f, 0.7f, 1.0f};
  for (CompositeMode m : {CompositeMode::direct, CompositeMode::adaptive, CompositeMode::mc}) {
    CompositeParams p;
    p.mode = m;
    p.samples = 17;
    const Rgba c = composite({ray, 3}, 9, p);
    EXPECT_FLOAT_EQ(c.r, 0.2f);
    EXPECT_FLOAT_EQ(c.g, 0.5f);
    EXPECT_FLOAT_EQ(c.b, 0.7f);
    EXPECT_FLOAT_EQ(c.a, 1.0f);
  }
}

TEST(Composite, ConstantSlabMatchesClosedForm) {
  // n samples of opacity alpha and colour C: alpha_n = 1 - (1 - alpha)^n,
  // C'_n = C alpha_n.
  for (float alpha : {0.01f, 0.05f, 0.3f, 0.9f}) {
    for (int n : {1, 2, 10, 100, 400}) {
      const std::vector<Rgba> ray(n, Rgba{0.6f * alpha, 0.3f * alpha, 0.1f * alpha, alpha});
      const Rgba c = composite_direct({ray, 0});
      const double an = 1.0 - std::pow(1.0 - alpha, n);
      EXPECT_NEAR(c.a, an, 1e-5) << alpha << " " << n;
      EXPECT_NEAR(c.r, 0.6 * an, 1e-5);
      EXPECT_NEAR(c.g, 0.3 * an, 1e-5);
      EXPECT_NEAR(c.b, 0.1 * an, 1e-5);
    }
  }
}

TEST(Composite, AdaptiveStopsAtThreshold) {
  const std::vector<Rgba> ray(100, Rgba{0.5f, 0.5f, 0.5f, 0.5f});
  // alpha after k samples: 1 - 0.5^k; 0.95 is first reached at k = 5 (0.96875).
  const Rgba c = composite_adaptive({ray, 0}, 0.95f);
  EXPECT_FLOAT_EQ(c.a, 0.96875f);
  const Rgba full = composite_adaptive({ray, 0}, 1.0f);
  EXPECT_FLOAT_EQ(full.a, composite_direct({ray, 0}).a);
  // NaN composited every sample, a negative threshold none.
  for (const float bad : {NAN, -1.0f, 0.0f, 1.5f})
    EXPECT_THROW(composite_adaptive({ray, 0}, bad), ArgumentError) << bad;
}

// Levoy's termination is alpha >= threshold: a ray whose alpha reaches the
// threshold exactly stops there. Two samples of alpha 1/2 give 3/4 exactly
// in float; a threshold of 3/4 keeps the third (green) sample out. With
// alpha > threshold (a mutant the suite let through) it was composited:
// alpha 0.875 and green 0.125.
TEST(Composite, AdaptiveStopsWhereAlphaEqualsTheThresholdExactly) {
  const std::vector<Rgba> ray{{0.5f, 0.0f, 0.0f, 0.5f},
                              {0.5f, 0.0f, 0.0f, 0.5f},
                              {0.0f, 0.5f, 0.0f, 0.5f},
                              {0.0f, 0.5f, 0.0f, 0.5f}};
  const Rgba c = composite_adaptive({ray, 0}, 0.75f);
  EXPECT_EQ(c.r, 0.75f);
  EXPECT_EQ(c.g, 0.0f);
  EXPECT_EQ(c.b, 0.0f);
  EXPECT_EQ(c.a, 0.75f);
  // Just above 3/4 the third sample is taken, and the fourth is not.
  const Rgba d = composite_adaptive({ray, 0}, std::nextafter(0.75f, 1.0f));
  EXPECT_EQ(d.g, 0.125f);
  EXPECT_EQ(d.a, 0.875f);
}

TEST(MonteCarlo, EstimatorMeanEqualsDirect) {
  // Each walk's pick X is one of the sample colours (or black) with the
  // probabilities of eq 7.3, so E[X] = over-composite exactly. With N walks
  // the mean's standard error is sqrt(Var X / N); we require every channel
  // within 5 standard errors (false alarm rate below 1e-6 per check).
  std::mt19937 rng(17);
  for (RandomStreams streams : {RandomStreams::per_ray, RandomStreams::shared}) {
    for (int trial = 0; trial < 4; ++trial) {
      const std::vector<Rgba> ray = random_ray(rng, 60, 0.15f);
      const Rgba d = composite_direct({ray, 0});
      // Exact variance of the pick, per channel.
      double ex2[4] = {0, 0, 0, 0}, ex[4] = {0, 0, 0, 0};
      double t = 1.0;
      for (const Rgba& s : ray) {
        const double w = s.a * t;
        const double col[4] = {s.r / s.a, s.g / s.a, s.b / s.a, 1.0};
        for (int c = 0; c < 4; ++c) {
          ex[c] += w * col[c];
          ex2[c] += w * col[c] * col[c];
        }
        t *= 1.0 - s.a;
      }
      EXPECT_NEAR(ex[3], d.a, 1e-5);
      CompositeParams p;
      p.mode = CompositeMode::mc;
      p.samples = 200000;
      p.seed = 1000 + trial;
      p.streams = streams;
      const Rgba m = composite_mc({ray, 0}, 12345, p);
      const double got[4] = {m.r, m.g, m.b, m.a};
      const double want[4] = {d.r, d.g, d.b, d.a};
      for (int c = 0; c < 4; ++c) {
        const double se = std::sqrt((ex2[c] - ex[c] * ex[c]) / p.samples);
        EXPECT_NEAR(got[c], want[c], 5 * se + 1e-6) << "channel " << c << " trial " << trial;
      }
    }
  }
}

TEST(MonteCarlo, SameSeedSameResultAndStreamsDiffer) {
  std::mt19937 rng(1);
  const std::vector<Rgba> ray = random_ray(rng, 40, 0.2f);
  CompositeParams p;
  p.mode = CompositeMode::mc;
  p.samples = 8;
  const Rgba a = composite_mc({ray, 0}, 7, p), b = composite_mc({ray, 0}, 7, p);
  EXPECT_EQ(a.r, b.r);
  EXPECT_EQ(a.a, b.a);
  // Per-ray streams: different rays over the same samples give different
  // estimates (in general); the shared stream gives identical ones.
  int differ = 0;
  for (uint32_t r = 0; r < 50; ++r)
    differ += composite_mc({ray, 0}, r, p).r != composite_mc({ray, 0}, r + 1000, p).r;
  EXPECT_GT(differ, 10);
  p.streams = RandomStreams::shared;
  for (uint32_t r = 0; r < 50; ++r)
    EXPECT_EQ(composite_mc({ray, 0}, r, p).r, composite_mc({ray, 0}, r + 1000, p).r);
}

// Exact opacity's stratified and fallback draws are keyed by the depth of
// the ray's first sample with alpha > 0: transparent samples in front of it
// (a PE left out by EngineOptions::skip_pes) change no result bit, for
// every variant and both streams; a different first opaque depth does.
TEST(MonteCarlo, TransparentSamplesInFrontChangeNoDraw) {
  std::mt19937 rng(5);
  int moved = 0;
  for (int trial = 0; trial < 40; ++trial) {
    std::vector<Rgba> ray = random_ray(rng, 30, 0.15f);
    ray[0] = Rgba{0.2f, 0.1f, 0.05f, 0.3f};  // the first opaque sample at depth 20
    const std::vector<Rgba> front(7, Rgba{});
    std::vector<Rgba> longer = front;
    longer.insert(longer.end(), ray.begin(), ray.end());
    for (int variant : {0, 1, 2})
      for (RandomStreams st : {RandomStreams::per_ray, RandomStreams::shared}) {
        CompositeParams p;
        p.mode = CompositeMode::mc;
        p.samples = 1 + trial % 9;
        p.seed = 99 + static_cast<uint64_t>(trial);
        p.streams = st;
        p.exact_opacity = variant >= 1;
        p.stratified = variant == 2;
        const Rgba a = composite_mc({ray, 20}, 3, p), b = composite_mc({longer, 13}, 3, p);
        EXPECT_EQ(std::memcmp(&a, &b, sizeof a), 0) << "trial " << trial << " variant " << variant;
        if (variant == 2) {
          const Rgba c = composite_mc({ray, 21}, 3, p);  // the opaque samples one step deeper
          moved += std::memcmp(&a, &c, sizeof a) != 0;
        }
      }
  }
  EXPECT_GT(moved, 20);
}
