// RenderEngine::render's EngineStats (engine.hpp) against the serial
// references on the same view: the loads after balancing equal
// balance_reference's exactly (samples = their sum, utilisation = mean / max),
// the segment count equals the balanced matching's, and the swap cost equals
// swap_cost of the plan made from the reference rectangles (direct
// compositing); a whole-ray adaptive frame has loads but no swap. With
// EngineOptions::balance_sweeps 0 and 1 the loads equal match_reference's
// and balance_reference's after one sweep, and the image stays the
// reference's (PSNR >= 80 dB, as the balanced frame's). The references take
// EngineOptions::skip_pes's PE mask from the reference's own classified
// voxels (stage_testing.hpp: reference_active).
#include <gtest/gtest.h>

#include <algorithm>

#include "simdvol/classify.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/match.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/swap_cl.hpp"
#include "stage_testing.hpp"

using namespace simdvol;

namespace {

// The frame both tests render: the 32^3 phantom at the headline view.
RenderOptions frame_options() {
  RenderOptions opt;
  opt.view = {20, 35, 10};
  opt.width = opt.height = 64;
  opt.classifier = classifier_preset("ct");
  return opt;
}

EngineOptions engine_options(int sweeps = kBalanceSweeps) {
  EngineOptions eo;
  eo.pes = 64;
  eo.fused = true;
  eo.balance_sweeps = sweeps;
  return eo;
}

}  // namespace

TEST(EngineStats, LoadsAndSwapCostEqualTheReferences) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 1);
  for (const bool skip_pes : {true, false}) {
    SCOPED_TRACE(skip_pes ? "skip_pes" : "every PE");
    RenderOptions opt = frame_options();
    EngineOptions eo = engine_options();
    eo.skip_pes = skip_pes;
    RenderEngine engine(dev, eo);
    EngineStats st;
    EngineTimes t;
    engine.render(vol, opt, &t, &st);

    const ViewGeometry view = make_view(vol, opt.view, opt.width, opt.height, opt.sampling);
    const KdSplit split = kd_split(vol.dims(), eo.pes);
    // With skip_pes the PEs whose cells have nothing in reach take no part
    // (the mask from the reference's classified voxels); some do here.
    const std::vector<uint8_t> active =
        skip_pes ? simdvol::testing::reference_active(vol, opt, split) : std::vector<uint8_t>{};
    if (skip_pes) {
      EXPECT_GT(std::count(active.begin(), active.end(), 0), 0);
    }
    const Matching m = balance_reference(match_reference(view, split, active), view, split);
    EXPECT_EQ(st.loads, m.loads);
    EXPECT_EQ(st.samples, m.total_load());
    EXPECT_GT(st.samples, 0);
    EXPECT_EQ(st.max_load(), m.max_load());
    EXPECT_DOUBLE_EQ(st.utilisation(), m.utilisation());
    EXPECT_EQ(st.segments, static_cast<int64_t>(m.segments.size()));
    ASSERT_TRUE(st.swapped);
    const PeGrid grid = pe_grid(eo.pes);
    const SwapCost want =
        swap_cost(plan_swap(m.rects, split, view, grid, eo.layout), split, view, grid);
    EXPECT_EQ(st.swap.moved, want.moved);
    EXPECT_GT(st.swap.moved, 0);
    EXPECT_EQ(st.swap.max_pe_sent, want.max_pe_sent);
    ASSERT_EQ(st.swap.stages.size(), want.stages.size());
    EXPECT_EQ(st.swap.stages.size(), 6u);  // log2(64)

    // Whole-ray adaptive compositing and Monte Carlo (exact opacity too):
    // no swap, the same PEs left out.
    opt.composite.mode = CompositeMode::adaptive;
    EngineStats sa;
    engine.render(vol, opt, nullptr, &sa);
    EXPECT_EQ(sa.loads, m.loads);
    EXPECT_FALSE(sa.swapped);
    EXPECT_EQ(sa.swap.moved, 0);
    opt.composite.mode = CompositeMode::mc;
    opt.composite.samples = 2;
    EngineStats sm;
    engine.render(vol, opt, nullptr, &sm);
    EXPECT_EQ(sm.loads, m.loads);
    opt.composite.exact_opacity = true;
    engine.render(vol, opt, nullptr, &sm);
    EXPECT_EQ(sm.loads, m.loads);
    if (skip_pes) {
      EXPECT_NE(sm.loads, balance_reference(match_reference(view, split), view, split).loads);
    }
  }
}

