// Serial references of the match and balance stages (see match.hpp).
#include "simdvol/match.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "simdvol/error.hpp"

namespace simdvol {

double Matching::utilisation() const {
  const int64_t mx = max_load();
  if (mx == 0 || loads.empty()) return 1.0;
  return static_cast<double>(total_load()) / static_cast<double>(loads.size()) /
         static_cast<double>(mx);
}

int64_t Matching::max_load() const {
  int64_t m = 0;
  for (int64_t l : loads) m = std::max(m, l);
  return m;
}

int64_t Matching::total_load() const {
  int64_t t = 0;
  for (int64_t l : loads) t += l;
  return t;
}

namespace {

// The box of the cell with index `idx`, clipped to the volume.
CellBox cell_box_at(const KdSplit& split, const Dims3& idx) {
  CellBox b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = idx[a] * split.cell[a];
    b.hi[a] = std::min(b.lo[a] + split.cell[a], split.dims[a]);
  }
  return b;
}

}  // namespace

CellBox cell_box(const KdSplit& split, int64_t pe) {
  return cell_box_at(split, split.cell_index(pe));
}

namespace {

void check_split(const ViewGeometry& view, const KdSplit& split) {
  for (int a = 0; a < 3; ++a)
    if (split.dims[a] != view.grid.dims[a])
      throw ArgumentError("split", "the k-d split's dims differ from the view's volume dims");
  if (split.bits < 0 || static_cast<int>(split.bit_axis.size()) != split.bits)
    throw ArgumentError("split", "malformed k-d split");
}

// Smallest k with base + k * d >= v (d > 0).
int64_t first_at_least(int64_t base, int64_t d, int64_t v) {
  int64_t k =
      static_cast<int64_t>(std::ceil(static_cast<double>(v - base) / static_cast<double>(d)));
  while (base + k * d < v) ++k;
  while (base + (k - 1) * d >= v) --k;
  return k;
}

// Smallest k with base + k * d < v (d < 0).
int64_t first_below(int64_t base, int64_t d, int64_t v) {
  int64_t k =
      static_cast<int64_t>(std::floor(static_cast<double>(base - v) / static_cast<double>(-d))) + 1;
  while (base + k * d >= v) ++k;
  while (base + (k - 1) * d < v) --k;
  return k;
}

}  // namespace

std::array<int64_t, 2> box_ray_range(const ViewGeometry& view, const CellBox& box, int64_t i,
                                     int64_t j) {
  if (box.empty()) return {0, 0};
  const int64_t depth = view.depth();
  int64_t lo = 0, hi = depth;
  for (int a = 0; a < 3; ++a) {
    const int64_t base = view.fixed(a, i, j, 0);
    const int64_t d = view.grid.step[a][2];
    const int64_t L = box.lo[a] * SV_ONE, H = box.hi[a] * SV_ONE;
    if (d == 0) {
      if (base < L || base >= H) return {0, 0};
      continue;
    }
    int64_t k0, k1;
    if (d > 0) {
      k0 = first_at_least(base, d, L);
      k1 = first_at_least(base, d, H);
    } else {
      k0 = first_below(base, d, H);
      k1 = first_below(base, d, L);
    }
    lo = std::max(lo, k0);
    hi = std::min(hi, k1);
    if (lo >= hi) return {0, 0};
  }
  return {lo, hi};
}

