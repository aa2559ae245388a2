// The shade stage on the device and the voxel-cells buffers (stages.hpp).
#include <climits>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "chunk_ranges.hpp"
#include "simdvol/stages.hpp"
#include "voxel_ranges.hpp"

namespace simdvol {

static_assert(sizeof(sv_shade_params) == 27 * 4, "sv_shade_params must be plain floats/ints");

namespace {

float finite_float(double v, const char* what) {
  const float f = static_cast<float>(v);
  if (!std::isfinite(v) || !std::isfinite(f))
    throw ArgumentError(std::string("shade.") + what,
                        "must be finite in float (got " + std::to_string(v) + ")");
  return f;
}

void check_same_cells(const CellLayout& a, const VoxelLayout& v, const char* what) {
  if (a.dims() != v.dims() || a.pes() != v.pes() || a.cell() != v.cell())
    throw ArgumentError(what, "voxel buffer was made for a different volume or PE count");
}

}  // namespace

bool VoxelLayout::same_cells(const VoxelLayout& o) const {
  return dims() == o.dims() && pes() == o.pes() && cell() == o.cell() && stride == o.stride;
}

VoxelLayout make_voxel_layout(const CellLayout& cells, bool interleaved) {
  VoxelLayout L;
  L.cells = cells;
  L.interleaved = interleaved;
  const int64_t n = cells.cell()[0] * cells.cell()[1] * cells.cell()[2];
  L.stride = (n + 15) / 16 * 16;
  if (L.stride > INT_MAX) throw ArgumentError("volume", "cell too large for 32-bit kernel indices");
  if (L.stride > std::numeric_limits<int64_t>::max() / 16 / cells.pes())
    throw ArgumentError("volume", "voxel buffer size overflows");
  return L;
}

VoxelBuffer::VoxelBuffer(Device& device, const VoxelLayout& layout) : layout_(layout) {
  buffer_ = device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(layout.bytes()), nullptr,
                          "voxel cell buffer");
}

VoxelBuffer::VoxelBuffer(const VoxelLayout& layout, cl::Buffer buffer) : layout_(layout) {
  if (!buffer()) throw ArgumentError("voxel cell buffer", "null buffer");
  const std::size_t size = buffer_size(buffer, "clGetMemObjectInfo(voxel cells)");
  if (size < layout.bytes())
    throw ArgumentError("voxel cell buffer", "the caller's buffer has " + std::to_string(size) +
                                                 " bytes; the layout needs " +
                                                 std::to_string(layout.bytes()));
  buffer_ = std::move(buffer);
}

// Host elements are (PE, position)-ordered 4-float records; the device
// buffer is planar per PE block, or those records themselves if interleaved.
void VoxelBuffer::read_raw(Device& device, void* out) const {
  if (layout_.interleaved) {
    cl_check(device.queue().enqueueReadBuffer(buffer_, CL_TRUE, 0,
                                              static_cast<std::size_t>(layout_.bytes()), out),
             "clEnqueueReadBuffer(voxel cells)");
    return;
  }
  std::vector<float> planar(static_cast<std::size_t>(layout_.elements()) * 4);
  cl_check(device.queue().enqueueReadBuffer(
               buffer_, CL_TRUE, 0, static_cast<std::size_t>(layout_.bytes()), planar.data()),
           "clEnqueueReadBuffer(voxel cells)");
  float* o = static_cast<float*>(out);
  const std::size_t st = static_cast<std::size_t>(layout_.stride);
  for (std::size_t p = 0; p < static_cast<std::size_t>(layout_.pes()); ++p)
    for (std::size_t c = 0; c < 4; ++c)
      for (std::size_t e = 0; e < st; ++e) o[(p * st + e) * 4 + c] = planar[(p * 4 + c) * st + e];
}

void VoxelBuffer::write_raw(Device& device, const void* in) {
  stored_ = true;
  if (layout_.interleaved) {
    cl_check(device.queue().enqueueWriteBuffer(buffer_, CL_TRUE, 0,
                                               static_cast<std::size_t>(layout_.bytes()), in),
             "clEnqueueWriteBuffer(voxel cells)");
    return;
  }
  std::vector<float> planar(static_cast<std::size_t>(layout_.elements()) * 4);
  const float* i = static_cast<const float*>(in);
  const std::size_t st = static_cast<std::size_t>(layout_.stride);
  for (std::size_t p = 0; p < static_cast<std::size_t>(layout_.pes()); ++p)
    for (std::size_t c = 0; c < 4; ++c)
      for (std::size_t e = 0; e < st; ++e) planar[(p * 4 + c) * st + e] = i[(p * st + e) * 4 + c];
  cl_check(device.queue().enqueueWriteBuffer(
               buffer_, CL_TRUE, 0, static_cast<std::size_t>(layout_.bytes()), planar.data()),
           "clEnqueueWriteBuffer(voxel cells)");
}

