// Binary swap schedule, references and communication (swap.hpp): the pixel
// bits of each stage, the final cut-and-stack / hierarchical layouts, the
// strided rectangles (nothing lost, nothing duplicated, bounded), swap +
// display against the per-ray depth-order composite of the footprints, and
// the communication counts against brute force. P = 1 .. 8192.
#include <gtest/gtest.h>

#include <random>

#include "simdvol/error.hpp"
#include "simdvol/match.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;

namespace {

ViewGeometry geometry(const Dims3& d, ViewAngles v, int w, int h, Sampling s = Sampling::voxel) {
  return make_view(d, {1.0, 1.0, 1.0}, v, w, h, s);
}

int log2i(int64_t n) {
  int b = 0;
  while ((int64_t(1) << b) < n) ++b;
  return b;
}

// The virtual processor (X, Y) of p: the PE bits of the stages on each axis,
// the first stage of an axis giving bit 0 (cut-and-stack) or the most
// significant bit (hierarchical).
std::array<int64_t, 2> split_pe(const std::vector<PixelBit>& bits, int64_t p, bool hier) {
  std::array<int64_t, 2> v{0, 0};
  for (std::size_t k = 0; k < bits.size(); ++k) {
    const int a = bits[k].axis;
    v[a] = hier ? (v[a] << 1) | ((p >> k) & 1) : v[a];
  }
  int j[2] = {0, 0};
  for (std::size_t k = 0; k < bits.size() && !hier; ++k)
    v[bits[k].axis] |= ((p >> k) & 1) << j[bits[k].axis]++;
  return v;
}

const std::vector<PeGrid> kGrids = [] {
  std::vector<PeGrid> g;
  for (int64_t p = 1; p <= 8192; p *= 2) g.push_back(pe_grid(p));
  g.push_back(parse_pe_grid("8x1"));
  g.push_back(parse_pe_grid("1x16"));
  g.push_back(parse_pe_grid("128x4"));
  return g;
}();

}  // namespace

TEST(SwapSchedule, ParseLayout) {
  EXPECT_EQ(parse_swap_layout("cut-and-stack"), SwapLayout::cut_and_stack);
  EXPECT_EQ(parse_swap_layout("hierarchical"), SwapLayout::hierarchical);
  EXPECT_THROW(parse_swap_layout("diagonal"), ArgumentError);
  EXPECT_STREQ(swap_layout_name(SwapLayout::hierarchical), "hierarchical");
}

TEST(SwapSchedule, StridedRange) {
  EXPECT_EQ(strided_range(3, 20, 4, 1).first, 5);
  EXPECT_EQ(strided_range(3, 20, 4, 1).count, 4);  // 5 9 13 17
  EXPECT_EQ(strided_range(3, 17, 4, 1).count, 3);
  EXPECT_EQ(strided_range(3, 5, 4, 2).count, 0);
  EXPECT_EQ(strided_range(0, 1, 1, 0).count, 1);
  EXPECT_EQ(strided_range(7, 7, 1, 0).count, 0);
  EXPECT_THROW(strided_range(0, 1, 0, 0), ArgumentError);
}

// Every (lo, hi, stride, residue) in a small box, negative values included,
// against counting the members one by one: the power-of-two strides take
// masks and shifts, the others divisions.
TEST(SwapSchedule, StridedRangeEqualsEnumeration) {
  for (int64_t stride : {1, 2, 3, 4, 5, 8, 16, 64})
    for (int64_t lo = -20; lo <= 20; ++lo)
      for (int64_t hi = lo - 2; hi <= lo + 40; ++hi)
        for (int64_t residue = -9; residue <= 9; ++residue) {
          int64_t first = -1, count = 0;
          for (int64_t x = lo; x < hi; ++x)
            if (((x - residue) % stride) == 0) {
              if (count++ == 0) first = x;
            }
          const StridedRange r = strided_range(lo, hi, stride, residue);
          ASSERT_EQ(r.count, count) << lo << " " << hi << " " << stride << " " << residue;
          ASSERT_EQ(r.first, count > 0 ? first : lo)
              << lo << " " << hi << " " << stride << " " << residue;
        }
}

