// Extreme but valid inputs through render_opencl, each against
// render_reference within 1e-5 (the tolerance of the engine's own tests:
// the device classify differs by ~1e-6 and the sub-ray composites
// re-associate over): 1x1x1 and 1xNx1 volumes, dims no cell size divides,
// views on the axes and at 45 degrees, P = 1 and P far above the voxel
// count (8192 PEs for 4x4x4), constant volumes, NaN voxels.
#include <gtest/gtest.h>

#include "extremes_cases.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/render.hpp"
#include "stage_testing.hpp"

using namespace simdvol;
using namespace simdvol::extremes;

namespace {

constexpr float kTol = 1e-5f;

struct Case {
  std::string name;
  Volume vol;
  RenderOptions opt;
};

std::string describe(const Case& c, const ViewAngles& v, Sampling s, int64_t pes) {
  return c.name + " view " + std::to_string(v.theta) + "," + std::to_string(v.phi) + "," +
         std::to_string(v.varphi) + (s == Sampling::voxel ? " voxel" : " pixel") + " P " +
         std::to_string(pes);
}

/// Renders every case on every view, both samplings and each P, against
/// the reference; returns how many renders were compared.
int compare_all(Device& dev, const std::vector<Case>& cases, const std::vector<int64_t>& pes_list,
                const std::vector<ViewAngles>& views) {
  int n = 0;
  for (const Case& c : cases)
    for (const ViewAngles& v : views)
      for (Sampling s : {Sampling::voxel, Sampling::pixel}) {
        RenderOptions opt = c.opt;
        opt.view = v;
        opt.sampling = s;
        const Image ref = render_reference(c.vol, opt);
        for (int64_t pes : pes_list) {
          const std::string what = describe(c, v, s, pes);
          Image img;
          try {
            img = render_opencl(dev, c.vol, opt, nullptr, pes, true);
          } catch (const std::exception& e) {
            ADD_FAILURE() << what << ": render_opencl threw: " << e.what();
            continue;
          }
          EXPECT_EQ(image_problem(img), "") << what;
          EXPECT_LE(max_abs_diff(ref, img), kTol) << what;
          ++n;
        }
      }
  return n;
}

}  // namespace

TEST(ExtremesOpenCl, DegenerateDims) {
  SIMDVOL_TEST_DEVICE(dev);
  std::vector<Case> cases;
  for (auto dims : {std::array<int64_t, 3>{1, 1, 1}, {1, 9, 1}, {9, 1, 1}, {1, 1, 9}, {1, 6, 5}})
    cases.push_back({"constant " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                         std::to_string(dims[2]),
                     constant_volume(dims, 100.0f), unlit(0.5f)});
  EXPECT_EQ(compare_all(dev, cases, {1, 8, 8192}, extreme_views()), 5 * 10 * 2 * 3);
}

TEST(ExtremesOpenCl, DimsNoCellSizeDivides) {
  SIMDVOL_TEST_DEVICE(dev);
  std::vector<Case> cases;
  RenderOptions lit = unlit(0.3f);
  lit.shade.enabled = true;
  lit.classifier = classifier_preset("ct");
  for (auto dims : {std::array<int64_t, 3>{7, 5, 3}, {13, 11, 9}, {17, 3, 10}})
    cases.push_back({"ramp " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                         std::to_string(dims[2]),
                     ramp_volume(dims), lit});
  EXPECT_EQ(compare_all(dev, cases, {1, 2, 64, 512, 8192}, extreme_views()), 3 * 10 * 2 * 5);
}

TEST(ExtremesOpenCl, MorePesThanVoxels) {
  SIMDVOL_TEST_DEVICE(dev);
  RenderOptions lit = unlit(0.3f);
  lit.shade.enabled = true;
  lit.classifier = classifier_preset("ct");
  std::vector<Case> cases{
      {"ramp 4x4x4", ramp_volume({4, 4, 4}), lit},
      {"constant 4x4x4", constant_volume({4, 4, 4}, 80.0f), unlit(0.2f)},
      {"constant 2x2x2 u8", constant_volume({2, 2, 2}, 7.0f, VoxelType::u8), unlit(0.9f)}};
  EXPECT_EQ(compare_all(dev, cases, {1, 64, 128, 1024, 8192}, extreme_views()), 3 * 10 * 2 * 5);
}

