// The resample and local stages on the device (kernels/resample.cl,
// kernels/local.cl); references in local.hpp.
//
// Inputs: the segments of a (balanced) matching on the device (CSR, int32
// offsets), the classified voxel cells (stages.hpp) and the view. Outputs:
// the samples in segment order (resample; for tests and per-stage timing)
// and the footprints of the per-segment composites (local, or the fused
// resample + local, the frame path).
//
// Decomposition: one work-item per segment (the work-items of a group are
// consecutive segments of one PE, similar rays), local size kSegmentWgs.
// Stencil voxels are read from their owner's cell through a per-axis address
// table (see resample.cl). Every enqueue_* validates first, enqueues without
// waiting and returns the kernel's profiling event; buffers must outlive the
// queue's work.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/local.hpp"
#include "simdvol/match.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// Work-items per work-group of the per-segment kernels.
inline constexpr std::size_t kSegmentWgs = 64;

/// A matching's segments on the device.
struct LocalSegments {
  int64_t pes = 0;                  ///< P (a power of two)
  int64_t count = 0;                ///< number of segments
  cl::Buffer segments;              ///< sv_segment[count]
  cl::Buffer seg_offset;            ///< cl_int[P + 1]
  cl::Buffer rects;                 ///< sv_rect[P]
  std::vector<sv_rect> host_rects;  ///< the same rectangles on the host (footprint sizes)
  /// Where a balance left its unpack pending (DeviceMatching::unpack_pending,
  /// BalanceUnpack::deferred): the segments' (k0, k1) are cl_short2 in
  /// `bounds` (the segments hold the matching's). Only enqueue_segment_order
  /// and the vector8 enqueue_resample_local take them there; every other
  /// stage throws ArgumentError on such segments (enqueue_balance_unpack
  /// first, then device_segments again).
  bool bounds_pending = false;
  cl::Buffer bounds;  ///< cl_short2[count] where bounds_pending
  /// The segments' samples (the sum of k1 - k0, sample_offsets(m).back())
  /// where the host knows it: upload_segments sets it; device_segments
  /// cannot without a read (-1), and a caller that has the total (the
  /// engine reads it to size its buffer) may set it. The stages that take
  /// a `samples` buffer check its size against it where it is not -1.
  int64_t sample_count = -1;
};
/// ArgumentError naming `stage` where segs.bounds_pending.
void check_bounds_unpacked(const LocalSegments& segs, const char* stage);
/// The checks every stage taking segments makes first (on the host: one
/// clGetMemObjectInfo per buffer, nothing enqueued, no wait): ArgumentError,
/// naming the member and the sizes, where P is not a power of two, count is
/// outside 0 .. 2^31 - 1, or the buffers hold fewer than `count` segments,
/// P + 1 offsets and P rectangles (`all` false: the segments alone, for the
/// stages that read nothing else), or `bounds` fewer than `count` short2
/// where bounds_pending.
void check_segments(const LocalSegments& segs, bool all = true);
/// ArgumentError where `sample_off` holds fewer than segs.count + 1 ints or
/// `samples` fewer than segs.sample_count float4 (where that is known).
void check_samples(const LocalSegments& segs, const cl::Buffer& sample_off,
                   const cl::Buffer& samples);
/// Uploads m's segments, offsets and rectangles (blocking). ArgumentError if
/// P is not a power of two or the counts exceed int32.
LocalSegments upload_segments(Device& device, const Matching& m);

/// The segments of a device matching (enqueue_match, enqueue_balance) without
/// copying them: reads back the segment count and the rectangles (blocking;
/// the footprints' sizes are needed on the host to allocate them).
/// finish_segments(start_segments(device, m), m).
LocalSegments device_segments(Device& device, const DeviceMatching& m);

