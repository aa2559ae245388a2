// The classify kernel (kernels/classify.cl), the fused shade + classify
// kernel and render_opencl against the serial reference.
//
// Tolerance: 1e-5 absolute per channel of the premultiplied RGBA.
//  - classify alone is fed the reference's own shading, so only its float
//    arithmetic differs from the reference's double: the mixture's exponent
//    L_j - L_i (terms up to ~130 for CT between soft tissue and bone, float
//    error ~1e-5 there) moves p_i by at most p_i (1 - p_i) times that, and
//    a' = 1 - (1 - a)^step (the reference's -expm1(step log1p(-a)) in
//    double; the device's 1 - e^(step ln(1 - a)) with ln(1 - a) from a and
//    1 - e^x without cancellation, a series below a = 2^-8) within 4 ulp
//    (OpacityStepWithinFourUlpOfTheReference).
//  - Empty voxels: exactly the reference's (empty_mismatches). Both take
//    the smaller mixture fraction as e^-|dl| / (1 + e^-|dl|), so it keeps a
//    relative accuracy of ~|dl| 1e-6 down to the smallest normal float, and
//    both make a subnormal alpha transparent.
//  - shade -> classify on the device against shade -> classify in the
//    reference adds the shade kernel's differences (test_shade_cl.cpp);
//    transfer functions see |g| only through ramps of slope <= 1/15 here.
//  - the fused kernel equals the two stages to 1e-6 (same float code,
//    compiled in another program); so do the scalar kernels (one voxel per
//    work-item) and the float16 ones (16 voxels per work-item, the
//    defaults), which do the same float operations lane by lane.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "simdvol/engine.hpp"
#include "simdvol/io.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/stages.hpp"
#include "stage_testing.hpp"
#include "testing.hpp"

namespace simdvol {
namespace {

constexpr double kTol = 1e-5;

double max_diff(const std::vector<Rgba>& a, const std::vector<Rgba>& b) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    d = std::max(d, static_cast<double>(std::fabs(a[i].r - b[i].r)));
    d = std::max(d, static_cast<double>(std::fabs(a[i].g - b[i].g)));
    d = std::max(d, static_cast<double>(std::fabs(a[i].b - b[i].b)));
    d = std::max(d, static_cast<double>(std::fabs(a[i].a - b[i].a)));
    if (std::isnan(b[i].r) || std::isnan(b[i].a)) return INFINITY;
  }
  return d;
}

// Voxels empty (alpha 0) in one and not the other. Must be none: Monte
// Carlo's allocation gives a walk to every sub-ray with alpha > 0 and its
// stratified picks are keyed by the first sample with alpha > 0, so a voxel
// of alpha 1e-11 that the device makes 0 changes the picks of whole rays.
int64_t empty_mismatches(const std::vector<Rgba>& a, const std::vector<Rgba>& b) {
  int64_t n = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) n += (a[i].a > 0) != (b[i].a > 0);
  return n;
}

// A transfer function with several knots, colour ramps and a step.
Classifier many_knots() {
  Classifier c;
  c.kind = Classifier::Kind::transfer;
  c.transfer.density.x = {-1000, -300, -100, 0, 80, 80, 300, 1200, 1800};
  c.transfer.density.y = {0, 0, 0.05f, 0.02f, 0.3f, 0.5f, 0.6f, 0.9f, 1};
  c.transfer.gradient.x = {0, 5, 20, 300};
  c.transfer.gradient.y = {0.1f, 0.2f, 1, 1};
  c.transfer.red.x = c.transfer.green.x = c.transfer.blue.x = {-1000, 0, 500, 1500};
  c.transfer.red.y = {0.2f, 0.9f, 1, 1};
  c.transfer.green.y = {0.1f, 0.5f, 0.8f, 1};
  c.transfer.blue.y = {0.8f, 0.3f, 0.6f, 1};
  return c;
}

// A mixture of n materials spread over -1000 .. 2000 with varied colours:
// n = 2 and n > 8 take the select chain of sv_mixture16, 3 <= n <= 8 its
// vpermps path (8: the last index 7 of the table).
Classifier mixture_of(int n) {
  Classifier c;
  c.kind = Classifier::Kind::mixture;
  c.mixture.materials.clear();
  for (int i = 0; i < n; ++i) {
    const float f = static_cast<float>(i) / static_cast<float>(n - 1);
    c.mixture.materials.push_back({std::to_string(i), -1000.0f + 3000.0f * f,
                                   60.0f + 40.0f * static_cast<float>(i % 3), f, 1.0f - f,
                                   0.3f + 0.5f * static_cast<float>(i % 2), 0.05f + 0.9f * f});
  }
  return c;
}

// Two materials far apart for their sigmas (red, then green; the point
// between them where their fractions cross at 0, exactly for a power of 2
// `scale`): means 4 x `scale` apart, sigmas 1 and 3.
Classifier far_pair(float scale) {
  Classifier c;
  c.kind = Classifier::Kind::mixture;
  c.mixture.materials = {{"lo", -scale, 1.0f, 1, 0, 0, 0.5f},
                         {"hi", 3 * scale, 3.0f, 0, 1, 0, 0.8f}};
  return c;
}

Classifier by_name(const std::string& name) {
  if (name == "far9") return far_pair(0x1p30f);
  if (name == "far18") return far_pair(0x1p60f);
  if (name.rfind("mix", 0) == 0) return mixture_of(std::stoi(name.substr(3)));
  if (name == "mri-max") {  // the preset's fractions of the whole range
    Classifier c = classifier_preset("mri");
    c.mixture.top_percentile = 100.0f;
    return c;
  }
  return name == "knots" ? many_knots() : classifier_preset(name);
}

