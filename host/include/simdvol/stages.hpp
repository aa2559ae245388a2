// The per-voxel stages on the device: shade (kernels/shade.cl) and classify
// (kernels/classify.cl), their parameter conversion from the reference's
// types, and the "voxel cells" buffers they produce.
//
// Voxel cells. A PE-major buffer of four floats per interior voxel of each
// PE's cell (no halo), stored planar within each PE's block so that the
// kernels access every quantity at unit stride (PoCL 3.1 vectorises across
// work-items only code without vector types): PE p's block is the 4 * stride
// floats from p * 4 * stride; quantity c (0..3) of interior voxel
// (lx, ly, lz), 0 <= l < cell, is float c * stride + (lz * cy + ly) * cx + lx
// of the block. stride = cx * cy * cz rounded up to a multiple of 16 (each
// plane starts on a 64-byte line). The tails (positions cx * cy * cz ..
// stride - 1) are zero from the shade and the fused shade + classify
// kernels; the classify kernels classify them as they classify the voxels,
// so after the shade's zero tails they hold what value 0 with Id = Is = |g|
// = 0 classifies to: colour 0 and that value's alpha after the opacity step,
// not 0 where the classifier gives value 0 any opacity. No later stage reads
// the RGBA tails (the gathers, the occupancy scan and the resample take the
// cells' voxels only). Interior positions past the volume's far faces
// (padding) hold the result for the edge-replicated value there; gathers
// skip them. With one PE the buffer is the flat volume, planar.
// Interleaved voxel cells (VoxelLayout::interleaved; classified voxels of the
// fused shade + classify only): the same blocks of 4 * stride floats, but
// the four quantities of a position together, quantity c of position e at
// float 4 * e + c of the block (a 16-byte element per position), so that
// the resample reads a corner's RGBA in one load (docs/PERFORMANCE.md).
// On the host, VoxelBuffer::read/write and voxels_to_cells/voxels_from_cells
// use one 16-byte element per voxel position in (PE, position) order instead
// (element index = p * stride + position), converting to and from planar.
//   shade output:    (Id, Is, |g|, v)  diffuse, specular, gradient magnitude
//                    (as ShadeSample) and the voxel's value
//   classify output: (a' C_r, a' C_g, a' C_b, a')  premultiplied RGBA (as Rgba)
//
// Every enqueue_* function validates its arguments (ArgumentError before
// anything is enqueued), enqueues without waiting, and returns the kernel's
// profiling event. Buffers must stay alive until the queue has finished.
#pragma once

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/error.hpp"
#include "simdvol/image.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/shade.hpp"

#include "simdvol_shared.h"

namespace simdvol {

/// Geometry of a voxel-cells buffer (see the file comment).
struct VoxelLayout {
  CellLayout cells;    ///< the cell geometry it was derived from (its halo is irrelevant here)
  int64_t stride = 0;  ///< voxel positions per PE block (floats per plane)
  bool interleaved = false;  ///< RGBA of a position together instead of planar (file comment)

