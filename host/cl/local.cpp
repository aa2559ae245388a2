// The resample and local stages on the device (local_cl.hpp).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#include "buffer_checks.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/resample.hpp"
#include "voxel_ranges.hpp"

namespace simdvol {

static_assert(sizeof(sv_segment) == 16 && sizeof(sv_rect) == 16, "plain int32 structs");
static_assert(sizeof(sv_view) == 160, "sv_view must have the same layout in OpenCL C");

namespace {

// The float8 kernels' `ordered`: 0 without an order, 1 with one, 2 with one
// that carries each work-item's PE after it (SegmentOrder::with_pe).
cl_int ordered_arg(const SegmentOrder* lanes) {
  return lanes ? (lanes->with_pe ? 2 : 1) : 0;
}

constexpr int64_t kInt32Max = std::numeric_limits<cl_int>::max();

int log2_exact(int64_t p) {
  int b = 0;
  while ((int64_t(1) << b) < p) ++b;
  return b;
}

// resample.cl followed by local.cl, specialised for `order`.
cl::Kernel stage_kernel(Device& device, const std::string& name, int order) {
  if (order < 0 || order > kMaxOrder)
    throw ArgumentError("order", "interpolation order " + std::to_string(order) +
                                     " is outside 0.." + std::to_string(kMaxOrder));
  const Defines defines{{"ORDER", std::to_string(order)}};
  cl::Program program =
      device.build_keyed(program_key("source", "resample", defines, {"local"}),
                         [&] { return program_source("resample", defines, {"local"}); });
  cl_int err = CL_SUCCESS;
  cl::Kernel k(program, name.c_str(), &err);
  if (err != CL_SUCCESS) throw CLError("clCreateKernel(" + name + ")", err);
  return k;
}

template <class T>
cl::Buffer upload(Device& device, const std::vector<T>& v, const std::string& what) {
  // A zero-sized buffer is not allowed: keep one element.
  std::vector<T> tmp;
  const std::vector<T>* src = &v;
  if (v.empty()) {
    tmp.resize(1);
    src = &tmp;
  }
  return device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, src->size() * sizeof(T),
                       const_cast<T*>(src->data()), what);
}

cl::NDRange segment_range(int64_t count) {
  return cl::NDRange(round_up(static_cast<std::size_t>(std::max<int64_t>(count, 1)), kSegmentWgs));
}

constexpr std::size_t kCellBitsInts = 104;  // resample_cell_bits

// The tables' layout, and their buffers' sizes (the kernels index `table`
// by voxel position, read one sv_view and, for interleaved cells, the pair
// table by position and the cell bits after it).
void check_tables(const LocalSegments& segs, const ResampleTables& t, const VoxelBuffer& voxels) {
  const VoxelLayout& L = voxels.layout();
  if (L.dims() != t.dims || L.pes() != t.pes || L.interleaved != t.interleaved)
    throw ArgumentError("resample tables", "were made for another voxel layout");
  if (segs.pes != t.pes) throw ArgumentError("segments", "PE count differs from the voxels'");
  const int64_t n = t.dims[0] + t.dims[1] + t.dims[2];
  detail::check_buffer(t.view, 1, sizeof(sv_view), "tables.view", "sv_view");
  detail::check_buffer(t.table, n, sizeof(cl_int), "tables.table", "int entries (nx + ny + nz)");
  if (t.pairs() != nullptr)
    detail::check_buffer(t.pairs, n + 6 + (t.cell_bits ? int64_t(kCellBitsInts / 2) : 0),
                         sizeof(cl_long), "tables.pairs",
                         t.cell_bits ? "long entries (nx + ny + nz + 6, then 104 ints of cell bits)"
                                     : "long entries (nx + ny + nz + 6)");
}

// A lane order, if any, must be made for `segs` and hold its positions (and
// the PEs after them where with_pe).
void check_lanes(const SegmentOrder* lanes, const LocalSegments& segs) {
  if (!lanes) return;
  if (lanes->count != segs.count)
    throw ArgumentError("segment order", "was made for other segments");
  detail::check_buffer(lanes->order, lanes->count + (lanes->with_pe ? (lanes->count + 7) / 8 : 0),
                       sizeof(cl_int), "lanes.order",
                       lanes->with_pe ? "int positions and PEs" : "int positions");
}

// The resample kernels' prefetch ahead (resample.cl, sv_prefetch_pe_ahead):
// the cells' origins and pe_cell = the cell's extents and, in w, 1 to
// prefetch. Tables made without origins (a caller's own ResampleTables)
// resample without the prefetch: w = 0, and any buffer in the origins' place,
// never read. Origins of the wrong size are an ArgumentError.
struct PrefetchArgs {
  cl::Buffer origins;
  cl_int4 pe_cell;
};
PrefetchArgs prefetch_args(const ResampleTables& t, const VoxelLayout& L) {
  const bool on = t.origins() != nullptr;
  if (on) {
    const std::size_t size = buffer_size(t.origins, "clGetMemObjectInfo(cell origins)");
    if (size < static_cast<std::size_t>(L.pes()) * sizeof(cl_int4))
      throw ArgumentError("resample tables", "the cell origins hold fewer than one int4 per PE");
  }
  return {on ? t.origins : t.table,
          cl_int4{{static_cast<cl_int>(L.cell()[0]), static_cast<cl_int>(L.cell()[1]),
                   static_cast<cl_int>(L.cell()[2]), on ? 1 : 0}}};
}

// The kernels with the cell bits (`_ilc`) where the tables carry them, at
// order 1 on interleaved cells (elsewhere the cell bits are not read).
std::string with_cell_bits(const std::string& name, const ResampleTables& t, const VoxelLayout& L,
                           int order) {
  return t.cell_bits && t.pairs() != nullptr && L.interleaved && order == 1 ? name + "c" : name;
}

// The v8 kernels' last argument: for interleaved cells the order-1 kernels'
// pair table (resample_pair_table), with the cell bits where `cell_bits`
// says so; the planar kernels never read it (any buffer will do). Tables
// made without one (a caller's own ResampleTables) get it here from their
// address table, read back (a few KiB, blocking), without cell bits. The
// sizes of both were checked (check_tables).
cl::Buffer pair_table(Device& device, const ResampleTables& t, const VoxelLayout& L, bool v8) {
  if (!v8 || !L.interleaved) return t.table;
  const int64_t n = t.dims[0] + t.dims[1] + t.dims[2];
  if (t.pairs() != nullptr) return t.pairs;
  std::vector<cl_int> table(static_cast<std::size_t>(n));
  cl_check(device.queue().enqueueReadBuffer(t.table, CL_TRUE, 0, table.size() * sizeof(cl_int),
                                            table.data()),
           "clEnqueueReadBuffer(resample address table)");
  return upload(device, resample_pair_table(table, t.dims), "resample pair table");
}

// An occupancy for skipping, if any, must be that of `voxels` for `order`,
// its reach one byte per brick.
void check_occupancy(const DeviceOccupancy* skip, const VoxelBuffer& voxels, int order) {
  if (!skip) return;
  if (skip->dims != voxels.layout().dims() || skip->order != order)
    throw ArgumentError("occupancy", "was made for other voxels or another interpolation order");
  for (int a = 0; a < 3; ++a)
    if (skip->bricks[static_cast<std::size_t>(a)] != (skip->dims[a] + kBrick - 1) / kBrick)
      throw ArgumentError("skip.bricks",
                          "axis " + std::to_string(a) + " has " +
                              std::to_string(skip->bricks[static_cast<std::size_t>(a)]) +
                              " bricks, not ceil(" + std::to_string(skip->dims[a]) + " / " +
                              std::to_string(kBrick) + ")");
  detail::check_buffer(skip->reach, skip->count(), 1, "skip.reach", "bytes of brick reach");
}

}  // namespace

