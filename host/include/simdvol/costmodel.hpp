// A cost model of the SIMD machine of the thesis (DESIGN.md "A cost model of
// the SIMD machine"): the DECmpp 12000 (= MasPar MP-1) with 8,192 PEs as a
// 128 x 64 mesh. Three things are computed from its constants:
//
//  * Table 7.1 (complexity of direct / adaptive / Monte Carlo compositing of
//    an N^3 volume, symbolic in t and n) as integer coefficients;
//  * Table 7.2 (local compositing of an 8 x 8 x 8 sub-block: direct, 32 and
//    64 Monte Carlo samples) in operation counts and clocks, beside the
//    printed figures (which carry two arithmetic slips);
//  * a frame prediction: the per-PE work of every stage of a real render's
//    geometry (k-d split, matching, balancing, binary swap: the core
//    functions of pe_array.hpp, match.hpp, swap.hpp), the busiest PE's
//    operations and X-Net transfers per stage (lockstep SIMD: a step costs as
//    much as its busiest PE), converted to clocks and seconds.
//
// Everything here is pure integer arithmetic on counts except the final
// conversion to seconds. No OpenCL. Every modelling assumption is named in
// the comments of costmodel.cpp and in FramePrediction::assumptions.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "simdvol/pe_array.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// Constants of the DECmpp 12000 / MasPar MP-1 (timing clocks). Each field
/// cites its place in the thesis (/work/shared/thesis.txt); fields that the
/// thesis does not give are marked "assumed".
struct MachineModel {
  /// PE integer (32-bit) multiplication: ch. 7.3 ("a comparison needs 24
  /// timing clocks while a multiplication needs 239") and ch. 7.4.
  int64_t pe_mul = 239;
  /// PE integer addition: ch. 7.4 ("only 24 time clocks for integer and 6
  /// clocks for character").
  int64_t pe_add = 24;
  /// PE 8-bit (character) addition: ch. 3.3 and ch. 7.4.
  int64_t pe_add8 = 6;
  /// PE integer comparison: ch. 7.3 (24 clocks).
  int64_t pe_cmp = 24;
  /// PE 8-bit comparison: ch. 7.4 ("6 clocks for character"; Table 7.2
  /// charges its comparisons at 6).
  int64_t pe_cmp8 = 6;
  /// PE 8-bit multiplication: ch. 3.3 ("addition and multiplication in PEs
  /// of character operands is 6 and 41 timing clocks").
  int64_t pe_mul8 = 41;
  /// ACU (array control unit) integer multiplication: ch. 7.4 (37 clocks).
  int64_t acu_mul = 37;
  /// Rounding / floor of a fixed-point value: assumed one addition-class
  /// operation (the thesis counts roundings, R, but gives no time).
  int64_t pe_round = 24;
  /// Division or square root: assumed as one integer multiplication (239);
  /// the thesis gives no time (a lower bound for a software divide).
  int64_t pe_div = 239;
  /// X-Net transfer of an N_opsize-bit operand over Dist PEs: (N + 2) Dist
  /// + 6 clocks, eq 3.1 (ch. 3.4).
  int64_t xnet_bit_extra = 2;
  int64_t xnet_startup = 6;
  /// Global router: "a random communication pattern with all PEs
  /// participating take an average of 5000 timing clocks for a 32 bit
  /// operand" (ch. 3.4).
  int64_t router_32 = 5000;
  /// Clock rate: not given in the thesis. Assumed 12.5 MHz (80 ns), the
  /// MasPar MP-1's clock as we recall it from Blank, "The MasPar MP-1
  /// architecture", IEEE COMPCON 1990 (not checked against the paper here).
  /// Consistent with the vendor's peak for 16,384 PEs of 26,000 MIPS and
  /// 1.3 GFLOPS (DECmpp 12000 announcement): 12.5 MHz / 6 clocks per 8-bit
  /// addition x 16,384 PEs = 34,000 MIPS.
  double clock_hz = 12.5e6;
  /// 8,192 PEs (ch. 3.3: "an array of 8,192 Processor Element(PE)s"), as
  /// the MP-1's 128 x 64 mesh.
  PeGrid grid{128, 64};

  /// Eq 3.1 for one operand of `bits` bits over `distance` PEs.
  int64_t xnet_clocks(int64_t bits, int64_t distance) const {
    return (bits + xnet_bit_extra) * distance + xnet_startup;
  }
};