TEST(EngineStats, BalanceSweepsOption) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 1);
  const RenderOptions opt = frame_options();
  const ViewGeometry view = make_view(vol, opt.view, opt.width, opt.height, opt.sampling);
  const KdSplit split = kd_split(vol.dims(), 64);
  const Matching plain =
      match_reference(view, split, simdvol::testing::reference_active(vol, opt, split));
  const Image ref = render_reference(vol, opt);
  double util_seen[2] = {0, 0};
  for (int sweeps : {0, 1}) {
    SCOPED_TRACE("sweeps " + std::to_string(sweeps));
    RenderEngine engine(dev, engine_options(sweeps));
    EngineStats st;
    EngineTimes t;
    const Image img = engine.render(vol, opt, &t, &st);
    const Matching m = sweeps == 0 ? plain : balance_reference(plain, view, split, sweeps);
    EXPECT_EQ(st.loads, m.loads);
    EXPECT_EQ(st.segments, static_cast<int64_t>(m.segments.size()));
    EXPECT_EQ(st.samples, plain.total_load());  // balancing moves samples, never adds
    if (sweeps == 0) {
      EXPECT_EQ(t.balance_ms, 0.0);
    }
    util_seen[sweeps] = st.utilisation();
    EXPECT_GE(psnr(ref, img), 80.0);
  }
  // The view is one that balancing improves, so the option reached the device.
  EXPECT_LT(util_seen[0], util_seen[1]);
  for (int sweeps : {-1, kMaxBalanceSweeps + 1})
    EXPECT_THROW(render_opencl(dev, vol, opt, engine_options(sweeps)), ArgumentError);
}

// EngineStats::swap_level_buffers / swap_level_bytes: the frame's swap takes
// one level buffer, the levels after the first one written going into the
// footprints' buffer (FootprintsAfterSwap::overwritten), of 16 bytes x the
// largest of the first slot's levels' pixels (a 13-stage swap at 8,192 PEs,
// pixel sampling, direct and per sub-ray Monte Carlo; the first slot's levels
// from the reference's plan). Two buffers, first and second slot, before.
// The image stays the reference's.
TEST(EngineStats, SwapLevelsAfterTheFirstTakeTheFootprintsBuffer) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 1);
  RenderOptions opt = frame_options();
  opt.sampling = Sampling::pixel;
  opt.width = opt.height = 96;
  EngineOptions eo = engine_options();
  eo.pes = 8192;
  const ViewGeometry view =
      make_view(vol, opt.view, opt.width, opt.height, opt.sampling, opt.framing);
  const KdSplit split = kd_split(vol.dims(), eo.pes);
  const Matching m = balance_reference(
      match_reference(view, split, simdvol::testing::reference_active(vol, opt, split)), view,
      split);
  const SwapPlan plan = plan_swap(m.rects, split, view, pe_grid(eo.pes), eo.layout);
  const int N = plan.stages();
  ASSERT_EQ(N, 13);
  // The first level written to memory (enqueue_swap): after the fused
  // launch where one runs, else after stage 0.
  const int64_t local = static_cast<int64_t>(dev.info().local_mem_bytes);
  int m0 = std::min({kSwapFusedStages, N, swap_fused_stages_limit(dev)});
  while (m0 >= kSwapFusedMin && swap_stages_local_need(plan, 0, m0) > local) --m0;
  const int first = m0 >= kSwapFusedMin ? m0 : 1;
  int64_t most = 1, after = 1;
  for (int L = first; L <= N; ++L)
    ((L - first) % 2 ? after : most) = std::max((L - first) % 2 ? after : most, plan.level_size(L));
  ASSERT_LE(after, plan.level_size(0));  // the footprints hold the second slot's levels
  const Image ref = render_reference(vol, opt);
  RenderEngine engine(dev, eo);
  EngineStats st;
  Image img = engine.render(vol, opt, nullptr, &st);
  ASSERT_TRUE(st.swapped);
  EXPECT_EQ(st.swap_level_buffers, 1);
  EXPECT_EQ(st.swap_level_bytes, most * 16);
  EXPECT_GE(psnr(ref, img), 80.0);
  // Per sub-ray Monte Carlo goes through the same swap.
  opt.composite.mode = CompositeMode::mc;
  opt.composite.samples = 2;
  eo.mc_scope = McScope::subray;
  eo.balance_sweeps = 0;
  RenderEngine mc(dev, eo);
  EngineStats sm;
  mc.render(vol, opt, nullptr, &sm);
  ASSERT_TRUE(sm.swapped);
  EXPECT_EQ(sm.swap_level_buffers, 1);
  // Whole-ray compositing: no swap, no level buffers.
  opt.composite.mode = CompositeMode::adaptive;
  EngineStats sa;
  engine.render(vol, opt, nullptr, &sa);
  EXPECT_FALSE(sa.swapped);
  EXPECT_EQ(sa.swap_level_buffers, 0);
  EXPECT_EQ(sa.swap_level_bytes, 0);
}