// Stage bits: N of them, alternating axes, levels ascending (cut-and-stack)
// or descending from B - 1 (hierarchical); every pixel lands on the PE the
// layout's formula names.
// ceil_log2 over its whole domain (past 2^62 it looped for ever, shifting
// 1 by 64), and the k-d split of the largest dimensions (its ceil_div
// overflowed to negative cells).
TEST(SwapSchedule, CeilLog2WholeRange) {
  EXPECT_EQ(ceil_log2(1), 0);
  EXPECT_EQ(ceil_log2(2), 1);
  EXPECT_EQ(ceil_log2(3), 2);
  EXPECT_EQ(ceil_log2(int64_t{1} << 62), 62);
  EXPECT_EQ(ceil_log2((int64_t{1} << 62) + 1), 63);
  EXPECT_EQ(ceil_log2(INT64_MAX), 63);
  EXPECT_THROW(ceil_log2(0), ArgumentError);
  const KdSplit s = kd_split({INT64_MAX, INT64_MAX, INT64_MAX}, 1 << 20);
  for (int a = 0; a < 3; ++a) EXPECT_GT(s.cell[a], 0) << a;
  EXPECT_EQ(s.cell[0], (INT64_MAX - 1) / (int64_t{1} << s.axis_bits[0]) + 1);
}

TEST(SwapSchedule, PixelBitsAndFinalLayout) {
  const int sizes[][2] = {{1, 1}, {7, 5}, {40, 36}, {256, 256}, {257, 129}, {512, 300}, {3, 700}};
  for (const PeGrid& g : kGrids)
    for (const auto& sz : sizes)
      for (SwapLayout L : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
        const int w = sz[0], h = sz[1];
        SCOPED_TRACE(std::to_string(g.width) + "x" + std::to_string(g.height) + " image " +
                     std::to_string(w) + "x" + std::to_string(h) + " " + swap_layout_name(L));
        const std::vector<PixelBit> bits = swap_pixel_bits(g, w, h, L);
        const int bx = log2i(g.width), by = log2i(g.height);
        ASSERT_EQ(static_cast<int>(bits.size()), bx + by);
        int j[2] = {0, 0};
        const int B[2] = {std::max(ceil_log2(w), bx), std::max(ceil_log2(h), by)};
        for (std::size_t k = 0; k < bits.size(); ++k) {
          const int a = bits[k].axis;
          // Alternation: while both axes have bits left, x and y take turns from x.
          if (k < 2 * static_cast<std::size_t>(std::min(bx, by))) {
            EXPECT_EQ(a, int(k % 2));
          }
          EXPECT_EQ(bits[k].level, L == SwapLayout::cut_and_stack ? j[a] : B[a] - 1 - j[a]);
          ++j[a];
        }
        EXPECT_EQ(j[0], bx);
        EXPECT_EQ(j[1], by);
        // Final layout through a plan's display tables.
        SwapPlan plan;
        plan.width = w, plan.height = h, plan.bits = bits;
        plan.xpe.assign(w, 0), plan.ype.assign(h, 0);
        for (std::size_t k = 0; k < bits.size(); ++k) {
          auto& t = bits[k].axis == 0 ? plan.xpe : plan.ype;
          for (std::size_t x = 0; x < t.size(); ++x)
            t[x] |= ((int64_t(x) >> bits[k].level) & 1) << k;
        }
        for (int y = 0; y < h; y += std::max(1, h / 37))
          for (int x = 0; x < w; x += std::max(1, w / 41)) {
            const auto v = split_pe(bits, plan.display_pe(x, y), L == SwapLayout::hierarchical);
            if (L == SwapLayout::cut_and_stack) {
              ASSERT_EQ(v[0], x % g.width);
              ASSERT_EQ(v[1], y % g.height);
            } else {
              ASSERT_EQ(v[0], x >> (B[0] - bx));
              ASSERT_EQ(v[1], y >> (B[1] - by));
            }
          }
      }
  EXPECT_THROW(swap_pixel_bits(PeGrid{3, 1}, 8, 8, SwapLayout::cut_and_stack), ArgumentError);
  EXPECT_THROW(swap_pixel_bits(PeGrid{4, 2}, 0, 8, SwapLayout::cut_and_stack), ArgumentError);
}

