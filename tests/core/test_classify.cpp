// The classify stage's reference (thesis eq 4.4): ramps, the material
// mixture, the transfer function, opacity-step correction, presets and the
// classifier file format.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include <unistd.h>

#include "simdvol/classify.hpp"
#include "simdvol/error.hpp"
#include "simdvol/volume.hpp"

using namespace simdvol;

namespace {

Ramp make_ramp(std::vector<float> x, std::vector<float> y) {
  Ramp r;
  r.x = std::move(x);
  r.y = std::move(y);
  return r;
}

// Three materials: A (0, sigma 1), B (10, sigma 2), C (20, sigma 2).
Classifier abc() {
  Classifier c;
  c.kind = Classifier::Kind::mixture;
  c.mixture.materials = {{"A", 0.0f, 1.0f, 1.0f, 0.0f, 0.0f, 0.5f},
                         {"B", 10.0f, 2.0f, 0.0f, 1.0f, 0.0f, 1.0f},
                         {"C", 20.0f, 2.0f, 0.0f, 0.0f, 1.0f, 0.2f}};
  return c;
}

// ln N(I; mean, sigma) up to the shared constant, written out.
double ll(double I, double mean, double sigma) {
  return -(I - mean) * (I - mean) / (2 * sigma * sigma) - std::log(sigma);
}

// A file in a per-process temporary directory, removed with the fixture.
class ClassifierFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("simdvol_test_classify_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::filesystem::path write(const std::string& text, const std::string& name = "tf.txt") {
    const auto p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }

  // Loads `text`, expects a FileError whose message names the file and
  // contains every piece of `expected`.
  void expect_error(const std::string& text, std::initializer_list<std::string> expected) {
    const auto p = write(text);
    try {
      load_classifier(p);
      ADD_FAILURE() << "no error for:\n" << text;
    } catch (const FileError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p.string()), std::string::npos) << msg;
      for (const auto& s : expected) EXPECT_NE(msg.find(s), std::string::npos) << msg;
    }
  }

  std::filesystem::path dir_;
};

}  // namespace

// ------------------------------------------------------------------ Ramp

TEST(Ramp, EmptyIsOne) {
  EXPECT_EQ(Ramp{}(-5.0f), 1.0f);
  EXPECT_EQ(Ramp{}(1e9f), 1.0f);
}

TEST(Ramp, KnotsBetweenAndBeyond) {
  const Ramp r = make_ramp({0, 10, 20}, {0.0f, 1.0f, 0.5f});
  EXPECT_EQ(r(-3.0f), 0.0f);  // constant below x0
  EXPECT_EQ(r(0.0f), 0.0f);
  EXPECT_EQ(r(10.0f), 1.0f);
  EXPECT_EQ(r(20.0f), 0.5f);
  EXPECT_EQ(r(99.0f), 0.5f);  // constant beyond the last
  EXPECT_EQ(r(5.0f), 0.5f);
  EXPECT_EQ(r(15.0f), 0.75f);
  EXPECT_EQ(r(2.5f), 0.25f);
  EXPECT_EQ(r(std::nanf("")), 0.0f);
}

TEST(Ramp, RepeatedXIsAStep) {
  const Ramp r = make_ramp({0, 5, 5, 10}, {0.0f, 0.0f, 1.0f, 1.0f});
  EXPECT_EQ(r(4.9f), 0.0f);
  EXPECT_EQ(r(5.0f), 1.0f);
  EXPECT_EQ(r(7.0f), 1.0f);
}

TEST(Ramp, MismatchedLengthsThrow) {
  EXPECT_THROW(make_ramp({0, 1}, {0.5f})(0.5f), ArgumentError);
}

// --------------------------------------------------------------- Mixture

TEST(Mixture, MidwayBetweenEqualSigmasIsExactlyHalf) {
  float col[3];
  const float a = classify_voxel(abc(), {}, 15.0f, 0.0f, col);
  EXPECT_EQ(col[0], 0.0f);
  EXPECT_EQ(col[1], 0.5f);  // 0.5 * 1 * 1: p_B is exactly 1/2
  EXPECT_FLOAT_EQ(col[2], 0.1f);
  EXPECT_FLOAT_EQ(a, 0.5f + 0.1f);
}

TEST(Mixture, AtAnInteriorMeanIsNearlyPure) {
  // I = 10 = mean of B; bracketing pair (B, C).
  // p_B = 1 / (1 + exp(L_C - L_B)), L_C - L_B = -100 / 8 = -12.5.
  const double pB = 1.0 / (1.0 + std::exp(ll(10, 20, 2) - ll(10, 10, 2)));
  EXPECT_NEAR(pB, 1.0 / (1.0 + std::exp(-12.5)), 1e-15);
  float col[3];
  const float a = classify_voxel(abc(), {}, 10.0f, 0.0f, col);
  EXPECT_NEAR(a, pB * 1.0 + (1 - pB) * 0.2, 1e-7);
  EXPECT_NEAR(col[1], pB, 1e-7);
  EXPECT_NEAR(col[2], (1 - pB) * 0.2, 1e-7);
  EXPECT_GT(pB, 0.99999);
}

