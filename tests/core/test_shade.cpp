// The shade stage's reference (thesis eq 4.1-4.3): gradients, L/H/depth
// frame, Phong lighting with depth cueing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

#include "simdvol/error.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/view.hpp"
#include "simdvol/volume.hpp"

using namespace simdvol;

namespace {

// A hand-made view: rotation `rot`, radius = half the volume's diagonal in
// units of the smallest spacing (as make_view computes it).
ViewGeometry hand_view(const Volume& vol, const Mat3& rot) {
  ViewGeometry v;
  v.rot = rot;
  const auto& sp = vol.spacing();
  const double smin = std::min({sp[0], sp[1], sp[2]});
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = static_cast<double>(vol.dims()[a]) * sp[a] / smin;
    d2 += e * e;
  }
  v.radius = 0.5 * std::sqrt(d2);
  return v;
}

const Mat3 kIdentity{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};

// f(x, y, z) = a x + b y + c z.
Volume linear_volume(std::array<int64_t, 3> dims, float a, float b, float c,
                     std::array<double, 3> spacing = {1, 1, 1}) {
  Volume vol(dims, VoxelType::f32, spacing);
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x)
        vol.at(x, y, z) =
            a * static_cast<float>(x) + b * static_cast<float>(y) + c * static_cast<float>(z);
  return vol;
}

// Depth d of voxel (x, y, z) written out from the definition: the voxel
// centre's viewing z relative to the volume centre, mapped [-R, R] -> [0, 1].
double depth_by_hand(const Volume& vol, const ViewGeometry& v, int64_t x, int64_t y, int64_t z) {
  const auto& sp = vol.spacing();
  const double smin = std::min({sp[0], sp[1], sp[2]});
  const double idx[3] = {static_cast<double>(x), static_cast<double>(y), static_cast<double>(z)};
  double zv = 0;
  for (int a = 0; a < 3; ++a)
    zv += v.rot[2][a] * (idx[a] + 0.5 - 0.5 * static_cast<double>(vol.dims()[a])) * sp[a] / smin;
  return (zv + v.radius) / (2 * v.radius);
}

}  // namespace

TEST(Gradient, LinearRampIsExactInsideAndHalvedAtClampedEdges) {
  const Volume vol = linear_volume({5, 6, 7}, 2.0f, 3.0f, -1.0f);
  const Vec3 unit{1, 1, 1};
  for (int64_t z = 0; z < 7; ++z)
    for (int64_t y = 0; y < 6; ++y)
      for (int64_t x = 0; x < 5; ++x) {
        const Vec3 g = gradient(vol, x, y, z, unit);
        // Central difference 0.5 (f(i+1) - f(i-1)) = slope; at an edge the
        // clamp gives 0.5 (f(1) - f(0)) = slope / 2. All exact in float.
        EXPECT_EQ(g[0], (x == 0 || x == 4) ? 1.0 : 2.0) << x << " " << y << " " << z;
        EXPECT_EQ(g[1], (y == 0 || y == 5) ? 1.5 : 3.0) << x << " " << y << " " << z;
        EXPECT_EQ(g[2], (z == 0 || z == 6) ? -0.5 : -1.0) << x << " " << y << " " << z;
      }
}

TEST(Gradient, AxisOfLengthOneHasZeroComponent) {
  const Volume vol = linear_volume({4, 1, 3}, 1.0f, 5.0f, 2.0f);
  const Vec3 g = gradient(vol, 1, 0, 1, {1, 1, 1});
  EXPECT_EQ(g[0], 1.0);
  EXPECT_EQ(g[1], 0.0);
  EXPECT_EQ(g[2], 2.0);
}

TEST(Gradient, AnisotropicSpacingScalesToSmallestSpacing) {
  // Spacing (1, 2, 0.5): the smallest is 0.5, so grad_scale = (0.5, 0.25, 1).
  const Volume vol = linear_volume({5, 5, 5}, 2.0f, 3.0f, -1.0f, {1.0, 2.0, 0.5});
  const ShadeFrame f = make_shade_frame(vol, hand_view(vol, kIdentity), ShadeParams{});
  EXPECT_EQ(f.grad_scale[0], 0.5);
  EXPECT_EQ(f.grad_scale[1], 0.25);
  EXPECT_EQ(f.grad_scale[2], 1.0);
  const Vec3 g = gradient(vol, 2, 2, 2, f.grad_scale);
  // Value change per 0.5 physical units: x 2 per 1 -> 1; y 3 per 2 -> 0.75;
  // z -1 per 0.5 -> -1.
  EXPECT_EQ(g[0], 1.0);
  EXPECT_EQ(g[1], 0.75);
  EXPECT_EQ(g[2], -1.0);
}