// The buffers a frame's stages release (Device::release) serve its later
// requests of a size the pool's rule allows: at pixel sampling (192^2, 8,192
// PEs) the segment order takes the row links, and the swap's level buffer
// the row sums where their size allows it (the rule: a free buffer of at
// least the bytes asked and at most twice them + 64 KiB): the first level
// the swap writes to memory follows the device's local memory (the fused
// launch's stages), 3.9 MB or less on PoCL's 1 and 2 MiB, 5.9 MB on a Zen
// 3's 512 KiB, where the 3.9 MB row sums cannot hold it; at voxel sampling the level buffer takes
// the PE totals and the intermediate image the segment counts (their sizes match exactly), so no
// buffer under those names is left in the pool. The output image is the returned Image's own memory
// (HostImage), no pool buffer beside it: pixel sampling's intermediate image is not in the pool,
// voxel sampling's warped output neither. EngineStats::pool_bytes is the pool's bytes at the
// frame's end, and the same frame again takes nothing more (the reuse keeps
// the pool's size rule: the pool does not grow from frame to frame).
TEST(EngineStats, ReleasedBuffersServeTheFramesLaterRequests) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 1);
  for (const Sampling sampling : {Sampling::pixel, Sampling::voxel}) {
    SCOPED_TRACE(sampling == Sampling::pixel ? "pixel" : "voxel");
    Device d(dev.info().index);
    RenderOptions opt = frame_options();
    opt.sampling = sampling;
    opt.width = opt.height = 192;
    EngineOptions eo = engine_options();
    eo.pes = 8192;
    RenderEngine engine(d, eo);
    EngineStats st;
    const Image first = engine.render(vol, opt, nullptr, &st);
    std::vector<std::string> names;
    std::size_t bytes = 0;
    for (const Device::PooledBuffer& b : d.pooled_buffers()) {
      names.push_back(b.what);
      bytes += b.bytes;
    }
    const auto has = [&](const char* what) {
      return std::find(names.begin(), names.end(), what) != names.end();
    };
    EXPECT_EQ(st.pool_bytes, static_cast<int64_t>(bytes));
    EXPECT_TRUE(has("swap level buffer"));
    if (sampling == Sampling::pixel) {
      EXPECT_TRUE(has("segment order"));
      EXPECT_FALSE(has("row links"));
      // The level buffer asked for st.swap_level_bytes (one slot: the
      // other level goes into the footprints): row sums of r bytes could
      // serve it where swap_level_bytes <= r <= 2 swap_level_bytes + 64 KiB.
      ASSERT_EQ(st.swap_level_buffers, 1);
      const int64_t want = st.swap_level_bytes;
      for (const Device::PooledBuffer& b : d.pooled_buffers()) {
        if (b.what != "row sums") continue;
        const auto r = static_cast<int64_t>(b.bytes);
        EXPECT_FALSE(r >= want && r <= 2 * want + 65536)
            << "row sums of " << r << " bytes left in the pool beside a level buffer of " << want
            << " bytes that it could have served";
      }
      EXPECT_FALSE(has("intermediate image"));
    } else {
      EXPECT_TRUE(has("intermediate image"));
      EXPECT_FALSE(has("PE totals"));
      EXPECT_FALSE(has("segment counts"));
      EXPECT_FALSE(has("output image"));
    }
    EngineStats again;
    const Image second = engine.render(vol, opt, nullptr, &again);
    EXPECT_EQ(again.pool_bytes, st.pool_bytes);
    EXPECT_EQ(max_abs_diff(first, second), 0.0f);
  }
}

