// The analytic phantoms: Shepp–Logan (HU) and Marschner–Lobb.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>
#include <utility>

#include "simdvol/error.hpp"
#include "simdvol/phantom.hpp"

namespace simdvol {
namespace {

TEST(PhantomCoord, MapsEndsAndCentre) {
  EXPECT_EQ(phantom_coord(0, 64), -1.0);
  EXPECT_EQ(phantom_coord(63, 64), 1.0);
  EXPECT_EQ(phantom_coord(32, 65), 0.0);
  EXPECT_EQ(phantom_coord(0, 1), 0.0);
}

// Region values documented in phantom.cpp.
TEST(SheppLogan, AnalyticSpotValues) {
  EXPECT_EQ(shepp_logan_hu(0, 0, 0), 40.0f);              // brain at the centre
  EXPECT_EQ(shepp_logan_hu(0.95, 0, 0), -1000.0f);        // air beside the head
  EXPECT_EQ(shepp_logan_hu(0, 0, 0.95), -1000.0f);        // air above the head
  EXPECT_EQ(shepp_logan_hu(-1, -1, -1), -1000.0f);        // corner
  EXPECT_EQ(shepp_logan_hu(0, 0.9, 0), 1000.0f);          // skull, front/back
  EXPECT_EQ(shepp_logan_hu(0.68, 0, 0), 1000.0f);         // skull, side
  EXPECT_EQ(shepp_logan_hu(0, 0, -0.89), 1000.0f);        // skull, bottom
  EXPECT_EQ(shepp_logan_hu(0.22, 0, -0.25), -100.0f);     // right ventricle (d) centre
  EXPECT_EQ(shepp_logan_hu(-0.22, 0, -0.25), -100.0f);    // left ventricle (c) centre
  EXPECT_EQ(shepp_logan_hu(0, 0.35, -0.25), 70.0f);       // e centre
  EXPECT_EQ(shepp_logan_hu(0, 0.08, -0.25), 70.0f);       // f, outside e
  EXPECT_EQ(shepp_logan_hu(0, 0.13, -0.25), 100.0f);      // e and f overlap
  EXPECT_EQ(shepp_logan_hu(-0.08, -0.65, -0.25), 60.0f);  // g centre
  EXPECT_EQ(shepp_logan_hu(0.06, -0.65, -0.25), 60.0f);   // h centre
  EXPECT_EQ(shepp_logan_hu(0.06, -0.105, 0.625), 70.0f);  // i centre
  EXPECT_EQ(shepp_logan_hu(0, 0.1, 0.625), 0.0f);         // j centre
}

TEST(SheppLogan, RotatedVentricleFollowsItsAngle) {
  // Ellipsoid c: centre (-0.22, 0, -0.25), semi-axes 0.41 x 0.16, rotated by
  // 108 degrees, so its long axis points along (cos 108, sin 108).
  const double t = 108.0 * std::numbers::pi / 180.0;
  const double along = 0.38, across = 0.14;
  EXPECT_EQ(shepp_logan_hu(-0.22 + along * std::cos(t), along * std::sin(t), -0.25), -100.0f);
  EXPECT_EQ(shepp_logan_hu(-0.22 - along * std::cos(t), -along * std::sin(t), -0.25), -100.0f);
  // 0.38 across the long axis is well outside the 0.16 semi-axis: brain.
  EXPECT_EQ(shepp_logan_hu(-0.22 - along * std::sin(t), along * std::cos(t), -0.25), 40.0f);
  EXPECT_EQ(shepp_logan_hu(-0.22 - across * std::sin(t), across * std::cos(t), -0.25), -100.0f);
}

TEST(SheppLogan, DimsTypeAndRange) {
  const Volume v = shepp_logan(64);
  EXPECT_EQ(v.dims(), (std::array<int64_t, 3>{64, 64, 64}));
  EXPECT_EQ(v.type(), VoxelType::i16);
  const ValueRange r = v.range();
  EXPECT_EQ(r.min, -1000.0f);
  EXPECT_EQ(r.max, 1000.0f);
  // Every value is one of the documented region sums (-70: ventricle c
  // overlapping e).
  const std::set<float> allowed{-1000, -100, -70, 0, 40, 60, 70, 100, 1000};
  std::set<float> seen;
  for (float x : v.data()) {
    ASSERT_TRUE(allowed.count(x)) << x;
    ASSERT_EQ(x, std::round(x));
    seen.insert(x);
  }
  // The main tissues are all present at this resolution.
  for (float x : {-1000.0f, -100.0f, 40.0f, 70.0f, 1000.0f}) EXPECT_TRUE(seen.count(x)) << x;
}

TEST(SheppLogan, GridEqualsAnalyticFunction) {
  for (int n : {64, 33}) {
    const Volume v = shepp_logan(n);
    int64_t mismatches = 0;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          if (v.at(i, j, k) !=
              shepp_logan_hu(phantom_coord(i, n), phantom_coord(j, n), phantom_coord(k, n)))
            ++mismatches;
    EXPECT_EQ(mismatches, 0) << "n = " << n;
  }
}

TEST(SheppLogan, VoxelCountsMatchEllipsoidVolumes) {
  // Each grid point stands for a cell of side h = 2 / (n - 1), so a region's
  // point count times h^3 approximates its volume: the head (ellipsoid a) and
  // the skull shell (a minus b).
  const int n = 128;
  const Volume v = shepp_logan(n);
  int64_t bone = 0, head = 0;
  for (float x : v.data()) {
    bone += x == 1000.0f;
    head += x != -1000.0f;
  }
  const double pi = std::numbers::pi, h = 2.0 / (n - 1), cell = h * h * h;
  const double va = 4.0 / 3.0 * pi * 0.69 * 0.92 * 0.90;
  const double vb = 4.0 / 3.0 * pi * 0.6624 * 0.874 * 0.88;
  EXPECT_NEAR(head * cell, va, 0.002 * va);
  EXPECT_NEAR(bone * cell, va - vb, 0.01 * (va - vb));
}

TEST(SheppLogan, Symmetries) {
  const int n = 96;
  const Volume v = shepp_logan(n);
  auto cls = [](float x) { return x <= -500.0f ? 0 : x >= 500.0f ? 2 : 1; };
  int64_t mx = 0, my = 0, mz = 0, top = 0;
  for (int k = 0; k < n; ++k) {
    const bool above_features = phantom_coord(k, n) > 0.75;  // i, j end at z = 0.725
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const float x = v.at(i, j, k);
        // Air and skull come from the two centred ellipsoids only: mirror
        // symmetric in every axis.
        mx += cls(x) != cls(v.at(n - 1 - i, j, k));
        my += cls(x) != cls(v.at(i, n - 1 - j, k));
        mz += cls(x) != cls(v.at(i, j, n - 1 - k));
        // Above the small features the whole phantom is symmetric in x and y.
        if (above_features) top += x != v.at(n - 1 - i, j, k) || x != v.at(i, n - 1 - j, k);
      }
  }
  EXPECT_EQ(mx, 0);
  EXPECT_EQ(my, 0);
  EXPECT_EQ(mz, 0);
  EXPECT_EQ(top, 0);
  // Not symmetric everywhere: the ventricles differ in size.
  EXPECT_EQ(shepp_logan_hu(-0.3, 0.35, -0.25), -100.0f);  // inside c
  EXPECT_EQ(shepp_logan_hu(0.3, 0.35, -0.25), 40.0f);     // outside the smaller d
}

TEST(SheppLogan, TinyAndInvalidSizes) {
  const Volume v = shepp_logan(1);
  ASSERT_EQ(v.voxel_count(), 1u);
  EXPECT_EQ(v.at(0, 0, 0), 40.0f);
  EXPECT_THROW(shepp_logan(0), ArgumentError);
  EXPECT_THROW(shepp_logan(-5), ArgumentError);
}

// Partial-volume (supersampled) phantom.

// Every voxel equals the rounded mean of the analytic phantom over its s^3
// sub-samples: this also checks that the implementation's shortcut (voxels
// far inside or outside an ellipsoid are not sub-sampled) is safe.
// (n >= 64 is made in z slabs on several threads: the same values.)
TEST(SheppLoganSupersampled, EqualsMeanOfAnalyticSubSamples) {
  for (auto [n, s] :
       {std::pair{33, 4}, std::pair{40, 3}, std::pair{17, 8}, std::pair{1, 2}, std::pair{67, 2}}) {
    const Volume v = shepp_logan(n, s);
    EXPECT_EQ(v.type(), VoxelType::i16);
    int64_t mismatches = 0;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          double sum = 0;
          for (int mz = 0; mz < s; ++mz)
            for (int my = 0; my < s; ++my)
              for (int mx = 0; mx < s; ++mx)
                sum +=
                    shepp_logan_hu(phantom_subsample(i, n, mx, s), phantom_subsample(j, n, my, s),
                                   phantom_subsample(k, n, mz, s));
          mismatches += v.at(i, j, k) != static_cast<float>(std::round(sum / (s * s * s)));
        }
    EXPECT_EQ(mismatches, 0) << "n = " << n << ", s = " << s;
  }
}

