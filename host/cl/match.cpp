// The match and balance stages on the device (see match_cl.hpp).
#include "simdvol/match_cl.hpp"

#include <algorithm>
#include <climits>
#include <string>

namespace simdvol {

namespace {

constexpr std::size_t kWgs = 16;  // one work-item per PE: 8,192 PEs -> 512 groups

const Defines& match_defines() {
  static const Defines d{{"WGS", std::to_string(kWgs)}};
  return d;
}

cl_int4 int4(int64_t x, int64_t y, int64_t z, int64_t w) {
  cl_int4 v;
  v.s[0] = static_cast<cl_int>(x);
  v.s[1] = static_cast<cl_int>(y);
  v.s[2] = static_cast<cl_int>(z);
  v.s[3] = static_cast<cl_int>(w);
  return v;
}

Dims3 splits_of(const KdSplit& split) {
  return {int64_t(1) << split.axis_bits[0], int64_t(1) << split.axis_bits[1],
          int64_t(1) << split.axis_bits[2]};
}

}  // namespace

std::uint64_t events_ns(const std::vector<StageEvent>& events) {
  std::uint64_t t = 0;
  for (const StageEvent& e : events) t += event_ns(e.event);
  return t;
}

DeviceMatching enqueue_match(Device& device, const ViewGeometry& view, const KdSplit& split) {
  const std::vector<sv_rect> cand = match_candidates(view, split);  // validates the split
  const int64_t pes = split.pes();
  if (pes > INT_MAX / 2) throw ArgumentError("split", "too many PEs");
  int64_t capacity = 0;
  for (const sv_rect& r : cand) capacity += int64_t(r.w) * r.h;
  if (capacity > INT_MAX / 4)
    throw ArgumentError("view", "too many candidate rays for 32-bit segment indices");
  for (int a = 0; a < 3; ++a)
    if (split.cell[a] > INT_MAX) throw ArgumentError("split", "cell too large");
  capacity = std::max<int64_t>(capacity, 1);

  DeviceMatching m;
  m.pes = pes;
  m.capacity = capacity;
  std::vector<cl_int4> cidx(static_cast<std::size_t>(pes));
  std::vector<cl_int> pe_of(static_cast<std::size_t>(pes));
  const Dims3 sp = splits_of(split);
  for (int64_t p = 0; p < pes; ++p) {
    const auto c = cell_index_of(split, p);
    cidx[p] = int4(c[0], c[1], c[2], 0);
    pe_of[(c[2] * sp[1] + c[1]) * sp[0] + c[0]] = static_cast<cl_int>(p);
  }
  const auto ro = CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR;
  m.cidx = device.buffer(ro, cidx.size() * sizeof(cl_int4), cidx.data(), "PE cell indices");
  m.pe_of = device.buffer(ro, pe_of.size() * sizeof(cl_int), pe_of.data(), "PE of cell");
  m.candidates = device.buffer(ro, cand.size() * sizeof(sv_rect), const_cast<sv_rect*>(cand.data()),
                               "candidate rectangles");
  sv_view v = view.grid;
  m.view = device.buffer(ro, sizeof(sv_view), &v, "view");
  const std::size_t P = static_cast<std::size_t>(pes);
  m.counts = device.buffer(CL_MEM_READ_WRITE, P * sizeof(cl_int), nullptr, "segment counts");
  m.seg_offset = device.buffer(CL_MEM_READ_WRITE, (P + 1) * sizeof(cl_int), nullptr, "seg_offset");
  m.segments =
      device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(capacity) * sizeof(sv_segment),
                    nullptr, "segments");
  m.rects = device.buffer(CL_MEM_READ_WRITE, P * sizeof(sv_rect), nullptr, "footprint rects");
  m.loads = device.buffer(CL_MEM_READ_WRITE, P * sizeof(cl_int), nullptr, "loads");

  const cl_int4 cell = int4(split.cell[0], split.cell[1], split.cell[2], 0);
  const cl_int npes = static_cast<cl_int>(pes);