TEST(ExtremesOpenCl, ConstantVolumes) {
  SIMDVOL_TEST_DEVICE(dev);
  RenderOptions mixture;  // shading on
  mixture.width = mixture.height = 24;
  mixture.classifier = classifier_preset("mri");
  RenderOptions ct = mixture;
  ct.classifier = classifier_preset("ct");
  std::vector<Case> cases{
      {"constant 0", constant_volume({8, 8, 8}, 0.0f), mixture},
      {"constant 1000 ct", constant_volume({9, 8, 7}, 1000.0f), ct},
      {"constant 255 u8", constant_volume({6, 6, 6}, 255.0f, VoxelType::u8), mixture}};
  EXPECT_EQ(compare_all(dev, cases, {1, 512}, extreme_views()), 3 * 10 * 2 * 2);
}

TEST(ExtremesOpenCl, NanVoxelsAgreeWithTheReference) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume all_nan = constant_volume({6, 6, 6}, std::numeric_limits<float>::quiet_NaN());
  Volume half = constant_volume({8, 8, 8}, 100.0f);
  for (int64_t z = 0; z < 4; ++z)
    for (int64_t y = 0; y < 8; ++y)
      for (int64_t x = 0; x < 8; ++x) half.at(x, y, z) = std::numeric_limits<float>::quiet_NaN();
  Volume sprinkled = ramp_volume({9, 7, 8});
  for (std::size_t i = 0; i < sprinkled.voxel_count(); i += 5)
    sprinkled.data()[i] = std::numeric_limits<float>::quiet_NaN();
  RenderOptions lit;
  lit.width = lit.height = 24;
  lit.classifier = classifier_preset("ct");
  std::vector<Case> cases{{"all NaN", all_nan, unlit(0.5f)},
                          {"half NaN", half, unlit(0.5f)},
                          {"sprinkled NaN, unlit", sprinkled, unlit(0.4f)},
                          {"sprinkled NaN, ct shaded", sprinkled, lit}};
  EXPECT_EQ(compare_all(dev, cases, {1, 64, 8192}, extreme_views()), 4 * 10 * 2 * 3);
}

// The thin transparent layer of extremes_cases.hpp at orders 2 and 3: the
// kernels clamp their samples as the reference does (sv_clamp_sample), so
// every pixel is a valid opacity and equals the reference's.
TEST(ExtremesOpenCl, HigherOrdersKeepEveryPixelAValidOpacity) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = thin_gap_volume();
  RenderOptions opt = thin_gap_options();
  for (int order : {2, 3})
    for (CompositeMode mode : {CompositeMode::direct, CompositeMode::adaptive, CompositeMode::mc}) {
      opt.order = order;
      opt.composite.mode = mode;
      opt.composite.samples = 5;
      const std::string what = "order " + std::to_string(order) +
                               (mode == CompositeMode::direct     ? " direct"
                                : mode == CompositeMode::adaptive ? " adaptive"
                                                                  : " mc");
      const Image ref = render_reference(vol, opt);
      const Image img = render_opencl(dev, vol, opt, nullptr, 64, true);
      EXPECT_EQ(image_problem(ref), "") << what;
      EXPECT_EQ(image_problem(img), "") << what;
      EXPECT_LE(max_abs_diff(ref, img), kTol) << what;
    }
}

// Images far wider or taller than the volume: voxel sampling's intermediate
// image is cut to the rays that can hit the volume, and the device's warp
// reads the columns and rows cut away as zeros, as the reference does (its
// taps far outside the image are moved next to it). 1000x16 of a 13x11x9
// volume keeps 33 of 1,002 columns; 1x300 renders the volume into one
// column. Before the cut the device refused none of these, but after it
// (without the taps moved) every voxel-sampled one failed "warp out of
// range".
TEST(ExtremesOpenCl, ImagesFarWiderOrTallerThanTheVolume) {
  SIMDVOL_TEST_DEVICE(dev);
  RenderOptions lit = unlit(0.3f);
  lit.shade.enabled = true;
  lit.classifier = classifier_preset("ct");
  std::vector<Case> cases;
  for (auto [w, h] : {std::pair{1000, 16}, {7, 900}, {1, 300}, {300, 1}}) {
    RenderOptions o = lit;
    o.width = w;
    o.height = h;
    cases.push_back({"ramp 13x11x9 at " + std::to_string(w) + "x" + std::to_string(h),
                     ramp_volume({13, 11, 9}), o});
  }
  EXPECT_EQ(compare_all(dev, cases, {1, 8192}, extreme_views()), 4 * 10 * 2 * 2);
}
