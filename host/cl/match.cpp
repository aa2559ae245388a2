// The match and balance stages on the device (see match_cl.hpp).
#include "simdvol/match_cl.hpp"

#include "env_switch.hpp"
#include "simdvol/local_cl.hpp"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <string>

namespace simdvol {

namespace {

// Work-items loop (scalar code under PoCL); 64 per group (WGS,
// Device::wgs(): fewer only where the device takes fewer) keeps the group
// count (P x H / 64 for the row kernels, P / 64 for the others) in the
// hundreds to thousands. The kernels are declared
// reqd_work_group_size(WGS, 1, 1): launched with exactly that local size.

cl_int4 int4(int64_t x, int64_t y, int64_t z, int64_t w) {
  cl_int4 v;
  v.s[0] = static_cast<cl_int>(x);
  v.s[1] = static_cast<cl_int>(y);
  v.s[2] = static_cast<cl_int>(z);
  v.s[3] = static_cast<cl_int>(w);
  return v;
}

}  // namespace

std::uint64_t events_ns(const std::vector<StageEvent>& events) {
  std::uint64_t t = 0;
  for (const StageEvent& e : events) t += event_ns(e.event);
  return t;
}

namespace {

// The row geometry of match.cl (sv_row_range): with (i, j, k) = M^-1 (X - o),
// u_a = the (i, j) components of M^-1 c_a e_a (the projection of a cell edge),
// the projection of cell cidx is the zonogon centred at
//   ctr = g0 + sum_a cidx_a u_a,  g0 = (M^-1 (c / 2 - o))_(i,j),
// the intersection of the strips |n_a . (p - ctr)| <= h_a, n_a a unit normal
// of u_a, h_a = 1/2 sum_(b != a) |n_a . u_b| (+ a pad of 0.05 px, far above
// the float rounding of the device). A strip that is degenerate or bounds j
// only (n_a.i ~ 0) is left out: the candidate rectangle bounds the rest.
// Layout: [0, 1] g0, [2..4] u_a.i, [5..7] u_a.j, [8..10] n_a.i,
// [11..13] n_a.j, [14..16] h_a.
std::array<float, 20> row_geometry(const ViewGeometry& view, const KdSplit& split) {
  Vec3 o{};
  const Mat3 inv = inverse_viewing_map(view, o);
  std::array<float, 20> g{};
  Vec3 half{};
  for (int a = 0; a < 3; ++a) half[a] = 0.5 * static_cast<double>(split.cell[a]) - o[a];
  const Vec3 g0 = multiply(inv, half);
  g[0] = static_cast<float>(g0[0]);
  g[1] = static_cast<float>(g0[1]);
  double u[3][2];
  for (int a = 0; a < 3; ++a) {
    u[a][0] = inv[0][a] * static_cast<double>(split.cell[a]);
    u[a][1] = inv[1][a] * static_cast<double>(split.cell[a]);
    g[2 + a] = static_cast<float>(u[a][0]);
    g[5 + a] = static_cast<float>(u[a][1]);
  }
  for (int a = 0; a < 3; ++a) {
    double ni = -u[a][1], nj = u[a][0];
    const double len = std::hypot(ni, nj);
    if (!(len > 1e-9)) continue;
    ni /= len;
    nj /= len;
    if (std::abs(ni) < 1e-6) continue;
    double h = 0.05;
    for (int b = 0; b < 3; ++b)
      if (b != a) h += 0.5 * std::abs(ni * u[b][0] + nj * u[b][1]);
    g[8 + a] = static_cast<float>(ni);
    g[11 + a] = static_cast<float>(nj);
    g[14 + a] = static_cast<float>(h);
  }
  return g;
}

// Per axis: m = |d|, and delta = dq m + dr (0 <= dr < m), delta = -s for
// d > 0, +s for d < 0 (s = step along i, d = step along k).
std::array<cl_long, 9> step_constants(const ViewGeometry& view) {
  std::array<cl_long, 9> c{};
  for (int a = 0; a < 3; ++a) {
    const int64_t s = view.grid.step[a][0], d = view.grid.step[a][2];
    if (d == 0) {
      c[3 * a] = 1;
      continue;
    }
    const int64_t m = d > 0 ? d : -d;
    const int64_t delta = d > 0 ? -s : s;
    int64_t dq = delta / m, dr = delta % m;
    if (dr < 0) dr += m, --dq;
    c[3 * a] = m;
    c[3 * a + 1] = dq;
    c[3 * a + 2] = dr;
  }
  return c;
}

}  // namespace

namespace {

// The matching with the PE mask `active` (cl_uchar[P]) already enqueued and
// the PE tables uploaded (upload_pe_tables).
DeviceMatching enqueue_match_masked(Device& device, const ViewGeometry& view, const KdSplit& split,
                                    DeviceMatching m, MatchLinks links);

void set_pe_tables(DeviceMatching& m, const DevicePeTables& t) {
  m.cidx = t.cidx;
  m.pe_of = t.pe_of;
  m.pairs = t.pairs;
  m.pair_first = t.pair_first;
}

// The matching with the brick reach's PE mask (simdvol_match_active) and
// the split's tables `t`.
DeviceMatching enqueue_match_reach(Device& device, const ViewGeometry& view, const KdSplit& split,
                                   const BrickReach& reach, const DevicePeTables& t,
                                   MatchLinks links);

}  // namespace

// cidx (cell index of each PE), pe_of (PE of each cell), the balance pairs.
DevicePeTables upload_pe_tables(Device& device, const KdSplit& split) {
  DevicePeTables m;
  m.split = split;
  const int64_t pes = split.pes();
  std::vector<cl_int4> cidx(static_cast<std::size_t>(pes));
  std::vector<cl_int> pe_of(static_cast<std::size_t>(pes));
  const Dims3 sp = split.splits();
  for (int64_t p = 0; p < pes; ++p) {
    const Dims3 c = split.cell_index(p);
    cidx[p] = int4(c[0], c[1], c[2], 0);
    pe_of[(c[2] * sp[1] + c[1]) * sp[0] + c[0]] = static_cast<cl_int>(p);
  }
  // The balance rounds' pairs, per (axis, parity): (the PE of cell index c,
  // the PE of c + 1) along the axis for c = 2 m + parity.
  std::vector<cl_int2> pairs;
  pairs.reserve(static_cast<std::size_t>(pes) * 3);
  for (int a = 0; a < 3; ++a)
    for (int par = 0; par < 2; ++par) {
      m.pair_first[static_cast<std::size_t>(2 * a + par)] = static_cast<cl_int>(pairs.size());
      for (int64_t p = 0; p < pes; ++p) {
        const cl_int4& ci = cidx[static_cast<std::size_t>(p)];
        Dims3 c{ci.s[0], ci.s[1], ci.s[2]};
        if ((c[a] & 1) != par || c[a] + 1 >= sp[a]) continue;
        c[a] += 1;
        pairs.push_back(
            cl_int2{{static_cast<cl_int>(p), pe_of[(c[2] * sp[1] + c[1]) * sp[0] + c[0]]}});
      }
    }
  m.pair_first[6] = static_cast<cl_int>(pairs.size());
  if (pairs.empty()) pairs.push_back(cl_int2{{0, 0}});  // (a buffer is never empty)
  const auto ro = CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR;
  m.cidx = device.buffer(ro, cidx.size() * sizeof(cl_int4), cidx.data(), "PE cell indices");
  m.pe_of = device.buffer(ro, pe_of.size() * sizeof(cl_int), pe_of.data(), "PE of cell");
  m.pairs = device.buffer(ro, pairs.size() * sizeof(cl_int2), pairs.data(), "balance pairs");
  std::vector<cl_uchar> every(static_cast<std::size_t>(std::max<int64_t>(pes, 1)), 1);
  m.every_pe = device.buffer(ro, every.size(), every.data(), "PE mask");
  return m;
}

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             MatchLinks links) {
  return enqueue_match(device, view, split, std::vector<uint8_t>{}, links);
}