/// device_segments in two halves, so that its reads wait for the matching
/// only: start_segments enqueues the reads of the segment count and the
/// rectangles (not blocking); finish_segments waits for those two and takes
/// the rest from m as it is then. A balance enqueued between the two
/// (enqueue_balance) moves no segment's ray, so the count and the
/// rectangles read are its segments' too: the engine balances in between,
/// and enqueues the resample before the device has finished the balance.
/// The reads' host memory lives in the SegmentReads (keep it until
/// finish_segments). ArgumentError from finish_segments where m is not the
/// matching the reads were started on.
/// Dropped unfinished (an error between the two), it waits for its reads,
/// so that they never write into freed memory.
struct SegmentReads {
  int64_t pes = 0;
  cl::Buffer seg_offset;            ///< the matching's (to check finish_segments' m)
  std::unique_ptr<cl_int> count;    ///< read into (a stable address); null once finished
  std::vector<sv_rect> host_rects;  ///< read into
  cl::Event count_read, rects_read;

  SegmentReads() = default;
  SegmentReads(SegmentReads&&) = default;
  SegmentReads& operator=(SegmentReads&&) = delete;
  SegmentReads(const SegmentReads&) = delete;
  SegmentReads& operator=(const SegmentReads&) = delete;
  ~SegmentReads();
};
SegmentReads start_segments(Device& device, const DeviceMatching& m);
LocalSegments finish_segments(SegmentReads& reads, const DeviceMatching& m);

/// sample_offsets(m) (int32) on the device, for enqueue_resample/enqueue_local.
cl::Buffer upload_sample_offsets(Device& device, const Matching& m);

/// The view and the per-axis address table of resample.cl for one voxel
/// layout.
struct ResampleTables {
  Dims3 dims{0, 0, 0};
  int64_t pes = 0;
  cl::Buffer view;   ///< one sv_view
  cl::Buffer table;  ///< cl_int[nx + ny + nz]
  /// cl_int4[P]: each PE's cell origin, for the resample's prefetch ahead;
  /// optional (tables built by hand without it resample without the prefetch)
  cl::Buffer origins;
  /// cl_long[nx + ny + nz + 6]: resample_pair_table, the order-1 kernels'
  /// table entries of f and f + 1 in one 64-bit load; optional (tables built
  /// by hand without it gather `table` twice: the same samples)
  cl::Buffer pairs;
  /// `pairs` carries the cell bits after its entries (resample_cell_bits):
  /// the order-1 interleaved kernels then take them (the `_ilc` kernels)
  bool cell_bits = false;
  cl_int channel_stride = 0;
  bool interleaved = false;  ///< made for interleaved voxel cells (stages.hpp)
};
/// ArgumentError if the voxel buffer exceeds int32 float indexing or `view`
/// was made for other dims. `origins`: the cells' origin table if the caller
/// has it on the device (CellBuffer::origins() of the cells `layout` was made
/// from, cell_origin_table of its split), taken instead of uploading a copy.
ResampleTables make_resample_tables(Device& device, const VoxelLayout& layout,
                                    const ViewGeometry& view, const cl::Buffer* origins = nullptr);
/// The tables' view replaced by `view` (uploaded), the rest kept: the
/// tables depend on the layout only, so a caller that renders many views of
/// one layout makes them once. ArgumentError if `view` was made for other
/// dims than the tables.
void set_resample_view(Device& device, ResampleTables& tables, const ViewGeometry& view);
/// The host table (for tests): float index of channel 0 of voxel g is
/// t[gx] + t[nx + gy] + t[nx + ny + gz]; `channel_stride` receives cs.
std::vector<cl_int> resample_address_table(const VoxelLayout& layout, cl_int* channel_stride);
/// The pair table of `table` (resample_address_table's, dims n): per axis a
/// (x, then y, then z), n[a] + 2 entries, entry f + 1 for f = -1 .. n[a]
/// holding t[clamp(f)] in its low 32 bits and t[clamp(f + 1)] in its high
/// 32 bits (clamp to [0, n[a] - 1], both as uint32 bit patterns), so that a
/// lane of the order-1 kernels gets both of an axis's entries in one
/// 64-bit gather; the kernels index it with clamp(f, -1, n[a]) + 1.
/// ArgumentError if `table` does not have n[0] + n[1] + n[2] entries.
std::vector<cl_long> resample_pair_table(const std::vector<cl_int>& table, const Dims3& dims);
/// The cell bits of `table` (resample_address_table's, dims n), where its
/// layout has them: per axis a, a shift s[a] such that every entry is
/// t[g] = bits[a][g >> s[a]] + (g & (2^s[a] - 1)) * stride[a] (the cells'
/// own entries and the axis's stride inside a cell: uniform cells of 2^s[a]
/// positions), with at most 32 cells (s the largest that holds). Returns
/// 104 ints: bits[0][0..31], bits[1][0..31], bits[2][0..31] (zero past the
/// last cell), s[0..2], stride[0..2], 0, 0; empty where an axis has no such
/// s. ArgumentError if `table` does not have n[0] + n[1] + n[2] entries.
std::vector<cl_int> resample_cell_bits(const std::vector<cl_int>& table, const Dims3& dims);

