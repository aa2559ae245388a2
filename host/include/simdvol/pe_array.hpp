// The PE array model: P processing elements (a power of two, default
// 8,192 = 128 x 64 like the DECmpp 12000), the k-d split of the volume into
// one cell per PE, the PE-major cell buffer layout with its halo, and the
// X-Net cost of filling the halo. Pure functions, no OpenCL (the device stages
// that use them are in layout.hpp).
//
// k-d split. For P = 2^N, PE-index bit b is assigned an axis bit_axis[b]. The
// axes are chosen greedily, coarsest first: bit N-1 is the first (coarsest)
// split, bit 0 the last (finest). Each split halves the axis whose current
// cell extent ceil(n_a / splits_a) is largest (ties: x, then y, then z).
// Along one axis, the PE bits of that axis, read from the highest to the
// lowest, form the cell's index along the axis (the higher bit is the coarser
// half). Cells are uniform: extent c_a = ceil(n_a / splits_a), origin
// index_a * c_a; cells at the far edges are padded past the volume (and a
// cell may lie wholly outside it when n_a < splits_a).
//
// Binary swap. Stage k pairs p with p ^ 2^k. After the stages below k, p's
// group holds kd_region(split, p, k) and the partner's group holds
// kd_region(split, p ^ 2^k, k): two boxes with equal extents, adjacent along
// bit_axis[k], split by an axis-aligned plane. The box of the PE whose bit k is
// 0 has the smaller coordinates along that axis.
//
// Cell buffer. PE p's block starts at p * cell_stride floats. Within a block,
// the (c_x + 2h) x (c_y + 2h) x (c_z + 2h) padded cell is stored x fastest,
// then y, then z; local position (lx, ly, lz), each in [-h, c + h), is at
// ((lz + h) * by + (ly + h)) * bx + (lx + h) with (bx, by, bz) = c + 2h.
// cell_stride is bx*by*bz rounded up to a multiple of 16 floats (64 bytes), so
// every block starts on a cache line; the tail is filled with zeros. Every
// position (interior, halo, pad) holds the volume value at the clamped
// position clamp(origin + l, 0, n - 1): halo and pad are edge-replicated,
// which matches Volume::at_clamped of the reference.
//
// Mesh. PE p sits at (p % W, p / W) on the W x H grid. X-Net links 8
// directions (thesis ch. 3.4), so the mesh distance is the Chebyshev
// (max-norm) distance max(|dx|, |dy|); there is no wraparound.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace simdvol {

using Dims3 = std::array<int64_t, 3>;

/// The PE grid: W x H PEs, W * H a power of two.
struct PeGrid {
  int64_t width = 128;
  int64_t height = 64;
  int64_t count() const { return width * height; }
  int bits() const;  ///< log2(count())
};

/// Largest supported PE count (2^20).
inline constexpr int64_t kMaxPes = int64_t(1) << 20;

/// The grid for `count` PEs: W = 2^ceil(N/2), H = 2^floor(N/2) (8192 -> 128 x 64).
/// Throws ArgumentError naming `argument` unless count is a power of two in [1, kMaxPes].
PeGrid pe_grid(int64_t count, const std::string& argument = "--pes");
/// Parses "N" (e.g. "8192") or "WxH" (e.g. "128x64", W and H >= 1, W * H a
/// power of two <= kMaxPes). Throws ArgumentError naming `argument` otherwise.
PeGrid parse_pe_grid(std::string_view spec, const std::string& argument = "--pes");

struct MeshCoord {
  int64_t x = 0;
  int64_t y = 0;
};
/// (p % W, p / W).
MeshCoord mesh_coord(const PeGrid& grid, int64_t pe);
/// Chebyshev distance between two PEs on the mesh (X-Net hops).
int64_t mesh_distance(const PeGrid& grid, int64_t a, int64_t b);

/// The k-d split of a volume over 2^bits PEs (see the file comment).
struct KdSplit {
  Dims3 dims{0, 0, 0};
  int bits = 0;
  std::vector<int> bit_axis;       ///< bit_axis[b]: axis (0 x, 1 y, 2 z) split by PE bit b
  std::array<int, 3> axis_bits{};  ///< number of PE bits per axis
  Dims3 cell{0, 0, 0};             ///< interior cell extent c_a

