// The resample and local stages on the device against their references
// (local.hpp): samples, footprints (separate and fused kernels) and the
// depth-order composite of the footprints against the serial renderer, for
// orders 0-3, several views, P from 1 to 8192, odd dims, balanced matchings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <string>

#include "simdvol/engine.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "stage_testing.hpp"

using namespace simdvol;
using simdvol::testing::host_occupancy;
using simdvol::testing::test_device;

namespace {

std::vector<Rgba> random_voxels(const Dims3& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  for (Rgba& x : v) {
    x.a = u(rng) * 0.25f;
    x.r = x.a * u(rng);
    x.g = x.a * u(rng);
    x.b = x.a * u(rng);
  }
  return v;
}

float max_diff(const std::vector<Rgba>& a, const std::vector<Rgba>& b) {
  EXPECT_EQ(a.size(), b.size());
  float m = 0;
  for (std::size_t n = 0; n < std::min(a.size(), b.size()); ++n)
    m = std::max({m, std::fabs(a[n].r - b[n].r), std::fabs(a[n].g - b[n].g),
                  std::fabs(a[n].b - b[n].b), std::fabs(a[n].a - b[n].a)});
  return m;
}

struct Fixture {
  Dims3 dims;
  Volume vol;
  std::vector<Rgba> voxels;
  Fixture(Dims3 d, unsigned seed)
      : dims(d), vol(d, VoxelType::f32), voxels(random_voxels(d, seed)) {}
};

// Runs both device paths for one (view, P, order) and checks them.
void check_case(Device& dev, const Fixture& fx, const ViewGeometry& view, int64_t pes, int order,
                bool balanced, const Image* reference_intermediate) {
  SCOPED_TRACE("P " + std::to_string(pes) + " order " + std::to_string(order) +
               (balanced ? " balanced" : ""));
  const KdSplit split = kd_split(fx.dims, pes);
  Matching m = match_reference(view, split);
  if (balanced) m = balance_reference(m, view, split);
  const VoxelLayout L = make_voxel_layout(make_cell_layout(fx.dims, pes, 1));
  VoxelBuffer vb(dev, L);
  vb.write(dev, voxels_to_cells(fx.voxels, L));

  const LocalSegments segs = upload_segments(dev, m);
  const ResampleTables tables = make_resample_tables(dev, L, view);
  const cl::Buffer soff = upload_sample_offsets(dev, m);
  const int64_t nsamples = sample_offsets(m).back();
  cl::Buffer samples =
      dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16,
                 nullptr, "samples");
  DeviceFootprints fp = make_footprints(dev, m.rects);
  DeviceFootprints fused = make_footprints(dev, m.rects);
  DeviceFootprints scalar = make_footprints(dev, m.rects);
  enqueue_zero_footprints(dev, fp);
  enqueue_zero_footprints(dev, fused);
  enqueue_zero_footprints(dev, scalar);
  enqueue_resample_local(dev, segs, tables, vb, order, scalar, LocalKernel::segment);
  cl::Buffer samples1 =
      dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16,
                 nullptr, "samples (one segment per work-item)");
  enqueue_resample(dev, segs, soff, tables, vb, order, samples1, LocalKernel::segment);
  enqueue_resample(dev, segs, soff, tables, vb, order, samples);
  cl::Buffer samples2 =
      dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16,
                 nullptr, "samples (lanes in length order)");
  const SegmentOrder lanes = enqueue_segment_order(dev, segs);
  enqueue_resample(dev, segs, soff, tables, vb, order, samples2, LocalKernel::vector8, &lanes);
  enqueue_local(dev, segs, soff, samples, fp);
  enqueue_resample_local(dev, segs, tables, vb, order, fused);
  dev.finish();

  std::vector<Rgba> got(static_cast<std::size_t>(nsamples));
  if (nsamples > 0)
    cl_check(dev.queue().enqueueReadBuffer(samples, CL_TRUE, 0, got.size() * 16, got.data()),
             "read samples");
  const std::vector<Rgba> want = resample_reference(m, fx.voxels, fx.dims, view, order);
  EXPECT_LE(max_diff(got, want), 1e-5f);
  std::vector<Rgba> got1(got.size());
  if (nsamples > 0)
    cl_check(dev.queue().enqueueReadBuffer(samples1, CL_TRUE, 0, got1.size() * 16, got1.data()),
             "read samples");
  EXPECT_EQ(max_diff(got, got1), 0.0f);  // float8 lanes: the same arithmetic
  std::vector<Rgba> got2(got.size());
  if (nsamples > 0)
    cl_check(dev.queue().enqueueReadBuffer(samples2, CL_TRUE, 0, got2.size() * 16, got2.data()),
             "read samples");
  EXPECT_EQ(std::memcmp(got.data(), got2.data(), got.size() * sizeof(Rgba)), 0);  // any lane order

  const Footprints ref =
      footprints_reference(m, local_reference(m, fx.voxels, fx.dims, view, order));
  const Footprints a = read_footprints(dev, fp), b = read_footprints(dev, fused);
  const Footprints c = read_footprints(dev, scalar);
  EXPECT_EQ(max_diff(b.pixels, c.pixels), 0.0f);  // same arithmetic, other decomposition
  EXPECT_EQ(a.rect_offset, ref.rect_offset);
  EXPECT_LE(max_diff(a.pixels, ref.pixels), 1e-5f);
  EXPECT_LE(max_diff(b.pixels, ref.pixels), 1e-5f);
  // Pixels without a segment are 0 (the references' footprints say where).
  for (std::size_t n = 0; n < ref.pixels.size(); ++n)
    if (ref.pixels[n].a == 0 && ref.pixels[n].r == 0) {
      EXPECT_EQ(b.pixels[n].a, 0.0f);
    }
  if (reference_intermediate) {
    const Image im = composite_footprints(m, b, view.width(), view.height());
    EXPECT_LE(max_abs_diff(im, *reference_intermediate), 1e-5f);
  }
}

}  // namespace

TEST(LocalCl, AddressTableMatchesTheVoxelLayout) {
  for (const Dims3 dims : {Dims3{37, 29, 23}, Dims3{16, 16, 16}})
    for (int64_t pes : {int64_t(1), int64_t(8), int64_t(512), int64_t(8192)}) {
      const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1));
      cl_int cs = 0;
      const std::vector<cl_int> t = resample_address_table(L, &cs);
      ASSERT_EQ(t.size(), static_cast<std::size_t>(dims[0] + dims[1] + dims[2]));
      EXPECT_EQ(cs, L.stride);  // planar cells
      for (int64_t z = 0; z < dims[2]; ++z)
        for (int64_t y = 0; y < dims[1]; ++y)
          for (int64_t x = 0; x < dims[0]; ++x) {
            const int64_t p = L.cells.split.owner({x, y, z});
            const Dims3 o = L.cells.split.cell_origin(p);
            // planar: channel 0 of position e of PE p at p * 4 * stride + e
            const int64_t e = L.index(0, x - o[0], y - o[1], z - o[2]);
            ASSERT_EQ(t[x] + t[dims[0] + y] + t[dims[0] + dims[1] + z], p * 4 * L.stride + e);
          }
    }
}

TEST(LocalCl, DeviceEqualsReferenceAcrossViewsOrdersAndPes) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Fixture fx({37, 29, 23}, 3);
  struct V {
    ViewAngles a;
    Sampling s;
  };
  const V views[] = {{{0, 0, 0}, Sampling::voxel},
                     {{0, 30, 0}, Sampling::voxel},
                     {{45, 45, 0}, Sampling::pixel},
                     {{-23.5, 71.25, 133.0}, Sampling::voxel}};
  for (const V& v : views) {
    const ViewGeometry view = make_view(fx.vol, v.a, 48, 40, v.s);
    for (int order = 0; order <= 3; ++order) {
      RenderOptions opt;
      opt.view = v.a, opt.width = 48, opt.height = 40, opt.sampling = v.s, opt.order = order;
      Image inter;
      render_classified(fx.voxels, fx.vol, view, opt, nullptr, &inter);
      for (int64_t pes : {int64_t(1), int64_t(8), int64_t(64), int64_t(512), int64_t(8192)})
        check_case(*dp, fx, view, pes, order, pes >= 64, &inter);
    }
  }
}

TEST(LocalCl, EveryPowerOfTwoPeCount) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Fixture fx({21, 17, 13}, 8);
  const ViewGeometry view = make_view(fx.vol, {30, 60, 10}, 32, 32, Sampling::voxel);
  RenderOptions opt;
  opt.view = {30, 60, 10}, opt.width = 32, opt.height = 32, opt.order = 1;
  Image inter;
  render_classified(fx.voxels, fx.vol, view, opt, nullptr, &inter);
  for (int64_t pes = 1; pes <= 8192; pes *= 2) check_case(*dp, fx, view, pes, 1, true, &inter);
}