std::vector<sv_rect> match_candidates(const ViewGeometry& view, const KdSplit& split) {
  check_split(view, split);
  // X = o + M (i, j, k): invert M (the fixed-point map is exact, so the
  // preimage of a box is exactly the parallelepiped spanned by the mapped
  // vertices; double rounding is far below the 1-pixel pad).
  Vec3 o{};
  const Mat3 inv = inverse_viewing_map(view, o);
  const int64_t w = view.width(), h = view.height();
  std::vector<sv_rect> rects(static_cast<std::size_t>(split.pes()), sv_rect{0, 0, 0, 0});
  // The cells' boxes (cell_box) from two tables of cell indices: each bit of
  // the PE index adds its power of two to one axis' index, so the index of
  // p is that of its low bits plus that of its high bits.
  const int low = split.bits / 2;
  std::vector<Dims3> lo_idx(std::size_t(1) << low), hi_idx(std::size_t(1) << (split.bits - low));
  for (std::size_t q = 0; q < lo_idx.size(); ++q) lo_idx[q] = split.cell_index(int64_t(q));
  for (std::size_t q = 0; q < hi_idx.size(); ++q) hi_idx[q] = split.cell_index(int64_t(q) << low);
  for (int64_t p = 0; p < split.pes(); ++p) {
    const Dims3& il = lo_idx[static_cast<std::size_t>(p & ((int64_t(1) << low) - 1))];
    const Dims3& ih = hi_idx[static_cast<std::size_t>(p >> low)];
    const CellBox box = cell_box_at(split, Dims3{il[0] + ih[0], il[1] + ih[1], il[2] + ih[2]});
    if (box.empty()) continue;
    double lo[2] = {std::numeric_limits<double>::infinity(),
                    std::numeric_limits<double>::infinity()};
    double hi[2] = {-lo[0], -lo[1]};
    // The vertices' i and j, as multiply(inv, x) sums them ((0 + t0) + t1)
    // + t2, from the 12 products inv[c][a] x[a] of the two values of each
    // x[a] (the same doubles, without 8 full matrix products per PE). With
    // the cell boxes from the tables above: 0.39 -> 0.17 ms for 8,192 PEs
    // (a host loop; the same rectangles over 960 views, P and volumes).
    double t[2][3][2];
    for (int a = 0; a < 3; ++a) {
      const double xl = static_cast<double>(box.lo[a]) - o[a];
      const double xh = static_cast<double>(box.hi[a]) - o[a];
      for (int c = 0; c < 2; ++c) {
        t[c][a][0] = inv[c][a] * xl;
        t[c][a][1] = inv[c][a] * xh;
      }
    }
    for (int v = 0; v < 8; ++v)
      for (int c = 0; c < 2; ++c) {
        const double ijk = ((0.0 + t[c][0][v & 1]) + t[c][1][(v >> 1) & 1]) + t[c][2][(v >> 2) & 1];
        lo[c] = std::min(lo[c], ijk);
        hi[c] = std::max(hi[c], ijk);
      }
    const int64_t i0 = std::max<int64_t>(0, static_cast<int64_t>(std::floor(lo[0])) - 1);
    const int64_t i1 = std::min<int64_t>(w - 1, static_cast<int64_t>(std::ceil(hi[0])) + 1);
    const int64_t j0 = std::max<int64_t>(0, static_cast<int64_t>(std::floor(lo[1])) - 1);
    const int64_t j1 = std::min<int64_t>(h - 1, static_cast<int64_t>(std::ceil(hi[1])) + 1);
    if (i0 > i1 || j0 > j1) continue;
    rects[p] = sv_rect{static_cast<sv_i32>(i0), static_cast<sv_i32>(j0),
                       static_cast<sv_i32>(i1 - i0 + 1), static_cast<sv_i32>(j1 - j0 + 1)};
  }
  return rects;
}

Matching match_reference(const ViewGeometry& view, const KdSplit& split,
                         const std::vector<uint8_t>& active) {
  const std::vector<sv_rect> cand = match_candidates(view, split);
  const int64_t pes = split.pes();
  if (!active.empty() && static_cast<int64_t>(active.size()) != pes)
    throw ArgumentError(
        "active", std::to_string(active.size()) + " flags for " + std::to_string(pes) + " PEs");
  Matching m;
  m.seg_offset.assign(static_cast<std::size_t>(pes + 1), 0);
  m.rects.assign(static_cast<std::size_t>(pes), sv_rect{0, 0, 0, 0});
  m.loads.assign(static_cast<std::size_t>(pes), 0);
  m.active = active;
  for (int64_t p = 0; p < pes; ++p) {
    if (!active.empty() && !active[p]) {
      m.seg_offset[p + 1] = static_cast<int64_t>(m.segments.size());
      continue;
    }
    const CellBox box = cell_box(split, p);
    const sv_rect& c = cand[p];
    int64_t i0 = INT64_MAX, j0 = INT64_MAX, i1 = -1, j1 = -1, load = 0;
    for (int64_t j = c.j0; j < c.j0 + c.h; ++j)
      for (int64_t i = c.i0; i < c.i0 + c.w; ++i) {
        const auto r = box_ray_range(view, box, i, j);
        if (r[0] >= r[1]) continue;
        m.segments.push_back(sv_segment{static_cast<sv_i32>(i), static_cast<sv_i32>(j),
                                        static_cast<sv_i32>(r[0]), static_cast<sv_i32>(r[1])});
        load += r[1] - r[0];
        i0 = std::min(i0, i);
        i1 = std::max(i1, i);
        j0 = std::min(j0, j);
        j1 = std::max(j1, j);
      }
    m.seg_offset[p + 1] = static_cast<int64_t>(m.segments.size());
    m.loads[p] = load;
    if (i1 >= 0)
      m.rects[p] = sv_rect{static_cast<sv_i32>(i0), static_cast<sv_i32>(j0),
                           static_cast<sv_i32>(i1 - i0 + 1), static_cast<sv_i32>(j1 - j0 + 1)};
  }
  return m;
}

