// The layout stage on the device (see layout.hpp).
#include "simdvol/layout.hpp"

#include <climits>
#include <utility>

namespace simdvol {

namespace {

cl_int4 int4(int64_t x, int64_t y, int64_t z, int64_t w) {
  cl_int4 v;
  v.s[0] = static_cast<cl_int>(x);
  v.s[1] = static_cast<cl_int>(y);
  v.s[2] = static_cast<cl_int>(z);
  v.s[3] = static_cast<cl_int>(w);
  return v;
}

std::size_t flat_count(const Dims3& d) {
  return static_cast<std::size_t>(d[0] * d[1] * d[2]);
}

}  // namespace

std::vector<cl_int4> cell_origin_table(const KdSplit& split) {
  std::vector<cl_int4> t(static_cast<std::size_t>(split.pes()));
  for (int64_t p = 0; p < split.pes(); ++p) {
    const Dims3 o = split.cell_origin(p);
    t[static_cast<std::size_t>(p)] = int4(o[0], o[1], o[2], 0);
  }
  return t;
}

namespace {

void check_cell_layout(const CellLayout& layout) {
  for (int a = 0; a < 3; ++a)
    if (layout.dims()[a] > INT_MAX / 2 || layout.block[a] > INT_MAX)
      throw ArgumentError("volume", "dimension too large for 32-bit kernel indices");
  if (layout.cell_stride > INT_MAX)
    throw ArgumentError("volume", "cell block of " + std::to_string(layout.cell_stride) +
                                      " floats is too large for 32-bit kernel indices");
}

}  // namespace

CellBuffer::CellBuffer(Device& device, const CellLayout& layout)
    : CellBuffer(device, layout, cl::Buffer()) {}

CellBuffer::CellBuffer(Device& device, const CellLayout& layout, cl::Buffer cells)
    : layout_(layout) {
  check_cell_layout(layout);
  if (cells()) {
    const std::size_t size = buffer_size(cells, "clGetMemObjectInfo(cell buffer)");
    if (size < layout.bytes())
      throw ArgumentError("cell buffer", "the caller's buffer has " + std::to_string(size) +
                                             " bytes; the layout needs " +
                                             std::to_string(layout.bytes()));
    cells_ = std::move(cells);
  } else {
    cells_ = device.buffer(CL_MEM_READ_WRITE, layout.bytes(), nullptr, "cell buffer");
  }
  const int64_t pes = layout.pes();
  std::vector<cl_int4> origins = cell_origin_table(layout.split);
  std::vector<cl_int> pe_of_cell(static_cast<std::size_t>(pes));
  const Dims3 splits = layout.split.splits();
  for (int64_t p = 0; p < pes; ++p) {
    Dims3 i = layout.split.cell_index(p);
    pe_of_cell[(i[2] * splits[1] + i[1]) * splits[0] + i[0]] = static_cast<cl_int>(p);
  }
  origins_ = device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                           origins.size() * sizeof(cl_int4), origins.data(), "PE origin table");
  pe_of_cell_ =
      device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, pe_of_cell.size() * sizeof(cl_int),
                    pe_of_cell.data(), "PE-of-cell table");
}

cl_int4 CellBuffer::dims_arg() const {
  return int4(layout_.dims()[0], layout_.dims()[1], layout_.dims()[2], 0);
}
cl_int4 CellBuffer::cell_arg() const {
  return int4(layout_.cell()[0], layout_.cell()[1], layout_.cell()[2], layout_.halo);
}
cl_int4 CellBuffer::block_arg() const {
  return int4(layout_.block[0], layout_.block[1], layout_.block[2], layout_.cell_stride);
}
cl_int4 CellBuffer::splits_arg() const {
  Dims3 s = layout_.split.splits();
  return int4(s[0], s[1], s[2], 0);
}

std::vector<float> CellBuffer::read(Device& device) const {
  std::vector<float> out(static_cast<std::size_t>(layout_.elements()));
  cl_check(
      device.queue().enqueueReadBuffer(cells_, CL_TRUE, 0, out.size() * sizeof(float), out.data()),
      "clEnqueueReadBuffer(cell buffer)");
  return out;
}

PeArray::PeArray(Device& device, PeGrid grid) : device_(&device), grid_(grid) {
  pe_grid(grid.count(), "PE grid");  // validates the count
  if (grid.width < 1 || grid.height < 1) throw ArgumentError("PE grid", "empty grid");
}

CellLayout PeArray::cell_layout(const Dims3& dims, int halo) const {
  CellLayout L = make_cell_layout(dims, pes(), halo);
  check_allocation(L.bytes(), device_->info().max_alloc_bytes, "volume (PE-major cell buffer)",
                   "use a smaller volume or fewer PEs/less halo");
  check_allocation(flat_count(dims) * sizeof(float), device_->info().max_alloc_bytes,
                   "volume (flat)", "use a smaller volume");
  return L;
}