namespace {

// The matching of the PEs flagged in `active` (every PE where empty: the
// tables' all-ones mask, no upload) with the split's tables `t`.
DeviceMatching enqueue_match_flags(Device& device, const ViewGeometry& view, const KdSplit& split,
                                   const std::vector<uint8_t>& active, const DevicePeTables& t,
                                   MatchLinks links) {
  DeviceMatching m;
  m.masked = !active.empty();
  if (m.masked) {
    std::vector<cl_uchar> flags(active.size());
    for (std::size_t p = 0; p < active.size(); ++p) flags[p] = active[p] ? 1 : 0;
    m.active = device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, flags.size(), flags.data(),
                             "PE mask");
  } else {
    m.active = t.every_pe;
  }
  set_pe_tables(m, t);
  return enqueue_match_masked(device, view, split, std::move(m), links);
}

// ArgumentError unless `tables` were made for `split`.
void check_tables(const DevicePeTables& tables, const KdSplit& split) {
  if (!(tables.split == split)) throw ArgumentError("tables", "PE tables made for another split");
}

// ArgumentError unless `reach` is a brick reach of the split's volume.
void check_reach(const BrickReach& reach, const KdSplit& split) {
  if (reach.reach == nullptr) throw ArgumentError("reach", "no brick reach buffer");
  for (int a = 0; a < 3; ++a)
    if (reach.bricks[a] != (split.dims[a] + (1 << SV_BRICK_LOG2) - 1) >> SV_BRICK_LOG2)
      throw ArgumentError("reach", "bricks do not tile the volume of the split");
}

}  // namespace

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const std::vector<uint8_t>& active, MatchLinks links) {
  const int64_t pes = split.pes();
  if (!active.empty() && static_cast<int64_t>(active.size()) != pes)
    throw ArgumentError(
        "active", std::to_string(active.size()) + " flags for " + std::to_string(pes) + " PEs");
  return enqueue_match_flags(device, view, split, active, upload_pe_tables(device, split), links);
}

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const DevicePeTables& tables, MatchLinks links) {
  check_tables(tables, split);
  return enqueue_match_flags(device, view, split, {}, tables, links);
}

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const BrickReach& reach, MatchLinks links) {
  check_reach(reach, split);  // (before the tables' upload)
  return enqueue_match_reach(device, view, split, reach, upload_pe_tables(device, split), links);
}

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split,
                             const BrickReach& reach, const DevicePeTables& tables,
                             MatchLinks links) {
  check_tables(tables, split);
  check_reach(reach, split);
  return enqueue_match_reach(device, view, split, reach, tables, links);
}