struct Case {
  const Volume* vol;
  std::string classifier;
  ViewAngles view;
  int64_t pes;
  double step = 1.0;
  ShadeParams shade{};
};

// Runs classify alone (fed the reference's shading), the two device stages,
// and the fused kernel; compares each with the reference.
void check_case(const Case& k) {
  const Volume& vol = *k.vol;
  SCOPED_TRACE(k.classifier + " pes=" + std::to_string(k.pes) + " step=" + std::to_string(k.step) +
               " view=(" + std::to_string(k.view.theta) + "," + std::to_string(k.view.phi) + ")");
  Device& dev = *testing::test_device();
  const Classifier c = by_name(k.classifier);
  const ViewGeometry view = make_view(vol, k.view, 64, 64, Sampling::voxel);
  const std::vector<ShadeSample> shading = shade(vol, view, k.shade);
  const std::vector<Rgba> ref = classify(vol, shading, c, k.step);
  const sv_classify_params cp = classify_params(c, classify_range(vol, c), k.step);
  const sv_shade_params sp = shade_params(make_shade_frame(vol, view, k.shade), k.shade);

  PeArray array(dev, pe_grid(k.pes));
  CellBuffer cells = array.layout(vol, 1);
  const VoxelLayout L = make_voxel_layout(cells.layout());
  VoxelBuffer shade_buf(dev, L), out(dev, L), fused(dev, L);

  // 1. classify alone, on the reference's shading (with v in the 4th channel).
  std::vector<ShadeSample> s4 = shading;
  for (std::size_t i = 0; i < s4.size(); ++i) s4[i].pad = vol.data()[i];
  shade_buf.write(dev, voxels_to_cells(s4, L));
  enqueue_classify(dev, shade_buf, cp, out);
  dev.finish();
  const std::vector<Rgba> alone = voxels_from_cells(out.read<Rgba>(dev), L);
  const double d_alone = max_diff(ref, alone);
  EXPECT_LE(d_alone, kTol) << "classify alone";
  EXPECT_EQ(empty_mismatches(ref, alone), 0) << "classify alone";
  // 1b. the scalar classify kernel gives the same (same float operations).
  VoxelBuffer scalar_out(dev, L);
  enqueue_classify(dev, shade_buf, cp, scalar_out, ClassifyKernel::scalar);
  dev.finish();
  EXPECT_EQ(max_diff(alone, voxels_from_cells(scalar_out.read<Rgba>(dev), L)), 0.0)
      << "scalar vs float16 classify";
  // 1c. in place (both kernels): the same bits in every position of the
  // buffer (block tails included), the shading overwritten.
  {
    const std::vector<Rgba> whole = out.read<Rgba>(dev);
    for (ClassifyKernel v : {ClassifyKernel::vec16, ClassifyKernel::scalar}) {
      VoxelBuffer in_place(dev, L);
      in_place.write(dev, voxels_to_cells(s4, L));
      enqueue_classify_in_place(dev, in_place, cp, v);
      dev.finish();
      const std::vector<Rgba> got = in_place.read<Rgba>(dev);
      ASSERT_EQ(got.size(), whole.size());
      EXPECT_EQ(std::memcmp(got.data(), whole.data(), got.size() * sizeof(Rgba)), 0)
          << "classify in place, " << (v == ClassifyKernel::vec16 ? "float16" : "scalar");
    }
  }

  // 2. shade -> classify on the device, gathered by the device gather.
  enqueue_shade(dev, cells, sp, shade_buf);
  enqueue_classify(dev, shade_buf, cp, out);
  std::vector<Rgba> staged(vol.voxel_count());
  gather_rgba(dev, out, staged.data());
  const double d_staged = max_diff(ref, staged);
  EXPECT_LE(d_staged, kTol) << "shade + classify";
  EXPECT_EQ(empty_mismatches(ref, staged), 0) << "shade + classify";

  // 3. fused, marking the brick occupancy of what it writes: the same as
  // the scan of the written voxels (enqueue_occupancy), exactly.
  DeviceOccupancy marked = make_occupancy(dev, L, 1);
  enqueue_shade_classify(dev, cells, sp, cp, fused, ShadeKernel::vec16, &marked);
  const DeviceOccupancy scanned = enqueue_occupancy(dev, fused, 1);
  dev.finish();
  {
    const auto n = static_cast<std::size_t>(marked.count());
    std::vector<cl_uint> a(n), b(n);
    cl_check(dev.queue().enqueueReadBuffer(marked.occupied, CL_TRUE, 0, n * 4, a.data()), "read");
    cl_check(dev.queue().enqueueReadBuffer(scanned.occupied, CL_TRUE, 0, n * 4, b.data()), "read");
    EXPECT_EQ(a, b) << "marked vs scanned brick occupancy";
  }
  EXPECT_THROW(enqueue_shade_classify(dev, cells, sp, cp, fused, ShadeKernel::range3d, &marked),
               ArgumentError);
  const double d_fused = max_diff(staged, voxels_from_cells(fused.read<Rgba>(dev), L));
  EXPECT_EQ(d_fused, 0.0) << "fused vs staged";

  // 3b. fused into interleaved cells (the engine's fused path): every
  // position of every block the same bits as the planar cells (block tails
  // aside: unspecified), the same marked and scanned occupancy, the same
  // gather; the other kernels refuse interleaved cells.
  {
    const VoxelLayout L4 = make_voxel_layout(cells.layout(), true);
    VoxelBuffer il(dev, L4);
    DeviceOccupancy marked4 = make_occupancy(dev, L4, 1);
    enqueue_shade_classify(dev, cells, sp, cp, il, ShadeKernel::vec16, &marked4);
    const DeviceOccupancy scanned4 = enqueue_occupancy(dev, il, 1);
    dev.finish();
    const std::vector<Rgba> a = voxels_from_cells(fused.read<Rgba>(dev), L);
    const std::vector<Rgba> b = voxels_from_cells(il.read<Rgba>(dev), L4);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Rgba)), 0) << "interleaved";
    const auto n = static_cast<std::size_t>(marked.count());
    std::vector<cl_uint> m0(n), m4(n), s4(n);
    cl_check(dev.queue().enqueueReadBuffer(marked.occupied, CL_TRUE, 0, n * 4, m0.data()), "read");
    cl_check(dev.queue().enqueueReadBuffer(marked4.occupied, CL_TRUE, 0, n * 4, m4.data()), "read");
    cl_check(dev.queue().enqueueReadBuffer(scanned4.occupied, CL_TRUE, 0, n * 4, s4.data()),
             "read");
    EXPECT_EQ(m0, m4) << "marked occupancy, interleaved";
    EXPECT_EQ(m0, s4) << "scanned occupancy, interleaved";
    std::vector<Rgba> g4(vol.voxel_count());
    gather_rgba(dev, il, g4.data());
    EXPECT_EQ(std::memcmp(g4.data(), staged.data(), g4.size() * sizeof(Rgba)), 0)
        << "gather, interleaved";
    EXPECT_THROW(enqueue_classify(dev, shade_buf, cp, il), ArgumentError);
    EXPECT_THROW(enqueue_classify_in_place(dev, il, cp), ArgumentError);
    EXPECT_THROW(enqueue_shade(dev, cells, sp, il), ArgumentError);
    EXPECT_THROW(enqueue_shade_classify(dev, cells, sp, cp, il, ShadeKernel::range3d),
                 ArgumentError);
  }

  // 4. the scalar fused kernel (3-D range) and the scalar stages.
  enqueue_shade_classify(dev, cells, sp, cp, fused, ShadeKernel::range3d);
  dev.finish();
  EXPECT_LE(max_diff(staged, voxels_from_cells(fused.read<Rgba>(dev), L)), 1e-6)
      << "scalar fused vs staged";
  enqueue_shade(dev, cells, sp, shade_buf, ShadeKernel::rows);
  enqueue_classify(dev, shade_buf, cp, out, ClassifyKernel::scalar);
  dev.finish();
  EXPECT_LE(max_diff(staged, voxels_from_cells(out.read<Rgba>(dev), L)), 1e-6)
      << "scalar stages vs staged";
}

