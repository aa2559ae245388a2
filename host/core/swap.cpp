// Binary swap and display: schedule, serial references, communication (swap.hpp).
#include "simdvol/swap.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

#include "simdvol/composite.hpp"
#include "simdvol/error.hpp"

namespace simdvol {

namespace {

bool is_pow2(int64_t n) {
  return n >= 1 && (n & (n - 1)) == 0;
}

int exact_log2(int64_t n) {
  int b = 0;
  while ((int64_t(1) << b) < n) ++b;
  return b;
}

// A half-open pixel box; empty when x0 >= x1 or y0 >= y1.
struct Box2 {
  int64_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  bool empty() const { return x0 >= x1 || y0 >= y1; }
};

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
  StridedRange r;
  if ((stride & (stride - 1)) == 0) {
    // A power of two (every stride of plan_swap): x mod stride is x & m for
    // any x in two's complement, and the divisions are shifts; the same
    // results as the general path below (tested).
    const int64_t m = stride - 1;
    r.first = lo + (((residue & m) - (lo & m)) & m);
    r.count = r.first < hi
                  ? ((hi - 1 - r.first) >> std::countr_zero(static_cast<uint64_t>(stride))) + 1
                  : 0;
    if (r.count == 0) r.first = lo;
    return r;
  }
  const int64_t rr = ((residue % stride) + stride) % stride;
  const int64_t lm = ((lo % stride) + stride) % stride;
  r.first = lo + ((rr - lm) % stride + stride) % stride;
  r.count = r.first < hi ? (hi - 1 - r.first) / stride + 1 : 0;
  if (r.count == 0) r.first = lo;
  return r;
}

std::vector<PixelBit> swap_pixel_bits(const PeGrid& grid, int width, int height,
                                      SwapLayout layout) {
  if (!is_pow2(grid.width) || !is_pow2(grid.height) || !is_pow2(grid.count()))
    throw ArgumentError("grid", "W and H must be powers of two");
  if (width < 1 || height < 1) throw ArgumentError("image", "width and height must be positive");
  const int nb[2] = {exact_log2(grid.width), exact_log2(grid.height)};
  const int64_t extent[2] = {width, height};
  int B[2];
  for (int a = 0; a < 2; ++a) B[a] = std::max(ceil_log2(extent[a]), nb[a]);
  std::vector<PixelBit> bits;
  int used[2] = {0, 0};
  int next = 0;  // axis to take when both have bits left
  while (used[0] < nb[0] || used[1] < nb[1]) {
    int a = next;
    if (used[a] >= nb[a]) a = 1 - a;
    const int j = used[a]++;
    bits.push_back({a, layout == SwapLayout::cut_and_stack ? j : B[a] - 1 - j});
    next = 1 - a;
  }
  return bits;
}

int swap_front(const KdSplit& split, const ViewGeometry& view, int stage) {
  if (stage < 0 || stage >= split.bits) throw ArgumentError("stage", "outside 0 .. N-1");
  const int a = split.bit_axis[static_cast<std::size_t>(stage)];
  return view.grid.step[a][2] >= 0 ? 0 : 1;
}

SwapPlan plan_swap(const std::vector<sv_rect>& rects, const KdSplit& split,
                   const ViewGeometry& view, const PeGrid& grid, SwapLayout layout) {
  const int64_t P = static_cast<int64_t>(rects.size());
  if (P != split.pes() || P != grid.count())
    throw ArgumentError("rects", "one footprint per PE of the split and the grid expected");
  const int N = split.bits;
  SwapPlan plan;
  plan.layout = layout;
  plan.width = view.width();
  plan.height = view.height();
  plan.pes = P;
  plan.bits = swap_pixel_bits(grid, plan.width, plan.height, layout);
  if (static_cast<int>(plan.bits.size()) != N) throw ArgumentError("grid", "PE bits differ");
  for (int k = 0; k < N; ++k) plan.front.push_back(swap_front(split, view, k));

  std::vector<Box2> F(static_cast<std::size_t>(P));
  for (int64_t p = 0; p < P; ++p) {
    const sv_rect& r = rects[static_cast<std::size_t>(p)];
    if (r.w < 0 || r.h < 0) throw ArgumentError("rects", "negative footprint size");
    if (r.w > 0 && r.h > 0 &&
        (r.i0 < 0 || r.j0 < 0 || r.i0 + r.w > plan.width || r.j0 + r.h > plan.height))
      throw ArgumentError("rects", "footprint of PE " + std::to_string(p) + " outside the image");
    F[static_cast<std::size_t>(p)] = {r.i0, int64_t(r.i0) + r.w, r.j0, int64_t(r.j0) + r.h};
  }
  const int64_t extent[2] = {plan.width, plan.height};
  plan.held.resize(static_cast<std::size_t>(N + 1));
  plan.offset.resize(static_cast<std::size_t>(N + 1));
  // Constraints of the stages before level L, per axis: j[a] constrained
  // levels, and PE p's values of them v[a][p] (grown by one stage per level).
  int j[2] = {0, 0};
  std::vector<int64_t> v[2] = {std::vector<int64_t>(static_cast<std::size_t>(P), 0),
                               std::vector<int64_t>(static_cast<std::size_t>(P), 0)};
  int B[2];  // hierarchical: the pixel bits per axis
  for (int a = 0; a < 2; ++a)
    B[a] =
        std::max(ceil_log2(extent[a]), a == 0 ? exact_log2(grid.width) : exact_log2(grid.height));
  std::vector<Box2> G(F.size());
  for (int L = 0; L <= N; ++L) {
    if (L > 0) {
      const int k = L - 1;
      for (int64_t p = 0; p < P; ++p)
        G[static_cast<std::size_t>(p)] = bbox(F[static_cast<std::size_t>(p)],
                                              F[static_cast<std::size_t>(p ^ (int64_t(1) << k))]);
      std::swap(F, G);
      const PixelBit& b = plan.bits[static_cast<std::size_t>(k)];
      for (int64_t p = 0; p < P; ++p)
        v[b.axis][static_cast<std::size_t>(p)] |= ((p >> k) & 1) << b.level;
      ++j[b.axis];
    }
    auto& held = plan.held[static_cast<std::size_t>(L)];
    auto& off = plan.offset[static_cast<std::size_t>(L)];
    held.resize(static_cast<std::size_t>(P));
    off.assign(static_cast<std::size_t>(P + 1), 0);
    const bool cut = layout == SwapLayout::cut_and_stack;
    const int64_t stride[2] = {cut ? int64_t(1) << j[0] : 1, cut ? int64_t(1) << j[1] : 1};
    const int32_t lx = cut ? j[0] : 0, ly = cut ? j[1] : 0;
    for (int64_t p = 0; p < P; ++p) {
      const Box2& f = F[static_cast<std::size_t>(p)];
      const int64_t lo[2] = {f.x0, f.y0}, hi[2] = {f.x1, f.y1};
      StridedRange rg[2];
      for (int a = 0; a < 2; ++a) {
        const int64_t va = v[a][static_cast<std::size_t>(p)];
        if (cut) {
          rg[a] = strided_range(lo[a], hi[a], stride[a], va);
        } else {
          // Levels B-1 .. B-j fixed: the block [v, v + 2^(B - j)).
          const int64_t blo = va, bhi = va + (int64_t(1) << (B[a] - j[a]));
          rg[a] = strided_range(std::max(lo[a], blo), std::min(hi[a], bhi), 1, 0);
        }
      }
      SwapRect h;
      h.sx = static_cast<int32_t>(stride[0]);
      h.sy = static_cast<int32_t>(stride[1]);
      h.lx = lx;
      h.ly = ly;
      if (!f.empty() && rg[0].count > 0 && rg[1].count > 0) {
        h.x0 = static_cast<int32_t>(rg[0].first);
        h.y0 = static_cast<int32_t>(rg[1].first);
        h.nx = static_cast<int32_t>(rg[0].count);
        h.ny = static_cast<int32_t>(rg[1].count);
      }
      held[static_cast<std::size_t>(p)] = h;
      off[static_cast<std::size_t>(p + 1)] = off[static_cast<std::size_t>(p)] + h.count();
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
  return plan;
}

std::vector<Rgba> swap_stage_reference(const SwapPlan& plan, int k, const std::vector<Rgba>& in) {
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
            p_front ? over(vp, vq) : over(vq, vp);
      }
  }
  return out;
}

std::vector<Rgba> swap_reference(const SwapPlan& plan, const Footprints& f) {
  if (f.rect_offset != plan.offset[0])
    throw ArgumentError("footprints", "do not match the plan's rectangles");
  std::vector<Rgba> buf = f.pixels;
  for (int k = 0; k < plan.stages(); ++k) buf = swap_stage_reference(plan, k, buf);
  return buf;
}

Image display_reference(const SwapPlan& plan, const std::vector<Rgba>& last) {
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