TEST(Mixture, UnequalSigmasByHand) {
  // I = 3 between A (0, 1) and B (10, 2):
  // L_A = -4.5, L_B = -49/8 - ln 2; p_A = 1 / (1 + exp(L_B - L_A)).
  const double pA = 1.0 / (1.0 + std::exp((-49.0 / 8.0 - std::log(2.0)) - (-4.5)));
  EXPECT_NEAR(pA, 0.9103, 1e-4);
  float col[3];
  const float a = classify_voxel(abc(), {}, 3.0f, 0.0f, col);
  EXPECT_NEAR(a, pA * 0.5 + (1 - pA) * 1.0, 1e-7);
  EXPECT_NEAR(col[0], pA * 0.5, 1e-7);
  EXPECT_NEAR(col[1], (1 - pA) * 1.0, 1e-7);
  EXPECT_EQ(col[2], 0.0f);
}

TEST(Mixture, BelowFirstAndAboveLastArePure) {
  float col[3];
  EXPECT_EQ(classify_voxel(abc(), {}, -5.0f, 0.0f, col), 0.5f);
  EXPECT_EQ(col[0], 0.5f);
  EXPECT_EQ(col[1], 0.0f);
  EXPECT_EQ(col[2], 0.0f);
  EXPECT_EQ(classify_voxel(abc(), {}, 0.0f, 0.0f, col), 0.5f);  // at the first mean
  EXPECT_EQ(classify_voxel(abc(), {}, 100.0f, 0.0f, col), 0.2f);
  EXPECT_EQ(col[0], 0.0f);
  EXPECT_EQ(col[1], 0.0f);
  EXPECT_EQ(col[2], 0.2f);
  EXPECT_EQ(classify_voxel(abc(), {}, 20.0f, 0.0f, col), 0.2f);  // at the last mean
}

TEST(Mixture, FarBetweenTwoMaterialsDoesNotOverflow) {
  // exp(L_j - L_i) overflows to inf far from material i: p_i = 0, not NaN.
  Classifier c;
  c.mixture.materials = {{"lo", 0.0f, 0.001f, 1, 1, 1, 0.3f}, {"hi", 1e6f, 1e5f, 1, 1, 1, 0.9f}};
  float col[3];
  EXPECT_FLOAT_EQ(classify_voxel(c, {}, 5e5f, 0.0f, col), 0.9f);
}

TEST(Mixture, SmallFractionKeepsItsValue) {
  // Between a transparent "air" (mean 0, sigma 1) and "fat" (100, 1,
  // opacity 0.5): L_fat - L_air = (I^2 - (100 - I)^2) / 2, so p_fat =
  // e^dl / (1 + e^dl) is 4e-18 at I = 49.6 (dl = -40) and 2e-35 at 49.2
  // (-80). 1 - p_air rounds each to 0 in double (and below 6e-8 in float):
  // the device and the reference then disagreed on which voxels are empty.
  Classifier c;
  c.mixture.materials = {{"air", 0.0f, 1.0f, 0, 0, 0, 0.0f}, {"fat", 100.0f, 1.0f, 1, 1, 1, 0.5f}};
  float col[3];
  for (float I : {49.6f, 49.5f, 49.3f, 49.2f}) {
    const double dl = (static_cast<double>(I) * I - (100.0 - I) * (100.0 - I)) / 2.0;
    const double want = 0.5 * std::exp(dl) / (1.0 + std::exp(dl));
    SCOPED_TRACE("I = " + std::to_string(I) + ", dl = " + std::to_string(dl));
    ASSERT_LT(want, 1e-16);  // 1 - p_air in double would give 0
    EXPECT_NEAR(classify_voxel(c, {}, I, 0.0f, col), want, want * 1e-6);
  }
  // The classify stage keeps such a voxel and corrects its opacity for the
  // step without cancellation (1 - (1 - a)^s = s a for small a), and makes
  // a subnormal alpha transparent.
  Volume vol({2, 1, 1}, VoxelType::f32);
  vol.data() = {49.5f, 49.0f};
  const std::vector<ShadeSample> sh(2, ShadeSample{1.0f, 0.0f, 0, 0});
  const double a = classify_voxel(c, {}, 49.5f, 0.0f, col);
  for (double step : {0.5, 1.7}) {
    const auto out = classify(vol, sh, c, step);
    EXPECT_NEAR(out[0].a, step * a, step * a * 1e-6) << "step " << step;
    EXPECT_EQ(out[1].a, 0.0f) << "step " << step;
    EXPECT_EQ(out[1].r, 0.0f) << "step " << step;
  }
}