const ViewAngles kViews[] = {{0, 0, 0}, {30, 45, 10}, {-70, 120, 200}};

TEST(ClassifyKernel, SheppLoganPresetsAndPeCounts) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(48);
  for (const char* name : {"ct", "ct-bone", "mri", "volpack", "knots"})
    for (int64_t pes : {1, 8, 512, 8192}) check_case({&vol, name, kViews[1], pes});
  check_case({&vol, "ct", kViews[2], 512});
  check_case({&vol, "knots", kViews[0], 8});
  // Air (-1000) at the first material's mean: whole chunks of it are empty
  // for the presets (opacity 0 there; the fused kernel stores them without
  // the mixture), not for these mixtures (first opacity 0.05).
  for (const char* name : {"mix2", "mix8"}) check_case({&vol, name, kViews[1], 512});
}

TEST(ClassifyKernel, MarschnerLobbRelativeMixture) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = marschner_lobb(48);
  for (int64_t pes : {8, 8192}) check_case({&vol, "mri", kViews[1], pes});
}

TEST(ClassifyKernel, OddVolumeAndOpacitySteps) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = testing::random_volume({37, 29, 23}, -1100.0f, 2000.0f, {1.0, 0.8, 2.5}, 7);
  for (const char* name : {"ct", "ct-bone", "mri", "knots"})
    for (int64_t pes : {1, 8, 512, 8192}) check_case({&vol, name, kViews[2], pes});
  for (const char* name : {"mix2", "mix8", "mix9"}) check_case({&vol, name, kViews[1], 512});
  for (double step : {0.37, 1.7, 3.0}) {
    check_case({&vol, "ct", kViews[1], 512, step});
    check_case({&vol, "knots", kViews[1], 8, step});
  }
  ShadeParams unlit;
  unlit.enabled = false;
  check_case({&vol, "ct", kViews[0], 8, 1.0, unlit});
}

