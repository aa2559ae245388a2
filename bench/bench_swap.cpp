// simdvol-bench-swap: whole frames of render_opencl (direct compositing,
// every stage on the device) against the serial reference in the same run,
// per-stage times, and the binary swap's communication against the bound of
// thesis ch. 6.2 (issue 5).
//
//   simdvol-bench-swap [--size N] [--pes P] [--order K] [--runs R]
//                      [--layout cut-and-stack|hierarchical] [--brain PATH]
//                      [--no-reference] [--comm-only] [--swap-only]
//
// Frames: the N^3 Shepp-Logan CT phantom (shepp_logan(N, 4), default 256,
// preset ct) to 256^2 and 512^2 (voxel sampling; 512^2 also with pixel
// sampling), and brainsmall.den (preset volpack; --brain PATH, else in
// $SIMDVOL_DATA_DIR where set, else in the source tree's data/; skipped
// where absent) to 256^2, view (0, 30, 0) and (20, 35, 10). Per frame: a
// warm-up call, then R calls (default 5): median wall time of the whole call
// and median device time of each stage (profiling events; the swap's also
// per launch, a launch running up to kSwapFusedStages stages); the serial
// reference (render_reference) once after a warm-up (bench_common.hpp's
// time_warm), its time, and PSNR / max abs difference of the frames.
// Communication (per frame): per swap stage the pixels and bytes moved
// (float4, 16 bytes per pixel), the most one PE sends, holds before the
// stage and composites (keeps), the X-Net distance of the partners; totals
// against S = (a^2 + b^2 + c^2) / 2 per PE (a, b, c the cell extents in
// viewing-grid units), times (M + N) and as printed, M x N.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/io.hpp"
#include "simdvol/match.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/swap_cl.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;
using namespace simdvol::bench;

