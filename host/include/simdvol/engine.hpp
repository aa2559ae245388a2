// The OpenCL render engine: the pipeline of thesis figure 1.2 on the PE
// array. Direct compositing, every stage on the device: layout -> shade ->
// classify -> match -> balance -> resample + local (fused) -> binary swap
// (the first seven stages in one launch, the rest one launch each; swap_cl.hpp)
// -> display (the final cut-and-stack or
// hierarchical layout -> intermediate image) -> warp (voxel sampling), then
// one read of the output image. The host reads only the footprint
// rectangles (to size the buffers) and plans the swap from them while the
// device resamples.
//
// Adaptive and Monte Carlo compositing also run on the device. The samples
// are resampled into a buffer in segment order (enqueue_resample) at offsets
// scanned on the device (kernels/adaptive.cl; the host reads the total to
// size the buffer), then:
//   adaptive             whole-ray early termination (composite_adaptive):
//                        per-pixel ray lists (mc_cl.hpp), one work-item per
//                        pixel walks its ray front to back and stops at the
//                        threshold (kernels/adaptive.cl) -> intermediate image
//   mc, scope whole      the same ray lists, enqueue_mc_whole (the pixel's
//                        owner walks the whole ray) -> intermediate image;
//                        equals render_reference's mc bit for bit on the same
//                        samples; the device's samples differ from the
//                        reference's by float rounding (<= 1e-5), so a walk
//                        whose u lies between the two alphas stops elsewhere:
//                        rare pixels differ (256^3 phantom, 16 walks: 89 dB)
//   mc, scope subray     enqueue_mc_local (ch. 7.4: each segment's walks over
//                        its own samples, optionally allocated by opacity,
//                        ch. 7.5 (b)) into the footprints, then the swap and
//                        display as direct compositing; equals mc.hpp's
//                        mc_sub_reference composited with over
// then the warp (voxel sampling) as direct compositing.
//
// RenderEngine keeps the PE array and the buffers the engine allocates
// itself (voxel cells, shading, classified voxels, samples, offsets,
// images) across frames, reallocated only when the volume's dims or the
// sizes grow: fresh buffers cost page faults (on PoCL a fresh buffer is new
// host memory, a fault per 4 KiB page the kernels first touch; the frame's
// scratch buffers took ~33,000 of them per 256^3 frame before they were
// reused: docs/PERFORMANCE.md, "Buffer reuse").
// Buffers allocated inside the stage functions (matching, footprints, swap
// levels) are still made per frame. render_opencl is a one-shot RenderEngine.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/image.hpp"
#include "simdvol/match.hpp"
#include "simdvol/render.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

/// One kernel of a frame on the device's clock (profiling events).
struct KernelSpan {
  std::string kernel;
  std::uint64_t start_ns = 0, end_ns = 0;  ///< the device's clock (0, 0: no profiling)
};

/// Per-stage times of one render_opencl call. Device stages: kernel time
/// from the profiling events (0 when the queue does not profile).
struct EngineTimes {
  double layout_ms = 0;          ///< flat volume -> PE-major cells with halo
  double shade_ms = 0;           ///< 0 when fused
  double classify_ms = 0;        ///< shade + classify when fused
  double gather_ms = 0;          ///< unused (0): nothing is gathered back any more
  double match_ms = 0;           ///< matching
  double balance_ms = 0;         ///< balancing
  double resample_local_ms = 0;  ///< zero footprints + brick occupancy + lane order +
                                 ///< fused resample + local (direct); resample into the
                                 ///< sample buffer (adaptive, mc)
  double occupancy_ms = 0;       ///< with skip_empty: the brick occupancy's zeroing,
                                 ///< scan (not fused: fused marks it inside classify_ms) and
                                 ///< reach (included in resample_local_ms); 0 where the
                                 ///< previous frame's is kept (EngineStats::unshaded_pes)
  double offsets_ms = 0;         ///< adaptive, mc: the sample offsets' scan
  double rays_ms = 0;            ///< adaptive, mc whole or allocated: per-pixel ray lists
  double walk_ms = 0;  ///< adaptive / mc walks (and the opacity allocation), zeroing included
  double plan_ms = 0;  ///< host: swap plan from the rectangles + its upload (overlaps the device)
  double swap_ms = 0;  ///< all swap stages
  std::vector<double> swap_stage_ms;  ///< per swap launch (DeviceSwapRun::stages)
  double display_ms = 0;              ///< final layout -> intermediate image
  double warp_ms = 0;                 ///< intermediate -> output (voxel sampling)
  double composite_ms = 0;            ///< swap + display + warp
  double device_wall_ms = 0;  ///< host wall time of the device part (allocation, builds, transfers)
  /// Every kernel the frame launched, in launch order (the queue is in
  /// order, so they run one after the other): where the device waited.
  std::vector<KernelSpan> kernels;
  double kernels_ms = 0;  ///< their durations summed
  double span_ms = 0;     ///< first kernel's start to last kernel's end
  /// The longest time between one kernel's end and the next one's start
  /// (copies, maps and host waits in between), and the kernel it preceded.
  double longest_wait_ms = 0;
  std::string longest_wait_before;
  RenderTimes host{};  ///< unused (0): no stage runs on the host
};

