// The swap, display and warp stages on the device (kernels/swap.cl); the
// schedule and the serial references are in swap.hpp.
//
// The plan is computed on the host from the footprint rectangles (which the
// host already reads to size the footprints) and uploaded once per frame:
// per level the strided rectangles and offsets. The first seven stages run in
// one launch (a work-group per 128 consecutive PEs, whose partners in those
// stages are all inside it; barriers between the stages; the six levels
// between in the work-group's local memory, fewer stages where they would
// not fit), the later ones one launch per stage (a work-item per PE; the
// partner's rectangle is read directly: the whole level is one buffer), no
// waits between them; the levels written to memory take turns in two
// buffer slots (ping-pong), each sized by its largest level. Every
// enqueue_* validates first and returns the profiling events.
#pragma once

#include <array>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// A SwapPlan with its tables on the device: every table a sub-buffer of
/// one buffer (`packed`), written by one command per frame.
struct DeviceSwapPlan {
  SwapPlan plan;
  std::vector<cl::Buffer> rects;    ///< per level: SwapRect[P] (int8)
  std::vector<cl::Buffer> offsets;  ///< per level: cl_int[P + 1]
  cl::Buffer xpe, ype;              ///< display tables (cl_int)
  /// The buffer the tables above are regions of, and its host image (the
  /// source of the write): each table at an offset aligned to the device's
  /// CL_DEVICE_MEM_BASE_ADDR_ALIGN, at least one element each.
  cl::Buffer packed;
  std::vector<cl_int> staging;
  std::vector<std::size_t> regions;  ///< (offset, bytes) of each table, as cut last
  void* mapped = nullptr;            ///< `packed` mapped for writing (map_swap_plan), or null
  std::size_t mapped_bytes = 0;
  cl::Event map_done;  ///< a non-blocking map's event (upload_swap_plan waits for it)
  /// Set where swap_plan_held_in_map gave the mapping's rectangle tables
  /// out: for a plan of (stages, width, height).
  std::optional<std::array<int, 3>> held_for;
};
/// Uploads `plan` (a blocking write). ArgumentError if a level exceeds
/// 2^31 - 1 pixels.
DeviceSwapPlan upload_swap_plan(Device& device, SwapPlan plan);
/// Uploads d.plan into d's buffers, reusing them (and d's host image) where
/// they are large enough: a DeviceSwapPlan kept from frame to frame (the
/// engine's) takes no fresh memory. One write command for all the tables
/// (each table a write of its own had cost the device about 1.4 ms per
/// frame of the 256^3 phantom at 8,192 PEs: docs/PERFORMANCE.md). With
/// blocking false the write is only enqueued: d must then stay alive and
/// unchanged until the queue has run it (a later blocking call or finish).
/// ArgumentError as above.
///
/// Where map_swap_plan mapped d's buffer before and the tables fit in it,
/// they are written into the mapped memory on the host and the buffer is
/// unmapped (enqueued; waited for if blocking): no copy on the device, which
/// on a CPU device maps host memory as it is. Else it is unmapped and
/// written as above.
void upload_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking);
/// Maps d's buffer (kept from an earlier upload) for the next
/// upload_swap_plan to write into. Blocking, it waits for the queue before
/// it, so call it where the queue has nothing left to run; not blocking,
/// the map is enqueued (d.map_done) and upload_swap_plan waits for it
/// before it writes (the engine: enqueued behind the footprint reads,
/// before the balance, so that the host writes the plan while the device
/// balances and resamples).
/// False where d has no buffer yet (the first upload writes). Nothing may
/// use d's tables until the upload unmaps it.
bool map_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking = true);
/// map_swap_plan for a plan of `stages` stages and a width x height
/// intermediate image: where d has no buffer yet, or one too small for that
/// plan's tables, a buffer large enough is made first (its regions cut
/// again at the upload), so that even a first frame's plan is written
/// straight into the mapping (swap_plan_held_in_map), with no host image
/// (d.staging) and no host copy of the rectangles (plan.held): about 1.4 KB
/// a PE of host memory fewer (1.4 GB at 2^20 PEs). ArgumentError for
/// stages outside 0 .. 30 or a non-positive size.
void map_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking, int stages, int width,
                   int height);