TEST(LocalCl, RejectsMismatchedInputs) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Fixture fx({9, 8, 7}, 1);
  const ViewGeometry view = make_view(fx.vol, {}, 8, 8, Sampling::voxel);
  const Matching m = match_reference(view, kd_split(fx.dims, 8));
  const VoxelLayout L8 = make_voxel_layout(make_cell_layout(fx.dims, 8, 1));
  const VoxelLayout L4 = make_voxel_layout(make_cell_layout(fx.dims, 4, 1));
  VoxelBuffer v4(dev, L4);
  const LocalSegments segs = upload_segments(dev, m);
  const ResampleTables t8 = make_resample_tables(dev, L8, view);
  DeviceFootprints fp = make_footprints(dev, m.rects);
  EXPECT_THROW(enqueue_resample_local(dev, segs, t8, v4, 1, fp), ArgumentError);
  const ResampleTables t4 = make_resample_tables(dev, L4, view);
  EXPECT_THROW(enqueue_resample_local(dev, segs, t4, v4, 1, fp), ArgumentError);
  VoxelBuffer v8(dev, L8);
  EXPECT_THROW(enqueue_resample_local(dev, segs, t8, v8, 4, fp), ArgumentError);
  const Volume other({9, 8, 6}, VoxelType::f32);
  EXPECT_THROW(make_resample_tables(dev, L8, make_view(other, {}, 8, 8, Sampling::voxel)),
               ArgumentError);
  DeviceFootprints fp4 = make_footprints(dev, std::vector<sv_rect>(4));
  EXPECT_THROW(enqueue_resample_local(dev, segs, t8, v8, 1, fp4), ArgumentError);
}

// render_opencl (match -> balance -> fused resample + local -> host
// composite of the footprints -> warp) against render_reference: direct
// compositing, orders 0-3, views axis/30/45/random, voxel and pixel
// sampling, P from 1 to 8192. Both classify differently by up to ~1e-6 (see
// test_classify_cl.cpp); the sub-ray composites re-associate over.
TEST(RenderOpenClFrame, DirectEqualsReference) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Volume vol = shepp_logan(27, 2);  // odd dims
  const ViewAngles views[] = {{0, 0, 0}, {0, 30, 0}, {45, 45, 0}, {-23.5, 71.25, 133.0}};
  int n = 0;
  for (const ViewAngles& a : views)
    for (int order = 0; order <= 3; ++order)
      for (Sampling smp : {Sampling::voxel, Sampling::pixel}) {
        RenderOptions opt;
        opt.width = 40, opt.height = 36, opt.view = a, opt.order = order, opt.sampling = smp;
        opt.classifier = classifier_preset("ct");
        const Image ref = render_reference(vol, opt);
        for (int64_t pes = 1; pes <= 8192; pes *= (order == 1 ? 2 : 64)) {
          EngineTimes t;
          const Image img = render_opencl(*dp, vol, opt, &t, pes, true);
          EXPECT_LE(max_abs_diff(ref, img), 1e-5f)
              << "view " << a.theta << "," << a.phi << " order " << order << " P " << pes
              << (smp == Sampling::pixel ? " pixel" : " voxel");
          ++n;
        }
      }
  EXPECT_EQ(n, 4 * 2 * (14 + 3 * 3));
}

TEST(RenderOpenClFrame, AdaptiveAndMonteCarloKeepTheReferencePath) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Volume vol = shepp_logan(20, 2);
  for (CompositeMode mode : {CompositeMode::adaptive, CompositeMode::mc}) {
    RenderOptions opt;
    opt.width = opt.height = 32;
    opt.view = {10, 30, 0};
    opt.classifier = classifier_preset("ct");
    opt.composite.mode = mode;
    opt.composite.samples = 8;
    const Image ref = render_reference(vol, opt);
    EngineTimes t;
    EXPECT_LE(max_abs_diff(ref, render_opencl(*dp, vol, opt, &t, 64, true)), 1e-5f);
  }
}

// ---- empty-space skipping (enqueue_occupancy, the fused kernel's reach) ----

namespace {

// Mostly zero voxels: random boxes of colour, and single voxels holding the
// values a bit test can get wrong (-0 is empty; a denormal, NaN and inf in
// one channel are not).
std::vector<Rgba> sparse_voxels(const Dims3& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  auto at = [&](int64_t x, int64_t y, int64_t z) -> Rgba& {
    return v[static_cast<std::size_t>((z * d[1] + y) * d[0] + x)];
  };
  auto pick = [&](int64_t n) { return static_cast<int64_t>(u(rng) * static_cast<float>(n)) % n; };
  for (int box = 0; box < 6; ++box) {
    const int64_t x0 = pick(d[0]), y0 = pick(d[1]), z0 = pick(d[2]);
    for (int64_t z = z0; z < std::min(z0 + 3, d[2]); ++z)
      for (int64_t y = y0; y < std::min(y0 + 2, d[1]); ++y)
        for (int64_t x = x0; x < std::min(x0 + 4, d[0]); ++x) {
          Rgba& c = at(x, y, z);
          c.a = 0.2f + 0.3f * u(rng);
          c.r = c.a * u(rng), c.g = c.a * u(rng), c.b = c.a * u(rng);
        }
  }
  for (int k = 0; k < 20; ++k) at(pick(d[0]), pick(d[1]), pick(d[2])) = {-0.0f, -0.0f, 0.0f, -0.0f};
  at(pick(d[0]), pick(d[1]), pick(d[2])).g = 1e-40f;  // denormal, colour only
  return v;
}

template <class T>
std::vector<T> read_all(Device& dev, const cl::Buffer& b, std::size_t n) {
  std::vector<T> out(n);
  cl_check(dev.queue().enqueueReadBuffer(b, CL_TRUE, 0, n * sizeof(T), out.data()), "read");
  return out;
}

bool same_bits(const Footprints& a, const Footprints& b) {
  return a.rect_offset == b.rect_offset && a.pixels.size() == b.pixels.size() &&
         std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(Rgba)) == 0;
}

// The index of the first float of a and b (n RGBA each) that differs other
// than in the sign of a zero or of a NaN, or -1 (no consumer of stored
// samples can tell those apart: over adds them as zeros, a Monte Carlo walk
// compares them with draws in [0, 1)).
std::ptrdiff_t first_difference_but_signs(const Rgba* a, const Rgba* b, std::size_t n) {
  for (std::size_t i = 0; i < 4 * n; ++i) {
    const float x = (&a[0].r)[i], y = (&b[0].r)[i];
    if (std::memcmp(&x, &y, sizeof x) == 0) continue;
    if ((x == 0.0f && y == 0.0f) || (std::isnan(x) && std::isnan(y))) continue;
    return static_cast<std::ptrdiff_t>(i);
  }
  return -1;
}

// Axis-aligned, 30 deg, (45, 45, 0) and two random views (seed).
std::vector<ViewAngles> skip_test_views(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ang(-180.0, 180.0);
  std::vector<ViewAngles> views = {{0, 0, 0}, {0, 30, 0}, {45, 45, 0}};
  for (int k = 0; k < 2; ++k) views.push_back({ang(rng), ang(rng), ang(rng)});
  return views;
}

}  // namespace

TEST(LocalCl, OccupancyEqualsBruteForce) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  // {150, 9, 7}: 38 bricks a row, two whole chunks of 16 of the reach and a
  // tail; {128, 9, 7}: 32, the last chunk's +1 offset at the row's end
  for (const Dims3 dims :
       {Dims3{37, 29, 23}, Dims3{16, 16, 16}, Dims3{5, 9, 3}, Dims3{150, 9, 7}, Dims3{128, 9, 7}})
    for (int64_t pes : {int64_t(1), int64_t(8), int64_t(512), int64_t(8192)}) {
      std::vector<Rgba> v = sparse_voxels(dims, static_cast<unsigned>(pes + dims[0]));
      v[v.size() / 3].b = std::numeric_limits<float>::quiet_NaN();
      v[v.size() / 2].a = std::numeric_limits<float>::infinity();
      const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1));
      VoxelBuffer vb(dev, L);
      vb.write(dev, voxels_to_cells(v, L));
      for (int order = 0; order <= 3; ++order) {
        SCOPED_TRACE("dims " + std::to_string(dims[0]) + " P " + std::to_string(pes) + " order " +
                     std::to_string(order));
        const DeviceOccupancy o = enqueue_occupancy(dev, vb, order);
        std::vector<cl_uint> occ;
        std::vector<cl_uchar> reach;
        host_occupancy(v, dims, order, occ, reach);
        ASSERT_EQ(static_cast<std::size_t>(o.count()), occ.size());
        EXPECT_EQ(read_all<cl_uint>(dev, o.occupied, occ.size()), occ);
        EXPECT_EQ(read_all<cl_uchar>(dev, o.reach, reach.size()), reach);
        if (dims[0] >= 32) {
          EXPECT_GT(std::count(reach.begin(), reach.end(), 0), 0);  // something to skip
        }
        EXPECT_GT(std::count(occ.begin(), occ.end(), 1u), 0);  // and something not
      }
    }
  const VoxelLayout L = make_voxel_layout(make_cell_layout({8, 8, 8}, 8, 1));
  VoxelBuffer vb(dev, L);
  EXPECT_THROW(enqueue_occupancy(dev, vb, 4), ArgumentError);
  EXPECT_THROW(enqueue_occupancy(dev, vb, -1), ArgumentError);
}