LocalSegments upload_segments(Device& device, const Matching& m) {
  const int64_t P = m.pes();
  if (P < 1 || (P & (P - 1)) != 0)
    throw ArgumentError("matching", "PE count must be a power of two");
  if (static_cast<int64_t>(m.seg_offset.size()) != P + 1 ||
      m.seg_offset.back() != static_cast<int64_t>(m.segments.size()))
    throw ArgumentError("matching", "segment offsets do not match the segments");
  if (static_cast<int64_t>(m.segments.size()) > kInt32Max)
    throw ArgumentError("matching", "more than 2^31 - 1 segments");
  LocalSegments s;
  s.pes = P;
  s.count = static_cast<int64_t>(m.segments.size());
  s.sample_count = 0;
  for (const sv_segment& g : m.segments) s.sample_count += std::max(g.k1 - g.k0, 0);
  std::vector<cl_int> off(m.seg_offset.begin(), m.seg_offset.end());
  s.segments = upload(device, m.segments, "segments");
  s.seg_offset = upload(device, off, "segment offsets");
  s.rects = upload(device, m.rects, "footprint rectangles");
  s.host_rects = m.rects;
  return s;
}

void check_segments(const LocalSegments& segs, bool all) {
  const int64_t P = segs.pes;
  if (P < 1 || (P & (P - 1)) != 0)
    throw ArgumentError("segs.pes", std::to_string(P) + " is not a power of two");
  if (segs.count < 0 || segs.count > kInt32Max)
    throw ArgumentError("segs.count", std::to_string(segs.count) + " is outside 0 .. 2^31 - 1");
  detail::check_buffer(segs.segments, segs.count, sizeof(sv_segment), "segs.segments", "segments");
  if (all) {
    detail::check_buffer(segs.seg_offset, P + 1, sizeof(cl_int), "segs.seg_offset",
                         "int offsets (P + 1)");
    detail::check_buffer(segs.rects, P, sizeof(sv_rect), "segs.rects", "rectangles (P)");
  }
  if (segs.bounds_pending)
    detail::check_buffer(segs.bounds, segs.count, sizeof(cl_short2), "segs.bounds",
                         "short2 bounds");
}

