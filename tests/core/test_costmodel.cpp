// The SIMD cost model (costmodel.hpp): the machine constants, Table 7.1 and
// Table 7.2 computed exactly (and the printed Table 7.2's two slips), and the
// frame prediction on a case whose busiest-PE counts are derived by hand.
#include <gtest/gtest.h>

#include <climits>

#include "simdvol/costmodel.hpp"
#include "simdvol/error.hpp"

using namespace simdvol;

TEST(CostModel, MachineConstants) {
  const MachineModel m = decmpp12000();
  EXPECT_EQ(m.pe_mul, 239);
  EXPECT_EQ(m.pe_add, 24);
  EXPECT_EQ(m.pe_add8, 6);
  EXPECT_EQ(m.pe_cmp, 24);
  EXPECT_EQ(m.pe_cmp8, 6);
  EXPECT_EQ(m.pe_mul8, 41);
  EXPECT_EQ(m.acu_mul, 37);
  EXPECT_EQ(m.router_32, 5000);
  EXPECT_EQ(m.grid.width, 128);
  EXPECT_EQ(m.grid.height, 64);
  EXPECT_DOUBLE_EQ(m.clock_hz, 12.5e6);
  // Eq 3.1: (N_opsize + 2) * Dist + 6.
  EXPECT_EQ(m.xnet_clocks(32, 1), 40);
  EXPECT_EQ(m.xnet_clocks(8, 3), 36);
  EXPECT_EQ(m.xnet_clocks(16, 64), 18 * 64 + 6);
  OpCounts o{1, 1, 1, 1, 1, 1, 1, 1};
  EXPECT_EQ(o.clocks(m), 239 + 24 + 24 + 24 + 239 + 6 + 6 + 37);
  EXPECT_EQ(o.clocks(m, true), 41 + 6 + 6 + 6 + 41 + 6 + 6 + 37);
}

TEST(CostModel, Table71) {
  const auto rows = table_7_1();
  ASSERT_EQ(rows.size(), 8u);
  // 256^3: direct, adaptive, 32 samples, per sample.
  EXPECT_EQ(rows[0].mul, 67108864);
  EXPECT_EQ(rows[0].add, 67108864);
  EXPECT_EQ(rows[0].mul_t, 0);
  EXPECT_EQ(rows[1].mul_t, 67108864);
  EXPECT_EQ(rows[1].add_t, 67108864);
  EXPECT_EQ(rows[1].mul, 0);
  EXPECT_EQ(rows[2].mul, 8192);         // 256 * 32
  EXPECT_EQ(rows[2].add, 8388608);      // 32 * 256^2 * 4
  EXPECT_EQ(rows[2].cmp_t, 536870912);  // 32 * 256^3
  EXPECT_EQ(rows[2].total_a_t(), 536870912);
  EXPECT_EQ(rows[3].mul, 256);
  EXPECT_EQ(rows[3].add, 262144);
  EXPECT_EQ(rows[3].cmp_t, 16777216);
  // 128^3.
  EXPECT_EQ(rows[4].mul, 8388608);
  EXPECT_EQ(rows[5].add_t, 8388608);
  EXPECT_EQ(rows[6].mul, 4096);
  EXPECT_EQ(rows[6].add, 2097152);
  EXPECT_EQ(rows[6].cmp_t, 67108864);
  EXPECT_EQ(rows[7].mul, 128);
  EXPECT_EQ(rows[7].add, 65536);
  EXPECT_EQ(rows[7].cmp_t, 2097152);
  // n samples scale linearly.
  EXPECT_EQ(complexity_monte_carlo(256, 64).cmp_t, 2 * rows[2].cmp_t);
}