  int64_t pes() const { return int64_t(1) << bits; }
  /// Number of cells along each axis, 2^axis_bits[a].
  Dims3 splits() const;
  /// The cell index of PE `pe` along each axis.
  Dims3 cell_index(int64_t pe) const;
  /// Inverse of cell_index.
  int64_t pe_of_cell(const Dims3& index) const;
  /// First voxel of the cell of `pe` (index * cell).
  Dims3 cell_origin(int64_t pe) const;
  /// The PE whose cell holds voxel v (0 <= v < dims).
  int64_t owner(const Dims3& voxel) const;
  bool operator==(const KdSplit&) const = default;
};

/// Splits `dims` over `pes` PEs. Throws ArgumentError for a non-positive
/// dimension or a PE count that is not a power of two in [1, kMaxPes].
KdSplit kd_split(const Dims3& dims, int64_t pes);

/// A half-open box [lo, hi) of voxel positions.
struct Box {
  Dims3 lo{0, 0, 0};
  Dims3 hi{0, 0, 0};
  bool operator==(const Box&) const = default;
};

/// The union of the cells of all PEs that agree with `pe` in bits >= level:
/// level 0 is pe's own cell, level bits the whole (padded) domain. It is a box
/// (in padded coordinates: it may reach past the volume).
Box kd_region(const KdSplit& split, int64_t pe, int level);

/// A PE-major cell layout with halo (see the file comment).
struct CellLayout {
  KdSplit split;
  int halo = 0;
  Dims3 block{0, 0, 0};     ///< padded cell extent, cell + 2 * halo
  int64_t cell_stride = 0;  ///< floats per PE block (multiple of 16)

  int64_t pes() const { return split.pes(); }
  const Dims3& dims() const { return split.dims; }
  const Dims3& cell() const { return split.cell; }
  /// Floats in the whole buffer, pes() * cell_stride.
  int64_t elements() const { return pes() * cell_stride; }
  std::uint64_t bytes() const { return static_cast<std::uint64_t>(elements()) * sizeof(float); }
  /// Buffer index of local position (lx, ly, lz), each in [-halo, cell + halo).
  int64_t index(int64_t pe, int64_t lx, int64_t ly, int64_t lz) const;
  /// The (clamped) volume voxel copied to local position l of `pe`.
  Dims3 source(int64_t pe, int64_t lx, int64_t ly, int64_t lz) const;
};

/// Layout of `dims` over `pes` PEs with halo width `halo` (0..8). Throws
/// ArgumentError for bad arguments or a buffer whose size overflows.
CellLayout make_cell_layout(const Dims3& dims, int64_t pes, int halo);

/// Serial reference of the layout stage: `volume` (x fastest, dims of the
/// layout) scattered into a PE-major buffer of layout.elements() floats.
std::vector<float> layout_reference(const std::vector<float>& volume, const CellLayout& layout);
/// Serial reference of the gather stage: interior voxels back to a flat volume.
std::vector<float> gather_reference(const std::vector<float>& cells, const CellLayout& layout);

/// One neighbouring PE whose voxels a PE's padded block copies.
struct HaloTransfer {
  int64_t from_pe = 0;
  int64_t distance = 0;  ///< Chebyshev mesh distance (X-Net hops)
  int64_t voxels = 0;
  int64_t bytes = 0;
};

/// The PEs (other than `pe`) whose voxels fill `pe`'s halo and pad positions,
/// with the number of voxels copied from each, sorted by from_pe. A position
/// is charged to the PE that owns its clamped source voxel; positions whose
/// source is pe's own cell cost nothing. grid.count() must equal layout.pes().
std::vector<HaloTransfer> halo_transfers(const CellLayout& layout, const PeGrid& grid, int64_t pe,
                                         std::size_t voxel_bytes = sizeof(float));

/// Totals of halo_transfers over all PEs.
struct HaloCost {
  int64_t transfers = 0;         ///< (PE, source PE) pairs
  int64_t voxels = 0;            ///< voxels copied in all
  int64_t bytes = 0;             ///< bytes copied in all
  int64_t max_pe_bytes = 0;      ///< most bytes received by one PE (the SIMD step cost)
  int64_t max_pe_transfers = 0;  ///< most source PEs of one PE
  int64_t max_distance = 0;      ///< longest X-Net distance of any transfer
  int64_t byte_hops = 0;         ///< sum of bytes * distance
};
HaloCost halo_cost(const CellLayout& layout, const PeGrid& grid,
                   std::size_t voxel_bytes = sizeof(float));

}  // namespace simdvol