sv_shade_params shade_params(const ShadeFrame& f, const ShadeParams& p) {
  sv_shade_params s{};
  for (int a = 0; a < 3; ++a) {
    s.light[a] = finite_float(f.light_obj[a], "light");
    s.halfway[a] = finite_float(f.halfway_obj[a], "halfway");
    s.depth_dir[a] = finite_float(f.depth_dir[a], "depth_dir");
    s.grad_scale[a] = finite_float(f.grad_scale[a], "grad_scale");
  }
  s.depth_offset = finite_float(f.depth_offset, "depth_offset");
  s.ka = finite_float(p.ka, "ka");
  s.kd = finite_float(p.kd, "kd");
  s.ks = finite_float(p.ks, "ks");
  s.shininess = finite_float(p.shininess, "shininess");
  s.k1 = finite_float(p.k1, "k1");
  s.k2 = finite_float(p.k2, "k2");
  s.enabled = p.enabled ? 1 : 0;
  s.spec_floor = specular_floor(p.shininess);
  s.grad_over = f.grad_over ? 1 : 0;
  s.surface_g2 = static_cast<float>(f.surface_g2);
  return s;
}

Defines shade_defines(const sv_shade_params& params) {
  if (params.grad_over) return {{"SV_GRAD_OVER", "1"}};
  return {};
}

cl::Event enqueue_shade(Device& device, const CellBuffer& cells, const sv_shade_params& params,
                        VoxelBuffer& out, ShadeKernel variant) {
  const CellLayout& C = cells.layout();
  const VoxelLayout& V = out.layout();
  if (C.halo < 1) throw ArgumentError("cells", "the shade stage needs a halo of at least 1");
  check_same_cells(C, V, "shade output");
  if (V.interleaved)
    throw ArgumentError("shade output", "the shading is planar voxel cells, not interleaved");
  cl::Buffer pbuf = device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof params,
                                  const_cast<sv_shade_params*>(&params), "shade parameters");
  const int rw = detail::shade_row_width(V.cell()[0]);  // every cx has a float16 form
  out.mark_stored();
  if (variant == ShadeKernel::vec16) {
    const std::string name = "simdvol_shade16";
    Defines defines = shade_defines(params);
    defines.emplace_back("SV_RW", std::to_string(rw));
    if (detail::nt_stores() && detail::nt_aligned({&out.buffer()}))
      defines.emplace_back("SV_NT", "1");
    cl::Kernel k = device.kernel("shade", name, defines);
    set_args(k, name, cells.cells(), out.buffer(), cells.origins(), cells.dims_arg(),
             cells.cell_arg(), cells.block_arg(), static_cast<cl_int>(C.pes()),
             static_cast<cl_int>(V.stride), pbuf);
    const detail::PlaneRange r = detail::chunk_range(V);
    return device.run(k, name, r.global, r.local, LocalSize::at_most);
  }
  const char* name = variant == ShadeKernel::range3d ? "simdvol_shade"
                     : variant == ShadeKernel::voxel ? "simdvol_shade_voxel"
                                                     : "simdvol_shade_rows";
  cl::Kernel k = device.kernel("shade", name, shade_defines(params));
  set_args(k, name, cells.cells(), out.buffer(), cells.origins(), cells.dims_arg(),
           cells.cell_arg(), cells.block_arg(), static_cast<cl_int>(C.pes()),
           static_cast<cl_int>(V.stride), pbuf);
  if (variant == ShadeKernel::range3d) {
    const detail::CellRange r = detail::cell_range(V);
    return device.run(k, name, r.global, r.local, LocalSize::at_most);
  }
  if (variant == ShadeKernel::voxel)
    return device.run(k, name, cl::NDRange(static_cast<std::size_t>(V.elements())),
                      cl::NDRange(detail::voxel_wgs()), LocalSize::at_most);
  const std::size_t rows = static_cast<std::size_t>(V.cell()[1] * V.cell()[2]);
  const std::size_t lr = std::min<std::size_t>(64, detail::pow2_at_least(rows));
  return device.run(
      k, name, cl::NDRange(rows, static_cast<std::size_t>(V.pes())),
      cl::NDRange(lr, std::max<std::size_t>(1, std::min<std::size_t>(64 / lr, V.pes()))),
      LocalSize::at_most);
}

}  // namespace simdvol