// The opacity step a' = 1 - (1 - a)^s of the kernels against the
// reference's double -expm1(s log1p(-a)) (rounded to float) in ulp, for
// alphas from 2^-10 to 1 - 2^-10 (a transfer function a = v, unlit) and
// steps below and above 1: within 4 ulp for every voxel, both kernels.
// Until 2026-12-06 the kernels took ln t of the rounded t = 1 - a below
// a = 1/2 and 1 - e^x in two steps: up to 332 ulp (3e-8 absolute, which at
// pixel sampling moved Monte Carlo's picks and adaptive stops in a few
// pixels of a 512 x 400 frame of ch2).
TEST(ClassifyKernel, OpacityStepWithinFourUlpOfTheReference) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume vol({64, 64, 16}, VoxelType::f32);
  auto& v = vol.data();
  const std::size_t n = v.size();
  for (std::size_t i = 0; i < n; ++i) {  // log-spaced in a and in 1 - a, half each
    const double f = static_cast<double>(i / 2) / static_cast<double>(n / 2);
    const double x = std::pow(2.0, -10.0 + 9.0 * f);  // 2^-10 .. 2^-1
    v[i] = static_cast<float>(i % 2 ? x : 1.0 - x);
  }
  Classifier c;
  c.kind = Classifier::Kind::transfer;
  c.transfer.density.x = {0, 1};
  c.transfer.density.y = {0, 1};
  std::vector<ShadeSample> shading(n, ShadeSample{1.0f, 0.0f, 0.0f, 0.0f});
  std::vector<ShadeSample> s4 = shading;
  for (std::size_t i = 0; i < n; ++i) s4[i].pad = v[i];
  PeArray array(dev, pe_grid(8));
  CellBuffer cells = array.layout(vol, 1);
  const VoxelLayout L = make_voxel_layout(cells.layout());
  VoxelBuffer in(dev, L), out(dev, L);
  in.write(dev, voxels_to_cells(s4, L));
  for (double step : {0.3, 0.7, 1.3, 2.5}) {
    const std::vector<Rgba> ref = classify(vol, shading, c, step);
    const sv_classify_params cp = classify_params(c, ValueRange{}, step);
    for (ClassifyKernel k : {ClassifyKernel::vec16, ClassifyKernel::scalar}) {
      enqueue_classify(dev, in, cp, out, k);
      dev.finish();
      const std::vector<Rgba> got = voxels_from_cells(out.read<Rgba>(dev), L);
      ASSERT_EQ(got.size(), n);
      int64_t worst = 0, equal = 0;
      for (std::size_t i = 0; i < n; ++i) {
        int32_t a, b;
        std::memcpy(&a, &got[i].a, 4);
        std::memcpy(&b, &ref[i].a, 4);
        ASSERT_GT(ref[i].a, 0.0f) << i;
        worst = std::max<int64_t>(worst, std::abs(static_cast<int64_t>(a) - b));
        equal += a == b;
      }
      std::printf("step %.1f, %s: worst %lld ulp, %.1f %% of the alphas the same bits\n", step,
                  k == ClassifyKernel::vec16 ? "float16" : "scalar", static_cast<long long>(worst),
                  100.0 * static_cast<double>(equal) / static_cast<double>(n));
      EXPECT_LE(worst, 4) << "step " << step;
    }
  }
}

// Integer volumes holding every value of their range once (in a shuffled
// order), with the "mri" preset's relative means (0.15, 0.45, 0.6, 0.85) of
// the whole range ("mri-max"; the preset's own, of its 99th percentile, too):
// for the ranges 0 .. 255 (value 153 = 0.6), 0 .. 100 (45 = 0.45),
// 0 .. 1000, -1000 .. 1000 and 0 .. 4095 some value lands exactly on a mean,
// where the mixture jumps (the bracketing pair changes); a reference that
// took I = (v - min) / (max - min) in double put those values on the other
// side of the mean from the kernel's float I (alpha 0.0192 against 0.0234
// at 153 of 0 .. 255, 3 of -1000 .. 1000's values with one side empty).
TEST(ClassifyKernel, RelativeMixtureAtTheMaterialMeans) {
  SIMDVOL_TEST_DEVICE(dev);
  const int ranges[][2] = {{0, 255}, {0, 100}, {0, 1000}, {-1000, 1000}, {0, 4095}};
  for (const auto& r : ranges) {
    const int64_t n = r[1] - r[0] + 1;
    const int64_t nx = 16, ny = 16, nz = (n + nx * ny - 1) / (nx * ny);
    Volume vol({nx, ny, nz}, r[0] < 0 ? VoxelType::i16 : VoxelType::u16);
    auto& v = vol.data();
    // every value once, the rest of the grid the range's minimum
    std::fill(v.begin(), v.end(), static_cast<float>(r[0]));
    for (int64_t k = 0; k < n; ++k)
      v[static_cast<std::size_t>((k * 7919) % (nx * ny * nz))] = static_cast<float>(r[0] + k);
    SCOPED_TRACE("range " + std::to_string(r[0]) + " .. " + std::to_string(r[1]));
    ASSERT_EQ(vol.range().min, static_cast<float>(r[0]));
    ASSERT_EQ(vol.range().max, static_cast<float>(r[1]));
    ShadeParams unlit;
    unlit.enabled = false;
    for (int64_t pes : {1, 512}) check_case({&vol, "mri-max", kViews[1], pes, 1.0, unlit});
    check_case({&vol, "mri-max", kViews[2], 8});
    check_case({&vol, "mri", kViews[2], 8});
  }
}

TEST(ClassifyKernel, BrainSmall) {
  const auto path = testing::data_dir() / "brainsmall.den";
  SIMDVOL_REQUIRE_FILE(path);
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = load_den(path);
  ShadeParams p;  // VolPack's rendervolume.c lighting
  p.ka = 0.18;
  p.kd = 0.35;
  p.ks = 0.39;
  p.shininess = 10;
  p.light = {0.3, 0.3, 1.0};
  check_case({&vol, "volpack", kViews[1], 8192, 1.0, p});
  check_case({&vol, "volpack", kViews[2], 512, 1.0, p});
  check_case({&vol, "mri", kViews[1], 8, 1.0, p});
}

// Cells whose x extent is 16k, 8 or 4 (the float16 shade kernel's row
// widths), with plane tails (cell voxels not a multiple of 16) for 8 and 4.
TEST(ClassifyKernel, Float16CellShapes) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume a = testing::random_volume({48, 7, 5}, -1100.0f, 1500.0f, {1, 1, 1}, 21);
  const Volume b = testing::random_volume({16, 3, 5}, -1100.0f, 1500.0f, {1, 1.5, 1}, 22);
  const Volume c = testing::random_volume({8, 3, 3}, -1100.0f, 1500.0f, {1, 1, 2}, 23);
  // The volume's far x edge inside a quad of lanes (the brick marking takes
  // 4 lanes at a time): cells 16, 8 and 4 wide whose last one sticks out by
  // 1, 3 and 1 voxels.
  const Volume d = testing::random_volume({31, 5, 6}, -1100.0f, 1500.0f, {1, 1, 1}, 24);
  const Volume e = testing::random_volume({61, 9, 7}, -1100.0f, 1500.0f, {1, 1, 1}, 25);
  const Volume f = testing::random_volume({15, 3, 3}, -1100.0f, 1500.0f, {1, 1, 1}, 26);
  EXPECT_EQ(make_cell_layout(d.dims(), 2, 1).cell()[0], 16);
  EXPECT_EQ(make_cell_layout(e.dims(), 8, 1).cell()[0], 8);
  EXPECT_EQ(make_cell_layout(f.dims(), 4, 1).cell()[0], 4);
  for (const char* name : {"ct", "knots"}) {
    check_case({&a, name, kViews[1], 1});       // 48 x 7 x 5: row width 16
    check_case({&b, name, kViews[1], 2});       // 8 x 3 x 5, tail 8
    check_case({&c, name, kViews[2], 2, 0.5});  // 4 x 3 x 3, tail 12
    check_case({&d, name, kViews[1], 2});       // 16 x 5 x 6
    check_case({&e, name, kViews[1], 8});       // 8 x 9 x 7
    check_case({&f, name, kViews[2], 4});       // 4 x 3 x 3
  }
}