/// Fills t.kernels_ms, t.span_ms and the longest wait from t.kernels (in
/// launch order; spans of (0, 0), without profiling, are left out).
void summarise_kernels(EngineTimes& t);

/// What one frame did beyond its times (RenderEngine::render's `stats`, for
/// the benchmarks; collecting them costs a read of P ints and the swap's
/// cost on the host, outside the times above).
struct EngineStats {
  /// Samples per PE after balancing (P entries; 0 for the PEs that
  /// EngineOptions::skip_pes left out).
  std::vector<int64_t> loads;
  int64_t samples = 0;   ///< sum of the loads: samples resampled this frame
  int64_t segments = 0;  ///< ray segments of the matching
  bool swapped = false;  ///< the frame went through the binary swap (direct, mc subray)
  SwapCost swap{};       ///< swap_cost of the frame's plan (when swapped)
  /// The level buffers the frame's swap allocated and their bytes as asked
  /// (when swapped; the levels after the first one written go into the
  /// footprints' buffer where it holds them: FootprintsAfterSwap).
  int swap_level_buffers = 0;
  int64_t swap_level_bytes = 0;
  /// Bytes of the buffers the device's pool held at the frame's end (its
  /// peak: the pool only grows within a frame): those the frame took from it,
  /// fresh or kept from earlier frames (buffers a stage released, such as
  /// the matching's once the balance is enqueued, taken again by later
  /// requests: Device::release), and those it keeps for later frames. Not
  /// the output image (HostImage: the returned Image's own memory). With
  /// engines rendering on one Device from several threads, the pool is
  /// theirs together: their buffers are counted too, and another thread's
  /// frame end may free some during this frame.
  int64_t pool_bytes = 0;
  /// PEs the shade + classify left as they were: their cells all zeros and
  /// transparent under the same classification of the kept volume (the
  /// previous frame's PEs without reach; EngineOptions::reuse_layout,
  /// fused, skip_pes). 0 in a frame that shaded every cell. Such a frame
  /// also keeps the previous frame's brick occupancy and reach where the
  /// order is the same (no marks, no reach kernel: the same bricks).
  int64_t unshaded_pes = 0;
  /// The shade + classify lit the kept classification of the volume
  /// (EngineOptions::keep_classification) instead of classifying again.
  bool classification_kept = false;
  /// Memory ran out for the kept classification in this frame: its
  /// buffer's allocation failed, or a later one while it was held (the
  /// frame then ran again without it; RenderEngine::render). The engine's
  /// frames classify from then on, for these cells.
  bool classification_let_go = false;
  /// SIMD utilisation after balancing: mean load / max load over all P PEs,
  /// the skipped ones included (1 when idle).
  double utilisation() const;
  int64_t max_load() const;
};

/// Which rays the Monte Carlo walks run over (--mc-scope).
enum class McScope {
  whole,   ///< whole rays after the swap (ch. 7.3): equals render_reference
  subray,  ///< per sub-ray in local compositing (ch. 7.4), then the swap
};