// Skipping samples of bricks without reach gives the footprints of the plain
// fused kernel bit for bit (NaN and inf voxels included), and a wrong reach
// (all zero) is caught by the same comparison.
TEST(LocalCl, SkippingEmptyBricksKeepsEveryBit) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{41, 35, 29};
  const Volume vol(dims, VoxelType::f32);
  const std::vector<ViewAngles> views = skip_test_views(11);
  int skipped_cases = 0;
  for (int64_t pes : {int64_t(1), int64_t(64), int64_t(8192)}) {
    std::vector<Rgba> v = sparse_voxels(dims, static_cast<unsigned>(pes));
    if (pes == 64) v[v.size() / 3].b = std::numeric_limits<float>::quiet_NaN();
    if (pes == 8192) v[v.size() / 2].a = std::numeric_limits<float>::infinity();
    const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1));
    VoxelBuffer vb(dev, L);
    vb.write(dev, voxels_to_cells(v, L));
    const KdSplit split = kd_split(dims, pes);
    for (const ViewAngles& a : views)
      for (int order = 0; order <= 3; ++order) {
        SCOPED_TRACE("P " + std::to_string(pes) + " order " + std::to_string(order) + " view " +
                     std::to_string(a.theta) + "," + std::to_string(a.phi) + "," +
                     std::to_string(a.varphi));
        const ViewGeometry view = make_view(vol, a, 48, 40, Sampling::voxel);
        const Matching m = balance_reference(match_reference(view, split), view, split);
        const LocalSegments segs = upload_segments(dev, m);
        const ResampleTables tables = make_resample_tables(dev, L, view);
        const DeviceOccupancy occ = enqueue_occupancy(dev, vb, order);
        DeviceFootprints plain = make_footprints(dev, m.rects);
        DeviceFootprints skip = make_footprints(dev, m.rects);
        enqueue_zero_footprints(dev, plain);
        enqueue_zero_footprints(dev, skip);
        enqueue_resample_local(dev, segs, tables, vb, order, plain);
        enqueue_resample_local(dev, segs, tables, vb, order, skip, LocalKernel::vector8, &occ);
        const Footprints p = read_footprints(dev, plain), s = read_footprints(dev, skip);
        EXPECT_TRUE(same_bits(p, s));
        // The lanes' segment order, with and without skipping: the same bits.
        const SegmentOrder lanes = enqueue_segment_order(dev, segs);
        for (const DeviceOccupancy* o : {static_cast<const DeviceOccupancy*>(nullptr), &occ}) {
          enqueue_zero_footprints(dev, skip);
          enqueue_resample_local(dev, segs, tables, vb, order, skip, LocalKernel::vector8, o,
                                 &lanes);
          EXPECT_TRUE(same_bits(p, read_footprints(dev, skip))) << (o ? "skip" : "no skip");
        }
        // The stored samples (adaptive, Monte Carlo): with skipping, those
        // out of reach are +0 without being gathered; every sample equals
        // the one gathered, bit for bit but for the sign of a zero, and
        // some were skipped.
        const cl::Buffer soff = upload_sample_offsets(dev, m);
        const std::size_t ns = static_cast<std::size_t>(sample_offsets(m).back());
        std::vector<Rgba> stored[2];
        for (int k = 0; k < 2; ++k) {
          cl::Buffer samples =
              dev.buffer(CL_MEM_READ_WRITE, std::max<std::size_t>(ns, 1) * 16, nullptr, "samples");
          // NaN everywhere first: a sample the kernel did not store fails.
          cl_check(dev.queue().enqueueFillBuffer(samples, std::numeric_limits<float>::quiet_NaN(),
                                                 0, std::max<std::size_t>(ns, 1) * 16),
                   "fill");
          enqueue_resample(dev, segs, soff, tables, vb, order, samples, LocalKernel::vector8,
                           &lanes, k == 1 ? &occ : nullptr);
          if (ns > 0) stored[k] = read_all<Rgba>(dev, samples, ns);
        }
        std::size_t zeros = 0;
        for (std::size_t i = 0; i < ns; ++i) {
          const float* a = &stored[0][i].r;
          const float* b = &stored[1][i].r;
          for (int c = 0; c < 4; ++c) {
            if (a[c] == 0.0f && b[c] == 0.0f) {
              ++zeros;
            } else {
              ASSERT_EQ(std::memcmp(&a[c], &b[c], sizeof(float)), 0) << "sample " << i;
            }
          }
        }
        EXPECT_GT(zeros, 0u);
        // The test can fail: with no brick in reach every footprint is 0.
        DeviceOccupancy none = occ;
        none.reach = dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(occ.count()), nullptr,
                                "no reach");
        cl_check(dev.queue().enqueueFillBuffer(none.reach, cl_uchar(0), 0,
                                               static_cast<std::size_t>(occ.count())),
                 "fill");
        enqueue_zero_footprints(dev, skip);
        enqueue_resample_local(dev, segs, tables, vb, order, skip, LocalKernel::vector8, &none);
        const Footprints z = read_footprints(dev, skip);
        const bool any_colour =
            std::any_of(p.pixels.begin(), p.pixels.end(), [](const Rgba& c) { return c.a != 0; });
        if (any_colour) {
          EXPECT_FALSE(same_bits(p, z));
          ++skipped_cases;
        }
      }
  }
  EXPECT_GT(skipped_cases, 30);
  const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, 8, 1));
  VoxelBuffer vb(dev, L);
  const ViewGeometry view = make_view(vol, {}, 16, 16, Sampling::voxel);
  const Matching m = match_reference(view, kd_split(dims, 8));
  const LocalSegments segs = upload_segments(dev, m);
  const ResampleTables tables = make_resample_tables(dev, L, view);
  DeviceFootprints fp = make_footprints(dev, m.rects);
  const DeviceOccupancy o1 = enqueue_occupancy(dev, vb, 1);
  EXPECT_THROW(enqueue_resample_local(dev, segs, tables, vb, 3, fp, LocalKernel::vector8, &o1),
               ArgumentError);  // made for another order
}

// Interleaved voxel cells (the engine's fused path): the same samples and
// footprints as planar cells, bit for bit, from every resample kernel
// (simdvol_resample_local_v8_il for the fused float8 lanes; the others
// through the address table and channel stride), with and without skipping
// and the lane order, NaN and inf voxels included; the occupancy scan the
// same; tables made for the other layout refused.
TEST(LocalCl, InterleavedCellsGiveTheSameBits) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{41, 35, 29};
  const Volume vol(dims, VoxelType::f32);
  const std::vector<ViewAngles> views = skip_test_views(23);
  int coloured = 0;
  for (int64_t pes : {int64_t(1), int64_t(64), int64_t(8192)}) {
    std::vector<Rgba> v = sparse_voxels(dims, static_cast<unsigned>(pes + 5));
    v[v.size() / 3].b = std::numeric_limits<float>::quiet_NaN();
    v[v.size() / 2].a = std::numeric_limits<float>::infinity();
    const CellLayout C = make_cell_layout(dims, pes, 1);
    const VoxelLayout L = make_voxel_layout(C), L4 = make_voxel_layout(C, true);
    VoxelBuffer vb(dev, L), vb4(dev, L4);
    vb.write(dev, voxels_to_cells(v, L));
    vb4.write(dev, voxels_to_cells(v, L4));
    {
      const std::vector<Rgba> back = voxels_from_cells(vb4.read<Rgba>(dev), L4);
      EXPECT_EQ(std::memcmp(back.data(), v.data(), v.size() * sizeof(Rgba)), 0);
    }
    const KdSplit split = kd_split(dims, pes);
    for (int order = 0; order <= 3; ++order) {
      const DeviceOccupancy occ = enqueue_occupancy(dev, vb, order);
      const DeviceOccupancy occ4 = enqueue_occupancy(dev, vb4, order);
      EXPECT_EQ(read_all<cl_uint>(dev, occ.occupied, static_cast<std::size_t>(occ.count())),
                read_all<cl_uint>(dev, occ4.occupied, static_cast<std::size_t>(occ4.count())));
      for (const ViewAngles& a : views) {
        SCOPED_TRACE("P " + std::to_string(pes) + " order " + std::to_string(order) + " view " +
                     std::to_string(a.theta) + "," + std::to_string(a.phi) + "," +
                     std::to_string(a.varphi));
        const ViewGeometry view = make_view(vol, a, 48, 40, Sampling::voxel);
        const Matching m = balance_reference(match_reference(view, split), view, split);
        const LocalSegments segs = upload_segments(dev, m);
        const ResampleTables t = make_resample_tables(dev, L, view);
        const ResampleTables t4 = make_resample_tables(dev, L4, view);
        const SegmentOrder lanes = enqueue_segment_order(dev, segs);
        DeviceFootprints fp = make_footprints(dev, m.rects);
        enqueue_zero_footprints(dev, fp);
        enqueue_resample_local(dev, segs, t, vb, order, fp);
        const Footprints want = read_footprints(dev, fp);
        // The one-segment kernel against itself on planar cells (it can
        // differ from the float8 kernel in the sign of a NaN).
        enqueue_zero_footprints(dev, fp);
        enqueue_resample_local(dev, segs, t, vb, order, fp, LocalKernel::segment);
        const Footprints want1 = read_footprints(dev, fp);
        coloured += std::any_of(want.pixels.begin(), want.pixels.end(),
                                [](const Rgba& c) { return c.a != 0; });
        for (int variant = 0; variant < 4; ++variant) {
          enqueue_zero_footprints(dev, fp);
          enqueue_resample_local(dev, segs, t4, vb4, order, fp,
                                 variant == 3 ? LocalKernel::segment : LocalKernel::vector8,
                                 variant == 1 || variant == 2 ? &occ4 : nullptr,
                                 variant == 2 ? &lanes : nullptr);
          EXPECT_TRUE(same_bits(variant == 3 ? want1 : want, read_footprints(dev, fp)))
              << "variant " << variant;
        }
        // The stored samples (adaptive and Monte Carlo compositing), with
        // and without skipping.
        const cl::Buffer soff = upload_sample_offsets(dev, m);
        const std::size_t ns = static_cast<std::size_t>(sample_offsets(m).back());
        for (int skip = 0; skip < 2; ++skip) {
          cl::Buffer s0 =
              dev.buffer(CL_MEM_READ_WRITE, std::max<std::size_t>(ns, 1) * 16, nullptr, "samples");
          cl::Buffer s4 =
              dev.buffer(CL_MEM_READ_WRITE, std::max<std::size_t>(ns, 1) * 16, nullptr, "samples");
          enqueue_resample(dev, segs, soff, t, vb, order, s0, LocalKernel::vector8, &lanes,
                           skip ? &occ : nullptr);
          enqueue_resample(dev, segs, soff, t4, vb4, order, s4, LocalKernel::vector8, &lanes,
                           skip ? &occ4 : nullptr);
          if (ns > 0) {
            const std::vector<Rgba> a0 = read_all<Rgba>(dev, s0, ns);
            const std::vector<Rgba> a4 = read_all<Rgba>(dev, s4, ns);
            // Order 1 on interleaved cells takes each axis's stencil in its
            // natural order (resample.cl, sv_sample8_il1): the same
            // samples but for the sign of a zero or a NaN.
            if (order == 1)
              EXPECT_EQ(first_difference_but_signs(a0.data(), a4.data(), ns), -1)
                  << "stored samples, skip " << skip;
            else
              EXPECT_EQ(std::memcmp(a0.data(), a4.data(), ns * sizeof(Rgba)), 0)
                  << "stored samples, skip " << skip;
          }
        }
        EXPECT_THROW(enqueue_resample_local(dev, segs, t, vb4, order, fp), ArgumentError);
        EXPECT_THROW(enqueue_resample_local(dev, segs, t4, vb, order, fp), ArgumentError);
      }
    }
  }
  EXPECT_GT(coloured, 40);  // the footprints compared are not all empty
}