TEST(CostModel, Table72ComputedAndSlips) {
  const auto rows = table_7_2();
  ASSERT_EQ(rows.size(), 3u);
  // Direct: 2048 multiplications at 239, 2048 additions at 24.
  EXPECT_EQ(rows[0].ops.mul, 2048);
  EXPECT_EQ(rows[0].ops.add, 2048);
  EXPECT_EQ(rows[0].mul_clocks, 489472);
  EXPECT_EQ(rows[0].add_clocks, 49152);
  EXPECT_EQ(rows[0].cmp_clocks, 0);
  EXPECT_EQ(rows[0].total, 538624);
  EXPECT_EQ(rows[0].total, rows[0].printed_total);
  // 32 samples: 256 ACU multiplications (37), 2048 additions, 16384 8-bit comparisons (6).
  EXPECT_EQ(rows[1].ops.acu_mul, 256);
  EXPECT_EQ(rows[1].ops.add, 2048);
  EXPECT_EQ(rows[1].ops.cmp8, 16384);
  EXPECT_EQ(rows[1].mul_clocks, 9472);
  EXPECT_EQ(rows[1].add_clocks, 49152);
  EXPECT_EQ(rows[1].cmp_clocks, 98304);
  EXPECT_EQ(rows[1].total, 156928);
  // 64 samples.
  EXPECT_EQ(rows[2].ops.acu_mul, 512);
  EXPECT_EQ(rows[2].ops.add, 4096);
  EXPECT_EQ(rows[2].ops.cmp8, 32768);
  EXPECT_EQ(rows[2].mul_clocks, 18944);
  EXPECT_EQ(rows[2].add_clocks, 98304);
  EXPECT_EQ(rows[2].cmp_clocks, 196608);
  EXPECT_EQ(rows[2].total, 313856);
  // The printed table differs in exactly the two slips and the totals that carry them.
  EXPECT_EQ(rows[1].printed_cmp_clocks, 98034);
  EXPECT_EQ(rows[2].printed_mul_clocks, 19944);
  EXPECT_EQ(rows[1].printed_total, 156658);
  EXPECT_EQ(rows[2].printed_total, 314856);
  int differences = 0;
  for (const auto& r : rows) {
    differences += (r.mul_clocks != r.printed_mul_clocks) + (r.add_clocks != r.printed_add_clocks) +
                   (r.cmp_clocks != r.printed_cmp_clocks);
    // Each printed total is the sum of its printed columns.
    EXPECT_EQ(r.printed_total, r.printed_mul_clocks + r.printed_add_clocks + r.printed_cmp_clocks);
  }
  EXPECT_EQ(differences, 2);
}

TEST(CostModel, PerVoxelAndPerSampleCounts) {
  EXPECT_EQ(shade_ops_per_voxel(), (OpCounts{28, 14, 4, 0, 4}));
  EXPECT_EQ(classify_ops_per_voxel(), (OpCounts{6, 7, 4, 0, 0}));
  EXPECT_EQ(resample_ops_per_sample_thesis(1), (OpCounts{23, 10, 0, 9, 0}));
  EXPECT_EQ(resample_ops_per_sample_thesis(0), (OpCounts{9, 3, 0, 1, 0}));
  EXPECT_THROW(resample_ops_per_sample_thesis(2), ArgumentError);
}

namespace {
const StagePrediction& stage(const FramePrediction& f, const std::string& name) {
  for (const auto& s : f.stages)
    if (s.name == name) return s;
  throw std::runtime_error("no stage " + name);
}
}  // namespace