/// Engine options (beyond RenderOptions, which the reference shares).
struct EngineOptions {
  int64_t pes = 8192;                             ///< a power of two (8,192 as the DECmpp 12000)
  bool fused = false;                             ///< shade + classify as one launch (same results)
  SwapLayout layout = SwapLayout::cut_and_stack;  ///< the swap's final layout (same image)
  McScope mc_scope = McScope::whole;
  /// Per sub-ray Monte Carlo: the ray's composite.samples walks allocated to
  /// its sub-rays by opacity (ch. 7.5 (b), allocate_walks) instead of
  /// composite.samples per sub-ray. ArgumentError with McScope::whole.
  bool mc_allocate = false;
  /// The caller promises that a volume rendered again (the same object, the
  /// same data pointer and dims) has not changed: its layout into PE cells
  /// is kept (a turntable). Off: every frame lays the volume out again.
  bool reuse_layout = false;
  /// Skip samples whose stencil reads only zero voxels (enqueue_occupancy):
  /// direct compositing steps over them, the other modes store them as +0
  /// without gathering (the same image bit for bit). Off: every sample is
  /// resampled (for comparison).
  bool skip_empty = true;
  /// With skip_empty: PEs whose whole cell lies in bricks without reach
  /// (match.hpp: match_active_reference) take no part in the matching,
  /// balancing, resampling and swap: their samples read only zero voxels
  /// (+-0 in every channel). Whole-ray adaptive compositing and whole-ray
  /// Monte Carlo walk each ray's samples in depth order (the walks' draws
  /// keyed by the absolute depth, exact opacity's stratified and fallback
  /// draws by the depth of the first sample with alpha > 0; alpha 0 stops no
  /// walk), so their images are the same bit for bit; so is direct
  /// compositing's with 0 balance sweeps; with balancing the other PEs'
  /// samples are grouped otherwise (no sample moves into an inactive PE),
  /// the same to float rounding. Per sub-ray Monte Carlo without balancing
  /// (0 sweeps) leaves them out too, with the same bits (the other sub-rays
  /// are cut and keyed as before; a left-out one is (0, 0, 0, 0)); with
  /// balancing it matches every PE. The loads (EngineStats) count the
  /// skipped PEs as idle. Off: every PE is matched (--no-skip-pes).
  bool skip_pes = true;
  /// The float8 resample kernels (fused with local compositing for direct,
  /// alone for adaptive and Monte Carlo) take segments into their lanes
  /// sorted by length within blocks of one PE (enqueue_segment_order; the
  /// same image bit for bit). Off: in segment order (for comparison).
  bool order_lanes = true;
  /// Load-balancing sweeps after the matching (enqueue_balance; the loads
  /// equal balance_reference's with as many sweeps). 0: none, the matching's
  /// own assignment. The thesis balances because its PEs step in lockstep;
  /// PoCL's work-items do not, so on a CPU device balancing costs its own
  /// time and saves none elsewhere (README: the figures). The image is the
  /// reference's either way, to float rounding (the samples composite in
  /// other groupings). 0 .. kMaxBalanceSweeps (--balance-sweeps).
  int balance_sweeps = kBalanceSweeps;
  /// With fused and reuse_layout: the fused shade + classify keeps each
  /// voxel's classification (its alpha and colour before lighting, which
  /// depend on the value, the gradient's magnitude and the classification,
  /// not on the view or the light) in a buffer the size of the voxel cells,
  /// and the later frames of the same volume, classification and gradient
  /// scale light it instead of classifying again (enqueue_shade_classify's
  /// `kept`; the same image bit for bit; for cells whose rows take the
  /// shade's general path, an x extent other than 4, 8 or a multiple of 16,
  /// the gradient too, 7 / 4 of the buffer). Off, or where the buffer would
  /// pass the device's largest allocation or, with the voxel cells of the
  /// same size, half its memory: every frame classifies; so too from the
  /// frame where memory runs out while it is kept (RenderEngine::render).
  bool keep_classification = true;
};

/// Checks the options against each other and `opt`; ArgumentError naming
/// the CLI option.
void validate(const EngineOptions& eo, const RenderOptions& opt);

/// The engine with its buffers kept between frames (see the file comment).
/// Not thread-safe: one thread at a time renders with it. Engines on
/// several threads may share one `device` (its buffer pool's scopes and its
/// launch logs are per thread; RenderEngine.EnginesOnSeveralThreadsShareOneDevice).
/// `device` must outlive it.
class RenderEngine {
 public:
  explicit RenderEngine(Device& device, EngineOptions options = {});
  ~RenderEngine();
  /// A moved-from engine may only be destroyed or assigned to: its
  /// options() and render() throw ArgumentError ("engine: was moved from").
  RenderEngine(RenderEngine&&) noexcept;
  RenderEngine& operator=(RenderEngine&&) noexcept;

  const EngineOptions& options() const;
  /// Renders one frame; same result as render_opencl with these options.
  /// `stats`, when given, receives the frame's EngineStats. Where memory
  /// runs out (a CLError of is_allocation_failure) while the engine keeps a
  /// classification, it lets that go and renders the frame once more
  /// without it (as where it never fit).
  Image render(const Volume& vol, const RenderOptions& opt, EngineTimes* times = nullptr,
               EngineStats* stats = nullptr);

 private:
  Image render_frame(const Volume& vol, const RenderOptions& opt, EngineTimes* times,
                     EngineStats* stats);
  struct State;
  std::unique_ptr<State> s_;
};

/// Renders `vol` with the OpenCL stages on `pes` PEs (a power of two,
/// default 8192 as the DECmpp 12000). `fused` runs shade and classify as one
/// launch (same results). `layout` is the swap's final layout (the image is
/// the same either way). Throws ArgumentError for bad options or a volume
/// whose buffers exceed the device's largest allocation.
Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt,
                    EngineTimes* times = nullptr, int64_t pes = 8192, bool fused = false,
                    SwapLayout layout = SwapLayout::cut_and_stack);
/// The same with every engine option (a one-shot RenderEngine).
Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt,
                    const EngineOptions& options, EngineTimes* times = nullptr);

}  // namespace simdvol
