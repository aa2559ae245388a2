// Monte Carlo compositing on the device (mc_cl.hpp) against the references
// (mc.hpp) for the same seed: ray lists and allocations exactly, estimates
// within 1e-5 (the kernels repeat the references' arithmetic, so in practice
// bit for bit; the count of differing values is checked to be 0 as well),
// work counters exactly. Whole ray and per sub-ray, plain, exact opacity,
// allocated, both random streams, transparent samples dropped or not; several
// views, orders and P from 1 to 8192; balanced matchings.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>

#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/render.hpp"
#include "stage_testing.hpp"

using namespace simdvol;
using simdvol::testing::test_device;

namespace {

std::vector<Rgba> random_voxels(const Dims3& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  for (Rgba& x : v) {
    if (u(rng) < 0.3f) continue;  // transparent voxels
    x.a = u(rng) * 0.3f;
    x.r = x.a * u(rng);
    x.g = x.a * u(rng);
    x.b = x.a * u(rng);
  }
  return v;
}

struct Diff {
  float max = 0;
  int64_t differing = 0;
};
Diff diff(const std::vector<Rgba>& a, const std::vector<Rgba>& b) {
  EXPECT_EQ(a.size(), b.size());
  Diff d;
  for (std::size_t n = 0; n < std::min(a.size(), b.size()); ++n) {
    const float m = std::max({std::fabs(a[n].r - b[n].r), std::fabs(a[n].g - b[n].g),
                              std::fabs(a[n].b - b[n].b), std::fabs(a[n].a - b[n].a)});
    d.max = std::max(d.max, m);
    if (a[n].r != b[n].r || a[n].g != b[n].g || a[n].b != b[n].b || a[n].a != b[n].a) ++d.differing;
  }
  return d;
}

void check_case(Device& dev, const Dims3& dims, const std::vector<Rgba>& voxels,
                const ViewGeometry& view, int64_t pes, int order, int nwalks) {
  SCOPED_TRACE("P " + std::to_string(pes) + " order " + std::to_string(order) + ", " +
               std::to_string(nwalks) + " walks");
  const KdSplit split = kd_split(dims, pes);
  const Matching m = balance_reference(match_reference(view, split), view, split);
  const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1));
  VoxelBuffer vb(dev, L);
  vb.write(dev, voxels_to_cells(voxels, L));
  const LocalSegments segs = upload_segments(dev, m);
  const ResampleTables tables = make_resample_tables(dev, L, view);
  const cl::Buffer soff = upload_sample_offsets(dev, m);
  const int64_t nsamples = sample_offsets(m).back();
  cl::Buffer samples =
      dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16,
                 nullptr, "samples");
  enqueue_resample(dev, segs, soff, tables, vb, order, samples);
  const int W = view.width(), H = view.height();
  DeviceRayLists rays = enqueue_ray_lists(dev, segs, view);
  dev.finish();
  // The references run on the device's samples (equal to resample_reference
  // within 1e-5, tested in test_local_cl): the walks compare u < alpha, so
  // the same seed gives the same walks only on the same samples.
  std::vector<Rgba> smp(static_cast<std::size_t>(nsamples));
  if (nsamples > 0)
    cl_check(dev.queue().enqueueReadBuffer(samples, CL_TRUE, 0, smp.size() * 16, smp.data()),
             "read samples");
  const RaySegments ref_rays = ray_segments(m, W, H);
  const RaySegments got_rays = read_ray_lists(dev, rays);
  ASSERT_EQ(got_rays.offset, ref_rays.offset);
  ASSERT_EQ(got_rays.items, ref_rays.items);

  cl::Buffer image =
      dev.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(W) * H * 16, nullptr, "image");
  for (RandomStreams st : {RandomStreams::per_ray, RandomStreams::shared})
    for (int variant : {0, 1, 2})  // plain, exact opacity, exact + stratified
      for (bool drop : {true, false}) {
        const bool exact = variant >= 1;
        SCOPED_TRACE(std::string(st == RandomStreams::shared ? "shared" : "per-ray") +
                     (variant == 2 ? " stratified"
                      : exact      ? " exact"
                                   : " plain") +
                     (drop ? " drop" : " keep"));
        CompositeParams p;
        p.mode = CompositeMode::mc;
        p.samples = nwalks;  // the kernels take the walks 8 at a time: 5 and 19
        p.seed = 0x1234567890ull;
        p.streams = st;
        p.exact_opacity = exact;
        p.stratified = variant == 2;
        p.drop_transparent = drop;
        // Whole ray.
        McStats ref_stats;
        const Image want = mc_whole_reference(m, smp, ref_rays, p, &ref_stats);
        DeviceMcStats ds;
        enqueue_mc_whole(dev, segs, soff, samples, rays, p, image, &ds);
        Image got(W, H);
        cl_check(dev.queue().enqueueReadBuffer(image, CL_TRUE, 0, got.pixels().size() * 16,
                                               got.pixels().data()),
                 "read image");
        const Diff dw = diff(got.pixels(), want.pixels());
        EXPECT_LE(dw.max, 1e-5f);
        EXPECT_EQ(dw.differing, 0);
        EXPECT_EQ(ds.read(dev), ref_stats);
        // Per sub-ray: p.samples each, and (exact only) allocated.
        for (bool alloc : {false, true}) {
          if (alloc && !exact) continue;
          SCOPED_TRACE(alloc ? "allocated" : "n per sub-ray");
          std::vector<int32_t> walks;
          std::optional<DeviceAllocation> da;
          if (alloc) {
            walks = allocation_reference(m, smp, ref_rays, nwalks + 1);
            da = enqueue_mc_allocation(dev, segs, soff, samples, rays, nwalks + 1);
            std::vector<cl_int> w(m.segments.size());
            if (!w.empty())
              cl_check(dev.queue().enqueueReadBuffer(da->walks, CL_TRUE, 0, w.size() * 4, w.data()),
                       "read walks");
            ASSERT_EQ(std::vector<int32_t>(w.begin(), w.end()), walks);
          }
          McStats rs;
          const Footprints fr =
              footprints_reference(m, mc_sub_reference(m, smp, ref_rays, p, walks, &rs));
          DeviceFootprints fp = make_footprints(dev, m.rects);
          enqueue_zero_footprints(dev, fp);
          DeviceMcStats ss;
          enqueue_mc_local(dev, segs, soff, samples, W, p, alloc ? &*da : nullptr, fp, &ss);
          const Footprints fg = read_footprints(dev, fp);
          const Diff dl = diff(fg.pixels, fr.pixels);
          EXPECT_LE(dl.max, 1e-5f);
          EXPECT_EQ(dl.differing, 0);
          EXPECT_EQ(ss.read(dev), rs);
        }
      }
}

}  // namespace

