// Extreme but valid inputs through the reference renderer: 1x1x1 and
// 1xNx1 volumes, dims no cell size divides, views exactly on the axes and at
// 45 degrees, constant volumes, and float volumes with NaN voxels (NaN is
// handled, not rejected: a NaN voxel classifies as transparent, and shading
// treats a NaN neighbour as no surface, so the image stays finite).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "extremes_cases.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/render.hpp"

using namespace simdvol;
using namespace simdvol::extremes;

namespace {

Image render(const Volume& vol, RenderOptions opt, ViewAngles v, Sampling s = Sampling::voxel,
             int order = 1) {
  opt.view = v;
  opt.sampling = s;
  opt.order = order;
  return render_reference(vol, opt);
}

}  // namespace

// A constant volume seen along an axis: the centre ray crosses the whole
// extent along that axis, so the largest opacity is exactly
// 1 - (1 - a)^extent in voxel sampling (within one sample of it in pixel
// sampling), whatever the dims (none is divisible by 2, 4 or 8 here but
// 8 x 8 x 8).
TEST(Extremes, AxisViewsOfConstantVolumesComposeExactly) {
  const float a = 0.5f;
  const RenderOptions o = unlit(a);
  struct AxisView {
    ViewAngles v;
    int axis;  // the object axis the view looks along
  };
  const AxisView views[] = {
      {{0, 0, 0}, 2}, {{0, 180, 0}, 2}, {{90, 0, 0}, 2}, {{0, 90, 0}, 0}, {{0, 0, 90}, 1}};
  int n = 0;
  for (auto dims : {std::array<int64_t, 3>{7, 5, 3}, {13, 11, 9}, {8, 8, 8}, {3, 17, 6}})
    for (const AxisView& av : views)
      for (Sampling s : {Sampling::voxel, Sampling::pixel}) {
        const Image img = render(constant_volume(dims, 100.0f), o, av.v, s);
        const std::string what = std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                 std::to_string(dims[2]) + " view " + std::to_string(av.v.theta) +
                                 "," + std::to_string(av.v.phi) + "," + std::to_string(av.v.varphi);
        EXPECT_EQ(image_problem(img), "") << what;
        const int extent = static_cast<int>(dims[av.axis]);
        if (s == Sampling::voxel) {
          EXPECT_NEAR(max_alpha(img), stacked_alpha(a, extent), 1e-6) << what;
        } else {  // pixel steps are not one voxel: within one sample of it
          EXPECT_GE(max_alpha(img), stacked_alpha(a, extent - 1)) << what;
          EXPECT_LE(max_alpha(img), stacked_alpha(a, extent + 1)) << what;
        }
        // The centre pixel sees the interior, which is uniform.
        EXPECT_NEAR(img.at(12, 12).a, max_alpha(img), 1e-6) << what;
        ++n;
      }
  EXPECT_EQ(n, 4 * 5 * 2);
}

// 45 degree views: the longest ray through a constant n^3 cube at 45
// degrees about one axis crosses between n and n * sqrt(2) + 1 samples.
TEST(Extremes, FortyFiveDegreeViewsStayWithinTheDiagonal) {
  const float a = 0.5f;
  const RenderOptions o = unlit(a);
  for (const ViewAngles& v : {ViewAngles{0, 45, 0}, ViewAngles{0, 0, 45}, ViewAngles{45, 45, 0}})
    for (Sampling s : {Sampling::voxel, Sampling::pixel}) {
      const Image img = render(constant_volume({8, 8, 8}, 100.0f), o, v, s);
      EXPECT_EQ(image_problem(img), "");
      EXPECT_GE(max_alpha(img), stacked_alpha(a, 8) - 1e-6f);
      EXPECT_LE(max_alpha(img), stacked_alpha(a, 13) + 1e-6f);
    }
}