std::vector<uint8_t> match_active_reference(const KdSplit& split,
                                            const std::vector<uint8_t>& reach) {
  const int64_t brick = int64_t(1) << SV_BRICK_LOG2;
  Dims3 nb{};
  for (int a = 0; a < 3; ++a) nb[a] = (split.dims[a] + brick - 1) / brick;
  if (static_cast<int64_t>(reach.size()) != nb[0] * nb[1] * nb[2])
    throw ArgumentError("reach", std::to_string(reach.size()) + " bricks, not " +
                                     std::to_string(nb[0] * nb[1] * nb[2]));
  std::vector<uint8_t> active(static_cast<std::size_t>(split.pes()), 0);
  for (int64_t p = 0; p < split.pes(); ++p) {
    const CellBox box = cell_box(split, p);
    if (box.empty()) continue;
    for (int64_t z = box.lo[2] / brick; z <= (box.hi[2] - 1) / brick; ++z)
      for (int64_t y = box.lo[1] / brick; y <= (box.hi[1] - 1) / brick; ++y)
        for (int64_t x = box.lo[0] / brick; x <= (box.hi[0] - 1) / brick; ++x)
          if (reach[static_cast<std::size_t>((z * nb[1] + y) * nb[0] + x)]) active[p] = 1;
  }
  return active;
}

void check_matching(const Matching& m) {
  const int64_t P = m.pes();
  if (P < 0 || static_cast<int64_t>(m.seg_offset.size()) != P + 1 || m.seg_offset[0] != 0 ||
      m.seg_offset[static_cast<std::size_t>(P)] != static_cast<int64_t>(m.segments.size()))
    throw ArgumentError("matching", "segment offsets do not match the segments and PEs");
  for (int64_t p = 0; p < P; ++p)
    if (m.seg_offset[static_cast<std::size_t>(p + 1)] < m.seg_offset[static_cast<std::size_t>(p)])
      throw ArgumentError("matching", "segment offsets decrease at PE " + std::to_string(p));
}

void check_matching(const Matching& m, const ViewGeometry& view) {
  check_matching(m);
  for (const sv_segment& s : m.segments)
    if (s.i < 0 || s.j < 0 || s.i >= view.width() || s.j >= view.height() || s.k0 < 0 ||
        s.k1 < s.k0 || s.k1 > view.depth())
      throw ArgumentError("matching", "segment (" + std::to_string(s.i) + ", " +
                                          std::to_string(s.j) + ", " + std::to_string(s.k0) + ".." +
                                          std::to_string(s.k1) + ") lies outside the viewing grid");
}

std::vector<int32_t> balance_links(const Matching& m, const ViewGeometry& view,
                                   const KdSplit& split) {
  check_split(view, split);
  // (An offset or a k1 far outside had balance_links read wild memory.)
  check_matching(m, view);
  const int64_t pes = split.pes();
  if (m.pes() != pes || static_cast<int64_t>(m.seg_offset.size()) != pes + 1)
    throw ArgumentError("matching", "made for another PE count");
  if (m.segments.size() > static_cast<std::size_t>(INT32_MAX / 4))
    throw ArgumentError("matching", "too many segments for 32-bit links");
  if (!m.active.empty() && m.active.size() != static_cast<std::size_t>(pes))
    throw ArgumentError("matching", "active flags for another PE count");
  std::vector<int32_t> link(m.segments.size(), -1);
  for (int64_t p = 0; p < pes; ++p) {
    const Dims3 cp = split.cell_index(p);
    for (int64_t s = m.seg_offset[p]; s < m.seg_offset[p + 1]; ++s) {
      const sv_segment& g = m.segments[s];
      if (g.k1 >= view.depth()) continue;
      Dims3 cq{};
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        const int64_t f = fixed_floor(view.fixed(a, g.i, g.j, g.k1));
        if (f < 0 || f >= split.dims[a]) inside = false;
        cq[a] = f / split.cell[a];
      }
      if (!inside) continue;
      int axis = -1, differing = 0;
      bool face = true;
      for (int a = 0; a < 3; ++a) {
        const int64_t dd = cq[a] - cp[a];
        if (dd == 0) continue;
        ++differing;
        axis = a;
        if (dd != 1 && dd != -1) face = false;
      }
      if (differing != 1 || !face) continue;
      const int64_t q = split.pe_of_cell(cq);
      if (!m.active.empty() && !m.active[q]) continue;  // no link into an inactive PE
      const auto first = m.segments.begin() + m.seg_offset[q];
      const auto last = m.segments.begin() + m.seg_offset[q + 1];
      const auto it =
          std::lower_bound(first, last, g, [](const sv_segment& x, const sv_segment& y) {
            return x.j != y.j ? x.j < y.j : x.i < y.i;
          });
      if (it == last || it->i != g.i || it->j != g.j || it->k0 != g.k1)
        throw ArgumentError("matching", "not the matching of this view and split");
      link[s] = static_cast<int32_t>((it - m.segments.begin()) * 4 + axis);
    }
  }
  return link;
}

