// The layout stage on the device: the PE array, its cell buffers, and the
// kernels that scatter a flat volume into PE-major cells with halo
// (simdvol_layout) and gather the interior back (simdvol_gather). Buffer
// layouts are described in pe_array.hpp, kernel arguments in kernels/common.cl.
//
// For later stages (shade, classify, ...): take a CellBuffer, build the
// stage's kernel with device.kernel("<stage>", "simdvol_<stage>", defines),
// and pass
//   cells.cells(), cells.origins(), cells.dims_arg(), cells.cell_arg(),
//   cells.block_arg(), (int)cells.layout().pes()
// where the kernel's own argument list has them, with its other arguments
// between and after them (common.cl says what each geometry argument holds;
// docs/KERNELS.md, section 5, lists each kernel's arguments in order). The
// shade kernels, for one, take (cells, out, origins, dims, cell, block, pes,
// vstride, params): the output second, the voxel stride and the parameters
// after pes. A stage that produces another per-voxel array of the same shape
// allocates it with CellBuffer(device, layout) (or its own buffer of
// layout().elements() elements of its type).
#pragma once

#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

/// Each PE's cell origin (x, y, z, 0), p = 0 .. P - 1: the table that
/// CellBuffer::origins() holds for the layout kernels and that the resample
/// kernels' prefetch reads (make_resample_tables).
std::vector<cl_int4> cell_origin_table(const KdSplit& split);

/// A PE-major cell buffer on the device plus its per-PE tables.
class CellBuffer {
 public:
  /// Allocates the cells (contents undefined until a layout fills them),
  /// and uploads the origins and pe_of_cell tables. Throws ArgumentError if
  /// the buffer exceeds the device's max allocation or int32 indexing.
  CellBuffer(Device& device, const CellLayout& layout);
  /// Wraps the caller's buffer `cells` (at least layout.bytes(), retained;
  /// ArgumentError if smaller) instead of allocating one; the small origin
  /// and pe_of_cell tables are still made here. A null `cells` allocates.
  CellBuffer(Device& device, const CellLayout& layout, cl::Buffer cells);

  const CellLayout& layout() const { return layout_; }
  /// float[layout().elements()], PE-major.
  const cl::Buffer& cells() const { return cells_; }
  /// cl_int4[pes]: first voxel of each PE's cell (w = 0).
  const cl::Buffer& origins() const { return origins_; }
  /// cl_int[pes]: the PE of cell (ix, iy, iz) at (iz * sy + iy) * sx + ix.
  const cl::Buffer& pe_of_cell() const { return pe_of_cell_; }

  /// Kernel arguments as in common.cl.
  cl_int4 dims_arg() const;
  cl_int4 cell_arg() const;   ///< w = halo
  cl_int4 block_arg() const;  ///< w = cell_stride
  cl_int4 splits_arg() const;

  /// Copies the whole buffer to the host (blocking).
  std::vector<float> read(Device& device) const;

 private:
  CellLayout layout_;
  cl::Buffer cells_;
  cl::Buffer origins_;
  cl::Buffer pe_of_cell_;
};

/// Kernel variant of the layout and gather stages (rows is the default; see
/// kernels/layout.cl for why).
enum class LayoutKernel { rows, voxel };

/// The PE array: a device and a W x H grid of PEs.
class PeArray {
 public:
  explicit PeArray(Device& device, PeGrid grid = {});

  Device& device() const { return *device_; }
  const PeGrid& grid() const { return grid_; }
  int64_t pes() const { return grid_.count(); }

  /// make_cell_layout for this PE count, checked against the device's max
  /// allocation (ArgumentError naming "volume").
  CellLayout cell_layout(const Dims3& dims, int halo) const;

  /// Scatters `data` (dims, x fastest) into a new cell buffer with halo width
  /// `halo`. Blocking. `event`, if given, receives the kernel's event.
  CellBuffer layout(const float* data, const Dims3& dims, int halo,
                    LayoutKernel variant = LayoutKernel::rows, cl::Event* event = nullptr) const;
  CellBuffer layout(const Volume& volume, int halo, LayoutKernel variant = LayoutKernel::rows,
                    cl::Event* event = nullptr) const;
  /// Scatters `data` (of cells.layout().dims()) into an existing buffer.
  void layout_into(const float* data, CellBuffer& cells, LayoutKernel variant = LayoutKernel::rows,
                   cl::Event* event = nullptr) const;

  /// Scatters a flat volume already on the device (`flat`: at least the
  /// dims-product floats, x fastest; e.g. the caller's own buffer) into
  /// `cells`. Enqueues without waiting and returns the kernel's event.
  cl::Event enqueue_layout(const cl::Buffer& flat, CellBuffer& cells,
                           LayoutKernel variant = LayoutKernel::rows) const;

  /// Gathers the interior voxels of `cells` into `out` (dims product floats,
  /// x fastest). Blocking.
  void gather(const CellBuffer& cells, float* out, LayoutKernel variant = LayoutKernel::rows,
              cl::Event* event = nullptr) const;
  std::vector<float> gather(const CellBuffer& cells,
                            LayoutKernel variant = LayoutKernel::rows) const;

  /// X-Net cost of filling the halo of `layout` on this grid.
  HaloCost halo_cost(const CellLayout& layout) const { return simdvol::halo_cost(layout, grid_); }

 private:
  Device* device_;
  PeGrid grid_;
};

}  // namespace simdvol