namespace {

// Every field of two plans equal.
bool same_plan(const SwapPlan& a, const SwapPlan& b) {
  return a.layout == b.layout && a.width == b.width && a.height == b.height && a.pes == b.pes &&
         a.bits == b.bits && a.front == b.front && a.held == b.held && a.offset == b.offset &&
         a.xpe == b.xpe && a.ype == b.ype;
}

// Every invariant of a plan, by brute force over the pixels (small images).
void check_plan(const SwapPlan& plan, const std::vector<sv_rect>& rects, const PeGrid& g) {
  const int N = plan.stages();
  const int64_t P = plan.pes;
  ASSERT_EQ(P, g.count());
  // Level 0 = the footprints.
  for (int64_t p = 0; p < P; ++p) {
    const SwapRect& h = plan.held[0][p];
    const sv_rect& r = rects[p];
    ASSERT_EQ(h.count(), int64_t(r.w) * r.h);
    if (h.count()) {
      EXPECT_EQ(h.x0, r.i0);
      EXPECT_EQ(h.y0, r.j0);
      EXPECT_EQ(h.nx, r.w);
      EXPECT_EQ(h.sx, 1);
    }
  }
  std::vector<int> nbits(2, 0);
  for (int k = 0; k < N; ++k) {
    const PixelBit& bit = plan.bits[k];
    ++nbits[bit.axis];
    for (int64_t p = 0; p < P; ++p) {
      const int64_t q = p ^ (int64_t(1) << k);
      const int own = (p >> k) & 1;
      const SwapRect& o = plan.held[k + 1][p];
      if (plan.layout == SwapLayout::cut_and_stack) {
        EXPECT_EQ(o.sx, 1 << nbits[0]);
        EXPECT_EQ(o.sy, 1 << nbits[1]);
      } else {
        EXPECT_EQ(o.sx, 1);
        EXPECT_EQ(o.sy, 1);
      }
      // Kept: every pixel of p's or q's level-k rectangle with p's bit.
      for (const SwapRect* h : {&plan.held[k][p], &plan.held[k][q]})
        for (int b = 0; b < h->ny; ++b)
          for (int a = 0; a < h->nx; ++a) {
            const int64_t x = h->x0 + a * h->sx, y = h->y0 + b * h->sy;
            const int64_t c = bit.axis == 0 ? x : y;
            if (((c >> bit.level) & 1) == own) {
              ASSERT_TRUE(o.contains(x, y)) << "stage " << k << " pe " << p;
            }
          }
      // And only pixels with p's bit.
      for (int b = 0; b < o.ny; ++b)
        for (int a = 0; a < o.nx; ++a) {
          const int64_t c = bit.axis == 0 ? o.x0 + a * o.sx : o.y0 + b * o.sy;
          ASSERT_EQ((c >> bit.level) & 1, own);
        }
    }
  }
  // Final level: a pixel is held only by display_pe.
  std::vector<int> holders(static_cast<std::size_t>(plan.width) * plan.height, 0);
  int64_t covered = 0;
  for (int64_t p = 0; p < P; ++p) {
    const SwapRect& h = plan.held[N][p];
    for (int b = 0; b < h.ny; ++b)
      for (int a = 0; a < h.nx; ++a) {
        const int64_t x = h.x0 + a * h.sx, y = h.y0 + b * h.sy;
        ASSERT_LT(x, plan.width);
        ASSERT_LT(y, plan.height);
        ASSERT_EQ(plan.display_pe(int(x), int(y)), p);
        ++holders[y * plan.width + x];
        ++covered;
      }
  }
  for (int v : holders) ASSERT_LE(v, 1);
  // Every footprint pixel survives to the end.
  for (const sv_rect& r : rects)
    for (int y = r.j0; y < r.j0 + r.h; ++y)
      for (int x = r.i0; x < r.i0 + r.w; ++x) ASSERT_EQ(holders[y * plan.width + x], 1);
  // Bounded: each PE at the end holds at most its share of the frame.
  if (plan.layout == SwapLayout::cut_and_stack) {
    for (int64_t p = 0; p < P; ++p)
      EXPECT_LE(plan.held[N][p].count(),
                ((plan.width + g.width - 1) / g.width) * ((plan.height + g.height - 1) / g.height));
  }
  for (int L = 0; L <= N; ++L) {
    int64_t s = 0;
    for (int64_t p = 0; p < P; ++p) {
      ASSERT_EQ(plan.offset[L][p], s);
      s += plan.held[L][p].count();
    }
    ASSERT_EQ(plan.level_size(L), s);
  }
  EXPECT_LE(covered, int64_t(plan.width) * plan.height);
}

// Random sub-ray composites; 0 for empty segments (as the local stage writes).
std::vector<Rgba> random_composites(const Matching& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(m.segments.size());
  for (std::size_t n = 0; n < v.size(); ++n) {
    Rgba& x = v[n];
    x.a = u(rng) * 0.6f;
    x.r = x.a * u(rng), x.g = x.a * u(rng), x.b = x.a * u(rng);
    if (m.segments[n].k1 <= m.segments[n].k0) x = Rgba{};
  }
  return v;
}

}  // namespace