namespace {

// (reach checked by the caller: check_reach)
DeviceMatching enqueue_match_reach(Device& device, const ViewGeometry& view, const KdSplit& split,
                                   const BrickReach& reach, const DevicePeTables& t,
                                   MatchLinks links) {
  const int64_t pes = split.pes();
  DeviceMatching m;
  m.masked = true;
  m.active = device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(pes, 1)),
                           nullptr, "PE mask");
  set_pe_tables(m, t);
  const cl_int4 cell = int4(split.cell[0], split.cell[1], split.cell[2], 0);
  const cl_int4 dims = int4(split.dims[0], split.dims[1], split.dims[2], 0);
  const cl_int4 nb = int4(reach.bricks[0], reach.bricks[1], reach.bricks[2], 0);
  cl::Kernel k = device.kernel("match", "simdvol_match_active", device.wgs_defines());
  set_args(k, "simdvol_match_active", m.cidx, cell, dims, static_cast<cl_int>(pes), *reach.reach,
           nb, m.active);
  m.match_events.push_back({"match_active", device.run(k, "simdvol_match_active",
                                                       cl::NDRange(static_cast<std::size_t>(pes)),
                                                       cl::NDRange(device.wgs()))});
  return enqueue_match_masked(device, view, split, std::move(m), links);
}