TEST(McCl, DeviceEqualsReferenceAcrossViewsOrdersAndPes) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Dims3 dims{37, 29, 23};
  const std::vector<Rgba> voxels = random_voxels(dims, 7);
  const std::array<int64_t, 3> d{dims[0], dims[1], dims[2]};
  const ViewAngles views[] = {{0, 0, 0}, {0, 30, 0}, {45, 45, 0}, {-23.5, 71.25, 133.0}};
  for (std::size_t v = 0; v < std::size(views); ++v) {
    const ViewGeometry view = make_view(d, {1.0, 1.0, 1.0}, views[v], 40, 40, Sampling::voxel);
    SCOPED_TRACE("view " + std::to_string(v));
    check_case(*dp, dims, voxels, view, v == 0 ? 1 : 64, 1, 5);
    check_case(*dp, dims, voxels, view, 8192, v == 2 ? 3 : 1, 19);
  }
}

// Per sub-ray Monte Carlo writes every segment's pixel, so zeroing only the
// footprint pixels without a segment (enqueue_zero_uncovered, as the
// engine does) gives the footprints that zeroing them all gives, bit for
// bit; without either, the uncovered pixels keep what was there (NaN
// here). Balanced device matchings, views with uncovered pixels.
TEST(McCl, ZeroUncoveredGivesTheSameFootprints) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  Device& dev = *dp;
  const Dims3 dims{37, 29, 23};
  const std::vector<Rgba> voxels = random_voxels(dims, 5);
  const std::array<int64_t, 3> d{dims[0], dims[1], dims[2]};
  int uncovered_cases = 0;
  for (const int64_t pes : {int64_t(64), int64_t(8192)}) {
    const KdSplit split = kd_split(dims, pes);
    const VoxelLayout L = make_voxel_layout(make_cell_layout(dims, pes, 1));
    VoxelBuffer vb(dev, L);
    vb.write(dev, voxels_to_cells(voxels, L));
    for (const ViewAngles& a : {ViewAngles{20, 35, 10}, ViewAngles{-63, 118, 27}}) {
      SCOPED_TRACE("P " + std::to_string(pes) + " view " + std::to_string(a.theta));
      const ViewGeometry view = make_view(d, {1.0, 1.0, 1.0}, a, 40, 40, Sampling::voxel);
      DeviceMatching dm = enqueue_match(dev, view, split);
      enqueue_balance(dev, dm, view, split, kBalanceSweeps, BalanceBounds::automatic,
                      BalanceUnpack::now);
      const LocalSegments segs = device_segments(dev, dm);
      const Matching m = dm.read(dev);
      int64_t area = 0;
      for (const sv_rect& r : m.rects) area += int64_t(r.w) * r.h;
      const bool uncovered = area > static_cast<int64_t>(m.segments.size());
      uncovered_cases += uncovered;
      const ResampleTables tables = make_resample_tables(dev, L, view);
      const cl::Buffer soff = upload_sample_offsets(dev, m);
      const int64_t nsamples = sample_offsets(m).back();
      cl::Buffer samples = dev.buffer(CL_MEM_READ_WRITE,
                                      static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16,
                                      nullptr, "samples");
      enqueue_resample(dev, segs, soff, tables, vb, 1, samples);
      CompositeParams p;
      p.mode = CompositeMode::mc;
      p.samples = 5;
      p.seed = 0x2468ull;
      p.exact_opacity = true;
      p.stratified = true;
      auto [all, some, none] = simdvol::testing::nan_footprints(dev, dm, segs.host_rects);
      for (DeviceFootprints* f : {&all, &some, &none})
        enqueue_mc_local(dev, segs, soff, samples, view.width(), p, nullptr, *f);
      const Footprints want = read_footprints(dev, all);
      const Footprints got = read_footprints(dev, some);
      ASSERT_EQ(got.pixels.size(), want.pixels.size());
      EXPECT_EQ(std::memcmp(got.pixels.data(), want.pixels.data(), got.pixels.size() * 16), 0);
      int64_t lit = 0;
      for (const Rgba& c : want.pixels) lit += c.a > 0;
      EXPECT_GT(lit, 0);
      if (uncovered) {
        const Footprints stale = read_footprints(dev, none);
        EXPECT_NE(std::memcmp(stale.pixels.data(), want.pixels.data(), stale.pixels.size() * 16),
                  0);
      }
    }
  }
  EXPECT_GE(uncovered_cases, 2);
}