namespace {

struct Frame {
  std::string name;
  const Volume* vol;
  Classifier cls;
  int size;
  Sampling sampling;
  ViewAngles view;
};

void communication(const Frame& f, int64_t pes, SwapLayout layout) {
  const ViewGeometry view = make_view(*f.vol, f.view, f.size, f.size, f.sampling);
  const KdSplit split = kd_split(f.vol->dims(), pes);
  const Matching m = balance_reference(match_reference(view, split), view, split);
  const PeGrid grid = pe_grid(pes);
  const SwapPlan plan = plan_swap(m.rects, split, view, grid, layout);
  const SwapCost c = swap_cost(plan, split, view, grid);
  std::printf(
      "\ncommunication: %s -> %dx%d (%s sampling, intermediate %dx%d), view (%g, %g, %g), %lld "
      "PEs, %s\n",
      f.name.c_str(), f.size, f.size, f.sampling == Sampling::voxel ? "voxel" : "pixel",
      view.width(), view.height(), f.view.theta, f.view.phi, f.view.varphi,
      static_cast<long long>(pes), swap_layout_name(layout));
  std::printf("stage bit  dist  moved_px   moved_MB  max_sent  max_held  max_kept  mean_held\n");
  for (int k = 0; k < plan.stages(); ++k) {
    const SwapStageCost& s = c.stages[static_cast<std::size_t>(k)];
    const PixelBit& b = plan.bits[static_cast<std::size_t>(k)];
    std::printf("%5d  %c%-2d %5lld %9lld %10.2f %9lld %9lld %9lld %10.1f\n", k,
                b.axis == 0 ? 'x' : 'y', b.level, static_cast<long long>(s.max_distance),
                static_cast<long long>(s.moved), s.moved * 16.0 / 1e6,
                static_cast<long long>(s.max_sent), static_cast<long long>(s.max_held),
                static_cast<long long>(s.max_kept), double(s.held) / double(pes));
  }
  std::printf("total moved %lld px = %.2f MB; most sent by one PE %lld px (%lld B)\n",
              static_cast<long long>(c.moved), c.moved * 16.0 / 1e6,
              static_cast<long long>(c.max_pe_sent), static_cast<long long>(c.max_pe_sent * 16));
  std::printf(
      "bound (ch. 6.2): cell %lldx%lldx%lld voxels, step %.3f: S = (a^2+b^2+c^2)/2 = %.1f px; "
      "M = %d x swaps, N = %d y swaps: (M+N) S = %.0f px, printed M x N x S = %.0f px; "
      "most sent by one PE / (M+N) S = %.3f\n",
      static_cast<long long>(split.cell[0]), static_cast<long long>(split.cell[1]),
      static_cast<long long>(split.cell[2]), view.step, c.cell_section, c.swaps_x, c.swaps_y,
      c.bound_sum(), c.bound_printed(), double(c.max_pe_sent) / c.bound_sum());
  // The thesis's other claim: S "may be used to estimate the maximum number
  // of data a processor could ever have". S is the cell's largest cross
  // section; what a PE holds is its cell's projection (at most
  // sqrt(a^2 b^2 + b^2 c^2 + c^2 a^2), the largest shadow of an a x b x c
  // box) in a bounding rectangle: at an oblique view it can pass S.
  int64_t held = 0;
  int at = 0;
  for (int k = 0; k < plan.stages(); ++k)
    if (c.stages[static_cast<std::size_t>(k)].max_held > held)
      held = c.stages[static_cast<std::size_t>(k)].max_held, at = k;
  const double a = double(split.cell[0]), b = double(split.cell[1]), d = double(split.cell[2]);
  const double shadow =
      std::sqrt(a * a * b * b + b * b * d * d + d * d * a * a) / (view.step * view.step);
  std::printf(
      "held: the most one PE holds is %lld px (stage %d) = %.2f S: the estimate S %s at this "
      "view; the cell's largest projection is %.1f px = %.2f S\n",
      static_cast<long long>(held), at, double(held) / c.cell_section,
      double(held) <= c.cell_section ? "holds" : "does NOT hold", shadow, shadow / c.cell_section);
}

// The swap stages alone with level buffers allocated once (no first-touch
// page faults): R runs after a warm-up, median per stage.
void swap_kernels_only(Device& dev, const Frame& f, int64_t pes, SwapLayout layout, int runs) {
  const ViewGeometry view = make_view(*f.vol, f.view, f.size, f.size, f.sampling);
  const KdSplit split = kd_split(f.vol->dims(), pes);
  const Matching m = balance_reference(match_reference(view, split), view, split);
  const auto tp = Clock::now();
  const DeviceSwapPlan plan =
      upload_swap_plan(dev, plan_swap(m.rects, split, view, pe_grid(pes), layout));
  const double plan_ms = ms_since(tp);
  DeviceFootprints fp = make_footprints(dev, m.rects);
  enqueue_zero_footprints(dev, fp);
  const int N = plan.plan.stages();
  int64_t most = 1;
  for (int L = 1; L <= N; ++L) most = std::max(most, plan.plan.level_size(L));
  cl::Buffer a = dev.buffer(CL_MEM_READ_WRITE, most * 16, nullptr, "a");
  cl::Buffer b = dev.buffer(CL_MEM_READ_WRITE, most * 16, nullptr, "b");
  std::vector<std::vector<double>> t(static_cast<std::size_t>(N));
  std::vector<std::vector<double>> tf;  // per launch of the fused run
  std::vector<double> total, total_fused;
  int64_t slot_bytes = 0;
  std::size_t slot_count = 0;
  // In turn, run after run: one launch per stage, and enqueue_swap's runs
  // of up to kSwapFusedStages stages per launch (its level buffers come
  // back from the pool of the previous run: no fresh pages).
  for (int r = 0; r <= runs; ++r) {
    std::vector<cl::Event> ev;
    cl::Buffer in = fp.pixels;
    for (int k = 0; k < N; ++k) {
      const cl::Buffer& out = k % 2 ? b : a;
      ev.push_back(enqueue_swap_stage(dev, plan, k, in, out));
      in = out;
    }
    dev.finish();
    DeviceSwapRun fused;
    {
      Device::ReuseScope reuse(dev);
      fused = enqueue_swap(dev, plan, fp);
      dev.finish();
    }
    slot_bytes = 0;
    slot_count = fused.slots.size();
    for (const cl::Buffer& sb : fused.slots)
      slot_bytes += static_cast<int64_t>(buffer_size(sb, "clGetMemObjectInfo(CL_MEM_SIZE)"));
    if (r == 0) continue;
    double sum = 0;
    for (int k = 0; k < N; ++k) {
      const double ms = static_cast<double>(event_ns(ev[static_cast<std::size_t>(k)])) * 1e-6;
      t[static_cast<std::size_t>(k)].push_back(ms);
      sum += ms;
    }
    total.push_back(sum);
    tf.resize(fused.stages.size());
    sum = 0;
    for (std::size_t l = 0; l < fused.stages.size(); ++l) {
      const double ms = static_cast<double>(event_ns(fused.stages[l])) * 1e-6;
      tf[l].push_back(ms);
      sum += ms;
    }
    total_fused.push_back(sum);
  }
  std::printf(
      "swap kernels only (buffers reused), %s -> %d %s, %s: total %.2f ms, plan %.2f ms; "
      "stages:",
      f.name.c_str(), f.size, f.sampling == Sampling::voxel ? "voxel" : "pixel",
      swap_layout_name(layout), median(total), plan_ms);
  for (const auto& v : t) std::printf(" %.2f", median(v));
  std::printf(
      "\n  up to %d stages per launch (the frame's swap, runs in turn with the above): "
      "total %.2f ms (%.2f x); launches:",
      kSwapFusedStages, median(total_fused), median(total_fused) / median(total));
  for (const auto& v : tf) std::printf(" %.2f", median(v));
  // The level buffers of that run, against one buffer per level of the
  // fused launch (slot (L - 1) mod 7, each sized by its largest level: the
  // form before the levels between moved to local memory).
  std::vector<int64_t> per_level(static_cast<std::size_t>(std::min(N, kSwapFusedStages + 1)), 1);
  for (int L = 1; L <= N; ++L) {
    int64_t& m = per_level[static_cast<std::size_t>((L - 1) % per_level.size())];
    m = std::max(m, plan.plan.level_size(L) * 16);
  }
  int64_t seven = 0;
  for (const int64_t v : per_level) seven += v;
  std::printf(
      "\n  level buffers %.1f MiB in %zu slots (a buffer per level of the launch: %.1f MiB)\n",
      static_cast<double>(slot_bytes) / 1048576.0, slot_count,
      static_cast<double>(seven) / 1048576.0);
}

constexpr const char* kUsage =
    "usage: simdvol-bench-swap [--size N] [--pes P] [--order K] [--runs R]\n"
    "                          [--layout cut-and-stack|hierarchical] [--brain PATH]\n"
    "                          [--no-reference] [--comm-only] [--swap-only]\n"
    "  N: 8..1024 (the N^3 phantom); P: a power of two in 1..1048576; K: 0..3; R: 1..1000;\n"
    "  PATH: brainsmall.den (default: in $SIMDVOL_DATA_DIR where set, else in the source\n"
    "  tree's data/)\n";

}  // namespace