DeviceMatching enqueue_match_masked(Device& device, const ViewGeometry& view, const KdSplit& split,
                                    DeviceMatching m, MatchLinks links) {
  const std::vector<sv_rect> cand = match_candidates(view, split);  // validates the split
  const int64_t pes = split.pes();
  if (pes > INT_MAX / 2) throw ArgumentError("split", "too many PEs");
  int64_t capacity = 0, rows = 1, most = 0;
  for (const sv_rect& r : cand) {
    capacity += int64_t(r.w) * r.h;
    rows = std::max<int64_t>(rows, r.h);
    most = std::max<int64_t>(most, int64_t(r.w) * r.h);
  }
  if (capacity > INT_MAX / 4)
    throw ArgumentError("view", "too many candidate rays for 32-bit segment indices");
  rows = (rows + 7) / 8 * 8;  // the row kernels take 8 rows of one PE per work-item
  if (pes * rows > INT_MAX / 2) throw ArgumentError("view", "too many rows for 32-bit indices");
  for (int a = 0; a < 3; ++a)
    if (split.cell[a] > INT_MAX) throw ArgumentError("split", "cell too large");
  capacity = std::max<int64_t>(capacity, 1);

  m.pes = pes;
  m.capacity = capacity;
  m.rows = rows;
  const Dims3 sp = split.splits();
  std::array<float, 20> geo = row_geometry(view, split);
  std::array<cl_long, 9> steps = step_constants(view);
  const auto ro = CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR;
  m.candidates = device.buffer(ro, cand.size() * sizeof(sv_rect), const_cast<sv_rect*>(cand.data()),
                               "candidate rectangles");
  sv_view v = view.grid;
  m.view = device.buffer(ro, sizeof(sv_view), &v, "view");
  m.geometry = device.buffer(ro, sizeof(geo), geo.data(), "row geometry");
  m.steps = device.buffer(ro, sizeof(steps), steps.data(), "step constants");
  const std::size_t P = static_cast<std::size_t>(pes);
  const std::size_t R = P * static_cast<std::size_t>(rows);
  const auto rw = CL_MEM_READ_WRITE;
  m.rowsum = device.scratch_buffer(rw, R * sizeof(cl_int4), "row sums");
  m.rowlinks = device.scratch_buffer(rw, R * sizeof(cl_int4), "row links");
  m.rowoff = device.scratch_buffer(rw, R * sizeof(cl_int4), "row offsets");
  m.petot = device.buffer(rw, P * sizeof(cl_int4), nullptr, "PE totals");
  m.counts = device.buffer(rw, P * sizeof(cl_int), nullptr, "segment counts");
  m.seg_offset = device.buffer(rw, (P + 1) * sizeof(cl_int), nullptr, "seg_offset");
  const std::size_t C = static_cast<std::size_t>(capacity);
  m.segments = device.scratch_buffer(rw, C * sizeof(sv_segment), "segments");
  m.rects = device.buffer(rw, P * sizeof(sv_rect), nullptr, "footprint rects");
  m.loads = device.buffer(rw, P * sizeof(cl_int), nullptr, "loads");
  m.linked = links == MatchLinks::make;
  // Without links the kernels write no link list (a placeholder).
  const std::size_t LC = m.linked ? C : 1;
  // Narrow links where every PE's segments (at most its candidate rays)
  // have 16-bit indices.
  m.links_narrow = m.linked && most <= 65536;
  // The balance's 16-bit bounds, where they will do: the fill writes them
  // beside the segments (a placeholder otherwise; enqueue_balance packs).
  m.bounds_filled = m.linked && balance_bounds16(view.grid.grid[2]);
  m.bounds =
      device.scratch_buffer(rw, (m.bounds_filled ? C : 1) * sizeof(cl_short2), "balance bounds");
  m.link_offset = device.buffer(rw, (P + 1) * sizeof(cl_int4), nullptr, "link offsets");
  m.link_list = device.scratch_buffer(rw, LC * (m.links_narrow ? sizeof(cl_uint) : sizeof(cl_int2)),
                                      "link lists");
  m.link_base =
      device.buffer(rw, (m.links_narrow ? P : 1) * sizeof(cl_int4), nullptr, "link bases");
  // The rows' column results saved for the fill (match.cl: sv_kpack8), where
  // 15-bit bounds hold every k and the scratch has 32-bit indices: per PE
  // ceil8(h) * w of them, koff[p] the sum over the PEs before p.
  std::vector<cl_int> koff(P, 0);
  int64_t kwords = 0;
  for (std::size_t p = 0; p < P; ++p) {
    koff[p] = static_cast<cl_int>(std::min<int64_t>(kwords, INT_MAX));
    kwords += int64_t(cand[p].w) * ((int64_t(cand[p].h) + 7) / 8 * 8);
  }
  m.columns_saved = view.grid.grid[2] <= 32767 && kwords <= INT_MAX - 8 &&
                    detail::env_switch("SIMDVOL_MATCH_SAVED").value_or(true);
  m.column_scratch = device.scratch_buffer(
      rw,
      static_cast<std::size_t>(m.columns_saved ? std::max<int64_t>(kwords, 1) : 1) *
          sizeof(cl_uint),
      "saved columns");
  m.column_offsets = device.buffer(ro, P * sizeof(cl_int), koff.data(), "saved column offsets");
  const std::string rows_name = m.linked ? "simdvol_match_rows" : "simdvol_match_rows_nolinks";
  const std::string fill_name = m.linked ? "simdvol_match_fill" : "simdvol_match_fill_nolinks";

  const cl_int4 cell = int4(split.cell[0], split.cell[1], split.cell[2], 0);
  const cl_int4 splits = int4(sp[0], sp[1], sp[2], 0);
  const cl_int npes = static_cast<cl_int>(pes), H = static_cast<cl_int>(rows);

  cl::Kernel k_rows = device.kernel("match", rows_name, device.wgs_defines());
  set_args(k_rows, rows_name, m.view, m.geometry, m.steps, m.candidates, m.cidx, cell, splits,
           m.pe_of, m.active, npes, H, m.rowsum, m.rowlinks, m.column_scratch, m.column_offsets,
           cl_int(m.columns_saved));
  m.match_events.push_back(
      {"match_rows", device.run(k_rows, rows_name, cl::NDRange(R / 8), cl::NDRange(device.wgs()))});
  cl::Kernel k_pe = device.kernel("match", "simdvol_match_pe", device.wgs_defines());
  set_args(k_pe, "simdvol_match_pe", m.candidates, m.active, npes, H, m.rowsum, m.rowlinks,
           m.rowoff, m.petot, m.counts, m.rects, m.loads);
  m.match_events.push_back({"match_pe", device.run(k_pe, "simdvol_match_pe", cl::NDRange(P),
                                                   cl::NDRange(device.wgs()))});
  cl::Kernel k_scan = device.kernel("match", "simdvol_match_scan", device.wgs_defines());
  set_args(k_scan, "simdvol_match_scan", m.petot, npes, m.seg_offset, m.link_offset);
  m.match_events.push_back(
      {"match_scan", device.run(k_scan, "simdvol_match_scan", cl::NDRange(device.wgs()),
                                cl::NDRange(device.wgs()))});
  cl::Kernel k_fill = device.kernel("match", fill_name, device.wgs_defines());
  set_args(k_fill, fill_name, m.view, m.geometry, m.steps, m.candidates, m.cidx, cell, splits,
           m.pe_of, m.active, npes, H, m.rowsum, m.rowlinks, m.rowoff, m.seg_offset, m.link_offset,
           m.segments, m.bounds, cl_int(m.bounds_filled), m.link_list, cl_int(m.links_narrow),
           m.link_base, m.column_scratch, m.column_offsets, cl_int(m.columns_saved));
  m.match_events.push_back(
      {"match_fill", device.run(k_fill, fill_name, cl::NDRange(R / 8), cl::NDRange(device.wgs()))});
  return m;
}

}  // namespace