TEST(Mixture, RelativeMapsTheRangeToZeroOne) {
  Classifier c;
  c.mixture.relative = true;
  c.mixture.materials = {{"lo", 0.0f, 0.1f, 1, 0, 0, 0.0f},
                         {"mid", 0.5f, 0.1f, 0, 1, 0, 0.4f},
                         {"hi", 1.0f, 0.1f, 0, 0, 1, 1.0f}};
  float col[3];
  // v = 150 in [100, 300] -> I = 0.25, midway lo/mid with equal sigma.
  EXPECT_FLOAT_EQ(classify_voxel(c, {100.0f, 300.0f}, 150.0f, 0.0f, col), 0.2f);
  EXPECT_FLOAT_EQ(col[1], 0.2f);
  // v = 300 -> I = 1: pure hi.
  EXPECT_EQ(classify_voxel(c, {100.0f, 300.0f}, 300.0f, 0.0f, col), 1.0f);
  // v = 100, the range's minimum -> I = 0: pure lo, transparent. Read as an
  // absolute intensity, 100 would lie beyond the last mean: pure hi.
  EXPECT_EQ(classify_voxel(c, {100.0f, 300.0f}, 100.0f, 0.0f, col), 0.0f);
  Classifier absolute = c;
  absolute.mixture.relative = false;
  EXPECT_EQ(classify_voxel(absolute, {100.0f, 300.0f}, 100.0f, 0.0f, col), 1.0f);
  // A constant volume (max == min) maps to I = 0.
  EXPECT_EQ(classify_voxel(c, {7.0f, 7.0f}, 7.0f, 0.0f, col), 0.0f);
}

TEST(Mixture, RejectsInvalidMixtures) {
  float col[3];
  Classifier empty;
  EXPECT_THROW(classify_voxel(empty, {}, 0.0f, 0.0f, col), ArgumentError);
  Classifier unsorted = abc();
  std::swap(unsorted.mixture.materials[0], unsorted.mixture.materials[2]);
  EXPECT_THROW(classify_voxel(unsorted, {}, 0.0f, 0.0f, col), ArgumentError);
  Classifier zero_sigma = abc();
  zero_sigma.mixture.materials[1].sigma = 0.0f;
  EXPECT_THROW(classify_voxel(zero_sigma, {}, 0.0f, 0.0f, col), ArgumentError);
  Classifier opaque = abc();
  opaque.mixture.materials[1].opacity = 1.5f;
  EXPECT_THROW(classify_voxel(opaque, {}, 0.0f, 0.0f, col), ArgumentError);
  // What the kernels' float cannot hold (the reference's double could):
  // 1 / (2 sigma^2), and (difference of the means)^2 / (2 sigma^2) of two
  // neighbours (means of -3e38 and 3e38 made NaN fractions on the device).
  Classifier tiny = abc();
  tiny.mixture.materials[1].sigma = 1e-30f;
  EXPECT_THROW(classify_voxel(tiny, {}, 0.0f, 0.0f, col), ArgumentError);
  Classifier far;
  far.mixture.materials = {{"lo", -3e38f, 1, 1, 1, 1, 0.5f}, {"hi", 3e38f, 1, 1, 1, 1, 0.5f}};
  EXPECT_THROW(classify_voxel(far, {}, 0.0f, 0.0f, col), ArgumentError);
  far.mixture.materials[1].mean = 2e19f;  // (2e19)^2 = 4e38: past FLT_MAX
  far.mixture.materials[0].mean = 0.0f;
  EXPECT_THROW(classify_voxel(far, {}, 0.0f, 0.0f, col), ArgumentError);
  far.mixture.materials[1].mean = 1e18f;  // 5e35: held
  EXPECT_NO_THROW(classify_voxel(far, {}, 0.0f, 0.0f, col));
  far.mixture.materials[1].sigma = 1e-3f;  // (1e18)^2 x 5e5: not held
  EXPECT_THROW(classify_voxel(far, {}, 0.0f, 0.0f, col), ArgumentError);
}

TEST(Mixture, NaNValueIsTransparent) {
  float col[3] = {9, 9, 9};
  EXPECT_EQ(classify_voxel(abc(), {}, std::nanf(""), 0.0f, col), 0.0f);
  EXPECT_EQ(col[0], 0.0f);
}

// ------------------------------------------------------ Transfer function

