// Binary swap and display: schedule, serial references, communication (swap.hpp).
#include "simdvol/swap.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

#include "over_inline.hpp"
#include "simdvol/composite.hpp"
#include "simdvol/error.hpp"

namespace simdvol {

namespace {

bool is_pow2(int64_t n) {
  return n >= 1 && (n & (n - 1)) == 0;
}

int exact_log2(int64_t n) {
  // (Up to 62: 1 << 63 overflows, and n past 2^62 looped for ever.)
  int b = 0;
  while (b < 63 && (int64_t(1) << b) < n) ++b;
  return b;
}

// A half-open pixel box; empty when x0 >= x1 or y0 >= y1.
using Box2 = detail::SwapBox;

Box2 bbox(const Box2& a, const Box2& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::max(a.x1, b.x1), std::min(a.y0, b.y0), std::max(a.y1, b.y1)};
}

// Values f + i * s (i < n, s a power of two) whose bit `level` equals 1.
int64_t count_bit_set(int64_t f, int64_t n, int64_t s, int level) {
  if (n <= 0) return 0;
  const int64_t half = int64_t(1) << level;
  if (s > half) return ((f >> level) & 1) ? n : 0;
  const int64_t period = half * 2, per = half / s, r = f % s;
  auto g = [&](int64_t X) {  // x in [0, X), x = r (mod s), bit set
    const int64_t m = std::max<int64_t>(0, X % period - half);
    return (X / period) * per + (m > r ? (m - r - 1) / s + 1 : 0);
  };
  return g(f + (n - 1) * s + 1) - g(f);
}

// Pixels of rectangle `h` whose bit (axis, level) equals b.
int64_t count_with_bit(const SwapRect& h, const PixelBit& bit, int b) {
  if (h.count() == 0) return 0;
  const int64_t along = bit.axis == 0 ? h.nx : h.ny;
  const int64_t other = bit.axis == 0 ? h.ny : h.nx;
  const int64_t set = bit.axis == 0 ? count_bit_set(h.x0, h.nx, h.sx, bit.level)
                                    : count_bit_set(h.y0, h.ny, h.sy, bit.level);
  return (b ? set : along - set) * other;
}

// The values x = r (mod 2^l) of [lo, hi): first and count (count 0: first =
// lo). x mod 2^l is x & (2^l - 1) for any x in two's complement.
StridedRange pow2_range(int64_t lo, int64_t hi, int l, int64_t residue) {
  const int64_t m = (int64_t(1) << l) - 1;
  StridedRange r;
  r.first = lo + (((residue & m) - (lo & m)) & m);
  r.count = r.first < hi ? ((hi - 1 - r.first) >> l) + 1 : 0;
  if (r.count == 0) r.first = lo;
  return r;
}

}  // namespace

SwapLayout parse_swap_layout(std::string_view s, const std::string& argument) {
  if (s == "cut-and-stack" || s == "cut_and_stack" || s == "cs") return SwapLayout::cut_and_stack;
  if (s == "hierarchical" || s == "hier") return SwapLayout::hierarchical;
  throw ArgumentError(
      argument, "unknown layout '" + std::string(s) + "' (expected cut-and-stack or hierarchical)");
}

const char* swap_layout_name(SwapLayout layout) {
  return layout == SwapLayout::cut_and_stack ? "cut-and-stack" : "hierarchical";
}

int ceil_log2(int64_t n) {
  if (n < 1) throw ArgumentError("n", "ceil_log2 needs n >= 1");
  return exact_log2(n);
}

bool SwapRect::contains(int64_t x, int64_t y) const {
  if (x < x0 || y < y0) return false;
  const int64_t dx = x - x0, dy = y - y0;
  return dx % sx == 0 && dy % sy == 0 && dx / sx < nx && dy / sy < ny;
}

StridedRange strided_range(int64_t lo, int64_t hi, int64_t stride, int64_t residue) {
  if (stride < 1) throw ArgumentError("stride", "must be positive");
  // A power of two (every stride of plan_swap): masks and shifts; the same
  // results as the general path below (tested).
  if ((stride & (stride - 1)) == 0)
    return pow2_range(lo, hi, std::countr_zero(static_cast<uint64_t>(stride)), residue);
  StridedRange r;
  const int64_t rr = ((residue % stride) + stride) % stride;
  const int64_t lm = ((lo % stride) + stride) % stride;
  r.first = lo + ((rr - lm) % stride + stride) % stride;
  r.count = r.first < hi ? (hi - 1 - r.first) / stride + 1 : 0;
  if (r.count == 0) r.first = lo;
  return r;
}