// The cells' origins in ResampleTables only steer the resample's prefetch:
// tables built without them (as a caller's own, examples/embed) give the same
// footprints and stored samples, bit for bit, in both layouts; origins of the
// wrong size are refused.
// The order-1 kernels' pair table: entry f + 1 of an axis holds the address
// table's entries at clamp(f) (low 32 bits) and clamp(f + 1) (high).
TEST(LocalCl, PairTableHoldsEachAxisEntryAndItsSuccessor) {
  for (const Dims3 dims : {Dims3{37, 29, 23}, Dims3{1, 2, 16}}) {
    const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, 8, 1), true);
    const std::vector<cl_int> t = resample_address_table(L, nullptr);
    const std::vector<cl_long> pairs = resample_pair_table(t, dims);
    ASSERT_EQ(pairs.size(), t.size() + 6);
    std::size_t at = 0, base = 0;
    for (int a = 0; a < 3; ++a) {
      const int64_t n = dims[a];
      for (int64_t f = -1; f <= n; ++f, ++at) {
        const auto entry = [&](int64_t g) {
          return t[base + static_cast<std::size_t>(std::clamp<int64_t>(g, 0, n - 1))];
        };
        const uint64_t q = static_cast<uint64_t>(pairs[at]);
        EXPECT_EQ(static_cast<cl_int>(static_cast<uint32_t>(q)), entry(f)) << a << " " << f;
        EXPECT_EQ(static_cast<cl_int>(static_cast<uint32_t>(q >> 32)), entry(f + 1))
            << a << " " << f;
      }
      base += static_cast<std::size_t>(n);
    }
    std::vector<cl_int> short_table(t.begin(), t.end() - 1);
    EXPECT_THROW(resample_pair_table(short_table, dims), ArgumentError);
  }
}

// The cell bits: where given, every table entry is its cell's entry plus
// the local position times the axis's stride; uniform power-of-two cells
// (the 256^3 phantom's 8 x 16 x 16 at 8,192 PEs) have them, an axis of more
// than 32 cells that no power of two tiles has none.
TEST(LocalCl, CellBitsReproduceTheAddressTable) {
  struct Case {
    Dims3 dims;
    int64_t pes;
    int expect;  // 1: has cell bits, 0: has none, -1: either (checked if any)
    int shifts[3];
  };
  const Case cases[] = {{{256, 256, 256}, 8192, 1, {3, 4, 4}}, {{64, 32, 16}, 512, 1, {-1, -1, -1}},
                        {{41, 35, 29}, 1, 1, {6, 6, 5}},       {{37, 29, 23}, 64, -1, {-1, -1, -1}},
                        {{99, 8, 8}, 16, 0, {-1, -1, -1}},     {{300, 8, 8}, 64, 0, {-1, -1, -1}}};
  for (const Case& c : cases) {
    SCOPED_TRACE(std::to_string(c.dims[0]) + "x" + std::to_string(c.dims[1]) + "x" +
                 std::to_string(c.dims[2]) + " P " + std::to_string(c.pes));
    const VoxelLayout L = make_voxel_layout(make_cell_layout(c.dims, c.pes, 1), true);
    const std::vector<cl_int> t = resample_address_table(L, nullptr);
    const std::vector<cl_int> bits = resample_cell_bits(t, c.dims);
    if (c.expect == 0) {
      // (cells of 6-7 and 4-5 positions: no power of two tiles them in at
      // most 32 cells)
      EXPECT_TRUE(bits.empty());
      continue;
    }
    if (c.expect < 0 && bits.empty()) continue;
    ASSERT_EQ(bits.size(), 104u);
    std::size_t base = 0;
    for (int a = 0; a < 3; ++a) {
      const int sh = bits[96 + a];
      const cl_int stride = bits[99 + a];
      if (c.shifts[a] >= 0) {
        EXPECT_EQ(sh, c.shifts[a]) << a;
      }
      ASSERT_LT((c.dims[a] - 1) >> sh, 32) << a;
      for (int64_t g = 0; g < c.dims[a]; ++g) {
        const cl_int want = t[base + static_cast<std::size_t>(g)];
        const cl_int got = bits[static_cast<std::size_t>(32 * a + (g >> sh))] +
                           static_cast<cl_int>(g & ((int64_t(1) << sh) - 1)) * stride;
        ASSERT_EQ(got, want) << a << " " << g;
      }
      base += static_cast<std::size_t>(c.dims[a]);
    }
  }
  EXPECT_THROW(resample_cell_bits(std::vector<cl_int>(5), {2, 2, 2}), ArgumentError);
}

// The order-1 kernels with the cell bits (_ilc) give the bits of those
// without (_il), on uniform cells at every power-of-two PE count; orders 0
// and 2 (where the cell bits are not read) too.
TEST(LocalCl, CellBitsKernelsGiveTheSameBits) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{32, 32, 16};
  const Volume vol(dims, VoxelType::f32);
  const std::vector<Rgba> v = sparse_voxels(dims, 11);
  int compared = 0;
  for (int64_t pes = 1; pes <= 8192; pes *= 8) {
    const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1), true);
    VoxelBuffer vb(dev, L);
    vb.write(dev, voxels_to_cells(v, L));
    const KdSplit split = kd_split(dims, pes);
    for (const ViewAngles& a : {ViewAngles{0, 0, 0}, ViewAngles{20, 35, 10}, ViewAngles{0, 45, 0},
                                ViewAngles{-23.5, 71.25, 133.0}}) {
      const ViewGeometry view = make_view(vol, a, 40, 36, Sampling::voxel);
      const Matching m = balance_reference(match_reference(view, split), view, split);
      const LocalSegments segs = upload_segments(dev, m);
      const ResampleTables with = make_resample_tables(dev, L, view);
      ASSERT_TRUE(with.cell_bits) << pes;
      ResampleTables without = with;
      without.cell_bits = false;
      const cl::Buffer soff = upload_sample_offsets(dev, m);
      const std::size_t ns = static_cast<std::size_t>(sample_offsets(m).back());
      for (int order : {0, 1, 2}) {
        SCOPED_TRACE("P " + std::to_string(pes) + " order " + std::to_string(order) + " view " +
                     std::to_string(a.phi));
        Footprints got[2];
        std::vector<Rgba> stored[2];
        DeviceFootprints fp = make_footprints(dev, m.rects);
        for (int k = 0; k < 2; ++k) {
          const ResampleTables& t = k ? without : with;
          enqueue_zero_footprints(dev, fp);
          enqueue_resample_local(dev, segs, t, vb, order, fp);
          got[k] = read_footprints(dev, fp);
          cl::Buffer samples =
              dev.buffer(CL_MEM_READ_WRITE, std::max<std::size_t>(ns, 1) * 16, nullptr, "samples");
          enqueue_resample(dev, segs, soff, t, vb, order, samples, LocalKernel::vector8);
          if (ns > 0) stored[k] = read_all<Rgba>(dev, samples, ns);
        }
        EXPECT_TRUE(same_bits(got[0], got[1]));
        ASSERT_EQ(stored[0].size(), stored[1].size());
        EXPECT_EQ(std::memcmp(stored[0].data(), stored[1].data(), ns * sizeof(Rgba)), 0);
        compared += order == 1 && std::any_of(got[0].pixels.begin(), got[0].pixels.end(),
                                              [](const Rgba& c) { return c.a != 0; });
      }
    }
  }
  EXPECT_GE(compared, 12);  // footprints with colour were compared at order 1
}