void check_samples(const LocalSegments& segs, const cl::Buffer& sample_off,
                   const cl::Buffer& samples) {
  detail::check_buffer(sample_off, segs.count + 1, sizeof(cl_int), "sample_off",
                       "int offsets (count + 1)");
  detail::check_buffer(samples, std::max<int64_t>(segs.sample_count, 0), sizeof(cl_float4),
                       "samples", "float4 samples");
}

void check_footprints(const DeviceFootprints& fp, int64_t pes) {
  if (static_cast<int64_t>(fp.rect_offset.size()) != pes + 1)
    throw ArgumentError("fp.rect_offset", "holds " + std::to_string(fp.rect_offset.size()) +
                                              " offsets, not P + 1 = " + std::to_string(pes + 1));
  detail::check_buffer(fp.offsets, pes, sizeof(cl_int), "fp.offsets", "int offsets (P)");
  detail::check_buffer(fp.pixels, std::max<int64_t>(fp.size(), 1), sizeof(cl_float4), "fp.pixels",
                       "float4 pixels");
}

void check_bounds_unpacked(const LocalSegments& segs, const char* stage) {
  if (segs.bounds_pending)
    throw ArgumentError("segments", std::string(stage) +
                                        " needs the balanced bounds in the segments (a deferred "
                                        "unpack is pending: enqueue_balance_unpack)");
}

namespace {

// The kernels' (kb, use_kb): the pending balanced bounds, or a placeholder
// buffer that use_kb = 0 leaves unread.
const cl::Buffer& bounds_arg(const LocalSegments& segs) {
  return segs.bounds_pending ? segs.bounds : segs.segments;
}

}  // namespace

SegmentReads::~SegmentReads() {
  if (!count) return;  // finished, or moved from
  for (cl::Event* e : {&count_read, &rects_read})
    if ((*e)()) e->wait();  // (an error here cannot be reported: the frame's own is)
}