namespace {

// swap_pixel_bits' arguments checked; the number of stages.
int pixel_bit_count(const PeGrid& grid, int width, int height) {
  if (!is_pow2(grid.width) || !is_pow2(grid.height) || !is_pow2(grid.count()))
    throw ArgumentError("grid", "W and H must be powers of two");
  if (width < 1 || height < 1) throw ArgumentError("image", "width and height must be positive");
  return exact_log2(grid.width) + exact_log2(grid.height);
}

// swap_pixel_bits into `bits` (its storage reused), the arguments checked.
void pixel_bits_into(std::vector<PixelBit>& bits, const PeGrid& grid, int width, int height,
                     SwapLayout layout) {
  const int nb[2] = {exact_log2(grid.width), exact_log2(grid.height)};
  const int64_t extent[2] = {width, height};
  int B[2];
  for (int a = 0; a < 2; ++a) B[a] = std::max(ceil_log2(extent[a]), nb[a]);
  bits.clear();
  int used[2] = {0, 0};
  int next = 0;  // axis to take when both have bits left
  while (used[0] < nb[0] || used[1] < nb[1]) {
    int a = next;
    if (used[a] >= nb[a]) a = 1 - a;
    const int j = used[a]++;
    bits.push_back({a, layout == SwapLayout::cut_and_stack ? j : B[a] - 1 - j});
    next = 1 - a;
  }
}

}  // namespace

std::vector<PixelBit> swap_pixel_bits(const PeGrid& grid, int width, int height,
                                      SwapLayout layout) {
  (void)pixel_bit_count(grid, width, height);
  std::vector<PixelBit> bits;
  pixel_bits_into(bits, grid, width, height, layout);
  return bits;
}

int swap_front(const KdSplit& split, const ViewGeometry& view, int stage) {
  if (stage < 0 || stage >= split.bits) throw ArgumentError("stage", "outside 0 .. N-1");
  const int a = split.bit_axis[static_cast<std::size_t>(stage)];
  return view.grid.step[a][2] >= 0 ? 0 : 1;
}

SwapPlan plan_swap(const std::vector<sv_rect>& rects, const KdSplit& split,
                   const ViewGeometry& view, const PeGrid& grid, SwapLayout layout) {
  SwapPlan plan;
  plan_swap_into(plan, rects, split, view, grid, layout);
  plan.work = {};  // (a plan made once keeps no working storage)
  return plan;
}