cl::Event enqueue_zero_uncovered(Device& device, const DeviceMatching& m, DeviceFootprints& fp) {
  if (static_cast<int64_t>(fp.rect_offset.size()) != m.pes + 1)
    throw ArgumentError("footprints", "made for another PE count than the matching");
  check_footprints(fp, m.pes);
  const std::string name = "simdvol_zero_uncovered";
  cl::Kernel k = device.kernel("match", name, device.wgs_defines());
  set_args(k, name, m.candidates, m.rects, m.rowsum, static_cast<cl_int>(m.pes),
           static_cast<cl_int>(m.rows), fp.offsets, fp.pixels);
  const std::size_t items = static_cast<std::size_t>(std::max<int64_t>(m.pes * m.rows / 8, 1));
  return device.run(k, name, cl::NDRange(items), cl::NDRange(device.wgs()));  // (run rounds up)
}

bool balance_bounds16(int64_t depth) {
  return depth <= 32767;
}

namespace {

void enqueue_unpack(Device& device, DeviceMatching& m, const std::string& name,
                    const cl::Buffer& kk) {
  cl::Kernel unpack = device.kernel("balance", name, device.wgs_defines());
  set_args(unpack, name, m.seg_offset, static_cast<cl_int>(m.pes), kk, m.segments);
  const std::size_t slots = static_cast<std::size_t>(m.capacity);  // Device::run rounds up
  m.balance_events.push_back(
      {"balance_unpack", device.run(unpack, name, cl::NDRange(slots), cl::NDRange(device.wgs()))});
}

}  // namespace

