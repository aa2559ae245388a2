// The OpenCL render engine (engine.hpp).
#include "simdvol/engine.hpp"

#include <chrono>
#include <optional>

#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap_cl.hpp"

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
                    int64_t pes, bool fused, SwapLayout swap_layout) {
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
  // The swap plan on the host while the device resamples.
  const auto tp = std::chrono::steady_clock::now();
  const DeviceSwapPlan plan =
      upload_swap_plan(device, plan_swap(segs.host_rects, split, view, grid, swap_layout));
  const double plan_ms = ms_since(tp);
  const DeviceSwapRun run = enqueue_swap(device, plan, fp);
  cl::Buffer intermediate, output;
  const cl::Event e_display = enqueue_display(device, plan, run.last, intermediate);
  cl::Event e_warp;
  Image out;
  if (view.sampling == Sampling::pixel) {
    out = read_device_image(device, intermediate, view.width(), view.height());  // blocking
  } else {
    e_warp = enqueue_warp(device, view, intermediate, output);
    out = read_device_image(device, output, view.out_width, view.out_height);  // blocking
  }
  if (times) {
    times->layout_ms = ms(e_layout);
    times->shade_ms = fused ? 0.0 : ms(e_shade);
    times->classify_ms = ms(e_classify);
    times->gather_ms = 0.0;
    times->match_ms = static_cast<double>(events_ns(dm.match_events)) * 1e-6;
    times->balance_ms = static_cast<double>(events_ns(dm.balance_events)) * 1e-6;
    times->resample_local_ms = ms(e_zero) + ms(e_local);
    times->plan_ms = plan_ms;
    times->swap_stage_ms.clear();
    times->swap_ms = 0;
    for (const cl::Event& e : run.stages) {
      times->swap_stage_ms.push_back(ms(e));
      times->swap_ms += times->swap_stage_ms.back();
    }
    times->display_ms = ms(e_display);
    times->warp_ms = view.sampling == Sampling::pixel ? 0.0 : ms(e_warp);
    times->composite_ms = times->swap_ms + times->display_ms + times->warp_ms;
    times->device_wall_ms = ms_since(t0);
  }
  return out;
}

}  // namespace simdvol
