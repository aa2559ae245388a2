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