/// Footprint buffers for rectangles `rects` (rect_offset = prefix of w * h).
struct DeviceFootprints {
  std::vector<int64_t> rect_offset;  ///< P + 1 on the host
  cl::Buffer offsets;                ///< cl_int[P] on the device
  cl::Buffer pixels;                 ///< cl_float4[rect_offset[P]] (at least one element)
  int64_t size() const { return rect_offset.empty() ? 0 : rect_offset.back(); }
};
/// ArgumentError where fp holds no rect_offset for `pes` PEs or its buffers
/// fewer than P offsets or max(fp.size(), 1) pixels (host-side, as
/// check_segments): the stages that write footprints check them first.
void check_footprints(const DeviceFootprints& fp, int64_t pes);
DeviceFootprints make_footprints(Device& device, const std::vector<sv_rect>& rects);
/// Zero-fills the footprints.
cl::Event enqueue_zero_footprints(Device& device, DeviceFootprints& fp);
/// Zero-fills only the footprint pixels that no segment of `m` covers
/// (match.cl: simdvol_zero_uncovered), which is enough before the direct
/// local kernels (enqueue_resample_local, enqueue_local) and the per
/// sub-ray Monte Carlo (enqueue_mc_local): they write every segment's
/// pixel, an empty segment's too. `fp` must be made from m's
/// rectangles (device_segments(device, m).host_rects); balancing moves no
/// segment's pixel. ArgumentError if fp holds another PE count.
cl::Event enqueue_zero_uncovered(Device& device, const DeviceMatching& m, DeviceFootprints& fp);
/// Reads the footprints back (blocking) as local.hpp's Footprints.
Footprints read_footprints(Device& device, const DeviceFootprints& fp);

/// The order in which the vector8 kernels take segments into their 8
/// lanes (local.cl: simdvol_segment_order): within each block of
/// SV_ORDER_BLOCK consecutive segments of one PE, by length, longest first,
/// so that the lanes that step together have similar lengths. Any order
/// gives the same footprints, bit for bit.
struct SegmentOrder {
  int64_t count = 0;  ///< the segments it orders (segs.count)
  /// cl_int[count]: position -> segment index; with `with_pe`, then
  /// cl_int[ceil(count / 8)]: the PE of position 8 w at count + w (the
  /// float8 kernels' first lane, so that they need not search for it)
  cl::Buffer order;
  bool with_pe = false;
  cl::Event event;
};
/// Enqueues the sort of `segs` (their current k0, k1, from `bounds` where
/// bounds_pending).
SegmentOrder enqueue_segment_order(Device& device, const LocalSegments& segs);