void enqueue_balance_unpack(Device& device, DeviceMatching& m) {
  if (!m.unpack_pending) return;
  enqueue_unpack(device, m, "simdvol_balance_unpack16", m.bounds);
  m.unpack_pending = false;
}

void enqueue_balance(Device& device, DeviceMatching& m, const ViewGeometry& view,
                     const KdSplit& split, int sweeps, BalanceBounds bounds, BalanceUnpack unpack) {
  if (sweeps < 0) throw ArgumentError("sweeps", "must be >= 0");
  if (m.pes != split.pes()) throw ArgumentError("matching", "made for another PE count");
  if (sweeps > 0 && !m.linked)
    throw ArgumentError("matching",
                        "made without balance links (MatchLinks::skip): balancing needs them");
  const Dims3 sp = split.splits();
  const cl_int npes = static_cast<cl_int>(m.pes);
  const int64_t depth = view.grid.grid[2];
  bool narrow = bounds == BalanceBounds::narrow;
  if (bounds == BalanceBounds::automatic) narrow = balance_bounds16(depth);
  if (narrow && !balance_bounds16(depth))
    throw ArgumentError(
        "bounds", "16-bit balance bounds cannot hold a grid depth of " + std::to_string(depth));
  struct Round {
    int axis, par, dir, sweep;
  };
  std::vector<Round> rounds;
  for (int sweep = 0; sweep < sweeps; ++sweep)
    for (int a = 0; a < 3; ++a) {
      const int64_t dir = view.grid.step[a][2];
      if (dir == 0 || sp[a] < 2) continue;
      for (int par = 0; par < 2; ++par) rounds.push_back({a, par, dir > 0 ? 1 : -1, sweep});
    }
  if (rounds.empty()) return;
  // The rounds move the bounds (k0, k1) in a compact copy (balance.cl).
  // The frame's program (stage_program_source): both widths' kernels in it.
  const Defines& defs = device.wgs_defines();
  const std::string sfx = narrow ? "16" : "";
  const std::string pack_name = "simdvol_balance_pack" + sfx,
                    round_name = "simdvol_balance_round" + sfx + (m.links_narrow ? "n" : ""),
                    unpack_name = "simdvol_balance_unpack" + sfx;
  const std::size_t slots = static_cast<std::size_t>(m.capacity);  // Device::run rounds up
  // The 16-bit bounds are the fill's (its copy of the segments' k0, k1, kept
  // equal to them by the unpack after every balance); else a pack.
  const bool filled = narrow && m.bounds_filled;
  // A 32-bit balance packs from the segments: a deferred unpack first.
  if (!filled) enqueue_balance_unpack(device, m);
  m.bounds_filled = filled;  // a 32-bit balance leaves the fill's copy behind
  const cl::Buffer kk =
      filled ? m.bounds
             : device.scratch_buffer(CL_MEM_READ_WRITE,
                                     static_cast<std::size_t>(m.capacity) * (narrow ? 4 : 8),
                                     "balance bounds");
  if (!filled) {
    cl::Kernel pack = device.kernel("balance", pack_name, defs);
    set_args(pack, pack_name, m.seg_offset, npes, m.segments, kk);
    m.balance_events.push_back({"balance_pack", device.run(pack, pack_name, cl::NDRange(slots),
                                                           cl::NDRange(device.wgs()))});
  }
  // Which sweeps moved samples: the rounds of a sweep after one that moved
  // none return at once (balance.cl, SV_BAL_SETTLED).
  // One flag per cache line (SV_BAL_MOVES_STRIDE ints).
  const std::size_t moves_bytes =
      static_cast<std::size_t>(sweeps) * SV_BAL_MOVES_STRIDE * sizeof(cl_int);
  const cl::Buffer moves = device.scratch_buffer(CL_MEM_READ_WRITE, moves_bytes, "balance moves");
  cl_check(device.queue().enqueueFillBuffer(moves, cl_int(0), 0, moves_bytes),
           "clEnqueueFillBuffer(balance moves)");
  for (const Round& r : rounds) {
    cl::Kernel round = device.kernel("balance", round_name, defs);
    const std::size_t list = static_cast<std::size_t>(2 * r.axis + r.par);
    const cl_int first = m.pair_first[list], npairs = m.pair_first[list + 1] - first;
    if (npairs == 0) continue;
    set_args(round, round_name, m.pairs, first, npairs, cl_int(r.axis), cl_int(r.dir),
             m.link_offset, m.link_list, kk, m.loads, moves, cl_int(r.sweep));
    m.balance_events.push_back(
        {"balance_round",
         device.run(round, round_name,
                    cl::NDRange((static_cast<std::size_t>(npairs) + SV_BAL_PES - 1) / SV_BAL_PES),
                    cl::NDRange(device.wgs()))});
  }
  // The fill's 16-bit copy may stay the only current one (deferred).
  if (filled && unpack == BalanceUnpack::deferred) {
    m.unpack_pending = true;
    return;
  }
  enqueue_unpack(device, m, unpack_name, kk);
  m.unpack_pending = false;  // (a 32-bit balance unpacked a pending one first)
}