TEST(ShadeFrame, HalfwayVectorByHand) {
  // L = (1, 0, -1)/sqrt(2) (45 degrees off the view towards +x), V = (0, 0, -1):
  // H bisects them, 22.5 degrees off V.
  const Volume vol({4, 4, 4}, VoxelType::f32);
  ShadeParams p;
  p.light = {1.0, 0.0, -1.0};
  const ShadeFrame f = make_shade_frame(vol, hand_view(vol, kIdentity), p);
  const double pi = std::acos(-1.0);
  EXPECT_NEAR(f.light_obj[0], std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(f.light_obj[1], 0.0, 1e-15);
  EXPECT_NEAR(f.light_obj[2], -std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(f.halfway_obj[0], std::sin(pi / 8), 1e-14);
  EXPECT_NEAR(f.halfway_obj[1], 0.0, 1e-15);
  EXPECT_NEAR(f.halfway_obj[2], -std::cos(pi / 8), 1e-14);
}

TEST(ShadeFrame, LightBehindTheVolumeGivesHalfwayAlongView) {
  const Volume vol({4, 4, 4}, VoxelType::f32);
  ShadeParams p;
  p.light = {0.0, 0.0, 2.0};  // V + L = 0
  const ShadeFrame f = make_shade_frame(vol, hand_view(vol, kIdentity), p);
  EXPECT_EQ(f.halfway_obj[0], 0.0);
  EXPECT_EQ(f.halfway_obj[1], 0.0);
  EXPECT_EQ(f.halfway_obj[2], -1.0);
  EXPECT_EQ(f.light_obj[2], 1.0);
}

TEST(ShadeFrame, RotatedViewUsesTransposeForLightAndRowTwoForDepth) {
  // rot maps object x to viewing -z (towards the observer), object z to
  // viewing +x; det = +1.
  const Mat3 rot{{{0, 0, 1}, {0, 1, 0}, {-1, 0, 0}}};
  const Volume vol({6, 4, 2}, VoxelType::f32);
  const ViewGeometry v = hand_view(vol, rot);
  ShadeParams p;
  p.light = {0.0, 0.0, -1.0};  // from the observer
  const ShadeFrame f = make_shade_frame(vol, v, p);
  // rot^T (0, 0, -1) = -(row 2) = (1, 0, 0).
  EXPECT_EQ(f.light_obj[0], 1.0);
  EXPECT_EQ(f.light_obj[1], 0.0);
  EXPECT_EQ(f.light_obj[2], 0.0);
  EXPECT_EQ(f.halfway_obj[0], 1.0);
  // Depth grows as object x falls: x = 5 is nearest, x = 0 farthest.
  EXPECT_NEAR(f.depth_dir[0], -1.0 / (2 * v.radius), 1e-15);
  EXPECT_EQ(f.depth_dir[1], 0.0);
  EXPECT_EQ(f.depth_dir[2], 0.0);
  for (int64_t x = 0; x < 6; ++x) {
    const double d = f.depth_dir[0] * x + f.depth_dir[1] * 1 + f.depth_dir[2] * 1 + f.depth_offset;
    EXPECT_NEAR(d, depth_by_hand(vol, v, x, 1, 1), 1e-14);
  }
  // d = (z + R) / (2R) with z = -(x + 0.5 - 3): x = 5 -> z = -2.5.
  EXPECT_NEAR(f.depth_dir[0] * 5 + f.depth_offset, (-2.5 + v.radius) / (2 * v.radius), 1e-14);
}

TEST(ShadeFrame, DepthOfEveryVoxelLiesInZeroOneForRealViews) {
  Volume vol({9, 5, 7}, VoxelType::f32, {1.0, 1.5, 0.7});
  for (const ViewAngles a :
       {ViewAngles{0, 0, 0}, ViewAngles{30, 47, 10}, ViewAngles{-120, 200, 75}}) {
    const ViewGeometry v = make_view(vol, a, 64, 64, Sampling::voxel);
    const ShadeFrame f = make_shade_frame(vol, v, ShadeParams{});
    for (int64_t z : {int64_t{0}, vol.nz() - 1})
      for (int64_t y : {int64_t{0}, vol.ny() - 1})
        for (int64_t x : {int64_t{0}, vol.nx() - 1}) {
          const double d =
              f.depth_dir[0] * x + f.depth_dir[1] * y + f.depth_dir[2] * z + f.depth_offset;
          EXPECT_GT(d, 0.0);
          EXPECT_LT(d, 1.0);
          EXPECT_NEAR(d, depth_by_hand(vol, v, x, y, z), 1e-12);
        }
  }
}

// grad_over: set where the value range lets a gradient's squared length
// overflow float (max - min >= 1e19), from the range given or the volume's.
TEST(ShadeFrame, GradOverFromTheValueRange) {
  Volume vol({5, 4, 3}, VoxelType::f32);
  for (std::size_t i = 0; i < vol.voxel_count(); ++i) vol.data()[i] = static_cast<float>(i % 256);
  const ViewGeometry v = make_view(vol, {0, 0, 0}, 8, 8, Sampling::voxel);
  EXPECT_FALSE(make_shade_frame(vol, v, ShadeParams{}).grad_over);
  EXPECT_FALSE(make_shade_frame(vol, v, ShadeParams{}, {-4e18f, 5e18f}).grad_over);
  EXPECT_TRUE(make_shade_frame(vol, v, ShadeParams{}, {-6e18f, 6e18f}).grad_over);
  vol.at(1, 1, 1) = 2e19f;
  EXPECT_TRUE(make_shade_frame(vol, v, ShadeParams{}).grad_over);
  vol.at(1, 1, 1) = -2e19f;
  EXPECT_TRUE(make_shade_frame(vol, v, ShadeParams{}).grad_over);
  vol.at(1, 1, 1) = INFINITY;  // not finite: not in the range
  EXPECT_FALSE(make_shade_frame(vol, v, ShadeParams{}).grad_over);
}

// The no-surface threshold on |g|^2: 1e-12 for a span of 1 or more, (1e-6
// span)^2 below, at least 1e-32; a span that is not finite counts as 1.
TEST(ShadeFrame, SurfaceThresholdFollowsTheSpanBelowOne) {
  EXPECT_EQ(surface_threshold(1.0), 1e-12);
  EXPECT_EQ(surface_threshold(2000.0), 1e-12);
  EXPECT_EQ(surface_threshold(3e30), 1e-12);
  EXPECT_EQ(surface_threshold(INFINITY), 1e-12);
  EXPECT_EQ(surface_threshold(NAN), 1e-12);
  EXPECT_DOUBLE_EQ(surface_threshold(0.5), 0.25e-12);
  EXPECT_DOUBLE_EQ(surface_threshold(1e-3), 1e-18);
  EXPECT_DOUBLE_EQ(surface_threshold(3e-9), 9e-30);
  EXPECT_DOUBLE_EQ(surface_threshold(1e-10), 1e-32);
  EXPECT_DOUBLE_EQ(surface_threshold(1e-20), 1e-32);
  EXPECT_DOUBLE_EQ(surface_threshold(0.0), 1e-32);
  // The kernels take it as a float: 1e-12 there is the literal they had.
  EXPECT_EQ(static_cast<float>(surface_threshold(1.0)), 1e-12f);
  // From the volume's range (or the range given).
  Volume vol({5, 4, 3}, VoxelType::f32);
  for (std::size_t i = 0; i < vol.voxel_count(); ++i)
    vol.data()[i] = 1e-9f * static_cast<float>(i % 4);
  const ViewGeometry v = make_view(vol, {0, 0, 0}, 8, 8, Sampling::voxel);
  EXPECT_DOUBLE_EQ(make_shade_frame(vol, v, ShadeParams{}).surface_g2,
                   surface_threshold(static_cast<double>(1e-9f * 3.0f)));
  EXPECT_EQ(make_shade_frame(vol, v, ShadeParams{}, {-10.0f, 10.0f}).surface_g2, 1e-12);
}

// A volume in small units is lit as the same volume in larger ones: values
// times 2^-40 (exact in float and double, so every gradient is the same
// times 2^-40) give the same lighting bit for bit and |g| times 2^-40.
// Before the threshold followed the span, |g|^2 < 1e-12 left every voxel of
// the scaled volume ambient only.
TEST(Shade, TinyValuesAreLitAsTheSameVolumeInLargerUnits) {
  Volume vol({9, 8, 7}, VoxelType::f32);
  uint32_t r = 12345;
  for (float& f : vol.data()) {
    r = r * 1664525u + 1013904223u;
    f = static_cast<float>(r >> 8) / static_cast<float>(1 << 24);  // [0, 1)
  }
  for (int64_t x = 0; x < 9; ++x)  // a flat slab: no surface in either
    for (int64_t y = 0; y < 8; ++y) vol.at(x, y, 0) = vol.at(x, y, 1) = vol.at(x, y, 2) = 0.5f;
  Volume tiny = vol;
  const float k = std::ldexp(1.0f, -40);
  for (float& f : tiny.data()) f *= k;
  const ViewGeometry view = make_view(vol, {30, 45, 10}, 16, 16, Sampling::voxel);
  const ShadeParams p;
  const auto a = shade(vol, view, p);
  const auto b = shade(tiny, view, p);
  std::size_t lit = 0, flat = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].diffuse, b[i].diffuse) << i;
    ASSERT_EQ(a[i].specular, b[i].specular) << i;
    ASSERT_EQ(a[i].gradient * k, b[i].gradient) << i;
    lit += a[i].diffuse > static_cast<float>(p.ka);
    flat += a[i].gradient == 0.0f;
  }
  EXPECT_GT(lit, a.size() / 2);
  EXPECT_GE(flat, 9u * 8u);  // the slab's middle slice
}