// 1x1x1 and 1xNx1 (and Nx1x1, 1x1xN) volumes render on every view. In
// pixel sampling a lone voxel seen along an axis gives exactly its own
// opacity; the 9-voxel line seen end-on gives 1 - (1 - a)^9. Otherwise a
// one-voxel-thin object is smeared by the bilinear warp (voxel sampling) or
// sampled a little more than once (pixel steps under one voxel): its
// opacity is positive and below that of one more voxel.
TEST(Extremes, DegenerateDimsRender) {
  const float a = 0.5f;
  const RenderOptions o = unlit(a);
  for (auto dims : {std::array<int64_t, 3>{1, 1, 1}, {1, 9, 1}, {9, 1, 1}, {1, 1, 9}, {1, 6, 5}})
    for (const ViewAngles& v : extreme_views())
      for (Sampling s : {Sampling::voxel, Sampling::pixel})
        for (int order = 0; order <= 3; ++order) {
          const Image img = render(constant_volume(dims, 100.0f), o, v, s, order);
          const std::string what = std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                   std::to_string(dims[2]) + " view " + std::to_string(v.theta) +
                                   "," + std::to_string(v.phi) + "," + std::to_string(v.varphi) +
                                   " order " + std::to_string(order);
          ASSERT_EQ(img.width(), 24);
          EXPECT_EQ(image_problem(img), "") << what;
          const int longest = static_cast<int>(std::max({dims[0], dims[1], dims[2]}));
          EXPECT_GT(max_alpha(img), 0.1f) << what;
          EXPECT_LE(max_alpha(img), stacked_alpha(a, 2 * longest + 1)) << what;
        }
  EXPECT_NEAR(max_alpha(render(constant_volume({1, 1, 1}, 1.0f), o, {}, Sampling::pixel)), a, 1e-6);
  EXPECT_NEAR(max_alpha(render(constant_volume({1, 9, 1}, 1.0f), o, {0, 0, 90}, Sampling::pixel)),
              stacked_alpha(a, 9), 1e-6);
}

// Constant volumes with shading and the CT, MRI and VolPack classifiers: the
// gradient is zero everywhere (no surface), which must not produce NaN.
// (The mixture presets classify relative to the value range, which is a
// single value here.)
TEST(Extremes, ConstantVolumesWithShading) {
  std::vector<RenderOptions> opts;
  for (const char* preset : {"ct", "mri", "volpack"}) {
    RenderOptions o;
    o.width = o.height = 24;
    o.classifier = classifier_preset(preset);
    opts.push_back(o);
  }
  for (const RenderOptions& o : opts)
    for (float value : {0.0f, 100.0f, 1000.0f})
      for (const ViewAngles& v : extreme_views()) {
        const Image img = render(constant_volume({9, 8, 7}, value), o, v);
        EXPECT_EQ(image_problem(img), "") << value;
      }
}

// NaN voxels are handled, not rejected: a NaN classifies as transparent
// (alpha 0, colour 0), and shading treats a NaN neighbour as no surface.
TEST(Extremes, NanVoxelsAreTransparent) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float a = 0.5f;
  const RenderOptions o = unlit(a);
  // All NaN: an empty image, exactly.
  for (const ViewAngles& v : extreme_views())
    for (Sampling s : {Sampling::voxel, Sampling::pixel}) {
      const Image img = render(constant_volume({6, 6, 6}, nan), o, v, s);
      for (const Rgba& p : img.pixels()) {
        ASSERT_EQ(p.a, 0.0f);
        ASSERT_EQ(p.r + p.g + p.b, 0.0f);
      }
    }
  // Half NaN (z < 4): seen along z (either way) the rays cross 4 opaque
  // voxels, and nearest-neighbour sampling does not blend the two halves.
  Volume half = constant_volume({8, 8, 8}, 100.0f);
  for (int64_t z = 0; z < 4; ++z)
    for (int64_t y = 0; y < 8; ++y)
      for (int64_t x = 0; x < 8; ++x) half.at(x, y, z) = nan;
  for (const ViewAngles& v : {ViewAngles{0, 0, 0}, ViewAngles{0, 180, 0}}) {
    const Image img = render(half, o, v, Sampling::voxel, 0);
    EXPECT_NEAR(max_alpha(img), stacked_alpha(a, 4), 1e-6);
  }
  // Scattered NaN in a shaded, CT-classified ramp: every pixel finite.
  Volume sprinkled = ramp_volume({9, 7, 8});
  for (std::size_t i = 0; i < sprinkled.voxel_count(); i += 5) sprinkled.data()[i] = nan;
  RenderOptions lit;
  lit.width = lit.height = 24;
  lit.classifier = classifier_preset("ct");
  for (const ViewAngles& v : extreme_views())
    for (int order = 0; order <= 3; ++order)
      EXPECT_EQ(image_problem(render(sprinkled, lit, v, Sampling::voxel, order)), "");
}