TEST(SheppLoganSupersampled, SubSamplesSplitTheFootprint) {
  // n = 5: centres -1, -0.5, 0, 0.5, 1, footprint of side h = 0.5.
  EXPECT_DOUBLE_EQ(phantom_subsample(2, 5, 0, 4), -0.1875);
  EXPECT_DOUBLE_EQ(phantom_subsample(2, 5, 3, 4), 0.1875);
  EXPECT_DOUBLE_EQ(phantom_subsample(4, 5, 1, 2), 1.125);
  EXPECT_DOUBLE_EQ(phantom_subsample(3, 5, 1, 3), 0.5);   // odd s: the centre is a sub-sample
  EXPECT_DOUBLE_EQ(phantom_subsample(0, 1, 0, 2), -0.5);  // n = 1: the footprint is [-1, 1]
}

// Voxels whose whole footprint lies in one region keep the s = 1 value. A
// footprint is taken to be in one region when the analytic value agrees at
// its centre, its 8 corners and a 5^3 grid across it (the features are far
// larger than h / 4 here).
TEST(SheppLoganSupersampled, UniformFootprintsKeepTheCentreValue) {
  const int n = 48, s = 4;
  const Volume v1 = shepp_logan(n), v4 = shepp_logan(n, s);
  const double h = 2.0 / (n - 1);
  int64_t uniform = 0, changed = 0, mismatches = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double cx = phantom_coord(i, n), cy = phantom_coord(j, n), cz = phantom_coord(k, n);
        const float centre = shepp_logan_hu(cx, cy, cz);
        bool same = true;
        for (int c = 0; c < 5 * 5 * 5 && same; ++c) {
          const double ox = (c % 5) / 4.0 - 0.5, oy = (c / 5 % 5) / 4.0 - 0.5,
                       oz = (c / 25) / 4.0 - 0.5;
          same = shepp_logan_hu(cx + ox * h, cy + oy * h, cz + oz * h) == centre;
        }
        if (same) {
          ++uniform;
          mismatches += v4.at(i, j, k) != v1.at(i, j, k) || v1.at(i, j, k) != centre;
        }
        changed += v4.at(i, j, k) != v1.at(i, j, k);
      }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(uniform, n * n * n * 85 / 100);  // most voxels are uniform (measured 89%)
  EXPECT_GT(changed, 1000);                  // and the boundary voxels did change
}