/// Enqueues the unmap of a mapped d (map_swap_plan); a null event where d
/// is not mapped.
cl::Event unmap_swap_plan(Device& device, DeviceSwapPlan& d);
/// Where d is mapped (map_swap_plan) and a plan of `stages` stages for a
/// width x height intermediate image fits in the mapping: waits for the
/// map, points held_out[L] at level L's rectangle table in the mapped
/// memory (2^stages rectangles each) and returns true; plan_swap_into(...,
/// held_out.data()) then writes the rectangles there and the next
/// upload_swap_plan writes only the rest (no copy of 3.7 MB a frame on the
/// 256^3 phantom). False (held_out empty) where d is not mapped or the plan
/// would not fit: plan with plan.held kept. upload_swap_plan throws
/// ArgumentError for a plan whose plan.held is empty otherwise.
bool swap_plan_held_in_map(Device& device, DeviceSwapPlan& d, int stages, int width, int height,
                           std::vector<SwapRect*>& held_out);

/// The level buffers of a swap run.
/// The most swap stages one launch runs (simdvol_swap_stages: a work-group
/// of 2^m work-items per group of 2^m PEs, barriers between the stages).
inline constexpr int kSwapFusedStages = 7;
/// Fewer stages than this go one launch per stage (simdvol_swap_stage: with
/// a work-group of 2 or 4 work-items per group, PoCL's cost per work-group
/// would outweigh what the launches save).
inline constexpr int kSwapFusedMin = 4;

struct DeviceSwapRun {
  std::vector<cl::Buffer>
      slots;        ///< float4 level buffers: level L (1 .. N) in slot (L - 1) mod size
  cl::Buffer last;  ///< level N (the footprints when N = 0)
  std::vector<cl::Event> stages;  ///< one event per launch (empty levels alone skip theirs)
  std::vector<int> first_stage;   ///< per launch: its first stage (the next's first ends it)
  /// The level buffers enqueue_swap allocated and their bytes (a slot that
  /// is the footprints' buffer, FootprintsAfterSwap::overwritten, is not
  /// counted).
  int allocated_slots = 0;
  int64_t allocated_bytes = 0;
};
/// What enqueue_swap may do with the footprints' buffer: leave it as it is
/// (`kept`), or, where the caller reads the footprints no more
/// (`overwritten`: the engine's frames), hold later levels in it. Only the
/// first launch reads the footprints, so the second slot (the levels after
/// the first one written) is the footprints' buffer where that is large
/// enough: one level buffer fewer, the largest of those levels' float4
/// (at 4096x4096 with pixel sampling, 97x301x33 on 8,192 PEs, 432 MB of
/// the frame's 3.65 GB). The levels are the same bit for bit.
enum class FootprintsAfterSwap { kept, overwritten };
/// Enqueues all N stages from the footprints `fp` (whose offsets must be the
/// plan's level 0): the first m stages in one launch (enqueue_swap_stages),
/// m the largest of min(max_fused, N), min(max_fused, N) - 1, ... whose
/// 2^m work-items the device takes in a work-group of simdvol_swap_stages
/// (CL_DEVICE_MAX_WORK_GROUP_SIZE, CL_DEVICE_MAX_WORK_ITEM_SIZES[0], the
/// kernel's CL_KERNEL_WORK_GROUP_SIZE) and whose levels between fit in
/// `local_bytes` of local memory (0: the device's CL_DEVICE_LOCAL_MEM_SIZE;
/// swap_stages_local_need) when it is at least kSwapFusedMin, the others one
/// launch per stage. max_fused in 1 .. kSwapFusedStages. The levels are the
/// same bit for bit whatever max_fused, local_bytes and the device's
/// limits. `after`: FootprintsAfterSwap.
DeviceSwapRun enqueue_swap(Device& device, const DeviceSwapPlan& plan, const DeviceFootprints& fp,
                           int max_fused = kSwapFusedStages, int64_t local_bytes = 0,
                           FootprintsAfterSwap after = FootprintsAfterSwap::kept);
/// Enqueues stage k alone: level k's buffer `in` -> level k + 1's `out`
/// (another buffer). ArgumentError where `in` holds fewer than
/// level_size(k) float4 or `out` fewer than level_size(k + 1).
cl::Event enqueue_swap_stage(Device& device, const DeviceSwapPlan& plan, int k,
                             const cl::Buffer& in, const cl::Buffer& out);
/// Enqueues stages k0 .. k0 + m - 1 (1 <= m <= kSwapFusedStages) in one
/// launch: level k0 in `in`, level k0 + m into `out` (large enough for it,
/// not `in`: both checked, as for enqueue_swap_stage); the levels between
/// stay in the work-groups' local memory. A negative local_bytes is an
/// ArgumentError (here and in enqueue_swap).
/// ArgumentError if they need more than `local_bytes` (0: the device's
/// local memory size; swap_stages_local_need), since PoCL aborts on a
/// launch with too much, and where the device takes fewer than 2^m
/// work-items in a work-group of simdvol_swap_stages (the message names the
/// limits and the largest m it takes).
cl::Event enqueue_swap_stages(Device& device, const DeviceSwapPlan& plan, int k0, int m,
                              const cl::Buffer& in, const cl::Buffer& out, int64_t local_bytes = 0);