TEST(Shade, GradientAlongLightGivesFullDiffuse) {
  // f = 6 y - 8 z: g = (0, 6, -8) inside, |g| = 10, N = (0, 0.6, -0.8) = L.
  const Volume vol = linear_volume({3, 5, 6}, 0.0f, 6.0f, -8.0f);
  const ViewGeometry v = hand_view(vol, kIdentity);
  ShadeParams p;
  p.light = {0.0, 0.6, -0.8};
  p.ka = 0.2;
  p.kd = 0.7;
  p.ks = 0.4;
  p.shininess = 5;
  p.k1 = 1.0;
  p.k2 = 0.5;
  const auto s = shade(vol, v, p);
  ASSERT_EQ(s.size(), vol.voxel_count());
  // H = normalize((0, 0, -1) + L) = (0, 0.6, -1.8) / sqrt(3.6); N.H = 1.8 / sqrt(3.6).
  const double nh = 1.8 / std::sqrt(3.6);
  for (int64_t z = 1; z < 5; ++z)
    for (int64_t y = 1; y < 4; ++y)
      for (int64_t x = 0; x < 3; ++x) {
        const double d = depth_by_hand(vol, v, x, y, z);
        const double cue = 1.0 / (1.0 + 0.5 * d);
        const ShadeSample& ss = s[vol.index(x, y, z)];
        EXPECT_NEAR(ss.diffuse, 0.2 + cue * 0.7, 1e-6);
        EXPECT_NEAR(ss.specular, cue * 0.4 * std::pow(nh, 5.0), 1e-6);
        EXPECT_EQ(ss.gradient, 10.0f);
      }
}