TEST(Transfer, VolPackPresetValues) {
  const Classifier c = classifier_preset("volpack");
  ASSERT_EQ(c.kind, Classifier::Kind::transfer);
  // Density ramp {0, 24, 255} -> {0, 1, 1}; gradient {0, 5, 20, 221} -> {0, 0, 1, 1}.
  EXPECT_EQ(c.transfer.density(0.0f), 0.0f);
  EXPECT_EQ(c.transfer.density(12.0f), 0.5f);
  EXPECT_EQ(c.transfer.density(24.0f), 1.0f);
  EXPECT_EQ(c.transfer.density(200.0f), 1.0f);
  EXPECT_EQ(c.transfer.gradient(3.0f), 0.0f);
  EXPECT_EQ(c.transfer.gradient(5.0f), 0.0f);
  EXPECT_EQ(c.transfer.gradient(12.5f), 0.5f);
  EXPECT_EQ(c.transfer.gradient(20.0f), 1.0f);
  EXPECT_EQ(c.transfer.gradient(221.0f), 1.0f);
  float col[3];
  EXPECT_EQ(classify_voxel(c, {}, 12.0f, 12.5f, col), 0.25f);
  for (float k : col) EXPECT_EQ(k, 0.25f);  // white
  EXPECT_EQ(classify_voxel(c, {}, 6.0f, 15.5f, col), 0.25f * 0.7f);
  EXPECT_EQ(classify_voxel(c, {}, 200.0f, 4.0f, col), 0.0f);  // flat region: no surface
  EXPECT_EQ(classify_voxel(c, {}, 200.0f, 100.0f, col), 1.0f);
}

TEST(Transfer, ColourRampsAndEmptyGradient) {
  Classifier c;
  c.kind = Classifier::Kind::transfer;
  c.transfer.density = make_ramp({0, 100}, {0.0f, 0.5f});
  c.transfer.red = make_ramp({0, 100}, {1.0f, 0.0f});
  c.transfer.green = make_ramp({0, 100}, {0.0f, 1.0f});
  c.transfer.blue = make_ramp({0, 100}, {0.5f, 0.5f});
  float col[3];
  const float a = classify_voxel(c, {}, 50.0f, 1000.0f, col);  // gradient ramp empty -> 1
  EXPECT_EQ(a, 0.25f);
  EXPECT_EQ(col[0], 0.25f * 0.5f);
  EXPECT_EQ(col[1], 0.25f * 0.5f);
  EXPECT_EQ(col[2], 0.25f * 0.5f);
  c.transfer.density.y[1] = 2.0f;  // opacity above 1
  EXPECT_THROW(classify_voxel(c, {}, 50.0f, 0.0f, col), ArgumentError);
}

// ---------------------------------------------------------------- classify

TEST(Classify, SmallVolumeByHand) {
  // Voxels: -5 (pure A), 15 (B/C half and half), 20 (pure C), 3 (A/B mix).
  Volume vol({4, 1, 1}, VoxelType::f32);
  vol.data() = {-5.0f, 15.0f, 20.0f, 3.0f};
  std::vector<ShadeSample> sh(4);
  sh[0] = {0.5f, 0.1f, 0.0f, 0.0f};
  sh[1] = {1.0f, 0.0f, 0.0f, 0.0f};
  sh[2] = {2.0f, 0.5f, 0.0f, 0.0f};
  sh[3] = {0.8f, 0.05f, 0.0f, 0.0f};
  const auto out = classify(vol, sh, abc(), 1.0);
  ASSERT_EQ(out.size(), 4u);
  // Voxel 0: alpha 0.5, colour (1, 0, 0): C = min(1, c Id + Is) = (0.6, 0.1, 0.1).
  EXPECT_FLOAT_EQ(out[0].a, 0.5f);
  EXPECT_FLOAT_EQ(out[0].r, 0.5f * 0.6f);
  EXPECT_FLOAT_EQ(out[0].g, 0.5f * 0.1f);
  EXPECT_FLOAT_EQ(out[0].b, 0.5f * 0.1f);
  // Voxel 1: alpha 0.6, premultiplied (0, 0.5, 0.1): colour (0, 5/6, 1/6).
  EXPECT_FLOAT_EQ(out[1].a, 0.6f);
  EXPECT_FLOAT_EQ(out[1].r, 0.0f);
  EXPECT_FLOAT_EQ(out[1].g, 0.5f);
  EXPECT_FLOAT_EQ(out[1].b, 0.1f);
  // Voxel 2: alpha 0.2, colour (0, 0, 1): C = (0.5, 0.5, min(1, 2.5) = 1).
  EXPECT_FLOAT_EQ(out[2].a, 0.2f);
  EXPECT_FLOAT_EQ(out[2].r, 0.1f);
  EXPECT_FLOAT_EQ(out[2].g, 0.1f);
  EXPECT_FLOAT_EQ(out[2].b, 0.2f);
  // Voxel 3: p_A from UnequalSigmasByHand.
  const double pA = 1.0 / (1.0 + std::exp((-49.0 / 8.0 - std::log(2.0)) - (-4.5)));
  const double a3 = pA * 0.5 + (1 - pA);
  EXPECT_NEAR(out[3].a, a3, 1e-6);
  EXPECT_NEAR(out[3].r, a3 * std::min(1.0, pA * 0.5 / a3 * 0.8 + 0.05), 1e-6);
  EXPECT_NEAR(out[3].g, a3 * std::min(1.0, (1 - pA) / a3 * 0.8 + 0.05), 1e-6);
  EXPECT_NEAR(out[3].b, a3 * 0.05, 1e-6);
}

