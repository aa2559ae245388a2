// The OpenCL render engine (engine.hpp).
#include "simdvol/engine.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>
#include <optional>
#include <string>

#include "chunk_ranges.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap_cl.hpp"

namespace simdvol {

namespace {
double ms(const cl::Event& e) {
  return e() ? static_cast<double>(event_ns(e)) * 1e-6 : 0.0;
}
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
double stage_ms(const std::vector<StageEvent>& ev) {
  return static_cast<double>(events_ns(ev)) * 1e-6;
}

constexpr std::size_t kWgs = 64;
cl::NDRange range(int64_t n) {
  return cl::NDRange(round_up(static_cast<std::size_t>(std::max<int64_t>(n, 1)), kWgs));
}

// A device buffer kept between frames, grown (never shrunk) on demand.
struct Scratch {
  cl::Buffer buffer;
  std::size_t bytes = 0;
  const cl::Buffer& at_least(Device& device, std::size_t need, const char* what) {
    need = std::max<std::size_t>(need, 16);
    if (need > bytes) {
      // (the frame's samples and images: both grow with the output size)
      check_allocation(need, device.info().max_alloc_bytes, what, "use a smaller --size");
      buffer = device.scratch_buffer(CL_MEM_READ_WRITE, need, what);
      bytes = buffer_size(buffer, "clGetMemObjectInfo(CL_MEM_SIZE)");
    }
    return buffer;
  }
};
}  // namespace

void validate(const EngineOptions& eo, const RenderOptions& opt) {
  validate(opt);
  pe_grid(eo.pes, "--pe");
  // (the mode first: --composite direct --allocate asked for --mc-scope
  // subray, which was then refused without --composite mc)
  if (eo.mc_allocate && opt.composite.mode != CompositeMode::mc)
    throw ArgumentError("--allocate", "needs --composite mc");
  if (eo.mc_allocate && eo.mc_scope != McScope::subray)
    throw ArgumentError("--allocate", "allocates walks to sub-rays: needs --mc-scope subray");
  if (eo.balance_sweeps < 0 || eo.balance_sweeps > kMaxBalanceSweeps)
    throw ArgumentError("--balance-sweeps", std::to_string(eo.balance_sweeps) + " is outside 0.." +
                                                std::to_string(kMaxBalanceSweeps));
}

// What a kept state of the cells was made for: the classification and the
// gradient scale (the transfer function's |g|), both of which decide every
// voxel's alpha and colour before lighting.
struct ClassifiedFor {
  sv_classify_params cp{};
  float grad[4]{};
  void set(const sv_classify_params& c, const sv_shade_params& sp) {
    cp = c;
    std::memcpy(grad, sp.grad_scale, sizeof grad);
  }
  bool holds_for(const sv_classify_params& c, const sv_shade_params& sp) const {
    return std::memcmp(&cp, &c, sizeof c) == 0 &&
           std::memcmp(grad, sp.grad_scale, sizeof grad) == 0;
  }
};

// The kept classification of the volume in the cells (KeptClassification)
// and what it was made for: the classification with its opacity step left
// out (applied after, `key`) and the gradient scale.
struct KeptClass {
  KeptClassification kept;
  ClassifiedFor made_for;
  static sv_classify_params key(sv_classify_params c) {
    c.step_is_one = 0;
    c.opacity_step = 0.0f;
    return c;
  }
};

// What the previous frame left in the voxel cells, for the next frame of the
// same volume: its PE mask (DeviceMatching::active), under whose 0 flags the
// cells hold zeros for classification `cp` and gradient scale `grad` (the
// transfer function's |g|), so the fused shade + classify leaves those cells
// as they are (enqueue_shade_classify's `live`); and its brick occupancy and
// reach (for its order), the same in a frame under the same conditions: no
// marks, no reach kernel.
struct LiveCells {
  cl::Buffer mask;
  std::optional<DeviceOccupancy> occupancy;
  ClassifiedFor made_for;
};

// Which volume something on the device was made from, while reuse_layout
// promises that volume unchanged between frames: the object, its serial,
// its voxels' storage and its dims (a volume resized in place has other
// dims at the same address; one made where an earlier one was destroyed
// has its address and storage, and another serial: a time series loaded
// frame by frame in one loop variable was rendered from its first frames'
// layout). The layout's and the relative classification's range each
// keep one: the range is needed before the layout decision, and survives
// frames that need no range while the layout's key moves on.
namespace {
struct KeptVolume {
  const Volume* volume = nullptr;
  std::uint64_t serial = 0;
  const float* data = nullptr;
  Dims3 dims{0, 0, 0};
  bool is(const Volume& v) const {
    return volume == &v && serial == v.serial() && data == v.data().data() && dims == v.dims();
  }
  void keep(const Volume& v) { *this = {&v, v.serial(), v.data().data(), v.dims()}; }
  void clear() { *this = {}; }
};
}  // namespace

struct RenderEngine::State {
  Device* device = nullptr;
  EngineOptions eo;
  std::optional<PeArray> array;
  // Keyed by the volume's dims (and the PE count, fixed per engine).
  std::optional<Dims3> dims;
  std::optional<CellBuffer> cells;
  std::optional<VoxelBuffer> rgba;
  // The resample's tables of `rgba`'s layout (address, pair and cell-bit
  // tables, the cells' origins): made with the cells, only their view is
  // uploaded again per frame (set_resample_view).
  std::optional<ResampleTables> tables;
  // The matching's PE tables of the split of `cells` (upload_pe_tables):
  // made with the cells, not per frame.
  std::optional<DevicePeTables> pe_tables;
  KeptVolume laid_out;  // reuse_layout: the volume in `cells`
  // The value range of a relative classification (the MRI preset), kept
  // for the volume it was computed from while reuse_layout promises that
  // volume unchanged: a scan of every voxel on the host before each frame
  // otherwise (about 2.4 ms for ch2, before any kernel is enqueued).
  std::optional<ValueRange> range;
  KeptVolume range_of;
  // The range a relative mixture's fractions are of where its top is a
  // percentile (mixture_range: a second pass, 30 ms for ch2's floats),
  // kept beside `range` for that percentile.
  std::optional<ValueRange> mixture_range;
  float mixture_percentile = 0;
  // The previous frame's PE mask while `rgba` holds zeros in the cells of
  // the PEs it flags 0 (LiveCells); none while the cells change.
  std::optional<LiveCells> live;
  // The kept classification of the volume in `cells` (EngineOptions::
  // keep_classification); its buffer stays while the cells do, its
  // `filled` is cleared where the cells or the classification change.
  std::optional<KeptClass> kept_class;
  bool kept_class_refused = false;  // its allocation failed for these cells
  // Sized by the frame, grown on demand.
  Scratch pe_total, total, sample_off, samples, image;
  // The swap plan, its host vectors and device tables reused from frame to
  // frame (written without waiting: the frame's ReuseScope finishes the
  // queue before the next frame changes them).
  DeviceSwapPlan swap_plan;
};

RenderEngine::RenderEngine(Device& device, EngineOptions options) : s_(std::make_unique<State>()) {
  s_->device = &device;
  s_->eo = options;
  s_->array.emplace(device, pe_grid(options.pes, "--pe"));
}
RenderEngine::~RenderEngine() = default;
RenderEngine::RenderEngine(RenderEngine&&) noexcept = default;
RenderEngine& RenderEngine::operator=(RenderEngine&&) noexcept = default;

namespace {
// A moved-from engine holds no state: its members refuse.
void check_not_moved(const void* state) {
  if (!state)
    throw ArgumentError("engine", "was moved from: render with the engine it was moved into");
}
}  // namespace

const EngineOptions& RenderEngine::options() const {
  check_not_moved(s_.get());
  return s_->eo;
}

double EngineStats::utilisation() const {
  const int64_t most = max_load();
  if (most == 0 || loads.empty()) return 1.0;
  return static_cast<double>(samples) / static_cast<double>(loads.size()) /
         static_cast<double>(most);
}
int64_t EngineStats::max_load() const {
  return loads.empty() ? 0 : *std::max_element(loads.begin(), loads.end());
}

void summarise_kernels(EngineTimes& t) {
  t.kernels_ms = t.span_ms = t.longest_wait_ms = 0;
  t.longest_wait_before.clear();
  std::uint64_t first = 0, last = 0;
  bool any = false;
  for (const KernelSpan& k : t.kernels) {
    if (k.end_ns == 0) continue;
    t.kernels_ms += static_cast<double>(k.end_ns - k.start_ns) * 1e-6;
    if (any && k.start_ns > last) {
      const double wait = static_cast<double>(k.start_ns - last) * 1e-6;
      if (wait > t.longest_wait_ms) {
        t.longest_wait_ms = wait;
        t.longest_wait_before = k.kernel;
      }
    }
    if (!any) first = k.start_ns;
    last = std::max(last, k.end_ns);
    any = true;
  }
  if (any) t.span_ms = static_cast<double>(last - first) * 1e-6;
}

Image RenderEngine::render(const Volume& vol, const RenderOptions& opt, EngineTimes* times,
                           EngineStats* stats) {
  check_not_moved(s_.get());
  try {
    return render_frame(vol, opt, times, stats);
  } catch (const CLError& e) {
    // The kept classification holds as much memory as the RGBA voxel cells
    // (7 / 4 of that with its gradient), and its rule (half the device's
    // memory) cannot see what the host has left: where memory ran out in a
    // frame while it was kept, it goes (and its buffer from the pool), and
    // the frame runs again classifying, as where it never fit. A frame
    // that fails part-way leaves the kept state consistent: each piece is
    // used only where it was made for the same cells and classification.
    State& S = *s_;
    if (!is_allocation_failure(e.code()) || !S.kept_class) throw;
    S.kept_class.reset();
    S.kept_class_refused = true;
    S.device->release_pooled();
    if (times) *times = EngineTimes{};
    if (stats) *stats = EngineStats{};
    Image img = render_frame(vol, opt, times, stats);
    if (stats) stats->classification_let_go = true;
    return img;
  }
}

Image RenderEngine::render_frame(const Volume& vol, const RenderOptions& opt, EngineTimes* times,
                                 EngineStats* stats) {
  State& S = *s_;
  Device& device = *S.device;
  const EngineOptions& eo = S.eo;
  validate(eo, opt);
  if (vol.voxel_count() == 0) throw ArgumentError("volume", "is empty");
  vol.check_voxel_count();
  const PeGrid grid = S.array->grid();
  const ViewGeometry view =
      make_view(vol, opt.view, opt.width, opt.height, opt.sampling, opt.framing);
  // Parameters first: every argument error is thrown before anything runs.
  // The value range (a pass over the voxels, kept with the layout): a
  // relative mixture's scale, and the shading's switch for gradients whose
  // squares overflow float (ShadeFrame::grad_over).
  ValueRange values{};
  if (!(eo.reuse_layout && S.range && S.range_of.is(vol))) {
    S.range.reset();
    S.mixture_range.reset();
    values = vol.range();
    if (eo.reuse_layout) {
      S.range = values;
      S.range_of.keep(vol);
    }
  }
  if (S.range) values = *S.range;
  const sv_shade_params sp =
      shade_params(make_shade_frame(vol, view, opt.shade, values), opt.shade);
  // (classify_params reads the range only for a relative mixture)
  // (first with the whole range: the classifier is checked before the
  // mixture range's pass over the voxels)
  sv_classify_params cp = classify_params(opt.classifier, values, view.step);
  if (const MaterialMixture& mix = opt.classifier.mixture;
      opt.classifier.kind == Classifier::Kind::mixture && mix.relative &&
      mix.top_percentile < 100.0f) {
    ValueRange mixture_values;
    if (S.mixture_range && S.mixture_percentile == mix.top_percentile) {
      mixture_values = *S.mixture_range;  // (kept only while `range` is)
    } else {
      mixture_values = mixture_range(vol, mix, values);
      if (S.range) {
        S.mixture_range = mixture_values;
        S.mixture_percentile = mix.top_percentile;
      }
    }
    cp = classify_params(opt.classifier, mixture_values, view.step);
  }
  const CompositeMode mode = opt.composite.mode;

  // Every launch logged for the frame's timeline (EngineTimes::kernels).
  device.log_launches(times != nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  // The frame's scratch buffers (matching, footprints, swap levels, ...) come
  // from the buffers the previous frames released, without page faults.
  Device::ReuseScope reuse(device);
  // Buffers keyed by dims.
  if (!S.dims || *S.dims != vol.dims()) {
    S.cells.reset();
    S.rgba.reset();
    S.tables.reset();
    S.pe_tables.reset();
    S.laid_out.clear();
    S.live.reset();
    S.kept_class.reset();
    S.kept_class_refused = false;
    const CellLayout cl_layout = S.array->cell_layout(vol.dims(), 1);
    // The fused shade + classify writes interleaved cells (a corner's RGBA
    // in one 16-byte load for the resample); the two-launch path classifies
    // the planar shading in place.
    const VoxelLayout vl = make_voxel_layout(cl_layout, eo.fused);
    check_allocation(vl.bytes(), device.info().max_alloc_bytes, "volume (voxel cells)",
                     "use a smaller volume or fewer PEs");
    S.cells.emplace(device, cl_layout);
    S.rgba.emplace(device, vl);
    S.dims = vol.dims();
  }
  cl::Event e_layout, e_shade, e_classify;
  const bool keep = eo.reuse_layout && S.laid_out.is(vol);
  if (!keep) {
    S.laid_out.clear();
    S.array->layout_into(vol.data().data(), *S.cells, LayoutKernel::rows, &e_layout);  // blocking
    S.laid_out.keep(vol);
  }
  // Empty-space skipping: the fused kernel marks the brick occupancy as it
  // writes the voxels (otherwise a scan makes it); direct compositing's
  // fused resample + local steps over the samples out of reach, the other
  // modes' resample stores them as +0 without gathering.
  std::optional<DeviceOccupancy> occupancy;
  const bool skip = eo.skip_empty;
  // Leaving out the PEs with nothing in reach (skip_pes): direct compositing
  // (the same footprints where no balancing regroups the samples), and the
  // whole-ray modes that walk each ray's samples in depth order, where
  // leaving out samples that are all +-0 changes no pixel whatever the
  // balancing: adaptive, and Monte Carlo (its walks' draws are keyed by the
  // absolute depth, and a sample of alpha 0 stops no walk; exact opacity's
  // stratified and fallback draws by the depth of the first sample with
  // alpha > 0, never a left-out PE's; its opacity is over's recurrence in
  // depth order, which samples of alpha 0 leave as it is). Per
  // sub-ray Monte Carlo (every variant) without balancing: the other PEs'
  // sub-rays are the same (their draws keyed by the ray and the absolute
  // depth, or by their own first sample with alpha > 0), and a left-out
  // sub-ray's estimate is (0, 0, 0, 0), which over leaves unchanged, and
  // which the allocation by opacity gives no walk; with balancing the
  // sub-rays would be cut otherwise, so every PE is matched.
  const bool whole_mc = mode == CompositeMode::mc && eo.mc_scope == McScope::whole;
  const bool subray_mc =
      mode == CompositeMode::mc && eo.mc_scope == McScope::subray && eo.balance_sweeps == 0;
  const bool mask_pes =
      eo.skip_empty && eo.skip_pes &&
      (mode == CompositeMode::direct || mode == CompositeMode::adaptive || whole_mc || subray_mc);
  const bool need_reach = skip || mask_pes;
  // The PEs whose cells are all transparent in the kept volume under the
  // same classification (the previous frame's mask: a PE without reach has
  // only zero voxels, and whether a voxel is transparent depends on its
  // value, gradient (its scale from the spacing) and the classification,
  // not on the view or the lighting) hold the zeros they would be given
  // again: the shade leaves them out. S.live is empty while the cells
  // change, set once this frame's mask is enqueued (the next frame's shade
  // reads it after).
  std::optional<LiveCells> live;
  if (eo.fused && keep && S.live && S.live->made_for.holds_for(cp, sp)) live = std::move(S.live);
  S.live.reset();
  const bool use_live = live.has_value();
  const cl::Buffer live_used = use_live ? live->mask : cl::Buffer();  // for the stats
  // The occupancy too, where the order (the reach's stencil) is the same.
  const bool reuse_occupancy =
      use_live && need_reach && live->occupancy && live->occupancy->order == opt.order;
  if (reuse_occupancy) {
    occupancy = live->occupancy;
    occupancy->events.clear();
  }
  // The kept classification, where the volume is kept: made in the first
  // such frame, read in the later ones of the same classification and
  // gradient scale. For a mixture (its Gaussians' exp per voxel), not for
  // a transfer function, whose ramps cost less than the kept planes' reads
  // (docs/PERFORMANCE.md).
  KeptClassification* kept = nullptr;
  bool let_go = false;  // its buffer's allocation failed in this frame
  if (eo.fused && eo.reuse_layout && eo.keep_classification && cp.kind == SV_CLASSIFY_MIXTURE) {
    if (!S.kept_class) {
      const VoxelLayout& V = S.rgba->layout();
      // The gradient too where the cells' rows take the shade's general
      // path (an x extent other than 4, 8 or a multiple of 16: each of the
      // six neighbours' loads takes a row-by-row select there); elsewhere
      // its 12 bytes a lit voxel cost more than the neighbours' loads
      // (docs/PERFORMANCE.md).
      const bool gradient = detail::shade_row_width(V.cell()[0]) == 1;
      // As large as the voxel cells (7 / 4 of them with the gradient): kept
      // where it and the cells together take at most half the device's
      // memory (on a CPU device, the host's).
      const std::size_t voxel_bytes = static_cast<std::size_t>(V.bytes());
      const std::size_t bytes = static_cast<std::size_t>(KeptClassification::bytes(V, gradient));
      const DeviceInfo& info = device.info();
      if (!S.kept_class_refused && bytes <= info.max_alloc_bytes &&
          (info.global_mem_bytes == 0 ||
           2 * (std::uint64_t(voxel_bytes) + bytes) <= info.global_mem_bytes)) {
        try {
          cl::Buffer planes =
              device.buffer(CL_MEM_READ_WRITE, bytes, nullptr, "kept classification");
          S.kept_class.emplace();
          S.kept_class->kept.planes = std::move(planes);
          S.kept_class->kept.gradient = gradient;
        } catch (const CLError&) {
          // No room for it: the frames classify, as without it (not asked
          // again for these cells).
          S.kept_class_refused = true;
          let_go = true;
        }
      }
    }
    if (S.kept_class) {
      if (!keep || !S.kept_class->made_for.holds_for(KeptClass::key(cp), sp)) {
        S.kept_class->kept.filled = false;
        S.kept_class->made_for.set(KeptClass::key(cp), sp);
      }
      kept = &S.kept_class->kept;
    }
  }
  const bool kept_read = kept && kept->filled;
  if (eo.fused) {
    if (need_reach && !reuse_occupancy)
      occupancy.emplace(make_occupancy(device, S.rgba->layout(), opt.order));
    e_classify = enqueue_shade_classify(device, *S.cells, sp, cp, *S.rgba, ShadeKernel::vec16,
                                        occupancy && !reuse_occupancy ? &*occupancy : nullptr,
                                        use_live ? &live->mask : nullptr, kept);
  } else {
    // Classified over the shading: no second voxel buffer, and a voxel
    // moves 32 bytes instead of 48 (enqueue_classify_in_place).
    e_shade = enqueue_shade(device, *S.cells, sp, *S.rgba);
    e_classify = enqueue_classify_in_place(device, *S.rgba, cp);
  }
  // The brick reach of empty-space skipping, before the matching (it may
  // leave out the PEs with nothing in reach).
  if (need_reach && !reuse_occupancy) {
    if (occupancy)
      enqueue_occupancy_reach(device, *occupancy);
    else
      occupancy.emplace(enqueue_occupancy(device, *S.rgba, opt.order));
  }
  // Match and balance on the PE array.
  const KdSplit& split = S.cells->layout().split;
  // The balance links only where balancing follows (a third of the matching).
  const MatchLinks links = eo.balance_sweeps > 0 ? MatchLinks::make : MatchLinks::skip;
  if (!S.pe_tables || !(S.pe_tables->split == split)) S.pe_tables = upload_pe_tables(device, split);
  DeviceMatching dm = mask_pes ? enqueue_match(device, view, split,
                                               BrickReach{&occupancy->reach, occupancy->bricks},
                                               *S.pe_tables, links)
                               : enqueue_match(device, view, split, *S.pe_tables, links);
  if (mask_pes && eo.fused && eo.reuse_layout) {
    S.live.emplace();
    S.live->mask = dm.active;
    S.live->occupancy = occupancy;
    S.live->made_for.set(cp, sp);
  }
  // The footprint sizes (the segment count and the rectangles) read as soon
  // as the matching has them: balancing moves no segment's ray. The host
  // waits for them while the device balances, and enqueues what follows
  // before the balance ends (waiting for the balance too left the device
  // idle between it and the segment order: 0.2 ms a frame on the phantom,
  // 0.6 on brainsmall).
  SegmentReads reads = start_segments(device, dm);
  // (Unmapped again if the frame ends in an error before the upload does.)
  struct UnmapOnError {
    Device& device;
    DeviceSwapPlan& plan;
    ~UnmapOnError() {
      if (plan.mapped == nullptr) return;
      try {
        unmap_swap_plan(device, plan);
      } catch (...) {  // (the frame's own error is the one to report)
      }
    }
  } unmap_on_error{device, S.swap_plan};
  // The swap plan's buffer mapped behind them (not blocking): the host
  // writes the plan into it while the device balances and resamples, and
  // no copy waits between the resample and the swap (upload_swap_plan).
  if (mode == CompositeMode::direct ||
      (mode == CompositeMode::mc && eo.mc_scope == McScope::subray))
    map_swap_plan(device, S.swap_plan, false, split.bits, view.width(), view.height());
  // Direct compositing's kernels (the segment order, the fused resample +
  // local) read the balanced bounds where the rounds left them: no unpack
  // pass over the segments (BalanceUnpack::deferred; about a third of the
  // balance stage).
  enqueue_balance(device, dm, view, split, eo.balance_sweeps, BalanceBounds::automatic,
                  mode == CompositeMode::direct ? BalanceUnpack::deferred : BalanceUnpack::now);
  cl_check(device.queue().flush(), "clFlush");
  LocalSegments segs = finish_segments(reads, dm);  // waits: footprint sizes
  // The matching's row tables, saved columns and link lists are read by
  // nothing after the balance (the row sums by the uncovered pixels' zeroing
  // still): later requests of the frame may take their buffers
  // (Device::release; the queue is in order).
  for (cl::Buffer* b : {&dm.rowlinks, &dm.rowoff, &dm.column_scratch, &dm.column_offsets, &dm.petot,
                        &dm.counts, &dm.link_offset, &dm.link_list, &dm.link_base})
    device.release(*b);
  // The tables of the cells' layout, made once with them (the origin table
  // is the layout's, already on the device); the frame's view uploaded.
  if (!S.tables)
    S.tables = make_resample_tables(device, S.rgba->layout(), view, &S.cells->origins());
  else
    set_resample_view(device, *S.tables, view);
  const ResampleTables& tables = *S.tables;
  const int W = view.width(), H = view.height();
  const int64_t npx = static_cast<int64_t>(W) * H;

  cl::Event e_zero, e_local;
  // The float8 resample kernels' lanes in length order (either mode).
  std::optional<SegmentOrder> lanes;
  if (eo.order_lanes) lanes.emplace(enqueue_segment_order(device, segs));
  std::vector<StageEvent> offset_events, walk_events;
  std::vector<StageEvent> ray_events;
  std::optional<DeviceFootprints> fp;
  // The output image where the device writes it in place (no second copy
  // read from a device buffer): pixel sampling's intermediate image, or
  // voxel sampling's warped one. (Before `out`: waits for the queue where a
  // frame ends in an error before the image is taken.)
  std::optional<HostImage> host_out;
  bool via_swap = true;  // direct and per sub-ray mc: footprints -> swap -> display
  if (mode == CompositeMode::direct) {
    fp.emplace(make_footprints(device, segs.host_rects));
    // The fused kernel writes every segment's pixel: only the others zeroed.
    e_zero = enqueue_zero_uncovered(device, dm, *fp);
    e_local =
        enqueue_resample_local(device, segs, tables, *S.rgba, opt.order, *fp, LocalKernel::vector8,
                               occupancy ? &*occupancy : nullptr, lanes ? &*lanes : nullptr);
  } else {
    // The samples in segment order at offsets scanned on the device.
    const int pes = static_cast<int>(segs.pes);
    const cl::Buffer& pe_total =
        S.pe_total.at_least(device, static_cast<std::size_t>(pes) * 8, "sample totals");
    const cl::Buffer& total = S.total.at_least(device, 8, "sample total");
    const cl::Buffer& soff = S.sample_off.at_least(
        device, static_cast<std::size_t>(segs.count + 1) * 4, "sample offsets");
    {
      cl::Kernel k = device.kernel("adaptive", "simdvol_sample_pe_count");
      set_args(k, "simdvol_sample_pe_count", segs.segments, segs.seg_offset, cl_int(pes), pe_total);
      offset_events.push_back({"pe count", device.run(k, "simdvol_sample_pe_count", range(pes),
                                                      cl::NDRange(kWgs), LocalSize::at_most)});
      cl::Kernel ks = device.kernel("adaptive", "simdvol_sample_pe_scan");
      set_args(ks, "simdvol_sample_pe_scan", pe_total, cl_int(pes), total);
      offset_events.push_back(
          {"pe scan", device.run(ks, "simdvol_sample_pe_scan", cl::NDRange(1), cl::NDRange(1))});
      cl::Kernel ko = device.kernel("adaptive", "simdvol_sample_offsets");
      set_args(ko, "simdvol_sample_offsets", segs.segments, segs.seg_offset, cl_int(pes), pe_total,
               soff);
      offset_events.push_back({"offsets", device.run(ko, "simdvol_sample_offsets", range(pes),
                                                     cl::NDRange(kWgs), LocalSize::at_most)});
    }
    cl_long nsamples = 0;
    cl_check(device.queue().enqueueReadBuffer(total, CL_TRUE, 0, sizeof nsamples, &nsamples),
             "clEnqueueReadBuffer(sample total)");
    if (nsamples > INT_MAX)
      throw ArgumentError("--size", "the frame has " + std::to_string(nsamples) +
                                        " samples: more than 32-bit offsets can index");
    segs.sample_count = nsamples;  // (the stages check `samples` against it)
    const cl::Buffer& samples =
        S.samples.at_least(device, static_cast<std::size_t>(nsamples) * 16, "samples");
    e_local = enqueue_resample(device, segs, soff, tables, *S.rgba, opt.order, samples,
                               LocalKernel::vector8, lanes ? &*lanes : nullptr,
                               occupancy ? &*occupancy : nullptr);
    const bool subray = mode == CompositeMode::mc && eo.mc_scope == McScope::subray;
    std::optional<DeviceRayLists> rays;
    if (!subray || eo.mc_allocate) {
      rays.emplace(enqueue_ray_lists(device, segs, view));
      ray_events = rays->events;
    }
    if (subray) {
      std::optional<DeviceAllocation> alloc;
      if (eo.mc_allocate) {
        alloc.emplace(
            enqueue_mc_allocation(device, segs, soff, samples, *rays, opt.composite.samples));
        walk_events = alloc->events;
      }
      fp.emplace(make_footprints(device, segs.host_rects));
      // The kernel writes every segment's pixel (an empty segment's 0): only
      // the others zeroed, as for the direct frames.
      e_zero = enqueue_zero_uncovered(device, dm, *fp);
      walk_events.push_back(
          {"mc local", enqueue_mc_local(device, segs, soff, samples, W, opt.composite,
                                        alloc ? &*alloc : nullptr, *fp)});
      // alloc's buffers are released here: the queue keeps them alive (the
      // kernels hold references) until the work is done.
    } else {
      via_swap = false;
      if (view.sampling == Sampling::pixel) host_out.emplace(device, W, H, "intermediate image");
      const cl::Buffer& image =
          host_out
              ? host_out->buffer()
              : S.image.at_least(device, static_cast<std::size_t>(npx) * 16, "intermediate image");
      if (mode == CompositeMode::mc) {
        walk_events.push_back({"mc whole", enqueue_mc_whole(device, segs, soff, samples, *rays,
                                                            opt.composite, image)});
      } else {
        cl::Kernel k = device.kernel("adaptive", "simdvol_adaptive_whole");
        set_args(k, "simdvol_adaptive_whole", segs.segments, soff, samples, rays->offset,
                 rays->items, cl_int(npx), cl_float(opt.composite.threshold), image);
        walk_events.push_back({"adaptive", device.run(k, "simdvol_adaptive_whole", range(npx),
                                                      cl::NDRange(kWgs), LocalSize::at_most)});
      }
    }
    device.queue().finish();  // the ray lists and the allocation go out of scope
  }

  double plan_ms = 0;
  bool swapped = false;  // the frame's plan is S.swap_plan.plan (for `stats`)
  int swap_level_buffers = 0;
  int64_t swap_level_bytes = 0;
  std::vector<double> swap_stage_ms;
  cl::Event e_display, e_warp;
  cl::Buffer intermediate;
  Image out;
  if (via_swap) {
    // The swap plan on the host while the device resamples (flushed first:
    // PoCL starts enqueued commands on a flush).
    cl_check(device.queue().flush(), "clFlush");
    // The rectangles straight into the mapped buffer where it holds the
    // plan (not where `stats` asks for the plan's cost, which reads them
    // from the plan): 3.7 MB a frame on the 256^3 phantom not copied.
    const auto tp = std::chrono::steady_clock::now();
    std::vector<SwapRect*> held_out;
    const bool in_map =
        !stats && swap_plan_held_in_map(device, S.swap_plan, split.bits, W, H, held_out);
    plan_swap_into(S.swap_plan.plan, segs.host_rects, split, view, grid, eo.layout,
                   in_map ? held_out.data() : nullptr);
    upload_swap_plan(device, S.swap_plan, false);
    const DeviceSwapPlan& plan = S.swap_plan;
    plan_ms = ms_since(tp);
    // The segments, their bounds and order and the row sums are read by
    // nothing after the local stage (enqueued): the swap's levels and the
    // display may take their buffers.
    for (cl::Buffer* b : {&segs.segments, &segs.bounds, &dm.segments, &dm.bounds, &dm.rowsum})
      device.release(*b);
    if (lanes) device.release(lanes->order);
    // (the footprints are read no more: the levels after the first may
    // take their buffer)
    const DeviceSwapRun run =
        enqueue_swap(device, plan, *fp, kSwapFusedStages, 0, FootprintsAfterSwap::overwritten);
    swap_level_buffers = run.allocated_slots;
    swap_level_bytes = run.allocated_bytes;
    if (view.sampling == Sampling::pixel) {
      host_out.emplace(device, W, H, "intermediate image");
      e_display = enqueue_display_into(device, plan, run.last, host_out->buffer());
    } else {
      e_display = enqueue_display(device, plan, run.last, intermediate);
      host_out.emplace(device, view.out_width, view.out_height, "output image");
      e_warp = enqueue_warp_into(device, view, intermediate, host_out->buffer());
    }
    out = host_out->take();  // blocking
    for (const cl::Event& e : run.stages) swap_stage_ms.push_back(ms(e));
    swapped = true;
  } else {
    if (view.sampling == Sampling::voxel) {
      host_out.emplace(device, view.out_width, view.out_height, "output image");
      e_warp = enqueue_warp_into(device, view, S.image.buffer, host_out->buffer());
    }
    out = host_out->take();  // blocking
  }
  // (the pool only grows within the frame: its bytes now are the frame's
  // peak, less what was let go where a request found no memory; with other
  // threads' engines on the device, theirs too)
  const std::size_t pool_bytes = device.pooled_bytes();
  if (times) {
    *times = EngineTimes{};
    times->layout_ms = ms(e_layout);
    times->shade_ms = eo.fused ? 0.0 : ms(e_shade);
    times->classify_ms = ms(e_classify);
    times->match_ms = stage_ms(dm.match_events);
    times->balance_ms = stage_ms(dm.balance_events);
    if (occupancy)
      for (const cl::Event& e : occupancy->events) times->occupancy_ms += ms(e);
    times->resample_local_ms = (mode == CompositeMode::direct ? ms(e_zero) : 0.0) +
                               times->occupancy_ms + (lanes ? ms(lanes->event) : 0.0) + ms(e_local);
    times->offsets_ms = stage_ms(offset_events);
    times->rays_ms = stage_ms(ray_events);
    times->walk_ms = stage_ms(walk_events) + (mode == CompositeMode::direct ? 0.0 : ms(e_zero));
    times->plan_ms = plan_ms;
    times->swap_stage_ms = swap_stage_ms;
    for (double t : swap_stage_ms) times->swap_ms += t;
    times->display_ms = ms(e_display);
    times->warp_ms = ms(e_warp);
    times->composite_ms = times->swap_ms + times->display_ms + times->warp_ms;
    times->device_wall_ms = ms_since(t0);
    for (const Device::Launch& l : device.take_launches()) {
      const auto [start, end] = event_span_ns(l.event);
      times->kernels.push_back({l.kernel, start, end});
    }
    device.log_launches(false);
    summarise_kernels(*times);
  }
  if (stats) {
    *stats = EngineStats{};
    std::vector<cl_int> loads(static_cast<std::size_t>(dm.pes));
    cl_check(device.queue().enqueueReadBuffer(dm.loads, CL_TRUE, 0, loads.size() * sizeof(cl_int),
                                              loads.data()),
             "clEnqueueReadBuffer(loads)");
    stats->loads.assign(loads.begin(), loads.end());
    for (int64_t l : stats->loads) stats->samples += l;
    stats->segments = segs.count;
    stats->swapped = swapped;
    stats->classification_kept = kept_read;
    stats->classification_let_go = let_go;
    if (swapped) stats->swap = swap_cost(S.swap_plan.plan, split, view, grid);
    stats->swap_level_buffers = swap_level_buffers;
    stats->swap_level_bytes = swap_level_bytes;
    stats->pool_bytes = static_cast<int64_t>(pool_bytes);
    if (live_used()) {
      std::vector<cl_uchar> live(static_cast<std::size_t>(dm.pes));
      cl_check(device.queue().enqueueReadBuffer(live_used, CL_TRUE, 0, live.size(), live.data()),
               "clEnqueueReadBuffer(live)");
      stats->unshaded_pes = std::count(live.begin(), live.end(), cl_uchar(0));
    }
  }
  return out;
}

Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt,
                    const EngineOptions& options, EngineTimes* times) {
  validate(options, opt);
  RenderEngine engine(device, options);
  return engine.render(vol, opt, times);
}

Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt, EngineTimes* times,
                    int64_t pes, bool fused, SwapLayout layout) {
  EngineOptions eo;
  eo.pes = pes;
  eo.fused = fused;
  eo.layout = layout;
  return render_opencl(device, vol, opt, eo, times);
}

}  // namespace simdvol