// 32^3 volume on 8 PEs (a 2 x 2 x 2 split of 16^3 cells on a 4 x 2 mesh),
// axis view: every voxel is one sample and every PE resamples its own cell,
// 16 x 16 rays of 16 samples, so every count of the busiest PE is known.
TEST(CostModel, PredictionAxisViewByHand) {
  FrameConfig c;
  c.dims = {32, 32, 32};
  c.width = c.height = 32;
  c.pes = 8;
  c.order = 1;
  const MachineModel m = decmpp12000();
  const FramePrediction f = predict_frame(c, m);
  EXPECT_EQ(f.grid.width, 4);
  EXPECT_EQ(f.grid.height, 2);
  EXPECT_EQ(f.cell, (Dims3{16, 16, 16}));
  EXPECT_EQ(f.samples, 32768);
  EXPECT_EQ(f.max_load_matched, 4096);
  EXPECT_EQ(f.max_load_balanced, 4096);  // already even: balancing moves nothing
  EXPECT_EQ(f.max_segments, 256);
  EXPECT_EQ(f.max_segment_length, 16);

  const int64_t v = 16 * 16 * 16;
  EXPECT_EQ(stage(f, "shade").ops, (OpCounts{28 * v, 14 * v, 4 * v, 0, 4 * v}));
  EXPECT_EQ(stage(f, "shade").op_clocks, v * (28 * 239 + 14 * 24 + 4 * 24 + 4 * 239));
  EXPECT_EQ(stage(f, "classify").op_clocks, v * (6 * 239 + 7 * 24 + 4 * 24));
  EXPECT_EQ(stage(f, "resample").ops, (OpCounts{23 * v, 10 * v, 0, 9 * v, 0}));
  EXPECT_EQ(stage(f, "resample").op_clocks, v * (23 * 239 + 10 * 24 + 9 * 24));
  EXPECT_EQ(stage(f, "local composite").op_clocks, v * 4 * (239 + 24));
  // Halo of width 1 of the 18^3 padded block of PE (0, 0, 0): local
  // coordinates -1 .. 16, position l reads the clamped voxel, which belongs
  // to a neighbour exactly along the axes where l = 16 (l = -1 clamps to
  // the PE's own voxel 0). Positions with one such axis: 3 x 17^2 (the
  // 17 other values -1 .. 15 on each remaining axis); two: 3 x 17; three: 1.
  // Every PE is a mirror image of that one.
  EXPECT_EQ(stage(f, "halo (raw voxels)").xnet_words, 3 * 17 * 17 + 3 * 17 + 1);
  EXPECT_EQ(stage(f, "halo (RGBA)").xnet_words, 919);
  EXPECT_EQ(stage(f, "halo (RGBA)").xnet_bytes, 919 * 4);
  // Balancing: loads equal, nothing moves; only the load words of 6 rounds x 8 sweeps.
  EXPECT_EQ(stage(f, "balance").xnet_words, 6 * 8);
  // Swap stage 0 pairs the two PEs along z (split bit 0): identical 16 x 16
  // footprints, each keeps half (128 pixels) and receives them from its
  // partner, a mesh neighbour (distance 1).
  const StagePrediction& s0 = stage(f, "swap 0");
  EXPECT_EQ(s0.xnet_words, 128);
  EXPECT_EQ(s0.xnet_max_distance, 1);
  EXPECT_EQ(s0.xnet_clocks, 128 * (34 + 6));
  EXPECT_EQ(s0.ops, (OpCounts{4 * 128, 4 * 128}));
  // Display: the intermediate image's pixels spread over 8 PEs, one router operand each.
  const int64_t px = int64_t(f.image_width) * f.image_height;
  EXPECT_EQ(stage(f, "display").router_words, (px + 7) / 8);
  EXPECT_EQ(stage(f, "display").router_clocks, (px + 7) / 8 * 5000);
  int64_t sum = 0;
  for (const auto& s : f.stages) sum += s.clocks();
  EXPECT_EQ(f.total_clocks(), sum);
  EXPECT_EQ(f.view_clocks(), sum - stage(f, "shade").clocks() - stage(f, "classify").clocks() -
                                 stage(f, "halo (raw voxels)").clocks());

  // Monte Carlo, 32 samples per sub-ray: 256 sub-rays x 32 additions,
  // 4096 x 32 8-bit comparisons, 16 x 32 ACU random numbers (Table 7.2's
  // formulas on a 16 x 16 x 16 block).
  c.mc_samples = 32;
  const FramePrediction g = predict_frame(c, m);
  EXPECT_EQ(stage(g, "local composite").ops,
            (OpCounts{0, 256 * 32, 0, 0, 0, 0, 4096 * 32, 16 * 32}));
  EXPECT_EQ(stage(g, "local composite").op_clocks, 256 * 32 * 24 + 4096 * 32 * 6 + 16 * 32 * 37);

  // 8-bit arithmetic: resampling at 41 / 6 clocks.
  c.mc_samples = 0;
  c.narrow = true;
  const FramePrediction h = predict_frame(c, m);
  EXPECT_EQ(stage(h, "resample").op_clocks, v * (23 * 41 + 10 * 6 + 9 * 6));
}

// A rotated view: the busiest PE can only have more samples than the mean,
// and balancing never makes it worse.
TEST(CostModel, PredictionRotatedView) {
  FrameConfig c;
  c.dims = {32, 32, 32};
  c.width = c.height = 32;
  c.pes = 64;
  c.view = ViewAngles{0, 30, 0};
  const FramePrediction f = predict_frame(c, decmpp12000());
  EXPECT_GE(f.max_load_matched * 64, f.samples);
  EXPECT_LE(f.max_load_balanced, f.max_load_matched);
  EXPECT_EQ(stage(f, "resample").ops.mul, 23 * f.max_load_balanced);
  EXPECT_EQ(static_cast<int>(f.stages.size()), 8 + 6 + 1);  // 8 stages, 6 swap stages, display
}

TEST(CostModel, BadConfig) {
  FrameConfig c;
  c.dims = {16, 16, 16};
  c.width = c.height = 16;
  c.pes = 6;
  EXPECT_THROW(predict_frame(c), ArgumentError);
  c.pes = 8;
  c.order = 3;
  EXPECT_THROW(predict_frame(c), ArgumentError);
  c.order = 1;
  c.sweeps = -1;
  EXPECT_THROW(predict_frame(c), ArgumentError);
  c.sweeps = INT_MAX;  // (ran on for hours)
  EXPECT_THROW(predict_frame(c), ArgumentError);
  EXPECT_THROW(local_composite_ops(-1, 8, 0), ArgumentError);
}