SegmentReads start_segments(Device& device, const DeviceMatching& m) {
  SegmentReads r;
  r.pes = m.pes;
  r.seg_offset = m.seg_offset;
  r.count = std::make_unique<cl_int>(0);
  r.host_rects.resize(static_cast<std::size_t>(m.pes));
  cl_check(device.queue().enqueueReadBuffer(m.seg_offset, CL_FALSE,
                                            static_cast<std::size_t>(m.pes) * sizeof(cl_int),
                                            sizeof(cl_int), r.count.get(), nullptr, &r.count_read),
           "clEnqueueReadBuffer(segment count)");
  cl_check(
      device.queue().enqueueReadBuffer(m.rects, CL_FALSE, 0, r.host_rects.size() * sizeof(sv_rect),
                                       r.host_rects.data(), nullptr, &r.rects_read),
      "clEnqueueReadBuffer(footprint rectangles)");
  return r;
}

LocalSegments finish_segments(SegmentReads& r, const DeviceMatching& m) {
  if (!r.count || r.pes != m.pes || r.seg_offset() != m.seg_offset())
    throw ArgumentError("segments", "finished on another matching than they were started on");
  cl_check(r.count_read.wait(), "clWaitForEvents(segment count)");
  cl_check(r.rects_read.wait(), "clWaitForEvents(footprint rectangles)");
  LocalSegments s;
  s.pes = m.pes;
  s.segments = m.segments;
  s.seg_offset = m.seg_offset;
  s.rects = m.rects;
  s.bounds_pending = m.unpack_pending;
  if (m.unpack_pending) s.bounds = m.bounds;
  s.host_rects = std::move(r.host_rects);
  s.count = *r.count;
  r.count.reset();  // finished: a second finish is refused
  return s;
}

LocalSegments device_segments(Device& device, const DeviceMatching& m) {
  SegmentReads r = start_segments(device, m);
  return finish_segments(r, m);
}

cl::Buffer upload_sample_offsets(Device& device, const Matching& m) {
  const std::vector<int64_t> off = sample_offsets(m);
  if (off.back() > kInt32Max) throw ArgumentError("matching", "more than 2^31 - 1 samples");
  std::vector<cl_int> o(off.begin(), off.end());
  return upload(device, o, "sample offsets");
}

std::vector<cl_int> resample_address_table(const VoxelLayout& L, cl_int* channel_stride) {
  const int64_t block = 4 * L.stride;  // floats per PE block
  if (L.pes() * block > kInt32Max)
    throw ArgumentError("volume", "voxel cells exceed int32 float indexing in the resample stage");
  const OwnerTables t = owner_tables(L.cells.split);
  // Planar cells (stages.hpp): channel c of position e of PE p is float
  // (p * 4 + c) * stride + e; interleaved: p * 4 * stride + 4 * e + c.
  const int64_t vm = L.interleaved ? 4 : 1;
  const Dims3& n = L.dims();
  const int64_t mult[3] = {vm, vm * L.cell()[0], vm * L.cell()[0] * L.cell()[1]};
  std::vector<cl_int> table;
  table.reserve(static_cast<std::size_t>(n[0] + n[1] + n[2]));
  for (int a = 0; a < 3; ++a)
    for (int64_t g = 0; g < n[a]; ++g)
      table.push_back(static_cast<cl_int>(t.bits[a][static_cast<std::size_t>(g)] * block +
                                          t.local[a][static_cast<std::size_t>(g)] * mult[a]));
  if (channel_stride) *channel_stride = static_cast<cl_int>(L.interleaved ? 1 : L.stride);
  return table;
}

namespace {

// resample_pair_table's and resample_cell_bits' input: nx + ny + nz entries.
void check_address_table(const std::vector<cl_int>& table, const Dims3& dims) {
  if (dims[0] < 1 || dims[1] < 1 || dims[2] < 1 ||
      static_cast<int64_t>(table.size()) != dims[0] + dims[1] + dims[2])
    throw ArgumentError("resample table", "does not hold nx + ny + nz entries");
}

}  // namespace