TEST(LocalCl, TablesWithoutOriginsOrPairsResampleTheSame) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Fixture fx({37, 29, 23}, 7);
  const ViewGeometry view = make_view(fx.vol, {20, 35, 10}, 40, 36, Sampling::voxel);
  int compared = 0;
  for (int64_t pes : {int64_t(8), int64_t(512)})
    for (bool il : {false, true}) {
      SCOPED_TRACE("P " + std::to_string(pes) + (il ? " interleaved" : " planar"));
      const Matching m = match_reference(view, kd_split(fx.dims, pes));
      const VoxelLayout L = make_voxel_layout(make_cell_layout(fx.dims, pes, 1), il);
      VoxelBuffer vb(dev, L);
      vb.write(dev, voxels_to_cells(fx.voxels, L));
      const LocalSegments segs = upload_segments(dev, m);
      const ResampleTables with = make_resample_tables(dev, L, view);
      ASSERT_NE(with.origins(), nullptr);
      ASSERT_NE(with.pairs(), nullptr);
      // Without the origins (no prefetch), without the pair table (made from
      // the address table by enqueue_*), without either: the same bits.
      ResampleTables variants[4] = {with, with, with, with};
      variants[1].origins = cl::Buffer();
      variants[2].pairs = cl::Buffer();
      variants[3].origins = cl::Buffer();
      variants[3].pairs = cl::Buffer();
      DeviceFootprints fp = make_footprints(dev, m.rects);
      Footprints got[4];
      std::vector<Rgba> stored[4];
      const cl::Buffer soff = upload_sample_offsets(dev, m);
      const std::size_t ns = static_cast<std::size_t>(sample_offsets(m).back());
      for (int k = 0; k < 4; ++k) {
        enqueue_zero_footprints(dev, fp);
        enqueue_resample_local(dev, segs, variants[k], vb, 1, fp);
        got[k] = read_footprints(dev, fp);
        cl::Buffer samples =
            dev.buffer(CL_MEM_READ_WRITE, std::max<std::size_t>(ns, 1) * 16, nullptr, "samples");
        enqueue_resample(dev, segs, soff, variants[k], vb, 1, samples, LocalKernel::vector8);
        if (ns > 0) stored[k] = read_all<Rgba>(dev, samples, ns);
      }
      for (int k = 1; k < 4; ++k) {
        SCOPED_TRACE("variant " + std::to_string(k));
        EXPECT_TRUE(same_bits(got[0], got[k]));
        ASSERT_EQ(stored[0].size(), stored[k].size());
        EXPECT_EQ(std::memcmp(stored[0].data(), stored[k].data(), ns * sizeof(Rgba)), 0);
      }
      compared += std::any_of(got[0].pixels.begin(), got[0].pixels.end(),
                              [](const Rgba& c) { return c.a != 0; });
      ResampleTables small = with;
      small.origins = dev.buffer(CL_MEM_READ_ONLY, 16, nullptr, "one origin");
      EXPECT_THROW(enqueue_resample_local(dev, segs, small, vb, 1, fp), ArgumentError);
      EXPECT_THROW(enqueue_resample(dev, segs, soff, small, vb, 1, fp.pixels, LocalKernel::vector8),
                   ArgumentError);
      if (il) {  // the planar kernels never read the pair table
        ResampleTables few = with;
        few.pairs = dev.buffer(CL_MEM_READ_ONLY, 16, nullptr, "two pairs");
        EXPECT_THROW(enqueue_resample_local(dev, segs, few, vb, 1, fp), ArgumentError);
        EXPECT_THROW(enqueue_resample(dev, segs, soff, few, vb, 1, fp.pixels, LocalKernel::vector8),
                     ArgumentError);
      }
    }
  EXPECT_EQ(compared, 4);  // footprints with colour were compared
}

// Tables made for one view and given another by set_resample_view (as the
// engine keeps them from frame to frame) resample that view as tables made
// for it do, bit for bit; a view of other dims is refused.
TEST(LocalCl, TablesGivenAnotherViewResampleIt) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Fixture fx({37, 29, 23}, 7);
  const ViewGeometry first = make_view(fx.vol, {0, 0, 0}, 40, 36, Sampling::voxel);
  const ViewGeometry view = make_view(fx.vol, {20, 35, 10}, 40, 36, Sampling::voxel);
  const int64_t pes = 64;
  const Matching m = match_reference(view, kd_split(fx.dims, pes));
  const VoxelLayout L = make_voxel_layout(make_cell_layout(fx.dims, pes, 1), true);
  VoxelBuffer vb(dev, L);
  vb.write(dev, voxels_to_cells(fx.voxels, L));
  const LocalSegments segs = upload_segments(dev, m);
  ResampleTables kept = make_resample_tables(dev, L, first);
  set_resample_view(dev, kept, view);
  const ResampleTables fresh = make_resample_tables(dev, L, view);
  DeviceFootprints fp = make_footprints(dev, m.rects);
  Footprints got[2];
  for (int k = 0; k < 2; ++k) {
    enqueue_zero_footprints(dev, fp);
    enqueue_resample_local(dev, segs, k == 0 ? fresh : kept, vb, 1, fp);
    got[k] = read_footprints(dev, fp);
  }
  EXPECT_TRUE(same_bits(got[0], got[1]));
  EXPECT_TRUE(std::any_of(got[0].pixels.begin(), got[0].pixels.end(),
                          [](const Rgba& c) { return c.a != 0; }));
  // The first view's tables resample it differently: the view is used.
  ResampleTables old = make_resample_tables(dev, L, first);
  enqueue_zero_footprints(dev, fp);
  enqueue_resample_local(dev, segs, old, vb, 1, fp);
  EXPECT_FALSE(same_bits(got[0], read_footprints(dev, fp)));
  const Fixture other({36, 29, 23}, 7);
  EXPECT_THROW(
      set_resample_view(dev, kept, make_view(other.vol, {20, 35, 10}, 40, 36, Sampling::voxel)),
      ArgumentError);
}

// The lanes' order: in each block of SV_ORDER_BLOCK positions cut at the PEs'
// boundaries, the segments stably sorted by min(k1 - k0, 63), longest first
// (a host sort of the same keys), so each segment stays in its PE's range.
TEST(LocalCl, SegmentOrderSortsWithinPeBlocks) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{93, 57, 31};
  const Volume vol(dims, VoxelType::f32);
  int sorted_cases = 0;
  for (int64_t pes : {int64_t(1), int64_t(8), int64_t(512), int64_t(8192)})
    for (const ViewAngles a :
         {ViewAngles{0, 0, 0}, ViewAngles{0, 30, 0}, ViewAngles{33, 71, -12}}) {
      const ViewGeometry view = make_view(vol, a, 120, 100, Sampling::voxel);
      const KdSplit split = kd_split(dims, pes);
      const Matching m = balance_reference(match_reference(view, split), view, split);
      const LocalSegments segs = upload_segments(dev, m);
      const SegmentOrder o = enqueue_segment_order(dev, segs);
      std::vector<cl_int> got(m.segments.size());
      ASSERT_EQ(o.count, static_cast<int64_t>(got.size()));
      cl_check(dev.queue().enqueueReadBuffer(o.order, CL_TRUE, 0, got.size() * sizeof(cl_int),
                                             got.data()),
               "read order");
      std::vector<cl_int> want(got.size());
      const auto key = [&](cl_int s) {
        return std::clamp(
            m.segments[static_cast<std::size_t>(s)].k1 - m.segments[static_cast<std::size_t>(s)].k0,
            0, 63);
      };
      for (int64_t p = 0; p < pes; ++p)
        for (int64_t b0 = m.seg_offset[p]; b0 < m.seg_offset[p + 1];) {
          const int64_t b1 =
              std::min<int64_t>((b0 / SV_ORDER_BLOCK + 1) * SV_ORDER_BLOCK, m.seg_offset[p + 1]);
          std::iota(want.begin() + b0, want.begin() + b1, static_cast<cl_int>(b0));
          std::stable_sort(want.begin() + b0, want.begin() + b1,
                           [&](cl_int x, cl_int y) { return key(x) > key(y); });
          b0 = b1;
        }
      EXPECT_EQ(got, want) << "P " << pes << " view " << a.theta << "," << a.phi;
      // After the order, the PE of each float8 work-item's first position
      // 8 w (the largest p with seg_offset[p] <= 8 w), which the float8
      // kernels take instead of searching.
      ASSERT_TRUE(o.with_pe);
      std::vector<cl_int> pe((got.size() + 7) / 8), pe_want(pe.size());
      cl_check(dev.queue().enqueueReadBuffer(o.order, CL_TRUE, got.size() * sizeof(cl_int),
                                             pe.size() * sizeof(cl_int), pe.data()),
               "read the order's PEs");
      for (std::size_t w = 0; w < pe.size(); ++w) {
        const auto at =
            std::upper_bound(m.seg_offset.begin(), m.seg_offset.end(), static_cast<int64_t>(8 * w));
        pe_want[w] = static_cast<cl_int>(at - m.seg_offset.begin() - 1);
      }
      EXPECT_EQ(pe, pe_want) << "P " << pes << " view " << a.theta << "," << a.phi;
      std::vector<cl_int> identity(got.size());
      std::iota(identity.begin(), identity.end(), 0);
      sorted_cases += got != identity;
    }
  EXPECT_GT(sorted_cases, 3);  // the oblique views do reorder segments
  // An order made for other segments is refused.
  const ViewGeometry view = make_view(vol, {}, 16, 16, Sampling::voxel);
  const Matching m = match_reference(view, kd_split(dims, 8));
  const LocalSegments segs = upload_segments(dev, m);
  const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, 8, 1));
  VoxelBuffer vb(dev, L);
  const ResampleTables tables = make_resample_tables(dev, L, view);
  DeviceFootprints fp = make_footprints(dev, m.rects);
  SegmentOrder wrong = enqueue_segment_order(dev, segs);
  wrong.count += 1;
  EXPECT_THROW(
      enqueue_resample_local(dev, segs, tables, vb, 1, fp, LocalKernel::vector8, nullptr, &wrong),
      ArgumentError);
}