CellBuffer PeArray::layout(const float* data, const Dims3& dims, int halo, LayoutKernel variant,
                           cl::Event* event) const {
  CellBuffer cells(*device_, cell_layout(dims, halo));
  layout_into(data, cells, variant, event);
  return cells;
}

CellBuffer PeArray::layout(const Volume& volume, int halo, LayoutKernel variant,
                           cl::Event* event) const {
  volume.check_voxel_count();  // (the buffer wraps dims' worth of its voxels)
  return layout(volume.data().data(), volume.dims(), halo, variant, event);
}

void PeArray::layout_into(const float* data, CellBuffer& cells, LayoutKernel variant,
                          cl::Event* event) const {
  if (!data) throw ArgumentError("volume", "null data");
  const std::size_t n = flat_count(cells.layout().dims());
  // Zero-copy on PoCL: the kernel reads the caller's memory directly.
  cl::Buffer in = device_->buffer(CL_MEM_READ_ONLY | CL_MEM_USE_HOST_PTR, n * sizeof(float),
                                  const_cast<float*>(data), "volume (flat)");
  cl::Event e = enqueue_layout(in, cells, variant);
  device_->finish();
  if (event) *event = e;
}

cl::Event PeArray::enqueue_layout(const cl::Buffer& flat, CellBuffer& cells,
                                  LayoutKernel variant) const {
  const CellLayout& L = cells.layout();
  if (L.pes() != pes()) throw ArgumentError("cells", "laid out for a different PE count");
  const std::size_t n = flat_count(L.dims());
  const std::size_t size = buffer_size(flat, "clGetMemObjectInfo(volume)");
  if (size < n * sizeof(float))
    throw ArgumentError("volume", "buffer of " + std::to_string(size) + " bytes holds fewer than " +
                                      std::to_string(n) + " floats");
  const bool rows = variant == LayoutKernel::rows;
  const std::string name = rows ? "simdvol_layout" : "simdvol_layout_voxel";
  cl::Kernel k = device_->kernel("layout", name, device_->wgs_defines());
  if (rows)
    set_args(k, name, flat, cells.cells(), cells.origins(), cells.pe_of_cell(), cells.dims_arg(),
             cells.cell_arg(), cells.block_arg(), cells.splits_arg());
  else
    set_args(k, name, flat, cells.cells(), cells.origins(), cells.dims_arg(), cells.cell_arg(),
             cells.block_arg(), static_cast<cl_int>(L.pes()));
  // rows: one work-item per padded row of a row of cells (layout.cl).
  const Dims3 splits = L.split.splits();
  const std::size_t items = static_cast<std::size_t>(
      rows ? splits[1] * splits[2] * L.block[1] * L.block[2] : L.elements());
  return device_->run(k, name, cl::NDRange(items), cl::NDRange(device_->wgs()));
}

void PeArray::gather(const CellBuffer& cells, float* out, LayoutKernel variant,
                     cl::Event* event) const {
  const CellLayout& L = cells.layout();
  if (L.pes() != pes()) throw ArgumentError("cells", "laid out for a different PE count");
  if (!out) throw ArgumentError("gather", "null output");
  const std::size_t n = flat_count(L.dims());
  cl::Buffer vol = device_->buffer(CL_MEM_WRITE_ONLY | CL_MEM_USE_HOST_PTR, n * sizeof(float), out,
                                   "volume (flat)");
  const bool rows = variant == LayoutKernel::rows;
  const std::string name = rows ? "simdvol_gather" : "simdvol_gather_voxel";
  cl::Kernel k = device_->kernel("layout", name, device_->wgs_defines());
  std::size_t items;
  if (rows) {
    set_args(k, name, cells.cells(), vol, cells.origins(), cells.dims_arg(), cells.cell_arg(),
             cells.block_arg(), static_cast<cl_int>(L.pes()));
    items = static_cast<std::size_t>(L.pes() * L.cell()[1] * L.cell()[2]);
  } else {
    set_args(k, name, cells.cells(), vol, cells.origins(), cells.pe_of_cell(), cells.dims_arg(),
             cells.cell_arg(), cells.block_arg(), cells.splits_arg());
    items = n;
  }
  cl::Event e = device_->run(k, name, cl::NDRange(items), cl::NDRange(device_->wgs()));
  // Map/unmap makes the results visible in `out` as the spec requires for
  // CL_MEM_USE_HOST_PTR (no copy on PoCL).
  cl_int err = CL_SUCCESS;
  void* p = device_->queue().enqueueMapBuffer(vol, CL_TRUE, CL_MAP_READ, 0, n * sizeof(float),
                                              nullptr, nullptr, &err);
  cl_check(err, "clEnqueueMapBuffer(volume)");
  cl_check(device_->queue().enqueueUnmapMemObject(vol, p), "clEnqueueUnmapMemObject(volume)");
  device_->finish();
  if (event) *event = e;
}

std::vector<float> PeArray::gather(const CellBuffer& cells, LayoutKernel variant) const {
  std::vector<float> out(flat_count(cells.layout().dims()));
  gather(cells, out.data(), variant);
  return out;
}

}  // namespace simdvol