std::vector<cl_long> resample_pair_table(const std::vector<cl_int>& table, const Dims3& dims) {
  check_address_table(table, dims);
  std::vector<cl_long> pairs;
  pairs.reserve(table.size() + 6);
  const cl_int* t = table.data();
  for (int a = 0; a < 3; ++a) {
    const int64_t n = dims[a];
    const auto at = [&](int64_t g) {
      return static_cast<uint64_t>(static_cast<uint32_t>(t[std::clamp<int64_t>(g, 0, n - 1)]));
    };
    for (int64_t f = -1; f <= n; ++f)
      pairs.push_back(static_cast<cl_long>(at(f) | (at(f + 1) << 32)));
    t += n;
  }
  return pairs;
}

std::vector<cl_int> resample_cell_bits(const std::vector<cl_int>& table, const Dims3& dims) {
  check_address_table(table, dims);
  constexpr int kCells = 32;
  std::vector<cl_int> out(3 * kCells + 8, 0);
  const cl_int* t = table.data();
  for (int a = 0; a < 3; ++a) {
    const int64_t n = dims[a];
    int found = -1;
    cl_int stride = 0;
    for (int sh = 30; sh >= 0 && found < 0; --sh) {
      if (((n - 1) >> sh) >= kCells) break;  // smaller shifts: more cells
      const int64_t c = int64_t(1) << sh, m = c - 1;
      if (c > 2 * n && sh > 0) continue;  // the same as a smaller shift
      const cl_int st = n >= 2 && c >= 2 ? t[1] - t[0] : 0;
      bool ok = true;
      for (int64_t g = 0; g < n && ok; ++g)
        ok = int64_t(t[g]) == int64_t(t[g & ~m]) + (g & m) * int64_t(st);
      if (ok) {
        found = sh;
        stride = st;
      }
    }
    if (found < 0) return {};
    for (int64_t ci = 0; (ci << found) < n; ++ci)
      out[static_cast<std::size_t>(a * kCells + ci)] = t[ci << found];
    out[static_cast<std::size_t>(3 * kCells + a)] = found;
    out[static_cast<std::size_t>(3 * kCells + 3 + a)] = stride;
    t += n;
  }
  return out;
}

void set_resample_view(Device& device, ResampleTables& tables, const ViewGeometry& view) {
  for (int a = 0; a < 3; ++a)
    if (view.grid.dims[a] != tables.dims[a])
      throw ArgumentError("view", "was made for a volume of other dimensions");
  std::vector<sv_view> v{view.grid};
  tables.view = upload(device, v, "view");
}

ResampleTables make_resample_tables(Device& device, const VoxelLayout& L, const ViewGeometry& view,
                                    const cl::Buffer* origins) {
  ResampleTables t;
  t.dims = L.dims();
  set_resample_view(device, t, view);  // first: a view of other dims uploads nothing else
  t.pes = L.pes();
  t.interleaved = L.interleaved;
  const std::vector<cl_int> table = resample_address_table(L, &t.channel_stride);
  t.table = upload(device, table, "resample address table");
  std::vector<cl_long> pairs = resample_pair_table(table, L.dims());
  // The cell bits after the pairs, as the kernels read them (ints in the
  // order of memory; host and device share the byte order).
  const std::vector<cl_int> bits = resample_cell_bits(table, L.dims());
  if (!bits.empty()) {
    const std::size_t at = pairs.size();
    pairs.resize(at + bits.size() / 2);
    std::memcpy(pairs.data() + at, bits.data(), bits.size() * sizeof(cl_int));
    t.cell_bits = true;
  }
  t.pairs = upload(device, pairs, "resample pair table");
  t.origins = origins ? *origins : upload(device, cell_origin_table(L.cells.split), "cell origins");
  return t;
}