// The mean of the volume times the footprint volume (n h)^3 approximates the
// integral of the phantom over [-1 - h/2, 1 + h/2]^3:
//   -1000 (n h)^3 + sum over ellipsoids of add_hu * 4/3 pi a b c
// (every ellipsoid lies inside the cube). Sub-sampling makes it much closer.
TEST(SheppLoganSupersampled, MeanApproachesTheAnalyticIntegral) {
  const double pi = std::numbers::pi;
  auto vol = [&](double a, double b, double c) { return 4.0 / 3.0 * pi * a * b * c; };
  const double ellipsoids = 2000 * vol(0.69, 0.92, 0.90) - 960 * vol(0.6624, 0.874, 0.88) -
                            140 * vol(0.41, 0.16, 0.21) - 140 * vol(0.31, 0.11, 0.22) +
                            30 * vol(0.21, 0.25, 0.50) + 30 * vol(0.046, 0.046, 0.046) +
                            20 * vol(0.046, 0.023, 0.02) + 20 * vol(0.046, 0.023, 0.02) +
                            30 * vol(0.056, 0.04, 0.10) - 40 * vol(0.056, 0.056, 0.10);
  const int n = 64;
  const double side = n * 2.0 / (n - 1);
  const double expected = -1000.0 + ellipsoids / (side * side * side);
  auto mean = [](const Volume& v) {
    double sum = 0;
    for (float x : v.data()) sum += x;
    return sum / static_cast<double>(v.voxel_count());
  };
  const double err1 = std::abs(mean(shepp_logan(n)) - expected);
  const double err4 = std::abs(mean(shepp_logan(n, 4)) - expected);
  const double err8 = std::abs(mean(shepp_logan(n, 8)) - expected);
  // Measured: err1 0.45 HU, err4 0.014 HU, err8 0.011 HU (what remains is
  // mostly the rounding of boundary voxels to integers).
  EXPECT_LT(err4, 0.03);
  EXPECT_LT(err8, 0.03);
  EXPECT_LT(err4, err1 / 10);
}