// Volume::range: the smallest and largest finite value, NaN and infinities
// left out, at every position of the sixteen running lanes and in the tail
// (sizes 1 .. 40, so counts below, at and past multiples of 16), against a
// plain loop over the values.
TEST(Extremes, RangeSkipsNonFiniteValuesAnywhere) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  int checked = 0;
  for (int64_t n = 1; n <= 40; ++n)
    for (int64_t at = 0; at < n; ++at) {
      Volume v({n, 1, 1}, VoxelType::f32);
      for (int64_t i = 0; i < n; ++i) v.data()[static_cast<std::size_t>(i)] = float(i % 7) - 3.0f;
      // One extreme value at `at`, the non-finite ones beside it.
      v.data()[static_cast<std::size_t>(at)] = at % 2 ? 100.0f + float(at) : -100.0f - float(at);
      if (at + 1 < n) v.data()[static_cast<std::size_t>(at + 1)] = at % 3 ? nan : inf;
      if (at > 0) v.data()[static_cast<std::size_t>(at - 1)] = -inf;
      float lo = inf, hi = -inf;
      for (float x : v.data())
        if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
      const ValueRange r = v.range();
      ASSERT_EQ(r.min, lo) << n << " " << at;
      ASSERT_EQ(r.max, hi) << n << " " << at;
      ++checked;
    }
  EXPECT_EQ(checked, 40 * 41 / 2);
  Volume none({20, 1, 1}, VoxelType::f32);
  for (float& x : none.data()) x = nan;
  none.data()[3] = inf;
  EXPECT_EQ(none.range().min, 0.0f);  // no finite value: {0, 0}
  EXPECT_EQ(none.range().max, 0.0f);
}

// Aitken orders 2 and 3 weigh neighbours by factors below 0 and above 1, so
// between opaque slabs a transparent layer two voxels thick samples to a
// negative alpha, and over() with (1 - alpha) > 1 amplified the rays
// grazing it: pixels of alpha -171.7. The samples are now clamped to valid
// opacities before compositing (clamp_sample); orders 0 and 1 never needed
// it.
TEST(Extremes, HigherOrdersKeepEveryPixelAValidOpacity) {
  const Volume vol = thin_gap_volume();
  RenderOptions opt = thin_gap_options();
  for (int order = 0; order <= 3; ++order)
    for (CompositeMode mode : {CompositeMode::direct, CompositeMode::adaptive}) {
      opt.order = order;
      opt.composite.mode = mode;
      EXPECT_EQ(image_problem(render_reference(vol, opt)), "")
          << "order " << order << (mode == CompositeMode::direct ? " direct" : " adaptive");
    }
}

// An image far wider than the volume: its intermediate image is cut to the
// rays that can hit the volume (make_view), and the warp reads the columns
// cut away as zeros. The 1000x16 image of a 16^3 volume (scale 1: 1002
// columns uncut, 32 kept) holds in its middle 16 columns the 16x16 image
// (18 columns; both even, so the rays lie alike), and nothing where no ray
// reaches; at a view on the axes the grid's positions are exact, so the two
// agree bit for bit.
TEST(Extremes, ImagesFarWiderThanTheVolumeHoldTheSquareImage) {
  const Volume vol = ramp_volume({16, 16, 16});
  RenderOptions lit = unlit(0.3f);
  lit.shade.enabled = true;
  lit.classifier = classifier_preset("ct");
  for (const ViewAngles v : {ViewAngles{0, 0, 0}, ViewAngles{0, 90, 0}, ViewAngles{20, 35, 10}}) {
    RenderOptions wide = lit, square = lit;
    wide.width = 1000;
    wide.height = square.width = square.height = 16;
    const Image a = render(vol, wide, v), b = render(vol, square, v);
    ASSERT_EQ(a.width(), 1000);
    const bool exact = v.theta == 0 && v.varphi == 0;
    float worst = 0.0f;
    double outside = 0.0;
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 1000; ++x) {
        const Rgba p = a.at(x, y);
        if (x >= 492 && x < 508) {
          const Rgba q = b.at(x - 492, y);
          for (float d : {p.r - q.r, p.g - q.g, p.b - q.b, p.a - q.a})
            worst = std::max(worst, std::fabs(d));
        } else if (std::abs(x + 0.5 - 500.0) > 14.0) {  // beyond the radius, 13.86
          outside += p.r + p.g + p.b + p.a;
        }
      }
    EXPECT_LE(worst, exact ? 0.0f : 1e-6f) << v.theta << "," << v.phi << "," << v.varphi;
    EXPECT_EQ(outside, 0.0);
    EXPECT_GT(max_alpha(b), 0.05f);  // not an empty picture (0.079 at the axes)
  }
}