// Plans of real (balanced) matchings: invariants, and swap + display equal
// the per-ray composite of the footprints in increasing k0 (float
// re-association only). Swapping the depth order breaks it (the check can
// fail).
TEST(SwapReference, EqualsDepthOrderCompositeAllP) {
  const Dims3 d{23, 19, 13};
  const ViewAngles views[] = {
      {0, 0, 0}, {0, 90, 0}, {0, 30, 0}, {45, 45, 0}, {-23.5, 71.25, 133.0}, {180, 10, 200}};
  int checked = 0, order_matters = 0;
  SwapPlan reused;  // plan_swap_into over every case: P grows and shrinks
  for (const ViewAngles& va : views)
    for (Sampling smp : {Sampling::voxel, Sampling::pixel})
      for (int64_t P = 1; P <= 8192; P *= 2) {
        const ViewGeometry view = geometry(d, va, 30, 27, smp);
        const KdSplit split = kd_split(d, P);
        const Matching m = balance_reference(match_reference(view, split), view, split);
        const std::vector<Rgba> comp = random_composites(m, unsigned(P) + 7);
        const Footprints f = footprints_reference(m, comp);
        const Image want = composite_footprints(m, f, view.width(), view.height());
        const PeGrid g = pe_grid(P);
        for (SwapLayout L : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
          SCOPED_TRACE("view " + std::to_string(va.theta) + "," + std::to_string(va.phi) + " P " +
                       std::to_string(P) + " " + swap_layout_name(L));
          SwapPlan plan = plan_swap(m.rects, split, view, g, L);
          check_plan(plan, m.rects, g);
          plan_swap_into(reused, m.rects, split, view, g, L);
          EXPECT_TRUE(same_plan(reused, plan));
          // The rectangles written to held_out instead (the engine's mapped
          // tables): the same, plan.held empty, the rest of the plan the same.
          {
            const std::size_t levels = plan.held.size();
            std::vector<std::vector<SwapRect>> out(levels,
                                                   std::vector<SwapRect>(std::size_t(P) + 1));
            for (auto& o : out) o.back() = SwapRect{-7, -7, -7, -7, -7, -7, -7, -7};  // guard
            std::vector<SwapRect*> ptr;
            for (auto& o : out) ptr.push_back(o.data());
            plan_swap_into(reused, m.rects, split, view, g, L, ptr.data());
            for (std::size_t l = 0; l < levels; ++l) {
              EXPECT_TRUE(reused.held[l].empty());
              EXPECT_TRUE(std::equal(plan.held[l].begin(), plan.held[l].end(), out[l].begin()));
              EXPECT_EQ(out[l].back(), (SwapRect{-7, -7, -7, -7, -7, -7, -7, -7}));
            }
            SwapPlan without = plan;
            for (auto& h : without.held) h.clear();
            EXPECT_TRUE(same_plan(reused, without));
          }
          const Image got = display_reference(plan, swap_reference(plan, f));
          EXPECT_LE(max_abs_diff(want, got), 2e-6f);
          ++checked;
          if (P >= 8 && L == SwapLayout::cut_and_stack) {
            for (int& fr : plan.front) fr ^= 1;
            if (max_abs_diff(want, display_reference(plan, swap_reference(plan, f))) > 1e-3f)
              ++order_matters;
          }
        }
      }
  EXPECT_EQ(checked, 6 * 2 * 14 * 2);
  EXPECT_GT(order_matters, 6 * 2 * 8);  // almost every case
}

// A larger frame: 8192 PEs, 64^3 at 96^2 (P = 8192, cells of 4x4x2 voxels).
TEST(SwapReference, LargerFrame) {
  const Dims3 d{64, 64, 64};
  const ViewGeometry view = geometry(d, {20, 35, 10}, 96, 96);
  const KdSplit split = kd_split(d, 8192);
  const Matching m = balance_reference(match_reference(view, split), view, split);
  const Footprints f = footprints_reference(m, random_composites(m, 3));
  const Image want = composite_footprints(m, f, view.width(), view.height());
  for (SwapLayout L : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
    const SwapPlan plan = plan_swap(m.rects, split, view, pe_grid(8192), L);
    EXPECT_LE(max_abs_diff(want, display_reference(plan, swap_reference(plan, f))), 2e-6f);
  }
}

// Which half is in front follows the view direction along the stage's axis.
TEST(SwapSchedule, FrontFollowsViewDirection) {
  const Dims3 d{32, 32, 32};
  const KdSplit split = kd_split(d, 64);
  for (const ViewAngles& va :
       std::vector<ViewAngles>{{0, 0, 0}, {0, 180, 0}, {90, 0, 0}, {30, 120, 45}}) {
    const ViewGeometry view = geometry(d, va, 32, 32);
    for (int k = 0; k < split.bits; ++k) {
      const int a = split.bit_axis[k];
      EXPECT_EQ(swap_front(split, view, k), view.grid.step[a][2] < 0 ? 1 : 0);
    }
  }
  EXPECT_THROW(swap_front(split, geometry(d, {}, 8, 8), 6), ArgumentError);
}

