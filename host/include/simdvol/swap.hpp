// Binary swap and display on the PE array (thesis ch. 6 and 3.5): the
// schedule as pure functions, the serial references of the `swap` and
// `display` stages, and the communication they cost. The device stages are
// in swap_cl.hpp (kernels/swap.cl).
//
// Input: the footprints of the local stage (local.hpp): PE p holds one
// premultiplied (C', a) per pixel of its rectangle rects[p] (0 where it has
// no segment).
//
// Stages. With P = 2^N PEs, stage k = 0 .. N-1 pairs p with q = p ^ 2^k.
// Before stage k, p's group (the PEs that agree with p in bits >= k) holds
// the samples of kd_region(split, p, k); p's and q's groups hold two boxes
// adjacent along a = split.bit_axis[k], and the group whose bit k is 0 has
// the smaller coordinates along a. Every ray crosses the plane between them
// at most once, in the direction of the view's sign along a (the fixed-point
// step d X_a / d k): when that step is >= 0 the bit-0 group is in front
// (SwapPlan::front[k] = 0), else the bit-1 group (front[k] = 1). Balancing
// moves only boundaries between consecutive segments of a ray, so this order
// still holds after it. Stage k splits the pixels of the pair by one pixel
// bit (bits[k]: axis x or y, bit level): p keeps the pixels whose bit equals
// bit k of p and receives them from q; q keeps the others. Each kept pixel
// becomes over(front, back) of p's and q's values (0 where one has none).
//
// Pixel bits (swap_pixel_bits). The PE grid is W x H = 2^bx x 2^by. The N
// stages take bx bits of x and by bits of y, alternating x, y, x, y, ...
// starting with x while both axes have bits left, then the rest of the axis
// that has more. Stage k's bit of axis a is, when it is the j-th stage of
// that axis (j = 0, 1, ...):
//   cut-and-stack: level j (least significant up), so after the swap pixel
//     (x, y) lives on the PE with x mod W, y mod H in its x- and y-bits;
//   hierarchical: level B_a - 1 - j (most significant down), B_a =
//     max(ceil(log2(extent_a)), bits of a), so pixel (x, y) lives on the PE
//     with x >> (B_x - bx), y >> (B_y - by) in its x- and y-bits.
// "x-bits of p" are the PE bits k with bits[k].axis == x, the j-th x stage
// giving bit j of a number X (cut-and-stack) or bit bx - 1 - j
// (hierarchical; likewise Y): the final layout is the thesis's cut-and-stack
// (x mod W = X, eq 3.3) or hierarchical (x DIV 2^(B_x - bx) = X, eq 3.2)
// virtualisation of the image over a W x H virtual processor array whose
// processor (X, Y) is the PE with those bits (x and y bits alternate in the
// PE index, a Morton order of the W x H mesh). The
// alternation keeps the strides of x and y equal (to within a factor of
// two) at every stage, so the strided rectangles below stay balanced for
// square-ish footprints; taking all x bits first (the mesh's row-major
// order) leaves PEs empty once 2^k exceeds the group footprint's width.
//
// Bounded buffers. After L stages p holds the pixels of its group footprint
// F_L(p) (bounding box of the rectangles of p's group: F_0 = rects[p],
// F_{L+1}(p) = bbox(F_L(p), F_L(p ^ 2^L))) that satisfy p's L pixel-bit
// constraints: per axis x = r (mod s) within [lo, hi) (cut-and-stack: s =
// 2^j, r = the x-bits of p; hierarchical: s = 1 and a block of 2^(B-j)
// values). That set is a strided rectangle (SwapRect: origin, count, stride
// per axis), stored densely (row-major); held[0] are the footprints
// themselves. Level L's buffer is the concatenation of held[L][p] over p
// (offset[L]): never a full frame per PE.
//
// Display: after the N stages, pixel (x, y) of the intermediate image is on
// PE display_pe(x, y) = xpe[x] | ype[y] (separable), at its index in
// held[N][p] (0 when outside: no sample).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/local.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// Final layout of the swap (thesis ch. 3.5).
enum class SwapLayout { cut_and_stack, hierarchical };
/// "cut-and-stack" (or "cut_and_stack", "cs") / "hierarchical" ("hier");
/// ArgumentError naming `argument` otherwise.
SwapLayout parse_swap_layout(std::string_view s, const std::string& argument = "--layout");
const char* swap_layout_name(SwapLayout layout);