Matching DeviceMatching::read(Device& device) const {
  const std::size_t P = static_cast<std::size_t>(pes);
  std::vector<cl_int> off(P + 1), loads32(P);
  Matching m;
  m.rects.resize(P);
  auto& q = device.queue();
  cl_check(q.enqueueReadBuffer(seg_offset, CL_TRUE, 0, off.size() * sizeof(cl_int), off.data()),
           "clEnqueueReadBuffer(seg_offset)");
  m.segments.resize(static_cast<std::size_t>(off[P]));
  if (off[P] > 0) {
    cl_check(q.enqueueReadBuffer(segments, CL_TRUE, 0, m.segments.size() * sizeof(sv_segment),
                                 m.segments.data()),
             "clEnqueueReadBuffer(segments)");
    if (unpack_pending) {  // the balanced bounds are in `bounds` only
      std::vector<cl_short2> b(m.segments.size());
      cl_check(q.enqueueReadBuffer(bounds, CL_TRUE, 0, b.size() * sizeof(cl_short2), b.data()),
               "clEnqueueReadBuffer(balance bounds)");
      for (std::size_t s = 0; s < b.size(); ++s) {
        m.segments[s].k0 = b[s].s[0];
        m.segments[s].k1 = b[s].s[1];
      }
    }
  }
  cl_check(q.enqueueReadBuffer(rects, CL_TRUE, 0, P * sizeof(sv_rect), m.rects.data()),
           "clEnqueueReadBuffer(rects)");
  cl_check(q.enqueueReadBuffer(loads, CL_TRUE, 0, P * sizeof(cl_int), loads32.data()),
           "clEnqueueReadBuffer(loads)");
  m.seg_offset.assign(off.begin(), off.end());
  m.loads.assign(loads32.begin(), loads32.end());
  if (masked) {
    m.active.resize(P);
    cl_check(q.enqueueReadBuffer(active, CL_TRUE, 0, P, m.active.data()),
             "clEnqueueReadBuffer(PE mask)");
  }
  return m;
}