// The engine reads the footprint sizes before the balance (start_segments)
// and takes them after it (finish_segments): the same count, rectangles and
// bounds state as device_segments after the balance, and as the serial
// matching's; finishing on another matching, or twice, is refused, and
// one dropped unfinished waits for its reads.
TEST(LocalCl, SegmentsReadBeforeTheBalanceAreTheBalancedOnes) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{41, 35, 29};
  const Volume vol(dims, VoxelType::f32);
  int moved = 0;
  for (int64_t pes : {int64_t(1), int64_t(64), int64_t(8192)})
    for (const ViewAngles& a : {ViewAngles{0, 45, 0}, ViewAngles{20, 35, 10}}) {
      SCOPED_TRACE("P " + std::to_string(pes) + " view " + std::to_string(a.phi));
      const ViewGeometry view = make_view(vol, a, 48, 40, Sampling::voxel);
      const KdSplit split = kd_split(dims, pes);
      DeviceMatching dm = enqueue_match(dev, view, split);
      SegmentReads reads = start_segments(dev, dm);
      enqueue_balance(dev, dm, view, split, kBalanceSweeps, BalanceBounds::automatic,
                      BalanceUnpack::deferred);
      const LocalSegments got = finish_segments(reads, dm);
      EXPECT_THROW(finish_segments(reads, dm), ArgumentError);  // finished already
      const LocalSegments want = device_segments(dev, dm);
      EXPECT_EQ(got.count, want.count);
      EXPECT_EQ(got.bounds_pending, want.bounds_pending);
      EXPECT_EQ(got.bounds_pending, dm.unpack_pending);
      ASSERT_EQ(got.host_rects.size(), want.host_rects.size());
      EXPECT_EQ(std::memcmp(got.host_rects.data(), want.host_rects.data(),
                            got.host_rects.size() * sizeof(sv_rect)),
                0);
      const Matching ref = balance_reference(match_reference(view, split), view, split);
      moved += ref.loads != match_reference(view, split).loads;
      EXPECT_EQ(got.count, static_cast<int64_t>(ref.segments.size()));
      ASSERT_EQ(got.host_rects.size(), ref.rects.size());
      for (std::size_t p = 0; p < ref.rects.size(); ++p) {
        EXPECT_EQ(got.host_rects[p].i0, ref.rects[p].i0) << p;
        EXPECT_EQ(got.host_rects[p].j0, ref.rects[p].j0) << p;
        EXPECT_EQ(got.host_rects[p].w, ref.rects[p].w) << p;
        EXPECT_EQ(got.host_rects[p].h, ref.rects[p].h) << p;
      }
      DeviceMatching other = enqueue_match(dev, view, split);
      {  // dropped unfinished (a frame's error): it waits for its reads
        SegmentReads dropped = start_segments(dev, other);
        enqueue_balance(dev, other, view, split);
      }
      dev.finish();
      SegmentReads elsewhere = start_segments(dev, other);
      EXPECT_THROW(finish_segments(elsewhere, dm), ArgumentError);
      EXPECT_NO_THROW(finish_segments(elsewhere, other));
    }
  EXPECT_GT(moved, 0);  // the balance moved samples in some case
}

// Segments whose balance left its unpack pending (BalanceUnpack::deferred,
// the engine's direct frames): the segment order and the fused float8
// kernel read the balanced bounds from the 16-bit copy and give the same
// order and footprints, bit for bit, as segments of the same balance
// unpacked at once (orders 1 and 3, with and without skipping and the lane
// order); the stages that read the segments' own bounds refuse them.
TEST(LocalCl, DeferredBalanceUnpackGivesTheSameBits) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{41, 35, 29};
  const Volume vol(dims, VoxelType::f32);
  int moved = 0, coloured = 0;
  for (int64_t pes : {int64_t(8), int64_t(512), int64_t(8192)}) {
    const std::vector<Rgba> v = sparse_voxels(dims, static_cast<unsigned>(pes + 3));
    const VoxelLayout L4 = make_voxel_layout(make_cell_layout(dims, pes, 1), true);
    VoxelBuffer vb4(dev, L4);
    vb4.write(dev, voxels_to_cells(v, L4));
    const KdSplit split = kd_split(dims, pes);
    for (const ViewAngles& a :
         {ViewAngles{0, 45, 0}, ViewAngles{20, 35, 10}, ViewAngles{33, 71, -12}}) {
      SCOPED_TRACE("P " + std::to_string(pes) + " view " + std::to_string(a.theta) + "," +
                   std::to_string(a.phi) + "," + std::to_string(a.varphi));
      const ViewGeometry view = make_view(vol, a, 48, 40, Sampling::voxel);
      DeviceMatching deferred = enqueue_match(dev, view, split);
      enqueue_balance(dev, deferred, view, split, kBalanceSweeps, BalanceBounds::automatic,
                      BalanceUnpack::deferred);
      ASSERT_TRUE(deferred.unpack_pending);
      DeviceMatching unpacked = enqueue_match(dev, view, split);
      enqueue_balance(dev, unpacked, view, split);
      const LocalSegments sd = device_segments(dev, deferred);
      const LocalSegments sn = device_segments(dev, unpacked);
      ASSERT_TRUE(sd.bounds_pending);
      ASSERT_FALSE(sn.bounds_pending);
      ASSERT_EQ(sd.count, sn.count);
      const Matching m = unpacked.read(dev);
      moved += m.loads != match_reference(view, split).loads;
      const SegmentOrder od = enqueue_segment_order(dev, sd);
      const SegmentOrder on = enqueue_segment_order(dev, sn);
      const std::size_t count = static_cast<std::size_t>(std::max<int64_t>(sd.count, 1));
      EXPECT_EQ(read_all<cl_int>(dev, od.order, count), read_all<cl_int>(dev, on.order, count));
      const ResampleTables t4 = make_resample_tables(dev, L4, view);
      DeviceFootprints fd = make_footprints(dev, m.rects), fn = make_footprints(dev, m.rects);
      for (int order : {1, 3}) {
        const DeviceOccupancy occ = enqueue_occupancy(dev, vb4, order);
        for (int variant = 0; variant < 3; ++variant) {
          const DeviceOccupancy* skip = variant >= 1 ? &occ : nullptr;
          enqueue_zero_footprints(dev, fd);
          enqueue_zero_footprints(dev, fn);
          enqueue_resample_local(dev, sd, t4, vb4, order, fd, LocalKernel::vector8, skip,
                                 variant == 2 ? &od : nullptr);
          enqueue_resample_local(dev, sn, t4, vb4, order, fn, LocalKernel::vector8, skip,
                                 variant == 2 ? &on : nullptr);
          const Footprints want = read_footprints(dev, fn);
          EXPECT_TRUE(same_bits(read_footprints(dev, fd), want))
              << "order " << order << " variant " << variant;
          coloured += std::any_of(want.pixels.begin(), want.pixels.end(),
                                  [](const Rgba& c) { return c.a != 0; });
        }
      }
      const cl::Buffer soff = upload_sample_offsets(dev, m);
      cl::Buffer samples =
          dev.buffer(CL_MEM_READ_WRITE,
                     static_cast<std::size_t>(std::max<int64_t>(sample_offsets(m).back(), 1)) * 16,
                     nullptr, "samples");
      EXPECT_THROW(enqueue_resample_local(dev, sd, t4, vb4, 1, fd, LocalKernel::segment),
                   ArgumentError);
      EXPECT_THROW(enqueue_resample(dev, sd, soff, t4, vb4, 1, samples), ArgumentError);
      EXPECT_THROW(enqueue_local(dev, sd, soff, samples, fd), ArgumentError);
      EXPECT_THROW(enqueue_ray_lists(dev, sd, view), ArgumentError);
      // once unpacked, the segments are those of the other balance
      enqueue_balance_unpack(dev, deferred);
      const LocalSegments su = device_segments(dev, deferred);
      EXPECT_FALSE(su.bounds_pending);
      EXPECT_NO_THROW(enqueue_resample(dev, su, soff, t4, vb4, 1, samples));
      const std::size_t n = static_cast<std::size_t>(sd.count);
      const std::vector<sv_segment> a0 = read_all<sv_segment>(dev, su.segments, n);
      const std::vector<sv_segment> a1 = read_all<sv_segment>(dev, sn.segments, n);
      EXPECT_EQ(std::memcmp(a0.data(), a1.data(), n * sizeof(sv_segment)), 0);
    }
  }
  EXPECT_GT(moved, 3);     // the balances moved samples
  EXPECT_GT(coloured, 9);  // and the footprints are not all empty
}