/// One pixel-coordinate bit: axis 0 = x (i), 1 = y (j); level = bit index.
struct PixelBit {
  int axis = 0;
  int level = 0;
  bool operator==(const PixelBit&) const = default;
};

/// ceil(log2(n)) for n >= 1.
int ceil_log2(int64_t n);

/// The pixel bit of every stage (see the file comment) for a grid of W x H
/// PEs and a width x height intermediate image. ArgumentError for a grid
/// that is not powers of two or a non-positive image size.
std::vector<PixelBit> swap_pixel_bits(const PeGrid& grid, int width, int height, SwapLayout layout);

/// A strided rectangle: pixels (x0 + a * sx, y0 + b * sy), a < nx, b < ny,
/// stored row-major (index b * nx + a); strides are powers of two, lx, ly
/// their log2. 32 bytes: an OpenCL int8 in swap.cl.
struct SwapRect {
  int32_t x0 = 0, y0 = 0, nx = 0, ny = 0, sx = 1, sy = 1, lx = 0, ly = 0;
  int64_t count() const { return int64_t(nx) * ny; }
  bool contains(int64_t x, int64_t y) const;
  /// Index of pixel (x, y), which must be contained.
  int64_t index(int64_t x, int64_t y) const { return (y - y0) / sy * nx + (x - x0) / sx; }
  bool operator==(const SwapRect&) const = default;
};

/// The pixels of [lo, hi) with x = r (mod s) along one axis: first pixel and
/// count (count 0: first = lo clipped).
struct StridedRange {
  int64_t first = 0;
  int64_t count = 0;
};
StridedRange strided_range(int64_t lo, int64_t hi, int64_t stride, int64_t residue);

namespace detail {
/// A half-open pixel box [x0, x1) x [y0, y1) (plan_swap_into's group
/// footprints); empty when x0 >= x1 or y0 >= y1.
struct SwapBox {
  int64_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  bool empty() const { return x0 >= x1 || y0 >= y1; }
};
}  // namespace detail

/// The whole schedule of one frame.
struct SwapPlan {
  SwapLayout layout = SwapLayout::cut_and_stack;
  int width = 0, height = 0;   ///< intermediate image
  int64_t pes = 0;             ///< P = 2^N
  std::vector<PixelBit> bits;  ///< N: the pixel bit of stage k
  std::vector<int> front;      ///< N: which half (bit k of the PE) is in front at stage k
  std::vector<std::vector<SwapRect>> held;   ///< N + 1 levels x P
  std::vector<std::vector<int64_t>> offset;  ///< N + 1 levels x (P + 1): prefix of counts
  std::vector<int64_t> xpe, ype;             ///< display_pe tables (width, height entries)
  /// plan_swap_into's working storage, not part of the schedule (nothing
  /// reads it after): kept with the plan, so that a plan made again for as
  /// many PEs takes no fresh host memory.
  struct Work {
    std::vector<detail::SwapBox> boxes;  ///< P: the group footprints
    std::vector<int32_t> residues[2];    ///< per axis, P: the PEs' constrained bits
  } work;

  int stages() const { return static_cast<int>(bits.size()); }
  /// Pixels stored at level L (offset[L][P]).
  int64_t level_size(int level) const { return offset[static_cast<std::size_t>(level)].back(); }
  /// The PE that holds pixel (x, y) after the swap.
  int64_t display_pe(int x, int y) const {
    return xpe[static_cast<std::size_t>(x)] | ype[static_cast<std::size_t>(y)];
  }
};

/// The direction flag of stage k (see the file comment): 0 when the group
/// whose bit k is 0 is in front for `view`, 1 otherwise.
int swap_front(const KdSplit& split, const ViewGeometry& view, int stage);

/// Plans the swap of footprints `rects` (one per PE) for `view` under
/// `split` on `grid` (grid.count() == split.pes() == rects.size()).
/// ArgumentError for mismatched sizes or a rectangle outside the image.
SwapPlan plan_swap(const std::vector<sv_rect>& rects, const KdSplit& split,
                   const ViewGeometry& view, const PeGrid& grid, SwapLayout layout);