/// The DECmpp 12000 as above.
MachineModel decmpp12000();

/// Operations of one PE (or of the ACU, acu_mul). Integer counts.
struct OpCounts {
  int64_t mul = 0;      ///< PE multiplications (32-bit integer unless `narrow`)
  int64_t add = 0;      ///< PE additions / subtractions
  int64_t cmp = 0;      ///< PE comparisons (min, max, abs, tests)
  int64_t rnd = 0;      ///< PE roundings / floors
  int64_t div = 0;      ///< PE divisions and square roots
  int64_t add8 = 0;     ///< PE 8-bit additions
  int64_t cmp8 = 0;     ///< PE 8-bit comparisons
  int64_t acu_mul = 0;  ///< ACU multiplications (shared by all PEs)

  OpCounts& operator+=(const OpCounts& o);
  OpCounts operator*(int64_t k) const;
  bool operator==(const OpCounts&) const = default;
  /// Clocks on `m`. With narrow = true, mul, add, cmp, rnd and div are taken
  /// as 8-bit (character) operations: mul at pe_mul8, the others at pe_add8
  /// (div at pe_mul8: assumed).
  int64_t clocks(const MachineModel& m, bool narrow = false) const;
};

// ------------------------------------------------------------- Table 7.1

/// One row of Table 7.1 for an N^3 volume: the counts as coefficients of 1
/// and of t (the fraction of a ray traced before adaptive termination, ch.
/// 7.3). Multiplications, additions and comparisons.
struct ComplexityRow {
  std::string method;  ///< "Direct", "Adap. Term.", "32 Samples", "N Samples"
  int64_t size = 0;    ///< N
  int64_t samples =
      0;  ///< n (0 for direct / adaptive; for "N Samples" the per-sample coefficient, n = 1)
  int64_t mul = 0, mul_t = 0;
  int64_t add = 0, add_t = 0;
  int64_t cmp = 0, cmp_t = 0;
  /// Total as the thesis writes it: M coefficient, A coefficient (additions
  /// and comparisons counted with one timing value A), each split into the
  /// part without t and the part with t.
  int64_t total_m() const { return mul; }
  int64_t total_m_t() const { return mul_t; }
  int64_t total_a() const { return add + cmp; }
  int64_t total_a_t() const { return add_t + cmp_t; }
  std::string printed_total;  ///< the "Total" column as printed
  std::string remark;         ///< how the printed total relates to the computed one
};

/// Direct compositing: N^3 * 4 multiplications and additions (Table 7.1).
ComplexityRow complexity_direct(int64_t n);
/// Adaptive termination: N^3 * 4 * t multiplications and additions (the
/// table's comparison column is 0; the text of ch. 7.3 adds N^3 t
/// comparisons, not counted here, as in the table).
ComplexityRow complexity_adaptive(int64_t n);
/// Monte Carlo with `samples` samples per ray: N * n multiplications
/// (random numbers), n * N^2 * 4 additions, n * N^3 * t comparisons.
ComplexityRow complexity_monte_carlo(int64_t n, int64_t samples);
/// The 8 rows of Table 7.1 (256^3 and 128^3; direct, adaptive, 32 samples,
/// n samples with n = 1), with the printed totals and remarks.
std::vector<ComplexityRow> table_7_1();

// ------------------------------------------------------------- Table 7.2

/// Local compositing of `rays` sub-rays of `length` samples on one PE
/// (ch. 7.4): direct (samples == 0): rays * length * 4 PE multiplications
/// and additions; Monte Carlo with `samples` samples per sub-ray: length *
/// samples random numbers on the ACU (multiplications), rays * samples PE
/// additions, rays * length * samples 8-bit comparisons (at most).
OpCounts local_composite_ops(int64_t rays, int64_t length, int64_t samples);

struct CompositeCostRow {
  std::string method;
  OpCounts ops;
  int64_t mul_clocks = 0, add_clocks = 0, cmp_clocks = 0, total = 0;  ///< computed
  int64_t printed_mul_clocks = 0, printed_add_clocks = 0, printed_cmp_clocks = 0,
          printed_total = 0;  ///< as printed in the thesis
};
/// Table 7.2: 8 x 8 x 8 sub-block, direct / 32 / 64 samples: multiplications
/// at 239 (PE, direct) or 37 (ACU, Monte Carlo), additions at 24,
/// comparisons at 6 (8-bit).
std::vector<CompositeCostRow> table_7_2(const MachineModel& m = decmpp12000());