// EngineTimes::kernels: every kernel of the frame in launch order, each
// starting after the one before ended (the queue is in order); the stages'
// times are sums of some of them, so the kernels' sum is at least the
// fused shade + classify's and the resample + local's and at most the span;
// a frame rendered without `times` logs nothing for the next one.
TEST(EngineTimes, KernelsOfTheFrameInOrder) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(32, 1);
  EngineOptions eo = engine_options();
  eo.reuse_layout = true;
  RenderEngine engine(dev, eo);
  EngineTimes t;
  engine.render(vol, frame_options(), nullptr);  // not logged
  engine.render(vol, frame_options(), &t);
  ASSERT_GE(t.kernels.size(), 10u);
  std::vector<std::string> names;
  for (std::size_t i = 0; i < t.kernels.size(); ++i) {
    const KernelSpan& k = t.kernels[i];
    names.push_back(k.kernel);
    ASSERT_GT(k.end_ns, 0u) << k.kernel;
    EXPECT_LE(k.start_ns, k.end_ns) << k.kernel;
    if (i > 0) {
      EXPECT_GE(k.start_ns, t.kernels[i - 1].end_ns) << k.kernel;
    }
  }
  for (const char* want :
       {"simdvol_shade_classify16_il", "simdvol_match_rows", "simdvol_match_fill",
        "simdvol_resample_local_v8_ilc", "simdvol_display", "simdvol_warp"})
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  // The layout was kept from the first frame: not launched again.
  EXPECT_EQ(std::find(names.begin(), names.end(), "simdvol_layout"), names.end());
  EXPECT_EQ(names.back(), "simdvol_warp");
  EXPECT_GE(t.kernels_ms, t.classify_ms);
  EXPECT_GE(t.kernels_ms, t.swap_ms + t.display_ms + t.warp_ms);
  EXPECT_LE(t.kernels_ms, t.span_ms + 1e-9);
  EXPECT_LE(t.span_ms, t.device_wall_ms);
  EXPECT_GE(t.longest_wait_ms, 0.0);
}

// summarise_kernels on spans made up here: the sum of the durations, first
// start to last end, and the longest wait with the kernel after it; spans
// without profiling times (0, 0) count for nothing.
TEST(EngineTimes, SummaryOfKernelSpans) {
  EngineTimes t;
  t.kernels = {{"a", 1000000, 3000000},
               {"b", 3500000, 4000000},
               {"none", 0, 0},
               {"c", 7000000, 7250000},
               {"d", 7250000, 9000000}};
  summarise_kernels(t);
  EXPECT_DOUBLE_EQ(t.kernels_ms, 2.0 + 0.5 + 0.25 + 1.75);
  EXPECT_DOUBLE_EQ(t.span_ms, 8.0);
  EXPECT_DOUBLE_EQ(t.longest_wait_ms, 3.0);
  EXPECT_EQ(t.longest_wait_before, "c");
  t.kernels = {{"x", 5, 5}};
  summarise_kernels(t);
  EXPECT_DOUBLE_EQ(t.kernels_ms, 0.0);
  EXPECT_DOUBLE_EQ(t.span_ms, 0.0);
  EXPECT_EQ(t.longest_wait_before, "");
  t.kernels.clear();
  summarise_kernels(t);
  EXPECT_DOUBLE_EQ(t.span_ms, 0.0);
}