// n = 65, so voxel 32 is at 0 and h = 1/32. Along the x axis the skull's outer
// surface is at x = 0.69, inside voxel 54's footprint [0.671875, 0.703125]
// (the inner surface, 0.6624, is not): about 58% of that footprint is bone,
// the rest air, so the exact partial-volume value is about -1000 + 0.58 * 2000
// = 160 HU. With s = 4, two of the four sub-sample columns (x = 0.67578 and
// 0.68359) are inside: 0 HU.
TEST(SheppLoganSupersampled, SkullBoundaryVoxelIsAMix) {
  const int n = 65;
  ASSERT_EQ(phantom_coord(32, n), 0.0);
  EXPECT_EQ(shepp_logan(n).at(54, 32, 32), 1000.0f);  // centre 0.6875 is in the skull
  const Volume v4 = shepp_logan(n, 4);
  EXPECT_EQ(v4.at(54, 32, 32), 0.0f);
  EXPECT_EQ(v4.at(55, 32, 32), -1000.0f);  // [0.703, 0.734]: air
  EXPECT_EQ(v4.at(32, 32, 32), 40.0f);     // brain
  // Finer sub-sampling approaches the exact 160 within one sub-sample column
  // (2000 / 8 HU).
  const float v8 = shepp_logan(n, 8).at(54, 32, 32);
  EXPECT_GT(v8, -1000.0f);
  EXPECT_LT(v8, 1000.0f);
  EXPECT_NEAR(v8, 160.0f, 250.0f);
  // Mirror symmetric: the same mix on the other side.
  EXPECT_EQ(v4.at(10, 32, 32), 0.0f);
}

TEST(SheppLoganSupersampled, OneIsTheCentreSampledPhantom) {
  for (int n : {1, 33, 64}) EXPECT_EQ(shepp_logan(n, 1).data(), shepp_logan(n).data()) << n;
}

TEST(SheppLoganSupersampled, InvalidFactorsThrow) {
  EXPECT_THROW(shepp_logan(16, 0), ArgumentError);
  EXPECT_THROW(shepp_logan(16, -2), ArgumentError);
  EXPECT_THROW(shepp_logan(16, 17), ArgumentError);
  EXPECT_THROW(shepp_logan(0, 4), ArgumentError);
  EXPECT_NO_THROW(shepp_logan(4, 16));
}