// Zeroing only the footprint pixels without a segment (simdvol_zero_uncovered)
// before the fused kernel gives the footprints of zeroing them all, bit for
// bit, from footprints full of NaN; without it the NaN stay (the test can
// fail), in the cases with uncovered pixels: oblique views, rows with holes
// (8,192 PEs: cells of 2-3 voxels), the PE mask of empty-space skipping.
TEST(LocalCl, ZeroUncoveredGivesTheSameFootprints) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{41, 35, 29};
  const Volume vol(dims, VoxelType::f32);
  int uncovered_cases = 0, hole_rows = 0, masked = 0;
  for (int64_t pes : {int64_t(1), int64_t(64), int64_t(8192)}) {
    const std::vector<Rgba> v = sparse_voxels(dims, static_cast<unsigned>(pes + 7));
    const VoxelLayout L4 = make_voxel_layout(make_cell_layout(dims, pes, 1), true);
    VoxelBuffer vb4(dev, L4);
    vb4.write(dev, voxels_to_cells(v, L4));
    const KdSplit split = kd_split(dims, pes);
    for (const ViewAngles& a : {ViewAngles{0, 0, 0}, ViewAngles{0, 45, 0}, ViewAngles{20, 35, 10},
                                ViewAngles{-63, 118, 27}})
      for (const bool mask : {false, true}) {
        SCOPED_TRACE("P " + std::to_string(pes) + " view " + std::to_string(a.theta) + "," +
                     std::to_string(a.phi) + "," + std::to_string(a.varphi) +
                     (mask ? " masked" : ""));
        const ViewGeometry view = make_view(vol, a, 48, 40, Sampling::voxel);
        const DeviceOccupancy occ = enqueue_occupancy(dev, vb4, 1);
        DeviceMatching dm =
            mask ? enqueue_match(dev, view, split, BrickReach{&occ.reach, occ.bricks})
                 : enqueue_match(dev, view, split);
        enqueue_balance(dev, dm, view, split, kBalanceSweeps, BalanceBounds::automatic,
                        BalanceUnpack::deferred);
        const LocalSegments segs = device_segments(dev, dm);
        const Matching m = dm.read(dev);
        if (mask) masked += std::count(m.active.begin(), m.active.end(), 0) > 0;
        int64_t area = 0;
        for (const sv_rect& r : m.rects) area += int64_t(r.w) * r.h;
        const bool uncovered = area > static_cast<int64_t>(m.segments.size());
        uncovered_cases += uncovered;
        for (int64_t p = 0; p < m.pes(); ++p) {  // rows whose segments have a gap
          for (int64_t s = m.seg_offset[p]; s + 1 < m.seg_offset[p + 1]; ++s)
            hole_rows +=
                m.segments[s + 1].j == m.segments[s].j && m.segments[s + 1].i > m.segments[s].i + 1;
        }
        const ResampleTables t4 = make_resample_tables(dev, L4, view);
        const SegmentOrder lanes = enqueue_segment_order(dev, segs);
        auto [all, some, none] = simdvol::testing::nan_footprints(dev, dm, segs.host_rects);
        for (DeviceFootprints* f : {&all, &some, &none})
          enqueue_resample_local(dev, segs, t4, vb4, 1, *f, LocalKernel::vector8, &occ, &lanes);
        const Footprints want = read_footprints(dev, all);
        EXPECT_TRUE(same_bits(read_footprints(dev, some), want));
        if (uncovered) {
          EXPECT_FALSE(same_bits(read_footprints(dev, none), want));
        }
      }
  }
  EXPECT_GT(uncovered_cases, 6);
  EXPECT_GT(hole_rows, 0);
  EXPECT_GT(masked, 0);
  // footprints of another PE count
  const ViewGeometry view = make_view(vol, {}, 16, 16, Sampling::voxel);
  DeviceMatching dm = enqueue_match(dev, view, kd_split(dims, 8));
  DeviceFootprints f4 = make_footprints(dev, std::vector<sv_rect>(4));
  EXPECT_THROW(enqueue_zero_uncovered(dev, dm, f4), ArgumentError);
}

// The engine with and without skip_empty, skip_pes and order_lanes: the
// same image, bit for bit, where no balancing regroups the samples into
// other sub-rays (0 sweeps, every PE matched, or whole-ray adaptive
// compositing); with direct compositing, balancing and skip_pes, the same to
// float rounding.
TEST(RenderOpenClFrame, SkipEmptyGivesTheSameImage) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Volume vol = shepp_logan(45, 2);
  for (const CompositeMode mode :
       {CompositeMode::direct, CompositeMode::adaptive, CompositeMode::mc})
    for (int order : {1, 3})
      for (const ViewAngles a : {ViewAngles{0, 0, 0}, ViewAngles{20, 35, 10}})
        for (const int sweeps : {0, kBalanceSweeps})
          for (const bool skip_pes : {true, false}) {
            SCOPED_TRACE("order " + std::to_string(order) + " sweeps " + std::to_string(sweeps) +
                         (skip_pes ? " skip_pes" : "") +
                         (mode == CompositeMode::direct ? " direct" : " whole ray"));
            RenderOptions opt;
            opt.width = opt.height = 48, opt.view = a, opt.order = order;
            opt.classifier = classifier_preset("ct");
            opt.composite.mode = mode;
            opt.composite.threshold = 0.9f;
            opt.composite.samples = 8;
            // Both kinds of stream, and draws for transparent samples too.
            opt.composite.streams = order == 1 ? RandomStreams::per_ray : RandomStreams::shared;
            opt.composite.drop_transparent = sweeps == 0;
            EngineOptions on, off;
            on.pes = off.pes = 512;
            on.balance_sweeps = off.balance_sweeps = sweeps;
            on.skip_pes = skip_pes;
            off.skip_empty = false;
            off.order_lanes = false;
            RenderEngine e_on(*dp, on), e_off(*dp, off);
            EngineTimes t;
            EngineStats st_on, st_off;
            const Image a_on = e_on.render(vol, opt, &t, &st_on);
            const Image a_off = e_off.render(vol, opt, nullptr, &st_off);
            // The brick occupancy is made whenever samples are skipped:
            // direct compositing steps over those out of reach, the other
            // modes store them as +0 without gathering.
            EXPECT_GT(t.occupancy_ms, 0.0);
            ASSERT_EQ(a_on.pixels().size(), a_off.pixels().size());
            if (sweeps == 0 || !skip_pes || mode != CompositeMode::direct) {
              EXPECT_EQ(std::memcmp(a_on.pixels().data(), a_off.pixels().data(),
                                    a_on.pixels().size() * sizeof(Rgba)),
                        0);
            } else {
              EXPECT_GE(psnr(a_off, a_on), 100.0);
            }
            // skip_pes left PEs out (fewer segments), and they were PEs with
            // samples: the test can tell the option from its absence.
            if (skip_pes) {
              EXPECT_LT(st_on.segments, st_off.segments);
              EXPECT_LT(st_on.samples, st_off.samples);
            } else {
              EXPECT_EQ(st_on.samples, st_off.samples);
            }
          }
}

// The resample's earlier forms, kept as kernel switches for timing
// comparisons, give the frame's image bit for bit: the corner offsets
// extracted from their vectors instead of stored and loaded back
// (SV_OFFS_EXTRACT; AVX-512 targets, and AVX2 ones at order 1 since
// 2026-12-07), loaded back once per use (SV_OFFS_RELOAD, AVX-512), the
// order-1 pair table's entries loaded one by one instead of by AVX2 gathers
// (SV_NO_GATHER_AVX2; AVX2 targets), the fused kernel's steps with those
// gathers not pipelined (SV_NO_PIPE; AVX2 targets at order 1, since the
// thirty-fourth session of 2026-12-07; SV_NO_GATHER_AVX2 implies it), the
// lanes trimmed to their samples in reach before stepping (SV_TRIM), the
// prefetch's PE found by a second search (SV_PE_SEARCH2). Orders 1 (the
// interleaved order-1 sampler) and 3 (the general one), an axis view and an
// oblique one, with balancing.
TEST(RenderOpenClFrame, KernelSwitchesGiveTheSameImage) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const char* old = std::getenv("SIMDVOL_CL_OPTIONS");
  const std::string saved = old ? old : "";
  // 45^3 at 512 PEs: cells of 6 voxels, whose pairs give the cell bits (the
  // _ilc kernels at order 1); 33^3: cells of 5, no cell bits, so order 1
  // takes the pair table's kernels (_il) there
  const Volume v45 = shepp_logan(45, 2), v33 = shepp_logan(33, 2);
  for (const Volume* pv : {&v45, &v33})
    for (int order : {1, 3})
      for (const ViewAngles a :
           {ViewAngles{0, 0, 0}, ViewAngles{20, 35, 10}, ViewAngles{0, 45, 0}}) {
        if (pv == &v33 && order != 1) continue;
        const Volume& vol = *pv;
        SCOPED_TRACE(std::to_string(vol.dims()[0]) + "^3, order " + std::to_string(order) +
                     " view (" + std::to_string(a.theta) + ", " + std::to_string(a.phi) + ", " +
                     std::to_string(a.varphi) + ")");
        RenderOptions opt;
        opt.width = opt.height = 48, opt.view = a, opt.order = order;
        opt.classifier = classifier_preset("ct");
        EngineOptions eo;
        eo.pes = 512;
        eo.fused = true;  // interleaved voxel cells, as the CLI's frames
        unsetenv("SIMDVOL_CL_OPTIONS");
        const Image want = RenderEngine(*dp, eo).render(vol, opt);
        // (one build of the frame's programs per switch set: all the
        // default's later forms at once, and the reload (AVX-512) with the
        // gathers unpipelined (AVX2))
        for (const char* sw : {"-DSV_OFFS_EXTRACT -DSV_NO_GATHER_AVX2 -DSV_TRIM -DSV_PE_SEARCH2",
                               "-DSV_OFFS_RELOAD -DSV_NO_PIPE"}) {
          SCOPED_TRACE(sw);
          setenv("SIMDVOL_CL_OPTIONS", sw, 1);
          const Image got = RenderEngine(*dp, eo).render(vol, opt);
          ASSERT_EQ(got.pixels().size(), want.pixels().size());
          EXPECT_EQ(std::memcmp(got.pixels().data(), want.pixels().data(),
                                got.pixels().size() * sizeof(Rgba)),
                    0);
        }
      }
  if (old)
    setenv("SIMDVOL_CL_OPTIONS", saved.c_str(), 1);
  else
    unsetenv("SIMDVOL_CL_OPTIONS");
}