TEST(Shade, DepthCueRunsFromOneOverK1ToOneOverK1PlusK2) {
  // A long 1 x 1 x 200 column, f = -z: N = (0, 0, -1) = L everywhere (at the
  // clamped ends too), so Id = ka + kd * cue(d) with d growing along z.
  const Volume vol = linear_volume({1, 1, 200}, 0.0f, 0.0f, -1.0f);
  const ViewGeometry v = hand_view(vol, kIdentity);
  ShadeParams p;
  p.light = {0, 0, -1};
  p.ka = 0.1;
  p.kd = 0.9;
  p.k1 = 1.0;
  p.k2 = 3.0;
  const auto s = shade(vol, v, p);
  for (int64_t z = 0; z < 200; ++z) {
    const double cue = 1.0 / (1.0 + 3.0 * depth_by_hand(vol, v, 0, 0, z));
    EXPECT_NEAR(s[z].diffuse, 0.1 + 0.9 * cue, 1e-6);
    if (z > 0) {
      EXPECT_LT(s[z].diffuse, s[z - 1].diffuse);  // monotonic: farther is darker
    }
  }
  // The column nearly spans the bounding sphere (R = 100.005): its end voxel
  // centres lie half a voxel inside it, d = 0.0025 and 0.9975, so Id is
  // within 0.9 * 3 * 0.0025 = 0.00675 of the d = 0 and d = 1 values.
  EXPECT_NEAR(s.front().diffuse, 0.1 + 0.9 / 1.0, 0.007);
  EXPECT_NEAR(s.back().diffuse, 0.1 + 0.9 / 4.0, 0.007);
  EXPECT_LT(s.front().diffuse, 0.1 + 0.9 / 1.0);
  EXPECT_GT(s.back().diffuse, 0.1 + 0.9 / 4.0);
}