TEST(Classify, TransparentVoxelIsZero) {
  Classifier c = abc();
  c.mixture.materials[0].opacity = 0.0f;
  Volume vol({1, 1, 1}, VoxelType::f32);
  vol.data()[0] = -10.0f;
  const auto out = classify(vol, {ShadeSample{1.0f, 0.9f, 0, 0}}, c, 2.0);
  EXPECT_EQ(out[0].r, 0.0f);
  EXPECT_EQ(out[0].g, 0.0f);
  EXPECT_EQ(out[0].b, 0.0f);
  EXPECT_EQ(out[0].a, 0.0f);
}

TEST(Classify, OpacityStepCorrection) {
  // Pure A: alpha 0.5, colour red.
  Volume vol({1, 1, 1}, VoxelType::f32);
  vol.data()[0] = -5.0f;
  const std::vector<ShadeSample> sh{{0.5f, 0.0f, 0, 0}};
  const auto one = classify(vol, sh, abc(), 1.0);
  EXPECT_EQ(one[0].a, 0.5f);
  const auto two = classify(vol, sh, abc(), 2.0);
  EXPECT_FLOAT_EQ(two[0].a, 1.0f - 0.25f);  // 1 - (1 - 0.5)^2
  EXPECT_FLOAT_EQ(two[0].r, 0.75f * 0.5f);
  const auto half = classify(vol, sh, abc(), 0.5);
  EXPECT_FLOAT_EQ(half[0].a, static_cast<float>(1.0 - std::sqrt(0.5)));
}

// Near an opaque material the opacity step takes the mixture's own
// transparency t = p_i (1 - a_i) + p_j (1 - a_j), not 1 - alpha: alpha
// rounds to float in steps of 6e-8, so where t is 1e-6 its 1 - alpha was up
// to 6 % off, and a sample 0.4 voxels long (1 - t^0.4) off by 1e-4, enough
// for the device's float and this double to differ so (the ct-bone preset
// with --sampling pixel: adaptive and Monte Carlo images 0.05 apart).
TEST(Classify, OpacityStepOfANearlyOpaqueVoxelFromItsTransparency) {
  // ct-bone's soft tissue (mean 40, sigma 60, opacity 0) and bone (1000,
  // 250, opacity 1): between them alpha = p_bone, t = p_soft = e / (1 + e),
  // e = exp(-|dl|), computed here in long double from the definitions.
  const Classifier c = classifier_preset("ct-bone");
  auto log_n = [](long double I, long double mean, long double sigma) {
    return -(I - mean) * (I - mean) / (2 * sigma * sigma) - std::log(sigma);
  };
  int checked = 0;
  for (float I = 250.0f; I <= 420.0f; I += 0.73f) {
    const long double dl = log_n(I, 1000, 250) - log_n(I, 40, 60);
    const long double t = 1.0L / (1.0L + std::exp(dl));  // p_soft
    if (t > 1e-3L || t < 1e-9L) continue;
    Volume vol({1, 1, 1}, VoxelType::f32);
    vol.data()[0] = I;
    const std::vector<ShadeSample> sh{{1.0f, 0.0f, 0, 0}};
    for (double step : {0.4, 0.7, 2.5}) {
      const long double want = 1.0L - std::pow(t, static_cast<long double>(step));
      const auto out = classify(vol, sh, c, step);
      SCOPED_TRACE("I = " + std::to_string(I) + ", t = " + std::to_string(static_cast<double>(t)) +
                   ", step " + std::to_string(step));
      // float rounding of a' near 1 (6e-8) and nothing more
      EXPECT_NEAR(out[0].a, static_cast<double>(want), 1.2e-7);
      ++checked;
    }
  }
  EXPECT_GT(checked, 100);
}

TEST(Classify, PremultipliedColourNeverExceedsAlpha) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> val(-10.0f, 30.0f), id(0.0f, 3.0f), is(0.0f, 1.5f);
  Volume vol({7, 5, 3}, VoxelType::f32);
  std::vector<ShadeSample> sh(vol.voxel_count());
  for (std::size_t n = 0; n < sh.size(); ++n) {
    vol.data()[n] = val(rng);
    sh[n] = {id(rng), is(rng), 0.0f, 0.0f};
  }
  int positive = 0;
  for (double step : {0.5, 1.0, 1.7}) {
    const auto out = classify(vol, sh, abc(), step);
    for (const auto& p : out) {
      EXPECT_GE(p.a, 0.0f);
      EXPECT_LE(p.a, 1.0f);
      for (float k : {p.r, p.g, p.b}) {
        EXPECT_GE(k, 0.0f);
        EXPECT_LE(k, p.a * (1.0f + 1e-6f));
      }
      positive += p.a > 0;
    }
  }
  EXPECT_EQ(positive, 3 * 7 * 5 * 3);  // every material here has a > 0
}

