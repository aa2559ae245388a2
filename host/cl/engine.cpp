// The OpenCL render engine (engine.hpp).
#include "simdvol/engine.hpp"

#include <chrono>
#include <optional>

#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/stages.hpp"

namespace simdvol {

namespace {
double ms(const cl::Event& e) {
  return static_cast<double>(event_ns(e)) * 1e-6;
}
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt, EngineTimes* times,
                    int64_t pes, bool fused) {
  validate(opt);
  if (vol.voxel_count() == 0) throw ArgumentError("volume", "is empty");
  const PeGrid grid = pe_grid(pes, "pes");
  const ViewGeometry view = make_view(vol, opt.view, opt.width, opt.height, opt.sampling);
  // Parameters first: every argument error is thrown before anything runs.
  const sv_shade_params sp = shade_params(make_shade_frame(vol, view, opt.shade), opt.shade);
  const bool need_range =
      opt.classifier.kind == Classifier::Kind::mixture && opt.classifier.mixture.relative;
  const sv_classify_params cp =
      classify_params(opt.classifier, need_range ? vol.range() : ValueRange{}, view.step);

  const auto t0 = std::chrono::steady_clock::now();
  PeArray array(device, grid);
  const CellLayout cl_layout = array.cell_layout(vol.dims(), 1);
  const VoxelLayout vl = make_voxel_layout(cl_layout);
  check_allocation(vl.bytes(), device.info().max_alloc_bytes, "volume (voxel cells)");
  cl::Event e_layout, e_shade, e_classify, e_gather;
  CellBuffer cells = array.layout(vol, 1, LayoutKernel::rows, &e_layout);
  VoxelBuffer rgba(device, vl);
  std::optional<VoxelBuffer> shading;  // alive until the gather has finished
  if (fused) {
    e_classify = enqueue_shade_classify(device, cells, sp, cp, rgba);
  } else {
    shading.emplace(device, vl);
    e_shade = enqueue_shade(device, cells, sp, *shading);
    e_classify = enqueue_classify(device, *shading, cp, rgba);
  }
  if (opt.composite.mode != CompositeMode::direct) {
    // Adaptive and Monte Carlo compositing: the reference finishes the frame.
    std::vector<Rgba> voxels(vol.voxel_count());
    gather_rgba(device, rgba, voxels.data(), &e_gather);  // blocking
    if (times) {
      times->layout_ms = ms(e_layout);
      times->shade_ms = fused ? 0.0 : ms(e_shade);
      times->classify_ms = ms(e_classify);
      times->gather_ms = ms(e_gather);
      times->device_wall_ms = ms_since(t0);
    }
    return render_classified(voxels, vol, view, opt, times ? &times->host : nullptr);
  }
  // Direct compositing: match, balance, resample + local on the PE array.
  const KdSplit& split = cl_layout.split;
  DeviceMatching dm = enqueue_match(device, view, split);
  enqueue_balance(device, dm, view, split);
  const LocalSegments segs = device_segments(device, dm);  // waits: footprint sizes
  const ResampleTables tables = make_resample_tables(device, vl, view);
  DeviceFootprints fp = make_footprints(device, segs.host_rects);
  const cl::Event e_zero = enqueue_zero_footprints(device, fp);
  const cl::Event e_local = enqueue_resample_local(device, segs, tables, rgba, opt.order, fp);
  const Footprints f = read_footprints(device, fp);  // blocking
  const Matching m = dm.read(device);
  if (times) {
    times->layout_ms = ms(e_layout);
    times->shade_ms = fused ? 0.0 : ms(e_shade);
    times->classify_ms = ms(e_classify);
    times->gather_ms = 0.0;
    times->match_ms = static_cast<double>(events_ns(dm.match_events)) * 1e-6;
    times->balance_ms = static_cast<double>(events_ns(dm.balance_events)) * 1e-6;
    times->resample_local_ms = ms(e_zero) + ms(e_local);
    times->device_wall_ms = ms_since(t0);
  }
  const auto tm = std::chrono::steady_clock::now();
  Image im = composite_footprints(m, f, view.width(), view.height());
  Image out = view.sampling == Sampling::pixel ? std::move(im) : warp_to_output(im, view);
  if (times) times->composite_ms = ms_since(tm);
  return out;
}

}  // namespace simdvol