void plan_swap_into(SwapPlan& plan, const std::vector<sv_rect>& rects, const KdSplit& split,
                    const ViewGeometry& view, const PeGrid& grid, SwapLayout layout,
                    SwapRect* const* held_out) {
  const int64_t P = static_cast<int64_t>(rects.size());
  if (P != split.pes() || P != grid.count())
    throw ArgumentError("rects", "one footprint per PE of the split and the grid expected");
  const int N = split.bits;
  const int width = view.width(), height = view.height();
  if (pixel_bit_count(grid, width, height) != N) throw ArgumentError("grid", "PE bits differ");
  // The footprints, checked before the schedule is touched (into the plan's
  // working storage: no fresh memory where it held as many PEs before).
  std::vector<Box2>& F = plan.work.boxes;
  F.resize(static_cast<std::size_t>(P));
  for (int64_t p = 0; p < P; ++p) {
    const sv_rect& r = rects[static_cast<std::size_t>(p)];
    if (r.w < 0 || r.h < 0) throw ArgumentError("rects", "negative footprint size");
    if (r.w > 0 && r.h > 0 &&
        (r.i0 < 0 || r.j0 < 0 || int64_t(r.i0) + r.w > width || int64_t(r.j0) + r.h > height))
      throw ArgumentError("rects", "footprint of PE " + std::to_string(p) + " outside the image");
    F[static_cast<std::size_t>(p)] = {r.i0, int64_t(r.i0) + r.w, r.j0, int64_t(r.j0) + r.h};
  }
  plan.layout = layout;
  plan.width = width;
  plan.height = height;
  plan.pes = P;
  pixel_bits_into(plan.bits, grid, width, height, layout);
  plan.front.clear();
  for (int k = 0; k < N; ++k) plan.front.push_back(swap_front(split, view, k));

  const int64_t extent[2] = {width, height};
  plan.held.resize(static_cast<std::size_t>(N + 1));
  plan.offset.resize(static_cast<std::size_t>(N + 1));
  // Constraints of the stages before level L, per axis: j[a] constrained
  // levels, and PE p's values of them, which depend only on its bits
  // 0 .. L - 1: v[a][r] for r = p mod 2^L (grown by one stage per level:
  // entries 2^(L-1) .. 2^L - 1 are those below with bit L - 1 added), in
  // the plan's working storage.
  int j[2] = {0, 0};
  std::vector<int32_t>(&v)[2] = plan.work.residues;
  for (std::vector<int32_t>& va : v) va.assign(static_cast<std::size_t>(P), 0);
  int B[2];  // hierarchical: the pixel bits per axis
  for (int a = 0; a < 2; ++a)
    B[a] =
        std::max(ceil_log2(extent[a]), a == 0 ? exact_log2(grid.width) : exact_log2(grid.height));
  const bool cut = layout == SwapLayout::cut_and_stack;
  // After stages 0 .. L - 1 the PEs of a block of 2^L consecutive indices
  // (those that differ only in bits 0 .. L - 1) share one box,
  // F_L(p) = G[p >> L]: G halves from level to level, each entry the bbox of
  // the two it replaces (F_L(p) = F_L(p ^ 2^k) = bbox(F_{L-1}(p),
  // F_{L-1}(p ^ 2^k)), k = L - 1). The engine plans while the device
  // resamples, on the cores PoCL's threads use: a frame with two more plans
  // took 1.034 of the time (scripts/bench-ab, 6 pairs, 2-core Intel Xeon,
  // 2026-12-05). G, the residues per r and the branchless ranges below:
  // 0.56 -> 0.36 ms a plan of the 256^3 phantom at 256^2, 8,192 PEs (a host
  // loop, warm caches), the same plans as before over 1,008 cases (views,
  // P, both layouts).
  std::vector<Box2>& G = F;
  for (int L = 0; L <= N; ++L) {
    if (L > 0) {
      const int k = L - 1;
      const int64_t groups = P >> L;
      for (int64_t g = 0; g < groups; ++g)
        G[static_cast<std::size_t>(g)] =
            bbox(G[static_cast<std::size_t>(2 * g)], G[static_cast<std::size_t>(2 * g + 1)]);
      const PixelBit& pb = plan.bits[static_cast<std::size_t>(k)];
      const int64_t half = int64_t(1) << k;
      for (int a = 0; a < 2; ++a) {
        int32_t* va = v[a].data();
        const int32_t add = a == pb.axis ? int32_t(1) << pb.level : 0;
        for (int64_t r = half; r < 2 * half; ++r) va[r] = va[r - half] | add;
      }
      ++j[pb.axis];
    }
    auto& held = plan.held[static_cast<std::size_t>(L)];
    auto& off = plan.offset[static_cast<std::size_t>(L)];
    if (held_out)
      std::vector<SwapRect>().swap(held);  // (the level's rectangles go to held_out[L])
    else
      held.resize(static_cast<std::size_t>(P));
    off.resize(static_cast<std::size_t>(P + 1));
    off[0] = 0;
    // Cut-and-stack: per axis the values x = v (mod 2^j) of [lo, hi).
    // Hierarchical: the block [v, v + 2^(B - j)) clipped to [lo, hi).
    // (pow2_range's arithmetic without its branches: a count below 1 is an
    // empty range, and a rectangle empty along either axis is all zeros.)
    const int32_t lx = cut ? j[0] : 0, ly = cut ? j[1] : 0;
    const int64_t mx = (int64_t(1) << lx) - 1, my = (int64_t(1) << ly) - 1;
    const int64_t bx = cut ? 0 : int64_t(1) << (B[0] - j[0]);
    const int64_t by = cut ? 0 : int64_t(1) << (B[1] - j[1]);
    const int32_t* vx = v[0].data();
    const int32_t* vy = v[1].data();
    SwapRect* h = held_out ? held_out[L] : held.data();
    int64_t* o = off.data();
    int64_t total = 0;
    const int32_t sx = int32_t(1) << lx, sy = int32_t(1) << ly;
    // Block by block (one box each), in 32 bits (every coordinate is inside
    // the image); the counts' prefix as they come (PE g * 2^L + r in order).
    const int64_t span = int64_t(1) << L;
    for (int64_t g = 0; g < (P >> L); ++g) {
      const Box2 f = G[static_cast<std::size_t>(g)];
      const int32_t x0 = static_cast<int32_t>(f.x0), x1 = static_cast<int32_t>(f.x1);
      const int32_t y0 = static_cast<int32_t>(f.y0), y1 = static_cast<int32_t>(f.y1);
      SwapRect* hg = h + (g << L);
      int64_t* og = o + (g << L) + 1;
      for (int64_t r = 0; r < span; ++r) {
        const int32_t ux = vx[r], uy = vy[r];
        int32_t fx, fy, cx, cy;
        if (cut) {
          fx = x0 + ((ux - x0) & static_cast<int32_t>(mx));
          fy = y0 + ((uy - y0) & static_cast<int32_t>(my));
          cx = ((x1 - 1 - fx) >> lx) + 1;
          cy = ((y1 - 1 - fy) >> ly) + 1;
        } else {
          fx = std::max(x0, ux);
          fy = std::max(y0, uy);
          cx = static_cast<int32_t>(std::min<int64_t>(x1, ux + bx) - fx);
          cy = static_cast<int32_t>(std::min<int64_t>(y1, uy + by) - fy);
        }
        const bool some = cx > 0 && cy > 0;
        SwapRect& q = hg[r];
        q.x0 = some ? fx : 0;
        q.y0 = some ? fy : 0;
        q.nx = some ? cx : 0;
        q.ny = some ? cy : 0;
        q.sx = sx;
        q.sy = sy;
        q.lx = lx;
        q.ly = ly;
        total += some ? int64_t(cx) * cy : 0;
        og[r] = total;
      }
    }
  }
  plan.xpe.assign(static_cast<std::size_t>(plan.width), 0);
  plan.ype.assign(static_cast<std::size_t>(plan.height), 0);
  for (int k = 0; k < N; ++k) {
    const PixelBit& b = plan.bits[static_cast<std::size_t>(k)];
    auto& t = b.axis == 0 ? plan.xpe : plan.ype;
    for (std::size_t x = 0; x < t.size(); ++x)
      t[x] |= ((static_cast<int64_t>(x) >> b.level) & 1) << k;
  }
}