// Marschner–Lobb: rho = (1 - sin(pi z/2) + a (1 + rho_r(r))) / (2 (1 + a)),
// rho_r(r) = cos(2 pi 6 cos(pi r / 2)), a = 0.25.
TEST(MarschnerLobb, HandComputedValues) {
  const double pi = std::numbers::pi;
  // Origin: rho_r(0) = cos(12 pi) = 1 -> (1 + 0.5) / 2.5.
  EXPECT_NEAR(marschner_lobb_value(0, 0, 0), 0.6, 1e-12);
  // z = 1: sin = 1 -> (0 + 0.5) / 2.5; z = -1: (2 + 0.5) / 2.5.
  EXPECT_NEAR(marschner_lobb_value(0, 0, 1), 0.2, 1e-12);
  EXPECT_NEAR(marschner_lobb_value(0, 0, -1), 1.0, 1e-12);
  // r = 2/3: cos(pi/3) = 1/2 -> rho_r = cos(6 pi) = 1; z = 1/3: sin(pi/6) = 1/2.
  EXPECT_NEAR(marschner_lobb_value(2.0 / 3.0, 0, 1.0 / 3.0), 0.4, 1e-12);
  EXPECT_NEAR(marschner_lobb_value(0, -2.0 / 3.0, 1.0 / 3.0), 0.4, 1e-12);
  // cos(pi r / 2) = 1/12 -> rho_r = cos(pi) = -1 -> (1 + 0) / 2.5.
  const double r = 2.0 / pi * std::acos(1.0 / 12.0);
  EXPECT_NEAR(marschner_lobb_value(r / std::sqrt(2.0), r / std::sqrt(2.0), 0), 0.4, 1e-12);
  // r = 1: cos(pi/2) = 0 -> rho_r = 1.
  EXPECT_NEAR(marschner_lobb_value(1, 0, 0), 0.6, 1e-12);
  // The radial term depends on x and y only through r.
  EXPECT_NEAR(marschner_lobb_value(0.3, 0.4, 0.2), marschner_lobb_value(0.5, 0, 0.2), 1e-12);
}

TEST(MarschnerLobb, GridEqualsAnalyticAndRange) {
  const int n = 41;
  const Volume v = marschner_lobb(n);
  EXPECT_EQ(v.dims(), (std::array<int64_t, 3>{n, n, n}));
  EXPECT_EQ(v.type(), VoxelType::f32);
  int64_t mismatches = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const float x = v.at(i, j, k);
        EXPECT_GE(x, 0.0f);
        EXPECT_LE(x, 1.0f);
        if (x != static_cast<float>(marschner_lobb_value(phantom_coord(i, n), phantom_coord(j, n),
                                                         phantom_coord(k, n))))
          ++mismatches;
      }
  EXPECT_EQ(mismatches, 0);
  // The axis (x = y = 0) at z = -1 is the maximum, 1; at z = 1 it is 0.2.
  EXPECT_NEAR(v.at(20, 20, 0), 1.0f, 1e-6f);
  EXPECT_NEAR(v.at(20, 20, n - 1), 0.2f, 1e-6f);
  EXPECT_NEAR(v.at(20, 20, 20), 0.6f, 1e-6f);
  EXPECT_THROW(marschner_lobb(0), ArgumentError);
  // n >= 64 is made in z slabs on several threads: the same values.
  const int m = 67;
  const Volume w = marschner_lobb(m);
  mismatches = 0;
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i)
        mismatches +=
            w.at(i, j, k) != static_cast<float>(marschner_lobb_value(
                                 phantom_coord(i, m), phantom_coord(j, m), phantom_coord(k, m)));
  EXPECT_EQ(mismatches, 0);
}

}  // namespace
}  // namespace simdvol