namespace {

// Monte Carlo on the CLI's small phantom at view (20, 35, 10), 48 x 48:
// per-ray streams at order 1, the shared sequence otherwise; transparent
// samples dropped at order 1, drawn for otherwise.
RenderOptions mc_options(int order, int samples, bool exact, bool stratified) {
  RenderOptions opt;
  opt.width = opt.height = 48, opt.view = {20, 35, 10}, opt.order = order;
  opt.classifier = classifier_preset("ct");
  opt.composite.mode = CompositeMode::mc;
  opt.composite.samples = samples;
  opt.composite.streams = order == 1 ? RandomStreams::per_ray : RandomStreams::shared;
  opt.composite.drop_transparent = order == 1;
  opt.composite.exact_opacity = exact;
  opt.composite.stratified = stratified;
  return opt;
}

}  // namespace

// skip_pes and Monte Carlo's variants (plain, exact opacity, stratified,
// and per sub-ray walks allocated by opacity; both streams): whole rays
// give the same bits with fewer samples whatever the balancing (exact
// opacity's draws are keyed by the first sample with alpha > 0), per
// sub-ray without balancing; with balancing per sub-ray matches every PE
// (the same samples).
TEST(RenderOpenClFrame, SkipPesMonteCarloVariants) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Volume vol = shepp_logan(45, 2);
  for (const McScope scope : {McScope::whole, McScope::subray})
    for (int variant = 0; variant < 4; ++variant)
      for (int order : {1, 3})
        for (const int sweeps : {0, kBalanceSweeps}) {
          if (scope == McScope::whole && variant == 3) continue;  // allocation: per sub-ray
          SCOPED_TRACE(std::string(scope == McScope::whole ? "whole" : "subray") + " variant " +
                       std::to_string(variant) + " order " + std::to_string(order) + " sweeps " +
                       std::to_string(sweeps));
          const RenderOptions opt = mc_options(order, 11, variant >= 1, variant == 2);
          EngineOptions on, off;
          on.pes = off.pes = 512;
          on.balance_sweeps = off.balance_sweeps = sweeps;
          on.mc_scope = off.mc_scope = scope;
          on.mc_allocate = off.mc_allocate = variant == 3;
          off.skip_pes = false;
          RenderEngine e_on(*dp, on), e_off(*dp, off);
          EngineStats st_on, st_off;
          const Image a_on = e_on.render(vol, opt, nullptr, &st_on);
          const Image a_off = e_off.render(vol, opt, nullptr, &st_off);
          ASSERT_EQ(a_on.pixels().size(), a_off.pixels().size());
          EXPECT_EQ(std::memcmp(a_on.pixels().data(), a_off.pixels().data(),
                                a_on.pixels().size() * sizeof(Rgba)),
                    0);
          if (sweeps == 0 || scope == McScope::whole) {
            EXPECT_LT(st_on.samples, st_off.samples);
          } else {
            EXPECT_EQ(st_on.samples, st_off.samples);
          }
        }
}

// Per sub-ray Monte Carlo with balancing matches every PE, so the stored
// resample sees samples out of reach in PEs with nothing to draw; with
// skip_empty it stores them as +0 without gathering. Every variant (plain,
// exact opacity, stratified, allocated by opacity; both streams, transparent
// samples dropped or drawn) gives the same image bit for bit as without.
TEST(RenderOpenClFrame, SkipEmptyPerSubRayMonteCarloSameImage) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Volume vol = shepp_logan(45, 2);
  for (int variant = 0; variant < 4; ++variant)
    for (int order : {1, 2}) {
      SCOPED_TRACE("variant " + std::to_string(variant) + " order " + std::to_string(order));
      const RenderOptions opt = mc_options(order, 9, variant == 1 || variant == 2, variant == 2);
      EngineOptions on, off;
      on.pes = off.pes = 512;
      on.mc_scope = off.mc_scope = McScope::subray;
      on.mc_allocate = off.mc_allocate = variant == 3;
      off.skip_empty = false;
      RenderEngine e_on(*dp, on), e_off(*dp, off);
      EngineTimes t_on, t_off;
      EngineStats st_on, st_off;
      const Image a_on = e_on.render(vol, opt, &t_on, &st_on);
      const Image a_off = e_off.render(vol, opt, &t_off, &st_off);
      EXPECT_GT(t_on.occupancy_ms, 0.0);
      EXPECT_EQ(t_off.occupancy_ms, 0.0);
      EXPECT_EQ(st_on.samples, st_off.samples);  // balanced: every PE matched
      ASSERT_EQ(a_on.pixels().size(), a_off.pixels().size());
      EXPECT_EQ(std::memcmp(a_on.pixels().data(), a_off.pixels().data(),
                            a_on.pixels().size() * sizeof(Rgba)),
                0);
      EXPECT_TRUE(std::any_of(a_on.pixels().begin(), a_on.pixels().end(),
                              [](const Rgba& c) { return c.a > 0.0f; }));
    }
}

// skip_pes on random cases where it claims the same bits: odd dims, P from
// 1 to 512, orders 0-3, both samplings, fused or not, mostly transparent
// volumes; direct compositing without balancing, adaptive and Monte Carlo
// with it. Some case must leave PEs out (fewer samples), so the comparison
// is not between two identical runs.
TEST(RenderOpenClFrame, SkipPesRandomCasesSameImage) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  std::mt19937 rng(77);
  std::uniform_real_distribution<double> ang(-180.0, 180.0);
  std::uniform_int_distribution<int> dim(5, 40);
  int64_t left_out = 0;
  for (int n = 0; n < 48; ++n) {
    const Dims3 d{dim(rng), dim(rng), dim(rng)};
    Volume vol = n % 2 ? shepp_logan(static_cast<int>(d[0]), 1)
                       : simdvol::testing::random_volume(d, -1000.0f, 2000.0f, {1, 1, 1}, n);
    if (n % 2 == 0)  // air with scattered dense voxels
      for (float& x : vol.data()) x = x > 1500.0f ? x : -1000.0f;
    RenderOptions opt;
    opt.width = 8 + n % 30, opt.height = 8 + (n * 7) % 30;
    opt.view = {ang(rng), ang(rng), ang(rng)};
    opt.order = n % 4;
    opt.sampling = n % 3 ? Sampling::voxel : Sampling::pixel;
    opt.classifier = classifier_preset(n % 5 ? "ct" : "mri");
    const CompositeMode modes[] = {CompositeMode::direct, CompositeMode::adaptive,
                                   CompositeMode::mc};
    opt.composite.mode = modes[n % 3];
    opt.composite.samples = 4;
    EngineOptions on, off;
    on.pes = off.pes = int64_t(1) << (n % 10);
    on.balance_sweeps = off.balance_sweeps = n % 3 == 0 ? 0 : kBalanceSweeps;
    off.skip_pes = false;
    on.fused = off.fused = n % 2 == 1;
    SCOPED_TRACE("case " + std::to_string(n) + " P " + std::to_string(on.pes));
    RenderEngine e_on(*dp, on), e_off(*dp, off);
    EngineStats s_on, s_off;
    const Image a = e_on.render(vol, opt, nullptr, &s_on);
    const Image b = e_off.render(vol, opt, nullptr, &s_off);
    ASSERT_EQ(a.pixels().size(), b.pixels().size());
    EXPECT_EQ(std::memcmp(a.pixels().data(), b.pixels().data(), a.pixels().size() * sizeof(Rgba)),
              0);
    EXPECT_LE(s_on.samples, s_off.samples);
    left_out += s_off.samples - s_on.samples;
  }
  EXPECT_GT(left_out, 0);
}