/// plan_swap into `plan`, reusing the storage of its vectors: a plan kept
/// from frame to frame takes no fresh memory (the engine's; no allocation
/// where P, N, the image size and whether `held_out` is given are those of
/// the plan's last making). The same plan; on an ArgumentError `plan` is
/// unchanged (but for `work`). With `held_out` (N + 1 pointers, one per
/// level, each to room for P rectangles) level L's rectangles are written
/// to held_out[L] instead, and plan.held is left empty (its memory freed):
/// the engine writes them straight into the device's mapped table buffer
/// (swap_cl.hpp: swap_plan_held_in_map). What reads plan.held (swap_cost,
/// the references, display_reference) needs a plan made without it.
void plan_swap_into(SwapPlan& plan, const std::vector<sv_rect>& rects, const KdSplit& split,
                    const ViewGeometry& view, const PeGrid& grid, SwapLayout layout,
                    SwapRect* const* held_out = nullptr);

/// Serial reference of stage k: level k's buffer -> level k + 1's.
std::vector<Rgba> swap_stage_reference(const SwapPlan& plan, int stage,
                                       const std::vector<Rgba>& in);
/// All stages from the footprints (level 0; f.rect_offset must equal
/// plan.offset[0]) to level N.
std::vector<Rgba> swap_reference(const SwapPlan& plan, const Footprints& f);
/// Serial reference of display: level N's buffer -> the intermediate image.
Image display_reference(const SwapPlan& plan, const std::vector<Rgba>& final_level);

/// Communication and load of the swap. A pixel moves at stage k when it is
/// in q's level-k rectangle and p keeps it (p receives it from q, as a
/// float4: 16 bytes).
struct SwapStageCost {
  int64_t moved = 0;         ///< pixels sent, all PEs
  int64_t max_sent = 0;      ///< most pixels one PE sends
  int64_t max_held = 0;      ///< most pixels one PE holds before the stage
  int64_t max_kept = 0;      ///< most pixels one PE composites (its level k + 1 rectangle)
  int64_t held = 0;          ///< pixels held before the stage, all PEs
  int64_t kept = 0;          ///< pixels after, all PEs
  int64_t max_distance = 0;  ///< X-Net hops between partners on the W x H mesh
};
struct SwapCost {
  std::vector<SwapStageCost> stages;
  int64_t moved = 0;        ///< pixels, all stages and PEs
  int64_t max_pe_sent = 0;  ///< most pixels one PE sends over all stages
  int64_t bytes_per_pixel = 16;
  /// The bound of ch. 6.2, per PE: the thesis estimates what a PE holds by
  /// S = (a^2 + b^2 + c^2) / 2 pixels (a, b, c its cell's extents in
  /// viewing-grid units; S bounds the cell's largest cross-section), and a
  /// PE sends at most what it holds at each of its M + N swaps (M, N the x
  /// and y swaps): (M + N) S in all, bound_sum(); the thesis prints the
  /// total as M x N x S. S is an estimate, not a bound, of what a PE holds:
  /// that is the cell's projection (up to sqrt(a^2 b^2 + b^2 c^2 + c^2 a^2),
  /// 1.15 S for a cube) in its bounding rectangle, 1.39 S at (20, 35, 10) in
  /// bench/REPRODUCTION.md; a PE sends about half of what it holds, and the
  /// holdings shrink stage by stage, so the measured sends stay far below
  /// bound_sum(). Compare bound_sum() with max_pe_sent (one PE's pixels),
  /// not with moved (all PEs').
  double cell_section = 0;  ///< S in pixels
  int swaps_x = 0, swaps_y = 0;
  double bound_sum() const { return (swaps_x + swaps_y) * cell_section; }
  double bound_printed() const { return double(swaps_x) * swaps_y * cell_section; }
};
/// Costs of `plan` for PEs on `grid` (cell extents from `split`, scaled by
/// 1 / view.step).
SwapCost swap_cost(const SwapPlan& plan, const KdSplit& split, const ViewGeometry& view,
                   const PeGrid& grid);

}  // namespace simdvol