  cl::Kernel count = device.kernel("match", "simdvol_match_count", match_defines());
  set_args(count, "simdvol_match_count", m.view, m.candidates, m.cidx, cell, npes, m.counts);
  m.match_events.push_back(
      {"match_count", device.run(count, "simdvol_match_count", cl::NDRange(P), cl::NDRange(kWgs))});
  cl::Kernel scan = device.kernel("match", "simdvol_match_scan", match_defines());
  set_args(scan, "simdvol_match_scan", m.counts, npes, m.seg_offset);
  m.match_events.push_back(
      {"match_scan", device.run(scan, "simdvol_match_scan", cl::NDRange(kWgs), cl::NDRange(kWgs))});
  cl::Kernel fill = device.kernel("match", "simdvol_match_fill", match_defines());
  set_args(fill, "simdvol_match_fill", m.view, m.candidates, m.cidx, cell, npes, m.seg_offset,
           m.segments, m.rects, m.loads);
  m.match_events.push_back(
      {"match_fill", device.run(fill, "simdvol_match_fill", cl::NDRange(P), cl::NDRange(kWgs))});
  return m;
}

void enqueue_balance(Device& device, DeviceMatching& m, const ViewGeometry& view,
                     const KdSplit& split, int sweeps) {
  if (sweeps < 0) throw ArgumentError("sweeps", "must be >= 0");
  if (m.pes != split.pes()) throw ArgumentError("matching", "made for another PE count");
  const std::size_t P = static_cast<std::size_t>(m.pes);
  if (!m.links())
    m.links =
        device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(m.capacity) * sizeof(cl_int),
                      nullptr, "balance links");
  const cl::Buffer& cidx = m.cidx;
  const cl::Buffer& pe_of = m.pe_of;
  const Dims3 sp = splits_of(split);
  const cl_int4 splits = int4(sp[0], sp[1], sp[2], 0);
  const cl_int4 cell = int4(split.cell[0], split.cell[1], split.cell[2], 0);
  const cl_int npes = static_cast<cl_int>(m.pes);

  cl::Kernel links = device.kernel("balance", "simdvol_balance_links", match_defines());
  set_args(links, "simdvol_balance_links", m.view, cidx, pe_of, cell, splits, npes, m.seg_offset,
           m.segments, m.links);
  m.balance_events.push_back({"balance_links", device.run(links, "simdvol_balance_links",
                                                          cl::NDRange(P), cl::NDRange(kWgs))});
  for (int sweep = 0; sweep < sweeps; ++sweep)
    for (int a = 0; a < 3; ++a) {
      const int64_t dir = view.grid.step[a][2];
      if (dir == 0 || sp[a] < 2) continue;
      for (int par = 0; par < 2; ++par) {
        cl::Kernel round = device.kernel("balance", "simdvol_balance_round", match_defines());
        set_args(round, "simdvol_balance_round", cidx, pe_of, splits, npes, cl_int(a), cl_int(par),
                 cl_int(dir > 0 ? 1 : -1), m.seg_offset, m.segments, m.links, m.loads);
        m.balance_events.push_back(
            {"balance_round",
             device.run(round, "simdvol_balance_round", cl::NDRange(P), cl::NDRange(kWgs))});
      }
    }
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
  if (off[P] > 0)
    cl_check(q.enqueueReadBuffer(segments, CL_TRUE, 0, m.segments.size() * sizeof(sv_segment),
                                 m.segments.data()),
             "clEnqueueReadBuffer(segments)");
  cl_check(q.enqueueReadBuffer(rects, CL_TRUE, 0, P * sizeof(sv_rect), m.rects.data()),
           "clEnqueueReadBuffer(rects)");
  cl_check(q.enqueueReadBuffer(loads, CL_TRUE, 0, P * sizeof(cl_int), loads32.data()),
           "clEnqueueReadBuffer(loads)");
  m.seg_offset.assign(off.begin(), off.end());
  m.loads.assign(loads32.begin(), loads32.end());
  return m;
}

std::vector<int32_t> DeviceMatching::read_links(Device& device) const {
  cl_int n = 0;
  cl_check(
      device.queue().enqueueReadBuffer(
          seg_offset, CL_TRUE, static_cast<std::size_t>(pes) * sizeof(cl_int), sizeof(cl_int), &n),
      "clEnqueueReadBuffer(seg_offset)");
  std::vector<int32_t> out(static_cast<std::size_t>(n));
  if (n > 0)
    cl_check(device.queue().enqueueReadBuffer(links, CL_TRUE, 0, out.size() * sizeof(cl_int),
                                              out.data()),
             "clEnqueueReadBuffer(links)");
  return out;
}

}  // namespace simdvol