int main(int argc, char** argv) {
  int size = 256, order = 1, runs = 5;
  int64_t pes = 8192;
  bool reference = true, comm_only = false, swap_only = false;
  SwapLayout layout = SwapLayout::cut_and_stack;
  std::string brain = (data_dir() / "brainsmall.den").string();
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::fputs(kUsage, stdout);
        return 0;
      } else if (args.is("--size")) {
        size = static_cast<int>(args.integer(8, 1024));
      } else if (args.is("--pes")) {
        pes = args.pes();
      } else if (args.is("--order")) {
        order = static_cast<int>(args.integer(0, 3));
      } else if (args.is("--runs")) {
        runs = static_cast<int>(args.integer(1, 1000));
      } else if (args.is("--layout")) {
        layout = parse_swap_layout(args.value(), args.option());
      } else if (args.is("--brain")) {
        brain = args.existing_file();
      } else if (args.is("--no-reference")) {
        reference = false;
      } else if (args.is("--comm-only")) {
        comm_only = true;
      } else if (args.is("--swap-only")) {
        swap_only = true;
      } else {
        args.unknown();
      }
    }
    // (--comm-only stops before the kernels: --swap-only was ignored)
    if (comm_only && swap_only)
      throw ArgumentError("--swap-only", "and --comm-only: give one of them");
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-swap", e, kUsage);
  }
  try {
    const auto tv = Clock::now();
    const Volume ct = shepp_logan(size, 4);
    std::printf("shepp_logan(%d, 4): %.0f ms\n", size, ms_since(tv));
    Volume brainvol;
    const bool have_brain = std::filesystem::exists(brain);
    if (have_brain)
      brainvol = load_volume(brain);
    else
      note_brainsmall_missing(brain);
    std::vector<Frame> frames;
    const std::string ctname = "ct-phantom-" + std::to_string(size);
    frames.push_back({ctname, &ct, classifier_preset("ct"), 256, Sampling::voxel, {0, 30, 0}});
    frames.push_back({ctname, &ct, classifier_preset("ct"), 512, Sampling::voxel, {0, 30, 0}});
    frames.push_back({ctname, &ct, classifier_preset("ct"), 512, Sampling::pixel, {0, 30, 0}});
    frames.push_back({ctname, &ct, classifier_preset("ct"), 256, Sampling::voxel, {20, 35, 10}});
    if (have_brain)
      frames.push_back({"brainsmall",
                        &brainvol,
                        classifier_preset("volpack"),
                        256,
                        Sampling::voxel,
                        {0, 30, 0}});
    // (the oblique view too: the estimate S of what a PE holds, which holds
    // at (0, 30, 0), does not there)
    for (const Frame& f : frames)
      if (!(f.size == 512 && f.sampling == Sampling::voxel)) communication(f, pes, layout);
    if (comm_only) return 0;

    Device dev;
    for (const Frame& f : frames)
      if (f.view.theta == 0) swap_kernels_only(dev, f, pes, layout, runs);
    if (swap_only) return 0;
    std::printf("\ndevice: %s; %lld PEs, order %d, %s, fused shade+classify, %d runs\n",
                dev.info().name.c_str(), static_cast<long long>(pes), order,
                swap_layout_name(layout), runs);
    std::printf("%-16s %4s %5s | %8s %8s | %6s %6s %6s %6s %6s %6s %6s %6s %6s | %8s %7s %9s\n",
                "volume", "out", "samp", "wall_ms", "dev_ms", "layout", "shcls", "match", "bal",
                "rs+loc", "plan", "swap", "disp", "warp", "ref_ms", "ratio", "PSNR/dB");
    for (const Frame& f : frames) {
      RenderOptions opt;
      opt.width = opt.height = f.size;
      opt.sampling = f.sampling;
      opt.order = order;
      opt.view = f.view;
      opt.classifier = f.cls;
      EngineTimes t;
      Image img = render_opencl(dev, *f.vol, opt, &t, pes, true, layout);  // warm-up
      std::vector<double> wall, devsum, lay, cls, mat, bal, rl, plan, swp, dsp, wrp;
      std::vector<std::vector<double>> stages;
      for (int r = 0; r < runs; ++r) {
        const auto t0 = Clock::now();
        img = render_opencl(dev, *f.vol, opt, &t, pes, true, layout);
        wall.push_back(ms_since(t0));
        lay.push_back(t.layout_ms), cls.push_back(t.classify_ms), mat.push_back(t.match_ms);
        bal.push_back(t.balance_ms), rl.push_back(t.resample_local_ms), plan.push_back(t.plan_ms);
        swp.push_back(t.swap_ms), dsp.push_back(t.display_ms), wrp.push_back(t.warp_ms);
        devsum.push_back(t.layout_ms + t.classify_ms + t.match_ms + t.balance_ms +
                         t.resample_local_ms + t.swap_ms + t.display_ms + t.warp_ms);
        stages.resize(t.swap_stage_ms.size());
        for (std::size_t k = 0; k < t.swap_stage_ms.size(); ++k)
          stages[k].push_back(t.swap_stage_ms[k]);
      }
      // With --no-reference: "-", not 0, where nothing was measured.
      char ref_text[96] = "       -       -         -";
      if (reference) {
        double ref_ms = 0;  // warm, as the engine's frames (bench_common.hpp)
        const Image ref = time_warm(
            1, [&] { return render_reference(*f.vol, opt); }, ref_ms);
        std::snprintf(ref_text, sizeof ref_text, "%8.0f %7.1f %9.1f  (max diff %.2g)", ref_ms,
                      ref_ms / median(wall), psnr(ref, img), max_abs_diff(ref, img));
      }
      std::printf(
          "%-16s %4d %5s | %8.1f %8.1f | %6.1f %6.1f %6.1f %6.1f %6.1f %6.2f %6.2f %6.2f %6.2f | "
          "%s\n",
          f.name.c_str(), f.size, f.sampling == Sampling::voxel ? "voxel" : "pixel", median(wall),
          median(devsum), median(lay), median(cls), median(mat), median(bal), median(rl),
          median(plan), median(swp), median(dsp), median(wrp), ref_text);
      // One time per launch: a launch runs up to kSwapFusedStages stages.
      std::printf("    swap launches (ms; %zu launch%s for %d stages):", stages.size(),
                  stages.size() == 1 ? "" : "es", kd_split(f.vol->dims(), pes).bits);
      for (const auto& s : stages) std::printf(" %.2f", median(s));
      std::printf("\n");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
