// The rotation of eq 5.2 and the viewing grid (matching: which samples fall
// inside the volume).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "simdvol/error.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;

TEST(Rotation, OrthonormalWithDeterminantPlusOne) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ang(-360.0, 360.0);
  for (int n = 0; n < 2000; ++n) {
    const Mat3 t = rotation(ang(rng), ang(rng), ang(rng));
    const Mat3 ttt = multiply(t, transpose(t));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(ttt[i][j], i == j ? 1.0 : 0.0, 1e-12);
    EXPECT_NEAR(determinant(t), 1.0, 1e-12);
  }
}

TEST(Rotation, ZeroAnglesAreIdentityAndPhiTurnsAboutVertical) {
  const Mat3 t = rotation(0, 0, 0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(t[i][j], i == j ? 1.0 : 0.0, 1e-15);
  // phi alone keeps the viewing y axis (image vertical) fixed.
  const Mat3 r = rotation(0, 37, 0);
  const Vec3 y = multiply(r, Vec3{0, 1, 0});
  EXPECT_NEAR(y[0], 0.0, 1e-15);
  EXPECT_NEAR(y[1], 1.0, 1e-15);
  EXPECT_NEAR(y[2], 0.0, 1e-15);
  // and turns object x by phi about it.
  const Vec3 x = multiply(r, Vec3{1, 0, 0});
  EXPECT_NEAR(x[0], std::cos(37 * M_PI / 180), 1e-15);
  EXPECT_NEAR(std::fabs(x[2]), std::sin(37 * M_PI / 180), 1e-15);
  // theta alone turns about the viewing z axis.
  const Vec3 z = multiply(rotation(25, 0, 0), Vec3{0, 0, 1});
  EXPECT_NEAR(z[2], 1.0, 1e-15);
}

// Eq 5.2 as printed, T = A(varphi) B(phi) C(theta), at an oblique view whose
// three angles differ: the matrix below was computed apart from simdvol
// (numpy, from the thesis's three factors, 2026-12-07), so a swapped angle,
// a reversed product or a sign flipped in one factor (each still
// orthonormal with determinant +1, which the tests above cannot tell) fails.
TEST(Rotation, EqualsTheThesisProductAtAnObliqueView) {
  const double want[3][3] = {{0.76975113132005724, 0.28016649959323547, -0.57357643635104605},
                             {-0.43041794645870102, 0.89135120011258873, -0.14224425972292404},
                             {0.47140596856400402, 0.3563702717168219, 0.80670728411159875}};
  const Mat3 t = rotation(20, 35, 10);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(t[i][j], want[i][j], 1e-15) << i << "," << j;
}

TEST(ViewGeometry, RayRangeEqualsTestingEverySample) {
  Volume vol({23, 17, 11}, VoxelType::u8, {1.0, 1.5, 2.0});
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ang(0.0, 360.0);
  std::vector<ViewAngles> views = {{0, 0, 0}, {0, 90, 0}, {0, 45, 0}, {30, 0, 0}, {90, 90, 90}};
  for (int n = 0; n < 12; ++n) views.push_back({ang(rng), ang(rng), ang(rng)});
  for (const auto& v : views) {
    for (Sampling s : {Sampling::voxel, Sampling::pixel}) {
      const ViewGeometry g = make_view(vol, v, 40, 29, s);
      std::size_t inside = 0;
      for (int j = 0; j < g.height(); ++j) {
        for (int i = 0; i < g.width(); ++i) {
          const auto [k0, k1] = g.ray_range(i, j);
          for (int64_t k = 0; k < g.depth(); ++k) {
            const bool in = g.inside(i, j, k);
            ASSERT_EQ(in, k >= k0 && k < k1) << "ray " << i << "," << j << " k " << k;
            inside += in;
          }
        }
      }
      EXPECT_GT(inside, 0u);
    }
  }
}

TEST(ViewGeometry, VoxelSamplingVisitsEachVoxelAboutOnce) {
  // Rotation only, unit step: the viewing grid has one sample per unit volume,
  // so the number of samples inside equals the voxel count up to the boundary.
  // (A 40 x 8 x 8 box: its diagonal is shorter than the 42-unit frame, so no
  // view crops it.)
  Volume bar({40, 8, 8}, VoxelType::u8);
  for (const ViewAngles v : {ViewAngles{30, 45, 10}, ViewAngles{12, 71, 33}}) {
    const ViewGeometry g = make_view(bar, v, 64, 64, Sampling::voxel);
    int64_t inside = 0;
    for (int j = 0; j < g.height(); ++j)
      for (int i = 0; i < g.width(); ++i) {
        const auto r = g.ray_range(i, j);
        inside += r[1] - r[0];
      }
    EXPECT_NEAR(static_cast<double>(inside), 2560.0, 2560.0 * 0.03);
  }
  Volume vol({40, 40, 40}, VoxelType::u8);
  // Axis-aligned: exactly one sample per voxel.
  const ViewGeometry g = make_view(vol, {0, 0, 0}, 64, 64, Sampling::voxel);
  int64_t inside = 0;
  for (int j = 0; j < g.height(); ++j)
    for (int i = 0; i < g.width(); ++i) {
      const auto r = g.ray_range(i, j);
      inside += r[1] - r[0];
    }
  EXPECT_EQ(inside, 64000);
}

TEST(ViewGeometry, LongestSideSpansTheImage) {
  Volume vol({100, 50, 20}, VoxelType::u8);
  // Pixel sampling, view along z: x spans the 200-pixel width exactly.
  const ViewGeometry g = make_view(vol, {0, 0, 0}, 200, 300, Sampling::pixel);
  EXPECT_DOUBLE_EQ(g.step, 0.5);
  int first = -1, last = -1;
  const int j = g.height() / 2;
  for (int i = 0; i < g.width(); ++i) {
    const auto r = g.ray_range(i, j);
    if (r[1] > r[0]) {
      if (first < 0) first = i;
      last = i;
    }
  }
  EXPECT_EQ(first, 0);
  EXPECT_EQ(last, 199);
  // Voxel sampling: output pixel centres map back onto the volume's extent.
  const ViewGeometry v = make_view(vol, {0, 0, 0}, 200, 200, Sampling::voxel);
  const auto a = v.output_to_intermediate(0, 100);
  const auto b = v.output_to_intermediate(199, 100);
  // 100 voxels across 200 pixels: pixel centres 0.5 voxel apart, 99.5 apart end to end.
  EXPECT_NEAR(b[0] - a[0], 99.5, 1e-9);
}

TEST(ViewGeometry, DiagonalFramingKeepsTheWholeVolumeInView) {
  // --fit diagonal: the diagonal spans min(W, H), so every corner of the
  // volume's box projects into the viewing grid at every view; with the
  // longest side spanning it, a 45-degree view cuts corners off.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ang(-180.0, 180.0);
  const std::array<int64_t, 3> dims{100, 50, 20};
  const std::array<double, 3> sp{1.0, 1.0, 2.5};
  for (int n = 0; n < 40; ++n) {
    const ViewAngles va = n == 0 ? ViewAngles{0, 45, 0} : ViewAngles{ang(rng), ang(rng), ang(rng)};
    for (const Sampling s : {Sampling::voxel, Sampling::pixel}) {
      const ViewGeometry g = make_view(dims, sp, va, 120, 90, s, Framing::diagonal);
      EXPECT_NEAR(g.span, std::sqrt(100.0 * 100 + 50.0 * 50 + 50.0 * 50), 1e-9);
      Vec3 o{};
      const Mat3 inv = inverse_viewing_map(g, o);
      for (int c = 0; c < 8; ++c) {
        const Vec3 x{c & 1 ? 100.0 : 0.0, c & 2 ? 50.0 : 0.0, c & 4 ? 20.0 : 0.0};
        const Vec3 ijk = multiply(inv, Vec3{x[0] - o[0], x[1] - o[1], x[2] - o[2]});
        EXPECT_GE(ijk[0], -0.5 - 1e-6) << n;
        EXPECT_LE(ijk[0], g.width() - 0.5 + 1e-6) << n;
        EXPECT_GE(ijk[1], -0.5 - 1e-6) << n;
        EXPECT_LE(ijk[1], g.height() - 0.5 + 1e-6) << n;
      }
    }
  }
  // Samples of a 40^3 cube at 45 degrees about the vertical axis: all of
  // them with the diagonal framing, about 6.6 % fewer with the longest side
  // (two corner prisms of the rotated cube fall outside the 42-unit grid).
  Volume cube({40, 40, 40}, VoxelType::u8);
  const auto count = [&](Framing f) {
    const ViewGeometry g = make_view(cube, {0, 45, 0}, 64, 64, Sampling::voxel, f);
    int64_t inside = 0;
    for (int j = 0; j < g.height(); ++j)
      for (int i = 0; i < g.width(); ++i) {
        const auto r = g.ray_range(i, j);
        inside += r[1] - r[0];
      }
    return static_cast<double>(inside);
  };
  EXPECT_NEAR(count(Framing::diagonal), 64000.0, 64000.0 * 0.03);
  EXPECT_LT(count(Framing::longest), 64000.0 * 0.96);
  // The diagonal spans the output: pixel centres 0 and 199 of a 200-pixel
  // row are 199 / 200 of it apart in voxel units.
  Volume box({100, 50, 20}, VoxelType::u8);
  const ViewGeometry v = make_view(box, {0, 0, 0}, 200, 200, Sampling::voxel, Framing::diagonal);
  const auto a = v.output_to_intermediate(0, 100);
  const auto b = v.output_to_intermediate(199, 100);
  EXPECT_NEAR(b[0] - a[0], 199.0 / 200.0 * std::sqrt(100.0 * 100 + 50 * 50 + 20 * 20), 1e-9);
}

TEST(ViewGeometry, RejectsBadSizes) {
  Volume vol({4, 4, 4}, VoxelType::u8);
  EXPECT_THROW(make_view(vol, {}, 0, 10, Sampling::voxel), ArgumentError);
  EXPECT_THROW(make_view(vol, {}, 10, -1, Sampling::pixel), ArgumentError);
  EXPECT_THROW(make_view(vol, {NAN, 0, 0}, 10, 10, Sampling::pixel), ArgumentError);
  // Pixel sampling of spacings 1e-6 .. 1e6 stepped 1e21 voxels a sample:
  // out of the fixed point's range (a step of -2^63, overflowing sums).
  EXPECT_THROW(make_view({4, 4, 4}, {1e-6, 1, 1e6}, {0, 0, 0}, 16, 16, Sampling::pixel),
               ArgumentError);
  // A strongly anisotropic volume still fits at pixel sampling.
  const ViewGeometry ok = make_view({4, 4, 4}, {1, 1, 1e4}, {0, 30, 0}, 16, 16, Sampling::pixel);
  EXPECT_EQ(ok.width(), 16);
}

// The geometry is in units of the smallest spacing, so a volume whose
// spacings are all alike has the geometry of spacing 1, however large or
// small they are: a NIfTI-2 file's doubles can hold 1.5e308, and dims x
// spacing overflowed to inf there (refused as "its largest over its smallest
// is too large to render", though the ratio was 1).
TEST(ViewGeometry, SpacingsAllAlikeGiveTheGeometryOfSpacingOne) {
  for (const Sampling sampling : {Sampling::voxel, Sampling::pixel}) {
    const ViewGeometry one = make_view({16, 12, 9}, {1, 1, 1}, {20, 35, 10}, 48, 40, sampling);
    for (const double s : {1.5e308, 1.7e308, 1e-300, 5e-324}) {
      const ViewGeometry g = make_view({16, 12, 9}, {s, s, s}, {20, 35, 10}, 48, 40, sampling);
      EXPECT_EQ(g.width(), one.width()) << s;
      EXPECT_EQ(g.height(), one.height()) << s;
      EXPECT_EQ(g.depth(), one.depth()) << s;
      EXPECT_EQ(g.step, one.step) << s;
      EXPECT_EQ(g.radius, one.radius) << s;
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(g.grid.origin[a], one.grid.origin[a]) << s;
        for (int b = 0; b < 3; ++b) EXPECT_EQ(g.grid.step[a][b], one.grid.step[a][b]) << s;
      }
    }
  }
  // Spacings whose ratio overflows are still refused, naming the ratio.
  try {
    (void)make_view({2, 2, 2}, {8e-317, 1.2e308, 7e182}, {0, 0, 0}, 16, 16, Sampling::voxel);
    ADD_FAILURE() << "a ratio of 1e624 was not refused";
  } catch (const ArgumentError& e) {
    EXPECT_NE(std::string(e.what()).find("its largest over its smallest"), std::string::npos)
        << e.what();
  }
}