DeviceFootprints make_footprints(Device& device, const std::vector<sv_rect>& rects) {
  DeviceFootprints f;
  f.rect_offset.assign(rects.size() + 1, 0);
  for (std::size_t p = 0; p < rects.size(); ++p) {
    if (rects[p].w < 0 || rects[p].h < 0) throw ArgumentError("rects", "negative footprint size");
    f.rect_offset[p + 1] = f.rect_offset[p] + int64_t(rects[p].w) * rects[p].h;
  }
  if (f.size() > kInt32Max) throw ArgumentError("rects", "footprints exceed 2^31 - 1 pixels");
  std::vector<cl_int> off(f.rect_offset.begin(), f.rect_offset.end() - 1);
  f.offsets = upload(device, off, "footprint offsets");
  const std::size_t n = static_cast<std::size_t>(std::max<int64_t>(f.size(), 1));
  f.pixels = device.scratch_buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4), "footprints");
  return f;
}

cl::Event enqueue_zero_footprints(Device& device, DeviceFootprints& fp) {
  detail::check_buffer(fp.pixels, std::max<int64_t>(fp.size(), 1), sizeof(cl_float4), "fp.pixels",
                       "float4 pixels");
  const std::string name = "simdvol_zero4";
  cl::Kernel k = stage_kernel(device, name, 1);
  const cl_int n = static_cast<cl_int>(std::max<int64_t>(fp.size(), 1));
  set_args(k, name, fp.pixels, n);
  return device.run(k, name, cl::NDRange(round_up(static_cast<std::size_t>(n), 256)),
                    cl::NDRange(256), LocalSize::at_most);
}

Footprints read_footprints(Device& device, const DeviceFootprints& fp) {
  Footprints f;
  f.rect_offset = fp.rect_offset;
  f.pixels.resize(static_cast<std::size_t>(fp.size()));
  if (!f.pixels.empty())
    cl_check(device.queue().enqueueReadBuffer(fp.pixels, CL_TRUE, 0, f.pixels.size() * sizeof(Rgba),
                                              f.pixels.data()),
             "clEnqueueReadBuffer(footprints)");
  return f;
}

cl::Event enqueue_resample(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const ResampleTables& tables, const VoxelBuffer& voxels, int order,
                           const cl::Buffer& samples, LocalKernel variant,
                           const SegmentOrder* lanes, const DeviceOccupancy* skip) {
  check_bounds_unpacked(segs, "enqueue_resample");
  check_segments(segs);
  check_samples(segs, sample_off, samples);
  check_tables(segs, tables, voxels);
  check_lanes(lanes, segs);
  const bool v8 = variant == LocalKernel::vector8;
  if (skip && !v8) throw ArgumentError("occupancy", "only the vector8 resample kernel skips");
  check_occupancy(skip, voxels, order);
  const std::string name =
      v8 ? with_cell_bits(detail::voxel_kernel("simdvol_resample_v8", voxels.layout()), tables,
                          voxels.layout(), order)
         : "simdvol_resample";
  cl::Kernel k = stage_kernel(device, name, order);
  set_args(k, name, segs.segments, static_cast<cl_int>(segs.count), sample_off, tables.view,
           tables.table, voxels.buffer(), tables.channel_stride, samples);
  // Without an order or skipping, the order and reach buffers are never
  // read: any buffer will do.
  const PrefetchArgs pf = prefetch_args(tables, voxels.layout());
  const cl::Buffer pairs = pair_table(device, tables, voxels.layout(), v8);
  if (v8)
    set_args_from(k, name, 8, lanes ? lanes->order : tables.table, ordered_arg(lanes),
                  skip ? skip->reach : tables.table, skip ? skip->bricks[0] : cl_int(0),
                  skip ? skip->bricks[1] : cl_int(0), cl_int(skip ? 1 : 0), segs.seg_offset,
                  static_cast<cl_int>(log2_exact(segs.pes)), pf.origins, pf.pe_cell, pairs);
  return device.run(k, name, segment_range(v8 ? (segs.count + 7) / 8 : segs.count),
                    cl::NDRange(kSegmentWgs), LocalSize::at_most);
}

