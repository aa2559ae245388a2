// The cost model of the SIMD machine (costmodel.hpp). Every modelling choice
// is stated where it is made and collected in FramePrediction::assumptions.
#include "simdvol/costmodel.hpp"

#include <algorithm>
#include <cstdlib>
#include <map>
#include <string>
#include <utility>

#include "simdvol/error.hpp"
#include "simdvol/match.hpp"

namespace simdvol {

MachineModel decmpp12000() {
  return MachineModel{};
}

OpCounts& OpCounts::operator+=(const OpCounts& o) {
  mul += o.mul;
  add += o.add;
  cmp += o.cmp;
  rnd += o.rnd;
  div += o.div;
  add8 += o.add8;
  cmp8 += o.cmp8;
  acu_mul += o.acu_mul;
  return *this;
}

OpCounts OpCounts::operator*(int64_t k) const {
  return OpCounts{mul * k, add * k, cmp * k, rnd * k, div * k, add8 * k, cmp8 * k, acu_mul * k};
}

int64_t OpCounts::clocks(const MachineModel& m, bool narrow) const {
  const int64_t cm = narrow ? m.pe_mul8 : m.pe_mul;
  const int64_t ca = narrow ? m.pe_add8 : m.pe_add;
  const int64_t cc = narrow ? m.pe_cmp8 : m.pe_cmp;
  const int64_t cr = narrow ? m.pe_add8 : m.pe_round;
  const int64_t cd = narrow ? m.pe_mul8 : m.pe_div;
  return mul * cm + add * ca + cmp * cc + rnd * cr + div * cd + add8 * m.pe_add8 +
         cmp8 * m.pe_cmp8 + acu_mul * m.acu_mul;
}

// ------------------------------------------------------------- Table 7.1

ComplexityRow complexity_direct(int64_t n) {
  ComplexityRow r;
  r.method = "Direct";
  r.size = n;
  r.mul = n * n * n * 4;
  r.add = n * n * n * 4;
  return r;
}

ComplexityRow complexity_adaptive(int64_t n) {
  ComplexityRow r;
  r.method = "Adap. Term.";
  r.size = n;
  r.mul_t = n * n * n * 4;
  r.add_t = n * n * n * 4;
  return r;
}

ComplexityRow complexity_monte_carlo(int64_t n, int64_t samples) {
  ComplexityRow r;
  r.method = std::to_string(samples) + " Samples";
  r.size = n;
  r.samples = samples;
  r.mul = n * samples;            // random numbers, one per sample position
  r.add = samples * n * n * 4;    // averaging the 4 components per ray
  r.cmp_t = samples * n * n * n;  // comparisons, stopping after a fraction t
  return r;
}

std::vector<ComplexityRow> table_7_1() {
  std::vector<ComplexityRow> rows;
  {
    auto r = complexity_direct(256);
    r.printed_total = "6.68e7M + 6.68e7A";
    r.remark = "256^3*4 = 67,108,864 = 6.71e7: printed 6.68e7 is low by 0.4% (a slip)";
    rows.push_back(r);
    r = complexity_adaptive(256);
    r.printed_total = "(6.68e7M + 6.68e7A)t";
    r.remark = "same coefficient as Direct: 6.71e7, printed 6.68e7";
    rows.push_back(r);
    r = complexity_monte_carlo(256, 32);
    r.printed_total = "8.2e3M + 6.24e8A*t";
    r.remark =
        "M agrees (8,192); the columns give 8.39e6 A + 5.37e8 A*t: printed 6.24e8 A*t follows from "
        "neither";
    rows.push_back(r);
    r = complexity_monte_carlo(256, 1);
    r.method = "N Samples";
    r.printed_total = "N(256M + 2.6e5A*t)";
    r.remark =
        "per sample 256 M + 262,144 A + 16,777,216 A*t: printed keeps the additions (2.6e5) as the "
        "t-term and drops the comparisons (1.68e7)";
    rows.push_back(r);
  }
  {
    auto r = complexity_direct(128);
    r.printed_total = "8.3e6M + 8.3e6A";
    r.remark = "128^3*4 = 8,388,608 = 8.39e6 (printed truncated to 8.3e6)";
    rows.push_back(r);
    r = complexity_adaptive(128);
    r.printed_total = "(8.3e6M + 8.3e6A)t";
    r.remark = "as Direct";
    rows.push_back(r);
    r = complexity_monte_carlo(128, 32);
    r.printed_total = "4.1e3M + 6.7e7A*t";
    r.remark =
        "agrees with the comparisons (32*128^3 = 6.71e7); the 2.10e6 additions (3%) are dropped";
    rows.push_back(r);
    r = complexity_monte_carlo(128, 1);
    r.method = "N Samples";
    r.printed_total = "N(128M + 2.1e6A*t)";
    r.remark =
        "agrees with the comparisons (128^3 = 2.10e6); the 65,536 additions (3%) are dropped";
    rows.push_back(r);
  }
  return rows;
}

// ------------------------------------------------------------- Table 7.2

OpCounts local_composite_ops(int64_t rays, int64_t length, int64_t samples) {
  if (rays < 0 || length < 0 || samples < 0)
    throw ArgumentError("local_composite_ops", "rays, length and samples must be >= 0");
  OpCounts o;
  if (samples == 0) {
    // Direct (ch. 7.4): "one multiplication on every sample of the ray in
    // each component" (R, G, B, alpha), and as many additions (Table 7.2).
    o.mul = rays * length * 4;
    o.add = rays * length * 4;
  } else {
    // Monte Carlo (ch. 7.4): "at most 8x32 random numbers" = length *
    // samples, generated on the ACU; "the number of addition is 8x8x32" =
    // rays * samples; "the maximum number of comparison is 8x8x8x32" = rays
    // * length * samples, on 8-bit opacities (Table 7.2 charges 6 clocks).
    o.acu_mul = length * samples;
    o.add = rays * samples;
    o.cmp8 = rays * length * samples;
  }
  return o;
}

std::vector<CompositeCostRow> table_7_2(const MachineModel& m) {
  struct Printed {
    const char* name;
    int64_t samples, mul, add, cmp, total;
  };
  // Table 7.2 as printed (thesis.txt, after ch. 7.4): clocks per column.
  const Printed printed[] = {{"Direct computation", 0, 489472, 49152, 0, 538624},
                             {"32 Sample", 32, 9472, 49152, 98034, 156658},
                             {"64 Sample", 64, 19944, 98304, 196608, 314856}};
  std::vector<CompositeCostRow> rows;
  for (const auto& p : printed) {
    CompositeCostRow r;
    r.method = p.name;
    r.ops = local_composite_ops(8 * 8, 8, p.samples);
    r.mul_clocks = r.ops.mul * m.pe_mul + r.ops.acu_mul * m.acu_mul;
    r.add_clocks = r.ops.add * m.pe_add;
    r.cmp_clocks = r.ops.cmp * m.pe_cmp + r.ops.cmp8 * m.pe_cmp8;
    r.total = r.mul_clocks + r.add_clocks + r.cmp_clocks;
    r.printed_mul_clocks = p.mul;
    r.printed_add_clocks = p.add;
    r.printed_cmp_clocks = p.cmp;
    r.printed_total = p.total;
    rows.push_back(r);
  }
  return rows;
}

// ------------------------------------------------------- frame prediction

OpCounts shade_ops_per_voxel() {
  // host/core/shade.cpp, line by line (SIMD: every PE runs every branch).
  OpCounts o;
  o.add += 3;  // gradient: f(i+1) - f(i-1) per axis
  o.mul += 6;  //   0.5 * diff * grad_scale per axis
  o.mul += 3;  // g.g
  o.add += 2;
  o.cmp += 1;  // isfinite(g.g)
  o.div += 1;  // |g| = sqrt(g.g)
  o.mul += 3;  // depth d = depth_dir . x + offset
  o.add += 3;
  o.mul += 1;  // cue = 1 / (k1 + k2 d)
  o.add += 1;
  o.div += 1;
  o.cmp += 1;  // g.g < surface_g2
  o.mul += 3;  // |N.L| = |g . L| / |g|
  o.add += 2;
  o.cmp += 1;
  o.div += 1;
  o.mul += 3;  // |N.H| = |g . H| / |g|
  o.add += 2;
  o.cmp += 1;
  o.div += 1;
  o.mul += 2;  // Id = ka + cue * kd * |N.L|
  o.add += 1;
  o.mul += 2;  // Is = cue * ks * |N.H|^n
  o.mul += 5;  //   |N.H|^24 by squaring: x^2, x^4, x^8, x^16, x^16 * x^8
  return o;    // 28M + 14A + 4C + 4 div/sqrt
}

OpCounts classify_ops_per_voxel() {
  // Modelled for the MP-1 (our classify.cpp evaluates the mixture in
  // float; on 8/16-bit voxels a table by intensity does the same): 4 table
  // loads (alpha, r, g, b: counted as additions), per channel min(1, c * Id
  // + Is) and the premultiplication a * C, and the test a > 0.
  OpCounts o;
  o.add += 4;  // table loads
  o.mul += 3;  // c * Id
  o.add += 3;  // + Is
  o.cmp += 3;  // min(1, .)
  o.mul += 3;  // a * C
  o.cmp += 1;  // a > 0
  return o;    // 6M + 7A + 4C
}

OpCounts resample_ops_per_sample_thesis(int order) {
  OpCounts o;
  if (order == 0) {  // ch. 5.7.2: "9M + 3A + R per sample" (nearest)
    o.mul = 9;
    o.add = 3;
    o.rnd = 1;
  } else if (order == 1) {  // ch. 5.7.2: "23M + 9R + 10A" (trilinear)
    o.mul = 23;
    o.add = 10;
    o.rnd = 9;
  } else {
    throw ArgumentError("order",
                        "the cost model has the operation counts of ch. 5.7.2 for orders "
                        "0 and 1 only (got " +
                            std::to_string(order) + ")");
  }
  return o;
}

OpCounts match_ops_per_ray() {
  // Our model of box_ray_range (match.hpp) per candidate ray: per axis the
  // ray's coordinate at k = 0 (2M + 2A), entry and exit depth against the
  // cell's two planes with a precomputed reciprocal of the step (2A + 2M);
  // max of 3 entries and min of 3 exits, clip to [0, depth) (6C); 2
  // roundings.
  OpCounts o;
  o.mul = 3 * 4;
  o.add = 3 * 4;
  o.cmp = 6;
  o.rnd = 2;
  return o;
}

OpCounts match_ops_per_pe() {
  // ch. 5.7.2: "only 8 forward transformations of the vertices", each "9
  // multiplications and 6 additions".
  OpCounts o;
  o.mul = 8 * 9;
  o.add = 8 * 6;
  return o;
}

int64_t FramePrediction::total_clocks() const {
  int64_t t = 0;
  for (const auto& s : stages) t += s.clocks();
  return t;
}

int64_t FramePrediction::view_clocks() const {
  int64_t t = 0;
  for (const auto& s : stages)
    if (s.name != "shade" && s.name != "classify" && s.name != "halo (raw voxels)") t += s.clocks();
  return t;
}

namespace {

// Mesh offset (dx, dy) of a transfer from `from` to `to`.
std::pair<int64_t, int64_t> mesh_offset(const PeGrid& g, int64_t from, int64_t to) {
  const MeshCoord a = mesh_coord(g, from), b = mesh_coord(g, to);
  return {b.x - a.x, b.y - a.y};
}

// The X-Net cost of a halo exchange: every PE receives, from each PE whose
// voxels fill its halo, `voxels` operands. In lockstep SIMD all PEs move
// along the same mesh offset at once, so the exchange is one step per
// offset (dx, dy), costing the most operands any PE receives along it, each
// at eq 3.1 with Dist = max(|dx|, |dy|) (8-way X-Net).
struct HaloGeometry {
  std::map<std::pair<int64_t, int64_t>, int64_t> max_per_offset;  // operands
  int64_t max_pe_voxels = 0;
  int64_t max_distance = 0;
};

HaloGeometry halo_geometry(const CellLayout& layout, const PeGrid& grid) {
  HaloGeometry h;
  for (int64_t p = 0; p < layout.pes(); ++p) {
    int64_t total = 0;
    for (const HaloTransfer& t : halo_transfers(layout, grid, p, 1)) {
      auto& m = h.max_per_offset[mesh_offset(grid, t.from_pe, p)];
      m = std::max(m, t.voxels);
      total += t.voxels;
      h.max_distance = std::max(h.max_distance, t.distance);
    }
    h.max_pe_voxels = std::max(h.max_pe_voxels, total);
  }
  return h;
}

StagePrediction halo_stage(const std::string& name, const HaloGeometry& h, int bits,
                           const MachineModel& m) {
  StagePrediction s;
  s.name = name;
  s.xnet_words = h.max_pe_voxels;
  s.xnet_bytes = h.max_pe_voxels * bits / 8;
  s.xnet_max_distance = h.max_distance;
  for (const auto& [off, n] : h.max_per_offset)
    s.xnet_clocks += n * m.xnet_clocks(bits, std::max(std::abs(off.first), std::abs(off.second)));
  s.note = std::to_string(h.max_per_offset.size()) + " mesh offsets, " + std::to_string(bits) +
           "-bit operands";
  return s;
}

}  // namespace

FramePrediction predict_frame(const FrameConfig& c, const MachineModel& machine) {
  if (c.order != 0 && c.order != 1) resample_ops_per_sample_thesis(c.order);  // throws
  if (c.sweeps < 0 || c.sweeps > kMaxBalanceSweeps)  // (INT_MAX ran on for hours)
    throw ArgumentError("sweeps", std::to_string(c.sweeps) + " is outside 0 .. " +
                                      std::to_string(kMaxBalanceSweeps));
  if (c.mc_samples < 0) throw ArgumentError("mc_samples", "must be >= 0 (0: direct)");
  if (c.voxel_bits < 1 || c.voxel_bits > 64 || c.rgba_bits < 1 || c.rgba_bits > 128)
    throw ArgumentError("voxel_bits/rgba_bits", "out of range");
  FramePrediction f;
  f.config = c;
  f.machine = machine;
  f.grid = pe_grid(c.pes, "pes");
  f.machine.grid = f.grid;
  const MachineModel& m = f.machine;
  const bool nar = c.narrow;

  const ViewGeometry view =
      make_view(c.dims, c.spacing, c.view, c.width, c.height, c.sampling, c.framing);
  const KdSplit split = kd_split(c.dims, c.pes);
  f.cell = split.cell;
  f.image_width = view.width();
  f.image_height = view.height();
  f.depth = view.depth();
  const int64_t cell_voxels = split.cell[0] * split.cell[1] * split.cell[2];

  f.assumptions = {
      "clock 12.5 MHz (80 ns), the MasPar MP-1's; not given in the thesis",
      std::string("arithmetic on ") +
          (nar ? "8-bit operands: multiplication 41, addition/comparison/rounding 6 clocks (ch. "
                 "3.3); division/sqrt at 41 (assumed)"
               : "32-bit integers: multiplication 239, addition/comparison 24 clocks (ch. 7.3, "
                 "7.4); rounding 24, division/sqrt 239 (assumed)"),
      "lockstep SIMD: a stage costs what its busiest PE costs; every PE runs its whole padded "
      "cell and every branch",
      "X-Net: eq 3.1 per operand, one lockstep step per mesh offset, Dist = max(|dx|, |dy|)",
      "shade: the operations of host/core/shade.cpp per voxel; classify: a table by intensity "
      "+ lighting + premultiplication",
      "halos of width 1: raw voxels (" + std::to_string(c.voxel_bits) +
          " bits) for the gradients, classified RGBA (" + std::to_string(c.rgba_bits) +
          " bits) for resampling; voxels needed after balancing moved samples are not counted",
      "matching: 8 vertex transforms per PE + 12M + 12A + 6C + 2R per candidate ray",
      "balancing: per round one load word to the face neighbour (1A + 1C); each boundary that "
      "moved sent once (one word at the farthest face neighbour's distance, 2M + 3A + 1R): a "
      "lower bound",
      "resampling: ch. 5.7.2's counts per sample (order 0: 9M + 3A + R; order 1: 23M + 10A + 9R)",
      c.mc_samples == 0 ? std::string("local compositing direct: 4M + 4A per sample (Table 7.2)")
                        : "local compositing Monte Carlo, " + std::to_string(c.mc_samples) +
                              " samples per sub-ray: at most every comparison made (t = 1), "
                              "random numbers on the ACU (ch. 7.4)",
      "binary swap: per stage the busiest PE's received pixels (" + std::to_string(c.rgba_bits) +
          " bits each) at the partner's distance; over on every kept pixel at 4M + 4A",
      "display: the intermediate image's pixels per PE through the router at 5,000 clocks "
      "per 32-bit operand (the thesis gives no display cost); the 2-D warp to the output "
      "size is not counted",
  };

  // Shade and classify: every voxel of the (padded) cell.
  {
    StagePrediction s;
    s.name = "shade";
    s.ops = shade_ops_per_voxel() * cell_voxels;
    s.op_clocks = s.ops.clocks(m, nar);
    s.note = std::to_string(cell_voxels) + " voxels x (28M + 14A + 4C + 4 div/sqrt)";
    f.stages.push_back(s);
  }
  const CellLayout halo_layout = make_cell_layout(c.dims, c.pes, 1);
  const HaloGeometry halo = halo_geometry(halo_layout, f.grid);
  f.stages.push_back(halo_stage("halo (raw voxels)", halo, c.voxel_bits, m));
  {
    StagePrediction s;
    s.name = "classify";
    s.ops = classify_ops_per_voxel() * cell_voxels;
    s.op_clocks = s.ops.clocks(m, nar);
    s.note = std::to_string(cell_voxels) + " voxels x (6M + 7A + 4C)";
    f.stages.push_back(s);
  }
  f.stages.push_back(halo_stage("halo (RGBA)", halo, c.rgba_bits, m));

  // Matching.
  const std::vector<sv_rect> cand = match_candidates(view, split);
  {
    int64_t max_rays = 0;
    for (const sv_rect& r : cand) max_rays = std::max<int64_t>(max_rays, int64_t(r.w) * r.h);
    StagePrediction s;
    s.name = "match";
    s.ops = match_ops_per_pe();
    s.ops += match_ops_per_ray() * max_rays;
    s.op_clocks = s.ops.clocks(m, nar);
    s.note = std::to_string(max_rays) + " candidate rays on the busiest PE";
    f.stages.push_back(s);
  }
  const Matching matched = match_reference(view, split);
  f.max_load_matched = matched.max_load();
  f.samples = matched.total_load();

  // Balancing. Per round (axis, parity) every PE exchanges its load with
  // its face neighbour (one 32-bit word at their mesh distance, 1A + 1C).
  // Then the boundaries that moved are sent: counted as a lower bound, each
  // segment whose [k0, k1) changed between matching and balancing costs
  // one 32-bit word, once, at the largest distance to the PE's face
  // neighbours, and 2M + 3A + 1R (its share of the transfer).
  const Matching bal = c.sweeps > 0 ? balance_reference(matched, view, split, c.sweeps) : matched;
  {
    StagePrediction s;
    s.name = "balance";
    const Dims3 splits = split.splits();
    std::vector<int64_t> far(static_cast<std::size_t>(c.pes),
                             0);  // per PE: farthest face neighbour
    int rounds = 0;
    for (int axis = 0; axis < 3; ++axis)
      for (int par = 0; par < 2; ++par) {
        if (splits[axis] < 2) continue;
        ++rounds;
        int64_t round_dist = 0;
        for (int64_t p = 0; p < c.pes; ++p) {
          Dims3 ci = split.cell_index(p);
          const int64_t i = ci[axis];
          const int64_t j = ((i - par) % 2 == 0) ? i + 1 : i - 1;
          if (j < 0 || j >= splits[axis]) continue;
          ci[axis] = j;
          const int64_t dist = mesh_distance(f.grid, p, split.pe_of_cell(ci));
          round_dist = std::max(round_dist, dist);
          far[static_cast<std::size_t>(p)] = std::max(far[static_cast<std::size_t>(p)], dist);
        }
        s.xnet_clocks += m.xnet_clocks(32, round_dist) * c.sweeps;
        s.xnet_words += c.sweeps;
        s.xnet_max_distance = std::max(s.xnet_max_distance, round_dist);
      }
    s.ops.add = int64_t(rounds) * c.sweeps;
    s.ops.cmp = int64_t(rounds) * c.sweeps;
    int64_t worst = -1, worst_moved = 0, worst_xnet = 0;
    for (int64_t p = 0; p < c.pes; ++p) {
      int64_t moved = 0;
      for (int64_t k = matched.seg_offset[p]; k < matched.seg_offset[p + 1]; ++k)
        if (matched.segments[k].k0 != bal.segments[k].k0 ||
            matched.segments[k].k1 != bal.segments[k].k1)
          ++moved;
      OpCounts o;
      o.mul = 2 * moved;
      o.add = 3 * moved;
      o.rnd = moved;
      const int64_t xn = moved * m.xnet_clocks(32, far[static_cast<std::size_t>(p)]);
      if (o.clocks(m, nar) + xn > worst) {
        worst = o.clocks(m, nar) + xn;
        worst_moved = moved;
        worst_xnet = xn;
      }
    }
    s.ops.mul += 2 * worst_moved;
    s.ops.add += 3 * worst_moved;
    s.ops.rnd += worst_moved;
    s.xnet_words += worst_moved;
    s.xnet_bytes = s.xnet_words * 4;
    s.op_clocks = s.ops.clocks(m, nar);
    s.xnet_clocks += worst_xnet;
    s.note = std::to_string(c.sweeps) + " sweeps x " + std::to_string(rounds) + " rounds, " +
             std::to_string(worst_moved) + " moved boundaries on the busiest PE";
    f.stages.push_back(s);
  }
  f.max_load_balanced = bal.max_load();
  for (int64_t p = 0; p < c.pes; ++p) {
    f.max_segments = std::max(f.max_segments, bal.seg_offset[p + 1] - bal.seg_offset[p]);
    for (int64_t s = bal.seg_offset[p]; s < bal.seg_offset[p + 1]; ++s)
      f.max_segment_length =
          std::max<int64_t>(f.max_segment_length, bal.segments[s].k1 - bal.segments[s].k0);
  }

  // Resampling.
  {
    StagePrediction s;
    s.name = "resample";
    s.ops = resample_ops_per_sample_thesis(c.order) * f.max_load_balanced;
    s.op_clocks = s.ops.clocks(m, nar);
    s.note = std::to_string(f.max_load_balanced) + " samples on the busiest PE";
    f.stages.push_back(s);
  }

  // Local compositing.
  {
    StagePrediction s;
    s.name = "local composite";
    if (c.mc_samples == 0) {
      s.ops = local_composite_ops(1, f.max_load_balanced, 0);
      s.note = "direct, " + std::to_string(f.max_load_balanced) + " samples";
    } else {
      int64_t best = -1;
      for (int64_t p = 0; p < c.pes; ++p) {
        const int64_t segs = bal.seg_offset[p + 1] - bal.seg_offset[p];
        const int64_t load = bal.loads[p];
        OpCounts o;
        o.add = segs * c.mc_samples;
        o.cmp8 = load * c.mc_samples;
        if (o.clocks(m, nar) > best) {
          best = o.clocks(m, nar);
          s.ops = o;
        }
      }
      s.ops.acu_mul = f.max_segment_length * c.mc_samples;  // shared random numbers
      s.note = "Monte Carlo, " + std::to_string(c.mc_samples) + " samples per sub-ray";
    }
    s.op_clocks = s.ops.clocks(m, nar);
    f.stages.push_back(s);
  }

  // Binary swap.
  {
    const SwapPlan plan = plan_swap(bal.rects, split, view, f.grid, c.layout);
    const SwapCost cost = swap_cost(plan, split, view, f.grid);
    for (std::size_t k = 0; k < cost.stages.size(); ++k) {
      const SwapStageCost& st = cost.stages[k];
      StagePrediction s;
      s.name = "swap " + std::to_string(k);
      s.xnet_words = st.max_sent;
      s.xnet_bytes = st.max_sent * c.rgba_bits / 8;
      s.xnet_max_distance = st.max_distance;
      s.xnet_clocks = st.max_sent * m.xnet_clocks(c.rgba_bits, st.max_distance);
      s.ops.mul = 4 * st.max_kept;
      s.ops.add = 4 * st.max_kept;
      s.op_clocks = s.ops.clocks(m, nar);
      s.note = "axis " + std::string(plan.bits[k].axis == 0 ? "x" : "y") + ", " +
               std::to_string(st.max_kept) + " pixels kept";
      f.stages.push_back(s);
    }
  }

  // Display.
  {
    StagePrediction s;
    s.name = "display";
    const int64_t pixels = int64_t(f.image_width) * f.image_height;
    s.router_words = (pixels + c.pes - 1) / c.pes;
    s.router_clocks = s.router_words * m.router_32;
    s.note = std::to_string(pixels) + " pixels";
    f.stages.push_back(s);
  }
  return f;
}

}  // namespace simdvol