// Values across the ct preset's air / fat boundary in steps of 1/16 HU:
// there the fat fraction falls from 1/2 to e^-87 and below (subnormal alpha:
// transparent). The device computes it in float, the reference in double;
// both keep the small fraction's value instead of 1 minus the large one, so
// the same voxels are empty (check_case) and the small alphas agree to a
// relative 1e-3 (the float log-likelihoods differ by up to ~1e-4 at
// |L_j - L_i| ~ 90).
TEST(ClassifyKernel, SmallFractionsAtAMaterialBoundary) {
  SIMDVOL_TEST_DEVICE(dev);
  const Classifier ct = classifier_preset("ct");
  const auto& mats = ct.mixture.materials;
  ASSERT_EQ(mats[0].opacity, 0.0f);  // air
  Volume vol({32, 32, 16}, VoxelType::f32);
  for (std::size_t n = 0; n < vol.data().size(); ++n)
    vol.data()[n] = mats[0].mean + static_cast<float>(n) / 16.0f;
  ASSERT_GT(vol.data().back(), mats[1].mean);
  for (double step : {1.0, 0.6}) check_case({&vol, "ct", kViews[1], 8, step});

  const ViewGeometry view = make_view(vol, kViews[1], 64, 64, Sampling::voxel);
  const std::vector<Rgba> ref = classify(vol, shade(vol, view, {}), ct, 1.0);
  PeArray array(dev, pe_grid(8));
  CellBuffer cells = array.layout(vol, 1);
  const VoxelLayout L = make_voxel_layout(cells.layout());
  VoxelBuffer out(dev, L);
  enqueue_shade_classify(dev, cells, shade_params(make_shade_frame(vol, view, {}), {}),
                         classify_params(ct, {}, 1.0), out);
  dev.finish();
  const std::vector<Rgba> got = voxels_from_cells(out.read<Rgba>(dev), L);
  int small = 0;
  for (std::size_t n = 0; n < ref.size(); ++n)
    if (ref[n].a > 0 && ref[n].a < 1e-7f) {
      ++small;
      EXPECT_NEAR(got[n].a, ref[n].a, 1e-3 * ref[n].a) << "value " << vol.data()[n];
    }
  EXPECT_GT(small, 20);  // the range reaches fractions far below float's 1 - p
}

// Means far apart for their sigmas (4 x 2^30 and 4 x 2^60 units, sigmas 1
// and 3),
// over intensities within 16 of the point between them where the
// fractions cross (0): the kernels take the log-likelihood difference
// about that point (mixture_pair), as the reference does, and equal it.
// As the difference of the two materials' terms (1e18 and more each) float
// had lost the crossing by tens of units: the image of a phantom 0.04 from
// the reference's at means 1e9 apart, 0.25 at 1e18.
TEST(ClassifyKernel, FarMeansCrossWhereTheReferenceDoes) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume vol({32, 16, 8}, VoxelType::f32);
  for (std::size_t n = 0; n < vol.data().size(); ++n)
    vol.data()[n] = (static_cast<float>(n) - 2048.0f) / 128.0f;
  for (float scale : {0x1p30f, 0x1p60f}) {
    ASSERT_EQ(
        mixture_pair(far_pair(scale).mixture.materials[0], far_pair(scale).mixture.materials[1]).c,
        0.0);
    float col[3];
    // By hand: red below 0, green above, both halves at 0.
    EXPECT_EQ(classify_voxel(far_pair(scale), {}, -1.0f / 128.0f, 0.0f, col), 0.5f);
    EXPECT_EQ(col[0], 0.5f);
    EXPECT_EQ(classify_voxel(far_pair(scale), {}, 1.0f / 128.0f, 0.0f, col), 0.8f);
    EXPECT_EQ(col[1], 0.8f);
  }
  check_case({&vol, "far9", kViews[1], 8, 1.0});
  check_case({&vol, "far18", kViews[1], 8, 0.6});
}