cl::Event enqueue_local(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                        const cl::Buffer& samples, DeviceFootprints& fp) {
  check_bounds_unpacked(segs, "enqueue_local");
  check_segments(segs);
  check_samples(segs, sample_off, samples);
  check_footprints(fp, segs.pes);
  const std::string name = "simdvol_local";
  cl::Kernel k = stage_kernel(device, name, 1);
  set_args(k, name, segs.segments, static_cast<cl_int>(segs.count), segs.seg_offset,
           static_cast<cl_int>(log2_exact(segs.pes)), sample_off, samples, segs.rects, fp.offsets,
           fp.pixels);
  return device.run(k, name, segment_range(segs.count), cl::NDRange(kSegmentWgs),
                    LocalSize::at_most);
}

DeviceOccupancy make_occupancy(Device& device, const VoxelLayout& L, int order) {
  if (order < 0 || order > kMaxOrder)
    throw ArgumentError("order", "interpolation order " + std::to_string(order) +
                                     " is outside 0.." + std::to_string(kMaxOrder));
  DeviceOccupancy o;
  o.dims = L.dims();
  o.order = order;
  for (int a = 0; a < 3; ++a) o.bricks[a] = static_cast<cl_int>((o.dims[a] + kBrick - 1) / kBrick);
  const std::size_t n = static_cast<std::size_t>(std::max<int64_t>(o.count(), 1));
  o.occupied = device.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_uint), nullptr, "brick occupancy");
  o.reach = device.buffer(CL_MEM_READ_WRITE, n, nullptr, "brick reach");
  cl::Event fill;
  cl_check(device.queue().enqueueFillBuffer(o.occupied, cl_uint(0), 0, n * sizeof(cl_uint), nullptr,
                                            &fill),
           "clEnqueueFillBuffer(brick occupancy)");
  o.events.push_back(fill);
  return o;
}

void enqueue_occupancy_reach(Device& device, DeviceOccupancy& o) {
  // one work-item per row of bricks (by, bz)
  const std::size_t n =
      static_cast<std::size_t>(std::max<int64_t>(int64_t(o.bricks[1]) * o.bricks[2], 1));
  const std::string name = "simdvol_occupancy_reach";
  cl::Kernel r = stage_kernel(device, name, o.order);
  // Stencil voxels f + p: p in 0..1 for orders 0 and 1, -1..2 for 2 and 3.
  set_args(r, name, o.occupied, o.bricks[0], o.bricks[1], o.bricks[2], cl_int(o.order >= 2 ? 1 : 0),
           cl_int(1), o.reach);
  o.events.push_back(device.run(r, name, cl::NDRange(round_up(n, kSegmentWgs)),
                                cl::NDRange(kSegmentWgs), LocalSize::at_most));
}

DeviceOccupancy enqueue_occupancy(Device& device, const VoxelBuffer& voxels, int order) {
  const VoxelLayout& L = voxels.layout();
  if (L.elements() * 4 > kInt32Max)
    throw ArgumentError("volume", "voxel cells exceed int32 float indexing in the resample stage");
  DeviceOccupancy o = make_occupancy(device, L, order);
  const int64_t P = L.pes();
  std::vector<cl_int4> origins(static_cast<std::size_t>(P));
  for (int64_t p = 0; p < P; ++p) {
    const Dims3 c = L.cells.split.cell_origin(p);
    origins[static_cast<std::size_t>(p)] = {
        {static_cast<cl_int>(c[0]), static_cast<cl_int>(c[1]), static_cast<cl_int>(c[2]), 0}};
  }
  const cl::Buffer org = upload(device, origins, "cell origins");
  const cl_int4 dims = {{static_cast<cl_int>(o.dims[0]), static_cast<cl_int>(o.dims[1]),
                         static_cast<cl_int>(o.dims[2]), 0}};
  const cl_int4 cell = {{static_cast<cl_int>(L.cell()[0]), static_cast<cl_int>(L.cell()[1]),
                         static_cast<cl_int>(L.cell()[2]), 0}};
  const std::string name = detail::voxel_kernel("simdvol_occupancy", L);
  cl::Kernel k = stage_kernel(device, name, order);
  set_args(k, name, voxels.buffer(), static_cast<cl_int>(L.stride), cell, org, dims, o.bricks[0],
           o.bricks[1], o.occupied);
  const std::size_t wz = std::min<std::size_t>(8, static_cast<std::size_t>(L.cell()[2]));
  o.events.push_back(device.run(
      k, name,
      cl::NDRange(round_up(static_cast<std::size_t>(L.cell()[2]), wz), static_cast<std::size_t>(P)),
      cl::NDRange(wz, 1), LocalSize::at_most));
  enqueue_occupancy_reach(device, o);
  return o;
}