  int64_t pes() const { return cells.pes(); }
  const Dims3& dims() const { return cells.dims(); }
  const Dims3& cell() const { return cells.cell(); }
  int64_t cell_voxels() const { return cell()[0] * cell()[1] * cell()[2]; }
  int64_t elements() const { return pes() * stride; }
  std::uint64_t bytes() const { return static_cast<std::uint64_t>(elements()) * 16u; }
  /// Element index of interior voxel (lx, ly, lz) of `pe`.
  int64_t index(int64_t pe, int64_t lx, int64_t ly, int64_t lz) const {
    return pe * stride + (lz * cell()[1] + ly) * cell()[0] + lx;
  }
  /// Same cell geometry (dims, PE count, cell extent)?
  bool same_cells(const VoxelLayout& o) const;
};

/// The voxel layout of `cells`' interiors, planar or interleaved.
VoxelLayout make_voxel_layout(const CellLayout& cells, bool interleaved = false);

/// Serial reference of the voxel-cells layout for any 16-byte element type
/// (ShadeSample, Rgba, cl_float4): a flat x-fastest array to voxel cells (pad
/// positions take the clamped voxel's element, tails are zero) and back.
template <class T>
std::vector<T> voxels_to_cells(const std::vector<T>& flat, const VoxelLayout& L) {
  static_assert(sizeof(T) == 16, "voxel cells hold 16-byte elements");
  const Dims3& n = L.dims();
  if (flat.size() != static_cast<std::size_t>(n[0] * n[1] * n[2]))
    throw ArgumentError("voxels", "size does not match the layout's dims");
  std::vector<T> cells(static_cast<std::size_t>(L.elements()), T{});
  for (int64_t pe = 0; pe < L.pes(); ++pe) {
    const Dims3 o = L.cells.split.cell_origin(pe);
    for (int64_t lz = 0; lz < L.cell()[2]; ++lz)
      for (int64_t ly = 0; ly < L.cell()[1]; ++ly)
        for (int64_t lx = 0; lx < L.cell()[0]; ++lx) {
          const int64_t x = std::min(o[0] + lx, n[0] - 1), y = std::min(o[1] + ly, n[1] - 1),
                        z = std::min(o[2] + lz, n[2] - 1);
          cells[static_cast<std::size_t>(L.index(pe, lx, ly, lz))] =
              flat[static_cast<std::size_t>((z * n[1] + y) * n[0] + x)];
        }
  }
  return cells;
}
template <class T>
std::vector<T> voxels_from_cells(const std::vector<T>& cells, const VoxelLayout& L) {
  static_assert(sizeof(T) == 16, "voxel cells hold 16-byte elements");
  if (cells.size() != static_cast<std::size_t>(L.elements()))
    throw ArgumentError("cells", "size does not match the voxel layout");
  const Dims3& n = L.dims();
  std::vector<T> flat(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  for (int64_t pe = 0; pe < L.pes(); ++pe) {
    const Dims3 o = L.cells.split.cell_origin(pe);
    for (int64_t lz = 0; lz < L.cell()[2] && o[2] + lz < n[2]; ++lz)
      for (int64_t ly = 0; ly < L.cell()[1] && o[1] + ly < n[1]; ++ly)
        for (int64_t lx = 0; lx < L.cell()[0] && o[0] + lx < n[0]; ++lx)
          flat[static_cast<std::size_t>(((o[2] + lz) * n[1] + o[1] + ly) * n[0] + o[0] + lx)] =
              cells[static_cast<std::size_t>(L.index(pe, lx, ly, lz))];
  }
  return flat;
}

/// A voxel-cells buffer on the device.
class VoxelBuffer {
 public:
  /// Allocates layout.bytes() (ArgumentError if over the device's max allocation).
  VoxelBuffer(Device& device, const VoxelLayout& layout);
  /// Wraps the caller's buffer (at least layout.bytes(), retained; e.g.
  /// cl::Buffer(mem, true) for a cl_mem) instead of allocating one.
  /// ArgumentError if it is null or smaller.
  VoxelBuffer(const VoxelLayout& layout, cl::Buffer buffer);
  const VoxelLayout& layout() const { return layout_; }
  const cl::Buffer& buffer() const { return buffer_; }
  /// Blocking copy of the whole buffer to the host, one element per voxel
  /// position (PE-major; see the file comment).
  template <class T>
  std::vector<T> read(Device& device) const {
    static_assert(sizeof(T) == 16, "voxel cells hold 16-byte elements");
    std::vector<T> out(static_cast<std::size_t>(layout_.elements()));
    read_raw(device, out.data());
    return out;
  }
  /// Blocking copy of host data (layout().elements() elements) to the buffer.
  template <class T>
  void write(Device& device, const std::vector<T>& cells) {
    static_assert(sizeof(T) == 16, "voxel cells hold 16-byte elements");
    if (cells.size() != static_cast<std::size_t>(layout_.elements()))
      throw ArgumentError("cells", "size does not match the voxel layout");
    write_raw(device, cells.data());
  }
  /// Whether the stages or write() have stored into the buffer through
  /// this object (set by them). The fused shade + classify stores
  /// non-temporally only into such a buffer (of 64 MiB or more): on fresh
  /// memory (a first frame) the host zeroes each page into the cache as it
  /// is first touched, which ordinary stores then hit; non-temporal ones
  /// took the phantom's first frame 45 ms longer (docs/PERFORMANCE.md).
  bool stored() const { return stored_; }
  void mark_stored() { stored_ = true; }

 private:
  void read_raw(Device& device, void* out) const;
  void write_raw(Device& device, const void* in);
  VoxelLayout layout_;
  cl::Buffer buffer_;
  bool stored_ = false;
};

// ------------------------------------------------------------------ shade

/// The kernel parameters from the reference's per-view frame and parameters
/// (make_shade_frame(vol, view, p) gives the frame). Throws ArgumentError for
/// non-finite values.
sv_shade_params shade_params(const ShadeFrame& frame, const ShadeParams& p);

/// The shade code's build defines for `params`: SV_GRAD_OVER where
/// params.grad_over is set (the gradients' lengths rescaled where their
/// squares overflow float; compiled in only then, since the test alone cost
/// the fused shade + classify 4-6 %), else none. enqueue_shade and
/// enqueue_shade_classify add them; a program built from shade.cl by hand
/// for such a volume needs them too.
Defines shade_defines(const sv_shade_params& params);

/// Decomposition of the shade kernel (kernels/shade.cl, which records the
/// measurements): vec16 (the default, fastest measured: explicit float16 on
/// chunks of 16 voxels, simdvol_shade16, for every x extent of the cells: the
/// row width SV_RW is 16 where cx is a multiple of 16, cx where it is 8 or 4,
/// and 1 for any other cx, per-lane positions and row-wise loads) or the
/// scalar alternatives.
enum class ShadeKernel { range3d, voxel, rows, vec16 };

/// Shades `cells` (halo >= 1, filled by the layout stage) into `out` (a voxel
/// buffer of the same cells).
cl::Event enqueue_shade(Device& device, const CellBuffer& cells, const sv_shade_params& params,
                        VoxelBuffer& out, ShadeKernel variant = ShadeKernel::vec16);

// --------------------------------------------------------------- classify

/// The kernel parameters from a classifier, the range its relative mixture's
/// fractions are of (used by relative mixtures only: pass
/// mixture_range(vol, c.mixture), as the engine and the reference do; for
/// the "mri" preset it is not vol.range()) and the opacity step. Throws ArgumentError for an
/// invalid classifier (as the reference does), more than SV_MAX_MATERIALS
/// materials or SV_MAX_KNOTS ramp points, or a step that is not positive.
/// opacity_step: the distance between consecutive samples of a ray in units
/// of the smallest voxel spacing (the unit the classifier's opacities are
/// given for); pass the view's ViewGeometry::step, as the engine and the
/// reference renderer do (make_view: 1 with voxel sampling, the spanned
/// length over min(width, height) with pixel sampling). Each alpha becomes
/// 1 - (1 - alpha)^opacity_step (alpha itself for exactly 1).
sv_classify_params classify_params(const Classifier& c, const ValueRange& range,
                                   double opacity_step);

/// Compile-time specialisation of the classify kernel for these parameters
/// (kind and counts; see kernels/classify.cl).
Defines classify_defines(const sv_classify_params& params);

/// Kernel of the classify stage (kernels/classify.cl): vec16 (the default,
/// explicit float16 on chunks of 16 voxels) or scalar (one work-item per
/// voxel; kept for comparison). Both give the same results.
enum class ClassifyKernel { vec16, scalar };

/// Classifies the shade stage's output `shading` into `out` (both voxel
/// buffers of the same cells; they may not be the same buffer).
cl::Event enqueue_classify(Device& device, const VoxelBuffer& shading,
                           const sv_classify_params& params, VoxelBuffer& out,
                           ClassifyKernel variant = ClassifyKernel::vec16);

/// Classifies `voxels` in place: the shade stage's output in it becomes
/// what enqueue_classify would write (the same bits). A voxel moves 32
/// bytes instead of 48 (no write-allocate of a separate output); the
/// shading is lost.
cl::Event enqueue_classify_in_place(Device& device, VoxelBuffer& voxels,
                                    const sv_classify_params& params,
                                    ClassifyKernel variant = ClassifyKernel::vec16);

struct DeviceOccupancy;  // local_cl.hpp

/// Shade and classify fused in one launch: `out` receives what
/// enqueue_classify would (the same float code). vec16 (the default) uses
/// the float16 kernel where the cells allow it (as enqueue_shade), any other
/// value the scalar 3-D range kernel. With `mark` (from make_occupancy for
/// out's layout; vec16 only, else ArgumentError) the kernel also sets the
/// brick occupancy of what it writes, as enqueue_occupancy's scan would.
/// With `live` (cl_uchar per PE; vec16 only, else ArgumentError; fewer than
/// P flags: ArgumentError) the PEs flagged 0 are left as they are in `out`
/// (no loads, stores or marks), and so are the chunks of 16 positions the
/// call finds transparent in the other PEs: pass it only where `out` holds
/// what this call wrote for the same cells, classification and gradient
/// scale (under any lighting), and each PE flagged 0 has every voxel
/// transparent (the engine passes the previous frame's PE mask of the same
/// volume and classification: match.hpp's inactive PEs).
/// With `kept` (vec16 only, else ArgumentError; a buffer of fewer than
/// KeptClassification::bytes for out's layout: ArgumentError): the classification
/// before lighting, kept for the frames after. Where kept->filled is false
/// the call classifies and writes it (per position: alpha where the voxel
/// is lit, i.e. alpha >= FLT_MIN, value not NaN, inside the volume's cell,
/// else 0; and each colour over that alpha; four planes per PE block as
/// planar voxel cells) and sets filled; where it is true the call reads it
/// instead of classifying (the same bits in `out`). Pass a filled one only
/// where a call wrote it from the same cells (values), classification (the
/// opacity step aside: it is applied after) and gradient scale.
struct KeptClassification {
  cl::Buffer planes;  ///< 4 * stride floats per PE of the voxel layout (7 with gradient)
  /// Also the gradient (planes 4..6: gx, gy, gz scaled as the shading's;
  /// the reading call takes |g| from them by the shading's expression),
  /// which the reading call lights instead of taking the six neighbours
  /// again.
  bool gradient = false;
  bool filled = false;           ///< written by a call (the next one reads it)
  bool filled_gradient = false;  ///< `gradient` when it was written
  /// The bytes `planes` needs for voxel layout V: 4 planes of V.stride
  /// floats per PE, 7 with the gradient.
  static std::uint64_t bytes(const VoxelLayout& V, bool gradient) {
    return V.bytes() / 4 * (gradient ? 7u : 4u);
  }
};
cl::Event enqueue_shade_classify(Device& device, const CellBuffer& cells,
                                 const sv_shade_params& shade, const sv_classify_params& classify,
                                 VoxelBuffer& out, ShadeKernel variant = ShadeKernel::vec16,
                                 DeviceOccupancy* mark = nullptr, const cl::Buffer* live = nullptr,
                                 KeptClassification* kept = nullptr);

/// Gathers the in-volume voxels of `voxels` into `flat` (a buffer of at
/// least dims-product 16-byte elements, x fastest).
cl::Event enqueue_gather_voxels(Device& device, const VoxelBuffer& voxels, const cl::Buffer& flat);

/// Blocking gather into host memory (dims-product Rgba): zero-copy on PoCL.
void gather_rgba(Device& device, const VoxelBuffer& voxels, Rgba* out, cl::Event* event = nullptr);

}  // namespace simdvol