// The fused kernel's `live` (a kept volume's next frame): the PEs flagged
// 0 and the chunks of 16 positions it finds transparent in the others are
// left as they are in `out`, every other chunk shaded again. On cells that
// hold the same kernel's result under another lighting (another view), the
// result equals a fresh call's bit for bit; on cells that hold NaN, those
// PEs and chunks keep it (what the kernel leaves alone), and every other
// chunk is the fresh call's. Interleaved cells (the engine's) and planar,
// a mixture (ct) and a transfer function (knots: its density is 0 in air).
TEST(ClassifyKernel, LiveLeavesUnflaggedPesAndTransparentChunks) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 2);
  const ViewGeometry va = make_view(vol, kViews[1], 48, 48, Sampling::voxel);
  const ViewGeometry vb = make_view(vol, kViews[2], 48, 48, Sampling::voxel);
  const sv_shade_params sa = shade_params(make_shade_frame(vol, va, {}), {});
  const sv_shade_params sb = shade_params(make_shade_frame(vol, vb, {}), {});
  PeArray array(dev, pe_grid(64));
  CellBuffer cells = array.layout(vol, 1);
  for (const char* name : {"ct", "knots"}) {
    for (bool il : {true, false}) {
      SCOPED_TRACE(std::string(name) + (il ? " interleaved" : " planar"));
      const Classifier c = by_name(name);
      const sv_classify_params cp = classify_params(c, classify_range(vol, c), 1.0);
      const VoxelLayout L = make_voxel_layout(cells.layout(), il);
      VoxelBuffer fresh(dev, L), kept(dev, L), poisoned(dev, L);
      enqueue_shade_classify(dev, cells, sb, cp, fresh);
      enqueue_shade_classify(dev, cells, sa, cp, kept);
      dev.finish();
      const std::vector<Rgba> want = fresh.read<Rgba>(dev);
      // Flag 0 exactly the PEs whose blocks are all zeros (every voxel
      // transparent), but for the first such PE (a transparent PE may be
      // flagged 1).
      const int64_t P = L.pes(), S = L.stride;
      ASSERT_EQ(static_cast<int64_t>(want.size()), P * S);
      const auto zero = [](const Rgba& x) { return x.r == 0 && x.g == 0 && x.b == 0 && x.a == 0; };
      std::vector<cl_uchar> flags(static_cast<std::size_t>(P), 1);
      int unflagged = 0;
      bool first = true;
      for (int64_t p = 0; p < P; ++p) {
        const auto b = want.begin() + p * S;
        if (std::all_of(b, b + S, zero)) {
          if (!first) {
            flags[static_cast<std::size_t>(p)] = 0;
            ++unflagged;
          }
          first = false;
        }
      }
      ASSERT_GT(unflagged, 0);
      ASSERT_LT(unflagged, P - 1);
      cl::Buffer live(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, flags.size(),
                      flags.data());
      // Over the other lighting's result: the fresh call's bits everywhere.
      enqueue_shade_classify(dev, cells, sb, cp, kept, ShadeKernel::vec16, nullptr, &live);
      dev.finish();
      const std::vector<Rgba> got = kept.read<Rgba>(dev);
      EXPECT_EQ(std::memcmp(got.data(), want.data(), got.size() * sizeof(Rgba)), 0);
      // Over NaN: what the kernel leaves alone keeps it.
      const float nan = std::nanf("");
      poisoned.write(dev, std::vector<Rgba>(want.size(), Rgba{nan, nan, nan, nan}));
      enqueue_shade_classify(dev, cells, sb, cp, poisoned, ShadeKernel::vec16, nullptr, &live);
      dev.finish();
      const std::vector<Rgba> mixed = poisoned.read<Rgba>(dev);
      const auto is_nan = [](const Rgba& x) {
        return std::isnan(x.r) && std::isnan(x.g) && std::isnan(x.b) && std::isnan(x.a);
      };
      const auto same = [](const Rgba* a, const Rgba* b, int64_t n) {
        return std::memcmp(a, b, static_cast<std::size_t>(n) * sizeof(Rgba)) == 0;
      };
      int64_t kept_chunks = 0, shaded_chunks = 0, bad = 0;
      for (int64_t p = 0; p < P; ++p) {
        const Rgba* g = mixed.data() + p * S;
        const Rgba* w = want.data() + p * S;
        if (!flags[static_cast<std::size_t>(p)]) {
          bad += !std::all_of(g, g + S, is_nan);
          continue;
        }
        if (!il) {  // planar: a chunk's positions are not adjacent Rgba
          bad +=
              !std::all_of(g, g + S, [&](const Rgba& x) { return is_nan(x) || !std::isnan(x.a); });
          continue;
        }
        for (int64_t e = 0; e < S; e += 16) {
          const bool nan_chunk = std::all_of(g + e, g + e + 16, is_nan);
          if (nan_chunk) {
            // left alone: only a transparent chunk (the fresh call's zeros)
            ++kept_chunks;
            bad += !std::all_of(w + e, w + e + 16, zero);
          } else {
            ++shaded_chunks;
            bad += !same(g + e, w + e, 16);
          }
        }
      }
      EXPECT_EQ(bad, 0);
      if (il) {
        EXPECT_GT(kept_chunks, 0);  // transparent chunks in flagged PEs
        EXPECT_GT(shaded_chunks, 0);
      }
    }
  }
}

