// The analytic phantoms: Shepp–Logan (HU) and Marschner–Lobb.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>

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
}

}  // namespace
}  // namespace simdvol