std::vector<int32_t> DeviceMatching::read_links(Device& device) const {
  if (!linked) throw ArgumentError("matching", "made without balance links (MatchLinks::skip)");
  cl_int n = 0;
  cl_check(
      device.queue().enqueueReadBuffer(
          seg_offset, CL_TRUE, static_cast<std::size_t>(pes) * sizeof(cl_int), sizeof(cl_int), &n),
      "clEnqueueReadBuffer(seg_offset)");
  // The lists hold each link as (segment, linked segment), axis by axis
  // (link_offset's y, z, w: where PE p's list along x, y, z starts; the
  // entry P holds the ends): link = linked * 4 + axis at the segment.
  const std::size_t P = static_cast<std::size_t>(pes);
  std::vector<cl_int4> lofs(P + 1);
  cl_check(device.queue().enqueueReadBuffer(link_offset, CL_TRUE, 0, lofs.size() * sizeof(cl_int4),
                                            lofs.data()),
           "clEnqueueReadBuffer(link offsets)");
  const cl_int end = lofs[P].s[3];
  if (lofs[0].s[1] != 0 || lofs[P].s[1] != lofs[0].s[2] || lofs[P].s[2] != lofs[0].s[3] || end > n)
    throw Error("device link offsets are inconsistent");
  std::vector<cl_int2> list(static_cast<std::size_t>(end));
  if (end > 0 && !links_narrow)
    cl_check(device.queue().enqueueReadBuffer(link_list, CL_TRUE, 0, list.size() * sizeof(cl_int2),
                                              list.data()),
             "clEnqueueReadBuffer(link lists)");
  if (end > 0 && links_narrow) {
    // (segment, linked segment) from the two 16-bit indices: PE p's list
    // along an axis holds p's segments linked to its target's on that axis.
    std::vector<cl_uint> words(static_cast<std::size_t>(end));
    std::vector<cl_int4> base(P);
    cl_check(device.queue().enqueueReadBuffer(link_list, CL_TRUE, 0, words.size() * sizeof(cl_uint),
                                              words.data()),
             "clEnqueueReadBuffer(link lists)");
    cl_check(device.queue().enqueueReadBuffer(link_base, CL_TRUE, 0, base.size() * sizeof(cl_int4),
                                              base.data()),
             "clEnqueueReadBuffer(link bases)");
    for (std::size_t p = 0; p < P; ++p)
      for (int axis = 0; axis < 3; ++axis)
        for (cl_int e = lofs[p].s[1 + axis]; e < lofs[p + 1].s[1 + axis]; ++e) {
          const cl_uint w = words[static_cast<std::size_t>(e)];
          list[static_cast<std::size_t>(e)] = {{base[p].s[3] + static_cast<cl_int>(w & 0xffffu),
                                                base[p].s[axis] + static_cast<cl_int>(w >> 16)}};
        }
  }
  std::vector<int32_t> out(static_cast<std::size_t>(n), -1);
  const std::array<cl_int, 4> starts{lofs[0].s[1], lofs[0].s[2], lofs[0].s[3], end};
  for (int axis = 0; axis < 3; ++axis)
    for (cl_int e = starts[axis]; e < starts[axis + 1]; ++e) {
      const cl_int2 st = list[static_cast<std::size_t>(e)];
      if (st.s[0] < 0 || st.s[0] >= n || st.s[1] < 0 || st.s[1] >= n ||
          out[static_cast<std::size_t>(st.s[0])] != -1)
        throw Error("device link list entry " + std::to_string(e) +
                    " is out of range or links a segment twice");
      out[static_cast<std::size_t>(st.s[0])] = st.s[1] * 4 + axis;
    }
  return out;
}

}  // namespace simdvol