namespace {

// Moves `t` samples across the face between F and B (B the face neighbour
// along `a` that F's rays pass into): F gives when t > 0, B gives when t < 0;
// capped by what the giver holds on the linked rays. Returns the number
// moved (same sign as t). Equal shares (see match.hpp): with n linked rays
// and W = |t|, linked ray r (0-based, in F's segment order) gives
// min(len_r, share_r): share_r = floor((r + 1) W / n) - floor(r W / n) for
// W >= n, 1 for r < W (else 0) for W < n; the shortfall, where some ray
// held less than its share, is then taken greedily in the same order (each
// ray gives what it still holds, until W is reached).
int64_t transfer(Matching& m, const std::vector<int32_t>& link, int64_t F, int a, int64_t t) {
  if (t == 0) return 0;
  const bool front_gives = t > 0;
  const int64_t want = front_gives ? t : -t;
  auto len = [&](int64_t s) -> int64_t {
    const sv_segment& g = front_gives ? m.segments[s] : m.segments[link[s] >> 2];
    return g.k1 - g.k0;
  };
  auto linked = [&](int64_t s) { return link[s] >= 0 && (link[s] & 3) == a; };
  auto give = [&](int64_t s, int64_t n) {
    const int64_t shift = front_gives ? -n : n;
    m.segments[s].k1 = static_cast<sv_i32>(m.segments[s].k1 + shift);
    m.segments[link[s] >> 2].k0 = static_cast<sv_i32>(m.segments[link[s] >> 2].k0 + shift);
  };
  int64_t n = 0;
  for (int64_t s = m.seg_offset[F]; s < m.seg_offset[F + 1]; ++s) n += linked(s);
  if (n == 0) return 0;
  int64_t moved = 0, r = 0;
  for (int64_t s = m.seg_offset[F]; s < m.seg_offset[F + 1]; ++s) {
    if (!linked(s)) continue;
    const int64_t share = want >= n ? (r + 1) * want / n - r * want / n : (r < want ? 1 : 0);
    ++r;
    const int64_t g = std::min(share, len(s));
    if (g > 0) give(s, g);
    moved += g;
  }
  for (int64_t s = m.seg_offset[F]; s < m.seg_offset[F + 1] && moved < want; ++s) {
    if (!linked(s)) continue;
    const int64_t g = std::min(want - moved, len(s));
    if (g > 0) give(s, g);
    moved += g;
  }
  return front_gives ? moved : -moved;
}

}  // namespace

Matching balance_reference(const Matching& m0, const ViewGeometry& view, const KdSplit& split,
                           int sweeps) {
  if (sweeps < 0 || sweeps > kMaxBalanceSweeps)  // (INT_MAX ran on for hours)
    throw ArgumentError(
        "sweeps", std::to_string(sweeps) + " is outside 0 .. " + std::to_string(kMaxBalanceSweeps));
  const std::vector<int32_t> link = balance_links(m0, view, split);
  Matching m = m0;
  const int64_t pes = split.pes();
  const Dims3 splits = split.splits();
  for (int sweep = 0; sweep < sweeps; ++sweep)
    for (int a = 0; a < 3; ++a) {
      const int64_t dir = view.grid.step[a][2];
      if (dir == 0) continue;  // no ray crosses a face along a
      for (int par = 0; par < 2; ++par)
        for (int64_t p = 0; p < pes; ++p) {
          Dims3 cp = split.cell_index(p);
          if (cp[a] % 2 != par || cp[a] + 1 >= splits[a]) continue;
          cp[a] += 1;
          const int64_t q = split.pe_of_cell(cp);
          const int64_t F = dir > 0 ? p : q, B = dir > 0 ? q : p;
          const int64_t diff = m.loads[F] - m.loads[B];
          const int64_t moved = transfer(m, link, F, a, diff / 2);  // truncates towards 0
          m.loads[F] -= moved;
          m.loads[B] += moved;
        }
    }
  return m;
}

}  // namespace simdvol