TEST(Philox, KnownAnswer) {
  // Random123's known-answer test for philox4x32-10 with zero counter and key.
  sv_u32x4 c{{0, 0, 0, 0}};
  const sv_u32x4 r = sv_philox4x32_10(c, 0, 0);
  EXPECT_EQ(r.v[0], 0x6627e8d5u);
  EXPECT_EQ(r.v[1], 0xe169c58du);
  EXPECT_EQ(r.v[2], 0xbc57ac4cu);
  EXPECT_EQ(r.v[3], 0x9b00dbd8u);
  // And with all-ones counter and key {0xffffffff, 0xffffffff}.
  sv_u32x4 c1{{0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu}};
  const sv_u32x4 r1 = sv_philox4x32_10(c1, 0xffffffffu, 0xffffffffu);
  EXPECT_EQ(r1.v[0], 0x408f276du);
  EXPECT_EQ(r1.v[1], 0x41c83b0eu);
  EXPECT_EQ(r1.v[2], 0xa20bc7c6u);
  EXPECT_EQ(r1.v[3], 0x6d5451fdu);
}

// Voxel sampling's intermediate image covers the output at voxel spacing,
// but a ray further from the centre than the volume's radius holds no
// sample: an image far wider or taller than the framed span is cut on both
// sides alike to ceil(diagonal) + 3 pixels (+ 4 where that keeps the count's
// parity, so the rays stay where they were). Before, a 1x512 image of a
// 97x301x33 volume took 303 x 154,114 pixels (747 MB of float4), and a
// 4096x1 image of the 256^3 phantom (1,048,578 x 258 pixels) was refused as
// a viewing grid over 2^28 pixels.
TEST(ViewGeometry, ImagesFarWiderThanTheVolumeKeepOnlyTheRaysThatCanHitIt) {
  struct Case {
    std::array<int64_t, 3> dims;
    std::array<double, 3> sp;
    int w, h;
    Framing fit;
    int want_w, want_h;  // uncut: ceil(W / scale) + 2 and ceil(H / scale) + 2
  };
  const std::array<double, 3> one{1, 1, 1};
  const Case cases[] = {
      // diagonal 317.96: cut to 321 or 322
      {{97, 301, 33}, one, 1, 512, Framing::longest, 303, 322},       // 303 x 154114 uncut
      {{97, 301, 33}, one, 512, 1, Framing::longest, 322, 303},       // 154114 x 303 uncut
      {{97, 301, 33}, one, 1, 512, Framing::diagonal, 320, 322},      // 320 x 162798 uncut
      {{256, 256, 256}, one, 4096, 1, Framing::longest, 448, 258},    // diagonal 443.41: 447 / 448
      {{256, 256, 256}, one, 4096, 64, Framing::longest, 448, 258},   // 16386 x 258 uncut
      {{256, 256, 256}, one, 4096, 64, Framing::diagonal, 448, 446},  // 28380 x 446 uncut
      {{16, 16, 16}, one, 1000, 16, Framing::longest, 32, 18},        // diagonal 27.71: 31 / 32
      {{16, 16, 16}, one, 32, 16, Framing::longest, 32, 18},          // 34 x 18 uncut
      {{16, 16, 16}, one, 16, 29, Framing::longest, 18, 31},          // 31: not over the cut
      {{16, 16, 16}, one, 16, 16, Framing::longest, 18, 18},          // square: never cut
      {{16, 16, 16}, one, 16, 16, Framing::diagonal, 30, 30},
      // extents 100 x 50 x 50 in the smallest spacing: diagonal 122.47, 126 / 127
      {{100, 50, 20}, {1, 1, 2.5}, 2000, 30, Framing::longest, 127, 102},  // 6669 x 102 uncut
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ang(-180.0, 180.0);
  for (const Case& c : cases) {
    const std::string what = std::to_string(c.dims[0]) + "x" + std::to_string(c.dims[1]) + "x" +
                             std::to_string(c.dims[2]) + " at " + std::to_string(c.w) + "x" +
                             std::to_string(c.h);
    for (int n = 0; n < 6; ++n) {
      const ViewAngles va = n == 0 ? ViewAngles{} : ViewAngles{ang(rng), ang(rng), ang(rng)};
      const ViewGeometry g = make_view(c.dims, c.sp, va, c.w, c.h, Sampling::voxel, c.fit);
      ASSERT_EQ(g.width(), c.want_w) << what;
      ASSERT_EQ(g.height(), c.want_h) << what;
      // A grid of the cut's size or more holds no sample on its edges:
      // nothing was cut away.
      const int cut = static_cast<int>(std::ceil(2.0 * g.radius)) + 3;
      if (g.height() >= cut)
        for (int i = 0; i < g.width(); ++i)
          for (int j : {0, g.height() - 1}) {
            const auto r = g.ray_range(i, j);
            EXPECT_GE(r[0], r[1]) << what << " ray " << i << "," << j;
          }
      if (g.width() >= cut)
        for (int j = 0; j < g.height(); ++j)
          for (int i : {0, g.width() - 1}) {
            const auto r = g.ray_range(i, j);
            EXPECT_GE(r[0], r[1]) << what << " ray " << i << "," << j;
          }
      // The output's centre still maps to the grid's centre.
      if (c.w % 2 == 0 && c.h % 2 == 0) {
        const auto m = g.output_to_intermediate(c.w / 2, c.h / 2);
        const double half = 0.5 * g.span / std::min(c.w, c.h);  // half a pixel in voxels
        EXPECT_NEAR(m[0], 0.5 * g.width() - 0.5 + half, 1e-9) << what;
        EXPECT_NEAR(m[1], 0.5 * g.height() - 0.5 + half, 1e-9) << what;
      }
    }
  }
}