/// The most pixels of level L that one work-group of enqueue_swap_stages
/// (k0, m) holds: the largest sum over a group's 2^m PEs (those differing
/// only in bits k0 .. k0 + m - 1). ArgumentError outside the plan.
int64_t swap_group_pixels(const SwapPlan& plan, int k0, int m, int L);
/// The two local buffers of enqueue_swap_stages (k0, m) in bytes: for the
/// levels k0 + s with s odd and with s even (0 < s < m), each the largest
/// of its levels' swap_group_pixels x 16.
std::array<int64_t, 2> swap_stages_local_bytes(const SwapPlan& plan, int k0, int m);
/// All the local memory enqueue_swap_stages (k0, m) takes: the two buffers,
/// the kernel's own tables and room for alignment (its 6,144 bytes and 1
/// KiB; on a device whose compiler reports more for simdvol_swap_stages,
/// CL_KERNEL_LOCAL_MEM_SIZE, the enqueue functions budget that plus 1 KiB
/// instead: PoCL reports the 6,144).
int64_t swap_stages_local_need(const SwapPlan& plan, int k0, int m);
/// The most stages one launch of simdvol_swap_stages runs on this device:
/// the largest m <= kSwapFusedStages whose 2^m work-items it takes in a
/// work-group (0 where it takes no group of 2); enqueue_swap fuses no more.
int swap_fused_stages_limit(Device& device);

/// Display: level N's buffer -> the intermediate image (float4,
/// width x height, allocated here into `image`). ArgumentError where `last`
/// holds fewer than level_size(N) float4.
cl::Event enqueue_display(Device& device, const DeviceSwapPlan& plan, const cl::Buffer& last,
                          cl::Buffer& image);
/// enqueue_display into a given `image` (a HostImage's buffer, say);
/// ArgumentError where it holds fewer than width x height float4.
cl::Event enqueue_display_into(Device& device, const DeviceSwapPlan& plan, const cl::Buffer& last,
                               const cl::Buffer& image);

/// warp_to_output on the device (voxel sampling): `intermediate`
/// (view.width() x view.height() float4) -> `out` (out_width x out_height,
/// allocated here). Source positions are computed on the host in double,
/// exactly as warp_to_output; same float arithmetic. ArgumentError where
/// `intermediate` holds fewer than view.width() x view.height() float4.
cl::Event enqueue_warp(Device& device, const ViewGeometry& view, const cl::Buffer& intermediate,
                       cl::Buffer& out);
/// enqueue_warp into a given `out` (a HostImage's buffer, say); ArgumentError
/// where it holds fewer than out_width x out_height float4.
cl::Event enqueue_warp_into(Device& device, const ViewGeometry& view,
                            const cl::Buffer& intermediate, const cl::Buffer& out);

/// An Image that the device writes in place, so that an output is not held
/// twice (a device buffer and the Image read from it): its buffer() is made
/// over the image's own pixels (CL_MEM_USE_HOST_PTR). On a CPU device
/// (PoCL) the kernels write the image's memory itself; a GPU may keep its
/// own copy, which take() reads back into the image. The buffer is the
/// Device's request named `what` (Device::buffer with the pixels as its
/// host pointer: not pooled). Neither copyable nor movable (the buffer
/// points into it); until take(), commands enqueued on the buffer may still
/// write the pixels, so the destructor of one not taken waits for the queue
/// first.
class HostImage {
 public:
  /// A width x height image of zeros and its buffer; ArgumentError naming
  /// `what` for a size that is not positive or larger than the device's
  /// largest allocation (as float4_buffer: "use a smaller --size").
  HostImage(Device& device, int width, int height, const std::string& what);
  ~HostImage();
  HostImage(const HostImage&) = delete;
  HostImage& operator=(const HostImage&) = delete;
  /// float4[width x height] over the image's pixels (row-major).
  const cl::Buffer& buffer() const { return buffer_; }
  /// Waits for the commands enqueued so far (a blocking map of the buffer
  /// for reading: where the device kept a copy, it is read back into the
  /// pixels), lets the buffer go and returns the image. Once only
  /// (ArgumentError after).
  Image take();

 private:
  Device* device_;
  Image image_;
  cl::Buffer buffer_;
};

/// Reads a width x height float4 image back (blocking). ArgumentError if the
/// size is not positive or `image` holds fewer than width x height pixels.
Image read_device_image(Device& device, const cl::Buffer& image, int width, int height);

}  // namespace simdvol