SegmentOrder enqueue_segment_order(Device& device, const LocalSegments& segs) {
  check_segments(segs);
  SegmentOrder o;
  o.count = segs.count;
  const std::size_t n = static_cast<std::size_t>(std::max<int64_t>(segs.count, 1));
  // The order, then the PE of each float8 work-item's first position.
  o.order =
      device.scratch_buffer(CL_MEM_READ_WRITE, (n + (n + 7) / 8) * sizeof(cl_int), "segment order");
  o.with_pe = true;
  const std::string name = "simdvol_segment_order";
  cl::Kernel k = stage_kernel(device, name, 1);
  set_args(k, name, segs.segments, static_cast<cl_int>(segs.count), segs.seg_offset,
           static_cast<cl_int>(log2_exact(segs.pes)), o.order, bounds_arg(segs),
           cl_int(segs.bounds_pending), cl_int(o.with_pe ? 1 : 0));
  const int64_t blocks = (segs.count + SV_ORDER_BLOCK - 1) / SV_ORDER_BLOCK;
  o.event =
      device.run(k, name, segment_range(blocks), cl::NDRange(kSegmentWgs), LocalSize::at_most);
  return o;
}

cl::Event enqueue_resample_local(Device& device, const LocalSegments& segs,
                                 const ResampleTables& tables, const VoxelBuffer& voxels, int order,
                                 DeviceFootprints& fp, LocalKernel variant,
                                 const DeviceOccupancy* skip, const SegmentOrder* lanes) {
  const bool v8 = variant == LocalKernel::vector8;
  if (!v8) check_bounds_unpacked(segs, "the scalar resample + local");
  check_segments(segs);
  check_tables(segs, tables, voxels);
  check_footprints(fp, segs.pes);
  check_occupancy(skip, voxels, order);
  check_lanes(lanes, segs);
  const std::string name =
      v8 ? with_cell_bits(detail::voxel_kernel("simdvol_resample_local_v8", voxels.layout()),
                          tables, voxels.layout(), order)
         : "simdvol_resample_local";
  cl::Kernel k = stage_kernel(device, name, order);
  set_args(k, name, segs.segments, static_cast<cl_int>(segs.count), segs.seg_offset,
           static_cast<cl_int>(log2_exact(segs.pes)), tables.view, tables.table, voxels.buffer(),
           tables.channel_stride, segs.rects, fp.offsets, fp.pixels);
  // The float8 kernel's skipping and order arguments; without them the
  // reach and order buffers are never read: any buffer will do.
  const PrefetchArgs pf = prefetch_args(tables, voxels.layout());
  const cl::Buffer pairs = pair_table(device, tables, voxels.layout(), v8);
  if (v8)
    set_args_from(k, name, 11, skip ? skip->reach : tables.table,
                  skip ? skip->bricks[0] : cl_int(0), skip ? skip->bricks[1] : cl_int(0),
                  cl_int(skip ? 1 : 0), lanes ? lanes->order : tables.table, ordered_arg(lanes),
                  pf.origins, pf.pe_cell, pairs, bounds_arg(segs), cl_int(segs.bounds_pending));
  return device.run(k, name, segment_range(v8 ? (segs.count + 7) / 8 : segs.count),
                    cl::NDRange(kSegmentWgs), LocalSize::at_most);
}

}  // namespace simdvol