/// Kernel of the resample stages: `vector8` (the default: 8 segments per
/// work-item in explicit float8 lanes, see resample.cl) or `segment` (one
/// segment per work-item, scalar under PoCL). Same results bit for bit.
enum class LocalKernel { vector8, segment };
struct DeviceOccupancy;
/// Resamples every sample of `segs` into `samples` (cl_float4, at
/// sample_offsets(m).back() elements at least: checked against
/// segs.sample_count where that is known; `sample_off` cl_int[count + 1]),
/// in segment order. Every stage here checks the sizes of the buffers it is
/// given (check_segments, check_samples, check_footprints, the tables'
/// `table`, `view`, `pairs` and `origins`, the order's and the occupancy's)
/// before it enqueues anything: ArgumentError naming the one too small. With
/// `lanes` (made for `segs`) the vector8 kernel takes the segments in that
/// order into its lanes (the same samples). With `skip` (the occupancy of
/// `voxels` for `order`; vector8 only) the samples out of reach are stored
/// as +0 without gathering their stencils: the same samples but for the
/// sign of a zero.
cl::Event enqueue_resample(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const ResampleTables& tables, const VoxelBuffer& voxels, int order,
                           const cl::Buffer& samples, LocalKernel variant = LocalKernel::vector8,
                           const SegmentOrder* lanes = nullptr,
                           const DeviceOccupancy* skip = nullptr);
/// Composites the samples of each segment into the footprints (zeroed first).
cl::Event enqueue_local(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                        const cl::Buffer& samples, DeviceFootprints& fp);
/// Empty-space skipping (resample.cl: simdvol_occupancy): the classified
/// voxels cut into kBrick^3 bricks; `reach` marks the bricks from which a
/// sample of interpolation order `order` may read a voxel that is not zero
/// in every channel. The fused kernel skips samples in the other bricks,
/// which cannot change a composite: the footprints are the same bits.
inline constexpr int kBrick = 1 << SV_BRICK_LOG2;  // simdvol_shared.h
struct DeviceOccupancy {
  Dims3 dims{0, 0, 0};                    ///< the voxels' volume dims
  int order = -1;                         ///< the interpolation order `reach` is for
  std::array<cl_int, 3> bricks{0, 0, 0};  ///< bricks per axis: ceil(dims / kBrick)
  cl::Buffer occupied;                    ///< cl_uint per brick: some voxel is not zero
  cl::Buffer reach;                       ///< cl_uchar per brick (see above)
  std::vector<cl::Event> events;          ///< zero fill, occupancy, reach
  int64_t count() const { return int64_t(bricks[0]) * bricks[1] * bricks[2]; }
};
/// Enqueues the kernels for `voxels` (classified, RGBA) and `order`
/// (ArgumentError outside 0..3): make_occupancy, the scan of the voxels
/// (simdvol_occupancy), enqueue_occupancy_reach.
DeviceOccupancy enqueue_occupancy(Device& device, const VoxelBuffer& voxels, int order);
/// The buffers for voxels of layout `L` and `order`, `occupied` zeroed
/// (enqueued): for a kernel that marks it while it writes the voxels
/// (enqueue_shade_classify's `mark`), then enqueue_occupancy_reach.
DeviceOccupancy make_occupancy(Device& device, const VoxelLayout& L, int order);
/// `reach` from `occupied` (simdvol_occupancy_reach); appends its event.
void enqueue_occupancy_reach(Device& device, DeviceOccupancy& o);

/// Fused resample + local: the same footprints, samples never stored
/// (`variant` as for enqueue_resample). With `skip` (made for these voxels
/// and `order`) the vector8 kernel steps over samples whose every stencil
/// voxel is zero; with `lanes` (made for `segs`) it takes the segments in
/// that order. The scalar `segment` kernel ignores both. The vector8 kernel
/// reads segs.bounds where segs.bounds_pending (the same footprints as
/// after enqueue_balance_unpack); the scalar one throws ArgumentError there.
cl::Event enqueue_resample_local(Device& device, const LocalSegments& segs,
                                 const ResampleTables& tables, const VoxelBuffer& voxels, int order,
                                 DeviceFootprints& fp, LocalKernel variant = LocalKernel::vector8,
                                 const DeviceOccupancy* skip = nullptr,
                                 const SegmentOrder* lanes = nullptr);

}  // namespace simdvol