TEST(Classify, RejectsBadArguments) {
  Volume vol({2, 2, 2}, VoxelType::f32);
  EXPECT_THROW(classify(vol, std::vector<ShadeSample>(7), abc(), 1.0), ArgumentError);
  EXPECT_THROW(classify(vol, std::vector<ShadeSample>(8), abc(), 0.0), ArgumentError);
  EXPECT_THROW(classify(vol, std::vector<ShadeSample>(8), Classifier{}, 1.0), ArgumentError);
}

// ----------------------------------------------------------------- presets

TEST(Presets, NamesAndValidity) {
  const auto names = classifier_preset_names();
  EXPECT_EQ(names, (std::vector<std::string>{"ct", "ct-bone", "mri", "volpack"}));
  for (const auto& n : names) {
    const Classifier c = classifier_preset(n);
    float col[3];
    EXPECT_NO_THROW(classify_voxel(c, {0.0f, 1.0f}, 0.5f, 1.0f, col)) << n;
  }
  try {
    classifier_preset("bogus");
    ADD_FAILURE();
  } catch (const ArgumentError& e) {
    EXPECT_NE(std::string(e.what()).find("bogus"), std::string::npos);
  }
}

TEST(Presets, CtMaterials) {
  const Classifier ct = classifier_preset("ct");
  float col[3];
  EXPECT_EQ(classify_voxel(ct, {}, -1000.0f, 0.0f, col), 0.0f);  // air
  const float soft = classify_voxel(ct, {}, 40.0f, 0.0f, col);
  const float bone = classify_voxel(ct, {}, 1000.0f, 0.0f, col);
  EXPECT_GT(soft, 0.0f);
  EXPECT_LT(soft, 0.01f);  // ~200 samples per ray: soft tissue stays faint
  EXPECT_GT(bone, 10 * soft);
  const Classifier bone_only = classifier_preset("ct-bone");
  EXPECT_EQ(classify_voxel(bone_only, {}, 1000.0f, 0.0f, col), 1.0f);
  // At the soft-tissue mean the bone fraction is 1 / (1 + exp(8.8)) ~ 1.5e-4.
  EXPECT_LT(classify_voxel(bone_only, {}, 40.0f, 0.0f, col), 2e-4f);
  EXPECT_EQ(classify_voxel(bone_only, {}, -100.0f, 0.0f, col), 0.0f);
  EXPECT_TRUE(classifier_preset("mri").mixture.relative);
  EXPECT_EQ(classifier_preset("mri").mixture.top_percentile, 99.0f);
}

// mixture_range: the minimum to the top_percentile-th percentile (the lower
// rank) of the foreground, the finite voxels above min + (max - min) / 10.
TEST(MixtureRange, PercentileOfTheForeground) {
  // 1001 voxels at 0, one each of 1 .. 100, one at 255: range 0 .. 255, the
  // foreground above 25.5 is 26 .. 100 and 255 (76 voxels); the 99th
  // percentile is rank floor(0.99 x 75) = 74 of them, 100.
  Volume vol({1102, 1, 1}, VoxelType::u8);
  for (int k = 1; k <= 100; ++k) vol.data()[static_cast<std::size_t>(k - 1)] = float(k);
  vol.data()[1100] = 255.0f;
  MaterialMixture mix;
  mix.relative = true;
  mix.top_percentile = 99.0f;
  EXPECT_EQ(mixture_range(vol, mix).min, 0.0f);
  EXPECT_EQ(mixture_range(vol, mix).max, 100.0f);
  mix.top_percentile = 50.0f;  // rank floor(0.5 x 75) = 37: 63
  EXPECT_EQ(mixture_range(vol, mix).max, 63.0f);
  mix.top_percentile = 100.0f;  // the maximum
  EXPECT_EQ(mixture_range(vol, mix).max, 255.0f);
  mix.top_percentile = 99.0f;
  // The same values in a float volume (selected, not counted), and with a
  // fraction (selected): the same rank.
  Volume f = vol;
  f.data()[5] = 6.5f;  // below the foreground: the ranks stay
  EXPECT_EQ(mixture_range(f, mix).max, 100.0f);
  f.data()[60] = 60.5f;  // in it, below the rank
  EXPECT_EQ(mixture_range(f, mix).max, 100.0f);
  f.data()[99] = 99.5f;  // the rank's own voxel: 100 -> 99.5
  EXPECT_EQ(mixture_range(f, mix).max, 99.5f);
  // NaN and infinities are not voxels of the foreground.
  f.data()[1101] = std::numeric_limits<float>::quiet_NaN();
  f.data()[1099] = std::numeric_limits<float>::infinity();
  EXPECT_EQ(mixture_range(f, mix).max, 99.5f);
  // Negative integers (i16) counted from the minimum.
  Volume h({2001, 1, 1}, VoxelType::i16);
  for (int k = 0; k <= 2000; ++k) h.data()[static_cast<std::size_t>(k)] = float(k - 1000);
  // foreground above -800: -799 .. 1000 (1800), rank floor(0.99 x 1799) = 1781: 982
  EXPECT_EQ(mixture_range(h, mix).min, -1000.0f);
  EXPECT_EQ(mixture_range(h, mix).max, 982.0f);
  // A range that is not the volume's (a caller's stale one; {} here): the
  // voxels outside it are selected, not counted past the count's end (a
  // heap overflow under ASan before). Above 0: 1 .. 100 and 255, rank 99.
  EXPECT_EQ(mixture_range(vol, mix, ValueRange{}).max, 100.0f);
  // No foreground, or not relative: the whole range.
  Volume flat({4, 4, 4}, VoxelType::u8);
  std::fill(flat.data().begin(), flat.data().end(), 7.0f);
  EXPECT_EQ(mixture_range(flat, mix).max, 7.0f);
  mix.relative = false;
  EXPECT_EQ(mixture_range(vol, mix).max, 255.0f);
  mix.relative = true;
  mix.top_percentile = 0.0f;
  EXPECT_THROW(mixture_range(vol, mix), ArgumentError);
  Classifier c = classifier_preset("mri");
  c.mixture.top_percentile = 101.0f;
  float col[3];
  EXPECT_THROW(classify_voxel(c, {0, 1}, 0.5f, 0.0f, col), ArgumentError);
}