namespace {

// What the references read of a plan (an empty SwapPlan{}, or one whose
// rectangles plan_swap_into held out, was dereferenced as null).
void check_plan(const SwapPlan& plan) {
  const std::size_t N = plan.bits.size(),
                    P = static_cast<std::size_t>(std::max<int64_t>(plan.pes, 0));
  bool ok = plan.pes >= 1 && plan.front.size() == N && plan.offset.size() == N + 1 &&
            plan.held.size() == N + 1 && plan.xpe.size() == static_cast<std::size_t>(plan.width) &&
            plan.ype.size() == static_cast<std::size_t>(plan.height);
  for (std::size_t L = 0; ok && L <= N; ++L)
    ok = plan.offset[L].size() == P + 1 && plan.held[L].size() == P;
  if (!ok)
    throw ArgumentError("plan", plan.held.empty() && !plan.offset.empty()
                                    ? "its rectangles were held out (plan_swap_into's held_out): "
                                      "the references read them from the plan"
                                    : "not a plan made by plan_swap (empty or inconsistent)");
}

}  // namespace

std::vector<Rgba> swap_stage_reference(const SwapPlan& plan, int k, const std::vector<Rgba>& in) {
  check_plan(plan);
  if (k < 0 || k >= plan.stages()) throw ArgumentError("stage", "outside 0 .. N-1");
  const auto& hin = plan.held[static_cast<std::size_t>(k)];
  const auto& oin = plan.offset[static_cast<std::size_t>(k)];
  const auto& hout = plan.held[static_cast<std::size_t>(k + 1)];
  const auto& oout = plan.offset[static_cast<std::size_t>(k + 1)];
  if (static_cast<int64_t>(in.size()) != oin.back())
    throw ArgumentError("swap input", "size differs from the plan's level");
  std::vector<Rgba> out(static_cast<std::size_t>(oout.back()));
  for (int64_t p = 0; p < plan.pes; ++p) {
    const int64_t q = p ^ (int64_t(1) << k);
    const bool p_front = ((p >> k) & 1) == plan.front[static_cast<std::size_t>(k)];
    const SwapRect& hp = hin[static_cast<std::size_t>(p)];
    const SwapRect& hq = hin[static_cast<std::size_t>(q)];
    const SwapRect& ho = hout[static_cast<std::size_t>(p)];
    for (int64_t b = 0; b < ho.ny; ++b)
      for (int64_t a = 0; a < ho.nx; ++a) {
        const int64_t x = ho.x0 + a * ho.sx, y = ho.y0 + b * ho.sy;
        const Rgba vp =
            hp.contains(x, y)
                ? in[static_cast<std::size_t>(oin[static_cast<std::size_t>(p)] + hp.index(x, y))]
                : Rgba{};
        const Rgba vq =
            hq.contains(x, y)
                ? in[static_cast<std::size_t>(oin[static_cast<std::size_t>(q)] + hq.index(x, y))]
                : Rgba{};
        out[static_cast<std::size_t>(oout[static_cast<std::size_t>(p)] + b * ho.nx + a)] =
            p_front ? detail::over_inline(vp, vq) : detail::over_inline(vq, vp);
      }
  }
  return out;
}