// The kept classification (enqueue_shade_classify's `kept`): the call that
// fills it writes what a call without it writes, and a later call that reads
// it, under another lighting and another opacity step, with the cells'
// brick occupancy marked, writes a fresh call's bits and marks its bricks.
// Its alpha plane holds the voxel's alpha (opacity step 1) where lit and
// +0 elsewhere: the output's alpha bit for bit. With and without the
// gradient kept (and a change of that setting after a fill: written
// again), odd dims (padding lanes; cells whose rows take the shade's
// general path), NaN voxels, interleaved and planar cells, a mixture (ct)
// and a transfer function (knots).
TEST(ClassifyKernel, KeptClassificationGivesTheSameBits) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume vol = shepp_logan(32, 2);
  vol.at(16, 16, 16) = std::nanf("");
  vol.at(3, 30, 17) = std::nanf("");
  Volume odd = testing::random_volume({21, 18, 13}, -200.0f, 1500.0f, {1, 1, 1}, 7);
  odd.at(5, 5, 5) = std::nanf("");
  const std::size_t F4 = sizeof(float);
  for (const Volume* v : {&vol, &odd}) {
    const ViewGeometry va = make_view(*v, kViews[1], 48, 48, Sampling::voxel);
    const ViewGeometry vb = make_view(*v, kViews[2], 48, 48, Sampling::voxel);
    const sv_shade_params sa = shade_params(make_shade_frame(*v, va, {}), {});
    const sv_shade_params sb = shade_params(make_shade_frame(*v, vb, {}), {});
    PeArray array(dev, pe_grid(64));
    CellBuffer cells = array.layout(*v, 1);
    for (const char* name : {"ct", "ct-bone", "knots"})
      for (bool il : {true, false})
        for (bool grad : {false, true}) {
          SCOPED_TRACE(std::string(name) + (il ? " interleaved" : " planar") +
                       (grad ? " with the gradient " : " ") + std::to_string(v->dims()[0]));
          const Classifier c = by_name(name);
          const sv_classify_params c1 = classify_params(c, classify_range(*v, c), 1.0);
          const sv_classify_params c7 = classify_params(c, classify_range(*v, c), 0.7);
          const VoxelLayout L = make_voxel_layout(cells.layout(), il);
          const std::size_t bytes = static_cast<std::size_t>(KeptClassification::bytes(L, grad));
          ASSERT_EQ(bytes, static_cast<std::size_t>(L.pes()) * (grad ? 7 : 4) * L.stride * F4);
          KeptClassification kept;
          kept.planes = cl::Buffer(dev.context(), CL_MEM_READ_WRITE, bytes);
          kept.gradient = grad;
          VoxelBuffer fresh(dev, L), filling(dev, L), reading(dev, L);
          enqueue_shade_classify(dev, cells, sa, c1, fresh);
          enqueue_shade_classify(dev, cells, sa, c1, filling, ShadeKernel::vec16, nullptr, nullptr,
                                 &kept);
          EXPECT_TRUE(kept.filled);
          dev.finish();
          const std::vector<Rgba> want1 = fresh.read<Rgba>(dev);
          const std::vector<Rgba> got1 = filling.read<Rgba>(dev);
          EXPECT_EQ(std::memcmp(got1.data(), want1.data(), got1.size() * sizeof(Rgba)), 0)
              << "the filling call";
          // The alpha plane: the output's alpha (step 1) bit for bit, below
          // 1/2 as it is, from 1/2 on as -t (the transparency: sign bit set,
          // alpha = 1 - t), unlit +0.
          std::vector<float> planes(bytes / F4);
          cl_check(dev.queue().enqueueReadBuffer(kept.planes, CL_TRUE, 0, bytes, planes.data()),
                   "read");
          const int64_t S = L.stride;
          int64_t lit = 0, opaque = 0, alpha_bad = 0;
          for (int64_t p = 0; p < L.pes(); ++p)
            for (int64_t e = 0; e < S; ++e) {
              const float k = planes[static_cast<std::size_t>(p * (grad ? 7 : 4) * S + e)];
              const Rgba& w = want1[static_cast<std::size_t>(p * S + e)];
              const bool neg = std::signbit(k);
              const float a = neg ? 1.0f + k : k;
              alpha_bad += std::memcmp(&a, &w.a, sizeof a) != 0 || (neg != (w.a >= 0.5f)) ||
                           (neg && !(-k <= 0.5f));
              lit += k > 0 || neg;
              opaque += neg;
            }
          EXPECT_EQ(alpha_bad, 0);
          EXPECT_GT(lit, 0);
          if (std::string(name) == "ct-bone") {
            EXPECT_GT(opaque, 0);  // (bone's opacity is 1)
          }
          // Read back under another lighting and opacity step, marking.
          VoxelBuffer fresh7(dev, L);
          DeviceOccupancy m_fresh = make_occupancy(dev, L, 1), m_kept = make_occupancy(dev, L, 1);
          enqueue_shade_classify(dev, cells, sb, c7, fresh7, ShadeKernel::vec16, &m_fresh);
          enqueue_shade_classify(dev, cells, sb, c7, reading, ShadeKernel::vec16, &m_kept, nullptr,
                                 &kept);
          dev.finish();
          const std::vector<Rgba> want7 = fresh7.read<Rgba>(dev);
          const std::vector<Rgba> got7 = reading.read<Rgba>(dev);
          EXPECT_EQ(std::memcmp(got7.data(), want7.data(), got7.size() * sizeof(Rgba)), 0)
              << "the reading call";
          EXPECT_NE(std::memcmp(want7.data(), want1.data(), want7.size() * sizeof(Rgba)), 0)
              << "the second call must differ from the first for this test";
          const auto n = static_cast<std::size_t>(m_kept.count());
          std::vector<cl_uint> a(n), b(n);
          cl_check(dev.queue().enqueueReadBuffer(m_kept.occupied, CL_TRUE, 0, n * 4, a.data()),
                   "read");
          cl_check(dev.queue().enqueueReadBuffer(m_fresh.occupied, CL_TRUE, 0, n * 4, b.data()),
                   "read");
          EXPECT_EQ(a, b) << "bricks marked";
          // The gradient asked for after a fill without it (or dropped after
          // one with it): the call writes the planes again, the same bits.
          kept.gradient = !grad;
          if (!grad)
            kept.planes = cl::Buffer(dev.context(), CL_MEM_READ_WRITE,
                                     static_cast<std::size_t>(KeptClassification::bytes(L, true)));
          VoxelBuffer again(dev, L), read_again(dev, L);
          enqueue_shade_classify(dev, cells, sb, c7, again, ShadeKernel::vec16, nullptr, nullptr,
                                 &kept);
          EXPECT_TRUE(kept.filled && kept.filled_gradient == !grad);
          enqueue_shade_classify(dev, cells, sa, c1, read_again, ShadeKernel::vec16, nullptr,
                                 nullptr, &kept);
          dev.finish();
          const std::vector<Rgba> g7 = again.read<Rgba>(dev), g1 = read_again.read<Rgba>(dev);
          EXPECT_EQ(std::memcmp(g7.data(), want7.data(), g7.size() * sizeof(Rgba)), 0)
              << "refilled with the other gradient setting";
          EXPECT_EQ(std::memcmp(g1.data(), want1.data(), g1.size() * sizeof(Rgba)), 0)
              << "read with the other gradient setting";
        }
  }
  // Refused: a buffer too small for the layout, a kernel that does not keep it.
  PeArray array(dev, pe_grid(64));
  CellBuffer cells = array.layout(vol, 1);
  const VoxelLayout L = make_voxel_layout(cells.layout(), false);
  VoxelBuffer out(dev, L);
  const ViewGeometry va = make_view(vol, kViews[1], 48, 48, Sampling::voxel);
  const sv_shade_params sa = shade_params(make_shade_frame(vol, va, {}), {});
  const sv_classify_params cp = classify_params(by_name("ct"), {}, 1.0);
  KeptClassification small;
  small.planes = cl::Buffer(dev.context(), CL_MEM_READ_WRITE,
                            static_cast<std::size_t>(L.pes()) * 4 * L.stride * F4 - 4);
  EXPECT_THROW(
      enqueue_shade_classify(dev, cells, sa, cp, out, ShadeKernel::vec16, nullptr, nullptr, &small),
      ArgumentError);
  KeptClassification short_gradient;  // room for the four planes, not the gradient's three
  short_gradient.planes =
      cl::Buffer(dev.context(), CL_MEM_READ_WRITE,
                 static_cast<std::size_t>(KeptClassification::bytes(L, true)) - 4);
  short_gradient.gradient = true;
  EXPECT_THROW(enqueue_shade_classify(dev, cells, sa, cp, out, ShadeKernel::vec16, nullptr, nullptr,
                                      &short_gradient),
               ArgumentError);
  KeptClassification none;
  EXPECT_THROW(
      enqueue_shade_classify(dev, cells, sa, cp, out, ShadeKernel::vec16, nullptr, nullptr, &none),
      ArgumentError);
  KeptClassification enough;
  enough.planes = cl::Buffer(dev.context(), CL_MEM_READ_WRITE,
                             static_cast<std::size_t>(L.pes()) * 4 * L.stride * F4);
  EXPECT_THROW(enqueue_shade_classify(dev, cells, sa, cp, out, ShadeKernel::range3d, nullptr,
                                      nullptr, &enough),
               ArgumentError);
  EXPECT_FALSE(small.filled || short_gradient.filled || none.filled || enough.filled);
}