// -------------------------------------------------------------- file format

TEST_F(ClassifierFile, ParsesATransferFunction) {
  const auto p = write(
      "# VolPack-like\n"
      "\n"
      "density 0 0 24 1   # first points\n"
      "density 255 1\n"
      "gradient 0 0 5 0 20 1 221 1\n"
      "color 0 1 0.5 0.25  100 0 1 0.5\n");
  const Classifier c = load_classifier(p);
  ASSERT_EQ(c.kind, Classifier::Kind::transfer);
  EXPECT_EQ(c.transfer.density.x, (std::vector<float>{0, 24, 255}));
  EXPECT_EQ(c.transfer.density.y, (std::vector<float>{0, 1, 1}));
  EXPECT_EQ(c.transfer.gradient.x, (std::vector<float>{0, 5, 20, 221}));
  EXPECT_EQ(c.transfer.gradient.y, (std::vector<float>{0, 0, 1, 1}));
  EXPECT_EQ(c.transfer.red.x, (std::vector<float>{0, 100}));
  EXPECT_EQ(c.transfer.green.x, (std::vector<float>{0, 100}));
  EXPECT_EQ(c.transfer.red.y, (std::vector<float>{1, 0}));
  EXPECT_EQ(c.transfer.green.y, (std::vector<float>{0.5f, 1}));
  EXPECT_EQ(c.transfer.blue.y, (std::vector<float>{0.25f, 0.5f}));
  float col[3];
  EXPECT_EQ(classify_voxel(c, {}, 12.0f, 12.5f, col), 0.25f);
}

// A UTF-8 byte-order mark and CRLF line ends (a file saved by a Windows
// editor) parse as the plain file does; the mark made line 1 fail before.
TEST_F(ClassifierFile, ParsesAFileWithAByteOrderMarkAndCrlf) {
  const Classifier plain = load_classifier(write("density 0 0 24 1\ncolor 0 1 0.5 0.25\n"));
  const Classifier bom =
      load_classifier(write("\xEF\xBB\xBF"
                            "density 0 0 24 1\r\ncolor 0 1 0.5 0.25\r\n"));
  ASSERT_EQ(bom.kind, Classifier::Kind::transfer);
  EXPECT_EQ(bom.transfer.density.x, plain.transfer.density.x);
  EXPECT_EQ(bom.transfer.density.y, plain.transfer.density.y);
  EXPECT_EQ(bom.transfer.red.y, plain.transfer.red.y);
  EXPECT_EQ(bom.transfer.blue.y, plain.transfer.blue.y);
  // Only at the start of the file: elsewhere the bytes are an unknown token.
  EXPECT_THROW(load_classifier(write("density 0 0 24 1\n\xEF\xBB\xBF"
                                     "color 0 1 1 1\n")),
               FileError);
}