std::vector<Rgba> swap_reference(const SwapPlan& plan, const Footprints& f) {
  check_plan(plan);
  if (f.rect_offset != plan.offset[0])
    throw ArgumentError("footprints", "do not match the plan's rectangles");
  std::vector<Rgba> buf = f.pixels;
  for (int k = 0; k < plan.stages(); ++k) buf = swap_stage_reference(plan, k, buf);
  return buf;
}

Image display_reference(const SwapPlan& plan, const std::vector<Rgba>& last) {
  check_plan(plan);
  const int N = plan.stages();
  if (static_cast<int64_t>(last.size()) != plan.level_size(N))
    throw ArgumentError("swap output", "size differs from the plan's last level");
  const auto& held = plan.held[static_cast<std::size_t>(N)];
  const auto& off = plan.offset[static_cast<std::size_t>(N)];
  Image im(plan.width, plan.height);
  for (int y = 0; y < plan.height; ++y)
    for (int x = 0; x < plan.width; ++x) {
      const int64_t p = plan.display_pe(x, y);
      const SwapRect& h = held[static_cast<std::size_t>(p)];
      if (h.contains(x, y))
        im.at(x, y) =
            last[static_cast<std::size_t>(off[static_cast<std::size_t>(p)] + h.index(x, y))];
    }
  return im;
}

SwapCost swap_cost(const SwapPlan& plan, const KdSplit& split, const ViewGeometry& view,
                   const PeGrid& grid) {
  check_plan(plan);
  if (grid.count() != plan.pes || split.pes() != plan.pes)
    throw ArgumentError("grid", "PE count differs from the plan's");
  SwapCost c;
  const int N = plan.stages();
  std::vector<int64_t> total_sent(static_cast<std::size_t>(plan.pes), 0);
  for (int k = 0; k < N; ++k) {
    const auto& hin = plan.held[static_cast<std::size_t>(k)];
    const auto& hout = plan.held[static_cast<std::size_t>(k + 1)];
    const PixelBit& bit = plan.bits[static_cast<std::size_t>(k)];
    SwapStageCost s;
    for (int64_t p = 0; p < plan.pes; ++p) {
      const int own = static_cast<int>((p >> k) & 1);
      const SwapRect& h = hin[static_cast<std::size_t>(p)];
      const int64_t sent = count_with_bit(h, bit, 1 - own);  // what the partner keeps
      s.moved += sent;
      s.max_sent = std::max(s.max_sent, sent);
      s.held += h.count();
      s.max_held = std::max(s.max_held, h.count());
      s.kept += hout[static_cast<std::size_t>(p)].count();
      s.max_kept = std::max(s.max_kept, hout[static_cast<std::size_t>(p)].count());
      s.max_distance = std::max(s.max_distance, mesh_distance(grid, p, p ^ (int64_t(1) << k)));
      total_sent[static_cast<std::size_t>(p)] += sent;
    }
    c.moved += s.moved;
    c.stages.push_back(s);
  }
  for (int64_t t : total_sent) c.max_pe_sent = std::max(c.max_pe_sent, t);
  double s2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = static_cast<double>(split.cell[a]) / view.step;
    s2 += e * e;
  }
  c.cell_section = 0.5 * s2;
  for (const PixelBit& b : plan.bits) ++(b.axis == 0 ? c.swaps_x : c.swaps_y);
  return c;
}

}  // namespace simdvol