TEST(ClassifyKernel, NanVoxelsAreTransparent) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume vol = testing::random_volume({12, 10, 9}, -200.0f, 1500.0f, {1, 1, 1}, 13);
  vol.at(3, 3, 3) = std::nanf("");
  for (const char* name : {"ct", "knots"}) check_case({&vol, name, kViews[1], 8});
}

TEST(ClassifyKernel, RejectsBadArguments) {
  SIMDVOL_TEST_DEVICE(dev);
  Classifier c = classifier_preset("ct");
  EXPECT_THROW(classify_params(c, {}, 0.0), ArgumentError);
  EXPECT_THROW(classify_params(c, {}, NAN), ArgumentError);
  Classifier many = c;
  many.mixture.materials.clear();
  for (int i = 0; i <= SV_MAX_MATERIALS; ++i)
    many.mixture.materials.push_back({"m", static_cast<float>(i), 1, 1, 1, 1, 0.5f});
  EXPECT_THROW(classify_params(many, {}, 1.0), ArgumentError);
  Classifier unsorted = c;
  std::swap(unsorted.mixture.materials[0], unsorted.mixture.materials[1]);
  EXPECT_THROW(classify_params(unsorted, {}, 1.0), ArgumentError);
  Classifier knots = many_knots();
  knots.transfer.density.x.assign(SV_MAX_KNOTS + 1, 0.0f);
  knots.transfer.density.y.assign(SV_MAX_KNOTS + 1, 0.5f);
  EXPECT_THROW(classify_params(knots, {}, 1.0), ArgumentError);

  const Volume vol = testing::random_volume({16, 16, 16}, 0, 1, {1, 1, 1}, 1);
  PeArray a8(dev, pe_grid(8)), a64(dev, pe_grid(64));
  CellBuffer c8 = a8.layout(vol, 1), c64 = a64.layout(vol, 1);
  VoxelBuffer v8(dev, make_voxel_layout(c8.layout())), v64(dev, make_voxel_layout(c64.layout()));
  const auto cp = classify_params(c, {}, 1.0);
  EXPECT_THROW(enqueue_classify(dev, v8, cp, v64), ArgumentError);
  EXPECT_THROW(enqueue_classify(dev, v8, cp, v8), ArgumentError);
}

TEST(RenderOpenCL, EqualsReference) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(40);
  for (const char* name : {"ct", "knots"}) {
    RenderOptions opt;
    opt.width = opt.height = 48;
    opt.view = {30, 45, 10};
    opt.classifier = by_name(name);
    const Image ref = render_reference(vol, opt);
    for (bool fused : {false, true}) {
      EngineTimes t;
      const Image img = render_opencl(dev, vol, opt, &t, 512, fused);
      EXPECT_LE(max_abs_diff(ref, img), 1e-5) << name << (fused ? " fused" : " staged");
      EXPECT_GT(psnr(ref, img), 80.0);
    }
  }
  RenderOptions bad;
  bad.width = 0;
  EXPECT_THROW(render_opencl(dev, vol, bad), ArgumentError);
  EXPECT_THROW(render_opencl(dev, vol, RenderOptions{}, nullptr, 100), ArgumentError);
}

}  // namespace
}  // namespace simdvol