TEST_F(ClassifierFile, ParsesAMixtureAndSortsByMean) {
  const auto p = write(
      "relative\n"
      "material bone 0.9 0.1 1 1 1 0.8\n"
      "material air 0 0.05 0 0 0 0\n"
      "material soft 0.4 0.1 0.8 0.5 0.4 0.01  # comment\n");
  const Classifier c = load_classifier(p);
  ASSERT_EQ(c.kind, Classifier::Kind::mixture);
  EXPECT_TRUE(c.mixture.relative);
  ASSERT_EQ(c.mixture.materials.size(), 3u);
  EXPECT_EQ(c.mixture.materials[0].name, "air");
  EXPECT_EQ(c.mixture.materials[1].name, "soft");
  EXPECT_EQ(c.mixture.materials[2].name, "bone");
  EXPECT_EQ(c.mixture.materials[1].mean, 0.4f);
  EXPECT_EQ(c.mixture.materials[1].sigma, 0.1f);
  EXPECT_EQ(c.mixture.materials[1].r, 0.8f);
  EXPECT_EQ(c.mixture.materials[1].opacity, 0.01f);
}

TEST_F(ClassifierFile, RejectsEachMalformedCaseWithItsLine) {
  expect_error("density 0 0\nfoo 1 2\n", {"line 2", "unknown directive 'foo'"});
  expect_error("# c\ndensity 0 0 10\n", {"line 2", "pairs"});
  expect_error("density 0 0 abc 1\n", {"line 1", "'abc' is not a number"});
  expect_error("density 0 0 10 1\ndensity 5 1\n", {"line 2", "ascending"});
  expect_error("gradient 5 0 5 1\n", {"line 1", "ascending"});
  expect_error("density 0 1.5\n", {"line 1", "outside [0, 1]"});
  expect_error("color 0 1 1\n", {"line 1", "four"});
  expect_error("color 0 1 1 2\n", {"line 1", "blue"});
  expect_error("material a 0 0 1 1 1 0.5\n", {"line 1", "sigma"});
  expect_error("\nmaterial a 0 -1 1 1 1 0.5\n", {"line 2", "sigma"});
  expect_error("material a 0 1 1 1 1 1.5\n", {"line 1", "opacity"});
  expect_error("material a 0 1 1 1\n", {"line 1", "7 values"});
  expect_error("material a 0 1 1 1 1 1\nmaterial b 0 2 1 1 1 1\n", {"line 2", "same mean"});
  expect_error("density 0 0 1 1\nmaterial a 0 1 1 1 1 1\n", {"line 2", "mixed"});
  expect_error("material a 0 1 1 1 1 1\ndensity 0 0 1 1\n", {"line 2", "mixed"});
  expect_error("material a -3e38 1 1 0 0 0.5\nmaterial b 3e38 1 0 1 0 0.5\n",
               {"line 2",
                "materials 'a' (mean -3e+38, sigma 1) and 'b' (mean 3e+38, sigma 1) are "
                "too far apart for their sigmas in float arithmetic"});
  expect_error("material b 3e38 1 0 1 0 0.5\n\nmaterial a -3e38 1 1 0 0 0.5\n",
               {"line 3", "too far apart"});
  // A relative sigma is held in float as it is (the intensity is mapped
  // to [0, 1], the means and sigmas are not scaled): checked as well.
  expect_error("relative\nmaterial a 0 1e-30 1 1 1 0.5\nmaterial b 1 0.1 1 1 1 0.5\n",
               {"line 2", "sigma 1e-30 of 'a' is too small for float arithmetic"});
  expect_error("relative 99 1\nmaterial a 0 1 1 1 1 0.5\n", {"line 1", "at most one value"});
  // ('relative 99' then 'relative' took 99, the reverse the maximum)
  expect_error("relative 99\nrelative\nmaterial a 0 1 1 1 1 0.5\n",
               {"line 2", "relative is given again (first on line 1)"});
  expect_error("relative 0\nmaterial a 0 1 1 1 1 0.5\n",
               {"line 1", "percentile 0 must lie in (0, 100]"});
  expect_error("relative 100.5\nmaterial a 0 1 1 1 1 0.5\n", {"line 1", "(0, 100]"});
  expect_error("relative x\nmaterial a 0 1 1 1 1 0.5\n", {"line 1", "'x' is not a number"});
  expect_error("relative\ndensity 0 0 1 1\n", {"line 1", "relative"});
  expect_error("density 0 nan\n", {"line 1", "nan"});
  expect_error("# only a comment\n\n", {"no directives"});
  expect_error("", {"no directives"});
}

TEST_F(ClassifierFile, MissingFileAndSpecs) {
  const auto missing = dir_ / "missing.txt";
  EXPECT_THROW(load_classifier(missing), FileError);
  try {
    classifier_from_spec(missing.string());
    ADD_FAILURE();
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(missing.string()), std::string::npos);
  }
  EXPECT_EQ(classifier_from_spec("volpack").kind, Classifier::Kind::transfer);
  EXPECT_EQ(classifier_from_spec("ct").mixture.materials.size(), 4u);
  const auto p = write("density 0 0 10 1\n");
  const Classifier c = classifier_from_spec(p.string());
  EXPECT_EQ(c.transfer.density.x, (std::vector<float>{0, 10}));
}