// Communication: swap_cost's per-stage moved pixels equal a brute-force count.
TEST(SwapCost, MovedPixelsMatchBruteForce) {
  const Dims3 d{40, 33, 21};
  for (int64_t P : {1, 4, 32, 512, 8192})
    for (SwapLayout L : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
      const ViewGeometry view = geometry(d, {15, 40, 5}, 50, 44);
      const KdSplit split = kd_split(d, P);
      const Matching m = match_reference(view, split);
      const PeGrid g = pe_grid(P);
      const SwapPlan plan = plan_swap(m.rects, split, view, g, L);
      const SwapCost c = swap_cost(plan, split, view, g);
      ASSERT_EQ(c.stages.size(), static_cast<std::size_t>(plan.stages()));
      int64_t total = 0;
      for (int k = 0; k < plan.stages(); ++k) {
        int64_t moved = 0, max_sent = 0;
        for (int64_t p = 0; p < P; ++p) {
          const SwapRect& h = plan.held[k][p];
          const int64_t q = p ^ (int64_t(1) << k);
          int64_t sent = 0;
          for (int b = 0; b < h.ny; ++b)
            for (int a = 0; a < h.nx; ++a)
              if (plan.held[k + 1][q].contains(h.x0 + a * h.sx, h.y0 + b * h.sy)) ++sent;
          moved += sent;
          max_sent = std::max(max_sent, sent);
        }
        EXPECT_EQ(c.stages[k].moved, moved) << "P " << P << " stage " << k;
        EXPECT_EQ(c.stages[k].max_sent, max_sent);
        EXPECT_EQ(c.stages[k].kept, plan.level_size(k + 1));
        EXPECT_EQ(c.stages[k].held, plan.level_size(k));
        total += moved;
      }
      EXPECT_EQ(c.moved, total);
      EXPECT_EQ(c.swaps_x + c.swaps_y, plan.stages());
      EXPECT_GT(c.cell_section, 0.0);
    }
}

TEST(SwapReference, RejectsMismatchedInputs) {
  const Dims3 d{16, 16, 16};
  const ViewGeometry view = geometry(d, {}, 16, 16);
  const KdSplit split = kd_split(d, 8);
  const Matching m = match_reference(view, split);
  EXPECT_THROW(plan_swap(m.rects, split, view, pe_grid(16), SwapLayout::cut_and_stack),
               ArgumentError);
  std::vector<sv_rect> bad = m.rects;
  bad[0].w = 40;
  EXPECT_THROW(plan_swap(bad, split, view, pe_grid(8), SwapLayout::cut_and_stack), ArgumentError);
  const SwapPlan plan = plan_swap(m.rects, split, view, pe_grid(8), SwapLayout::cut_and_stack);
  // A rejected plan_swap_into leaves the plan it was given as it was.
  SwapPlan kept = plan;
  EXPECT_THROW(plan_swap_into(kept, bad, split, view, pe_grid(8), SwapLayout::hierarchical),
               ArgumentError);
  EXPECT_THROW(plan_swap_into(kept, m.rects, split, view, pe_grid(16), SwapLayout::hierarchical),
               ArgumentError);
  EXPECT_TRUE(same_plan(kept, plan));
  EXPECT_THROW(swap_stage_reference(plan, 0, std::vector<Rgba>(3)), ArgumentError);
  // An empty plan, or one whose rectangles were held out, was read through
  // null vectors (SIGSEGV).
  EXPECT_THROW(swap_reference(SwapPlan{}, Footprints{}), ArgumentError);
  EXPECT_THROW(display_reference(SwapPlan{}, {}), ArgumentError);
  EXPECT_THROW(swap_stage_reference(SwapPlan{}, 0, {}), ArgumentError);
  EXPECT_THROW(swap_cost(SwapPlan{}, split, view, pe_grid(8)), ArgumentError);
  SwapPlan held_out = plan;
  held_out.held.clear();
  EXPECT_THROW(display_reference(held_out, std::vector<Rgba>(plan.level_size(plan.stages()))),
               ArgumentError);
  EXPECT_THROW(swap_cost(held_out, split, view, pe_grid(8)), ArgumentError);
  EXPECT_THROW(swap_stage_reference(plan, 3, std::vector<Rgba>(plan.level_size(3))), ArgumentError);
  EXPECT_THROW(display_reference(plan, std::vector<Rgba>(1)), ArgumentError);
}