// ------------------------------------------------------- frame prediction

/// Per-voxel operation counts of the shade stage as written in
/// host/core/shade.cpp (central differences, |g|, depth cue, two-sided
/// Phong with n = 24 by repeated squaring); SIMD runs every branch.
OpCounts shade_ops_per_voxel();
/// Per-voxel operations of classification modelled for the MP-1: a
/// lookup table by intensity (4 loads, counted as additions), lighting
/// min(1, c * Id + Is) per channel and the premultiplication by alpha.
OpCounts classify_ops_per_voxel();
/// Resampling per sample (ch. 5.7.2): order 0 (nearest) 9M + 3A + 1R,
/// order 1 (trilinear) 23M + 10A + 9R. ArgumentError for other orders.
OpCounts resample_ops_per_sample_thesis(int order);
/// Per candidate ray of the matching (our model of box_ray_range: the ray's
/// entry and exit per axis with precomputed reciprocals, max of entries,
/// min of exits, clip, 2 roundings): 12M + 12A + 6C + 2R.
OpCounts match_ops_per_ray();
/// Per PE of the matching: the 8 vertices of its cell mapped (ch. 5.7.2,
/// 9M + 6A each).
OpCounts match_ops_per_pe();

struct FrameConfig {
  Dims3 dims{256, 256, 256};
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  ViewAngles view{};
  int width = 256, height = 256;
  Sampling sampling = Sampling::voxel;
  Framing framing = Framing::longest;
  int order = 1;        ///< 0 or 1 (the orders ch. 5.7.2 counts)
  int64_t pes = 8192;   ///< power of two; the mesh is pe_grid(pes)
  int sweeps = 8;       ///< balancing sweeps (0: no balancing)
  int mc_samples = 0;   ///< 0: direct compositing; n: Monte Carlo, n per sub-ray
  int voxel_bits = 16;  ///< bits of a raw voxel (halo of the shade stage)
  int rgba_bits = 32;   ///< bits of a classified voxel / pixel (8 per channel)
  bool narrow = false;  ///< arithmetic on 8-bit operands (ch. 3.3's 6 / 41 clocks)
  SwapLayout layout = SwapLayout::cut_and_stack;
};

struct StagePrediction {
  std::string name;
  OpCounts ops;            ///< the busiest PE's operations (plus the ACU's)
  int64_t xnet_words = 0;  ///< operands the busiest PE receives over X-Net
  int64_t xnet_bytes = 0;
  int64_t xnet_max_distance = 0;
  int64_t router_words = 0;  ///< operands through the global router
  int64_t op_clocks = 0, xnet_clocks = 0, router_clocks = 0;
  int64_t clocks() const { return op_clocks + xnet_clocks + router_clocks; }
  std::string note;
};

struct FramePrediction {
  FrameConfig config;
  PeGrid grid;
  Dims3 cell{0, 0, 0};
  int image_width = 0, image_height = 0, depth = 0;  ///< intermediate (viewing) grid
  int64_t samples = 0;                               ///< samples inside the volume, all PEs
  int64_t max_load_matched = 0;                      ///< busiest PE's samples after matching
  int64_t max_load_balanced = 0;                     ///< after balancing (what resampling costs)
  int64_t max_segments = 0;                          ///< most sub-rays of one PE
  int64_t max_segment_length = 0;                    ///< longest sub-ray
  std::vector<StagePrediction> stages;
  std::vector<std::string> assumptions;

  int64_t total_clocks() const;
  /// Clocks without the shade and classify stages (and their halo): the
  /// frame when only the view changes and shading is view-independent.
  int64_t view_clocks() const;
  double seconds(int64_t clocks) const { return double(clocks) / machine.clock_hz; }
  MachineModel machine;
};

/// The frame prediction for `config` on `machine` (machine.grid is
/// replaced by pe_grid(config.pes)). ArgumentError for a bad config.
FramePrediction predict_frame(const FrameConfig& config,
                              const MachineModel& machine = decmpp12000());

}  // namespace simdvol