TEST(Shade, ZeroGradientIsAmbientOnly) {
  Volume vol({4, 3, 5}, VoxelType::f32);
  for (auto& f : vol.data()) f = 7.5f;
  ShadeParams p;
  p.shininess = 0;  // |N.H|^0 would be 1: a zero gradient must still give Is = 0
  const auto s = shade(vol, hand_view(vol, kIdentity), p);
  for (const auto& ss : s) {
    EXPECT_EQ(ss.diffuse, static_cast<float>(p.ka));
    EXPECT_EQ(ss.specular, 0.0f);
    EXPECT_EQ(ss.gradient, 0.0f);
  }
}

TEST(Shade, DisabledGivesUnlitButKeepsGradient) {
  const Volume vol = linear_volume({4, 4, 4}, 0.0f, 3.0f, 4.0f);
  ShadeParams p;
  p.enabled = false;
  const auto s = shade(vol, hand_view(vol, kIdentity), p);
  for (const auto& ss : s) {
    EXPECT_EQ(ss.diffuse, 1.0f);
    EXPECT_EQ(ss.specular, 0.0f);
  }
  EXPECT_EQ(s[vol.index(1, 1, 1)].gradient, 5.0f);  // |(0, 3, 4)|
  EXPECT_EQ(s[vol.index(0, 0, 0)].gradient, 2.5f);  // both halved at the corner
}

TEST(Shade, LightingIsTwoSided) {
  const Volume a = linear_volume({5, 4, 3}, 1.0f, -2.0f, 0.5f);
  Volume b = a;
  for (auto& f : b.data()) f = -f;
  ShadeParams p;
  p.light = {0.3, -0.2, -1.0};
  const Mat3 rot{{{0, 0, 1}, {0, 1, 0}, {-1, 0, 0}}};
  const auto sa = shade(a, hand_view(a, rot), p);
  const auto sb = shade(b, hand_view(b, rot), p);
  for (std::size_t n = 0; n < sa.size(); ++n) {
    EXPECT_EQ(sa[n].diffuse, sb[n].diffuse);
    EXPECT_EQ(sa[n].specular, sb[n].specular);
    EXPECT_EQ(sa[n].gradient, sb[n].gradient);
  }
}

TEST(Shade, RejectsBadParameters) {
  const Volume vol({2, 2, 2}, VoxelType::f32);
  const ViewGeometry v = hand_view(vol, kIdentity);
  ShadeParams p;
  p.light = {0, 0, 0};
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.k1 = 0;
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.k1 = 1;
  p.k2 = -1;  // k1 + k2 d reaches 0 at d = 1
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.shininess = std::nan("");
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  // Light beyond what float arithmetic holds (the device's cue became
  // infinite at k1 = 1e-40, inf * 0 a NaN; 42-52 dB from the reference).
  p = ShadeParams{};
  p.k1 = 1e-40;
  p.k2 = 0;
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.ks = 3e38;
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.k2 = 1e39;
  EXPECT_THROW(shade(vol, v, p), ArgumentError);
  p = ShadeParams{};
  p.k1 = 1e-30;  // light 0.7e30 + 0.1: within the bound
  p.k2 = 0;
  EXPECT_NO_THROW(shade(vol, v, p));
  ViewGeometry bad = v;
  bad.radius = 0;
  EXPECT_THROW(shade(vol, bad, ShadeParams{}), ArgumentError);
}