// The walk-by-walk loop the kernels keep for timing comparisons
// (SV_MC_SCALAR; the default takes the walks 8 at a time) against the same
// references.
TEST(McCl, WalkByWalkLoopEqualsReference) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const char* old = std::getenv("SIMDVOL_CL_OPTIONS");
  const std::string saved = old ? old : "";
  setenv("SIMDVOL_CL_OPTIONS", "-DSV_MC_SCALAR", 1);
  const Dims3 dims{37, 29, 23};
  const std::vector<Rgba> voxels = random_voxels(dims, 11);
  const std::array<int64_t, 3> d{dims[0], dims[1], dims[2]};
  const ViewGeometry view =
      make_view(d, {1.0, 1.0, 1.0}, {-23.5, 71.25, 133.0}, 40, 40, Sampling::voxel);
  check_case(*dp, dims, voxels, view, 512, 1, 19);
  if (old)
    setenv("SIMDVOL_CL_OPTIONS", saved.c_str(), 1);
  else
    unsetenv("SIMDVOL_CL_OPTIONS");
}

TEST(McCl, RejectsBadArguments) {
  Device* dp = test_device();
  if (!dp) GTEST_SKIP() << "no OpenCL platform";
  const Dims3 dims{8, 8, 8};
  const ViewGeometry view =
      make_view(std::array<int64_t, 3>{8, 8, 8}, {1.0, 1.0, 1.0}, {}, 8, 8, Sampling::voxel);
  const ViewGeometry empty_grid = [&] {
    ViewGeometry v = view;
    v.grid.grid[0] = 0;
    return v;
  }();
  const KdSplit split = kd_split(dims, 8);
  const Matching m = match_reference(view, split);
  const LocalSegments segs = upload_segments(*dp, m);
  const cl::Buffer soff = upload_sample_offsets(*dp, m);
  cl::Buffer samples = dp->buffer(CL_MEM_READ_WRITE, 16, nullptr, "samples");
  DeviceRayLists rays = enqueue_ray_lists(*dp, segs, view);
  cl::Buffer image = dp->buffer(CL_MEM_READ_WRITE, 16, nullptr, "image");
  CompositeParams p;
  p.samples = 0;
  EXPECT_THROW(enqueue_mc_whole(*dp, segs, soff, samples, rays, p, image), ArgumentError);
  EXPECT_THROW(enqueue_mc_allocation(*dp, segs, soff, samples, rays, -1), ArgumentError);
  EXPECT_THROW(enqueue_ray_lists(*dp, segs, empty_grid), ArgumentError);
  dp->finish();
}
