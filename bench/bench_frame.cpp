// simdvol-bench-frame: the per-frame stages after classification on the PE
// array (issue 4): match, balance, resample, local and the fused
// resample + local, ms per stage from the profiling events, against the
// serial reference doing the same work in the same run.
//
//   simdvol-bench-frame [--size N] [--pes P] [--order K] [--runs R]
//                       [--views 0,30,45] [--no-reference] [--kernels]
//
// The N^3 Shepp-Logan CT phantom (shepp_logan(N, 4), default 256), preset
// "ct", shaded and classified on the device (fused launch) once; per view
// (rotation phi about the vertical axis), voxel sampling at N x N: the
// matching and balancing come from the serial references (timed) until the
// device match/balance stages are wired in; the segments are uploaded; then,
// after a warm-up launch of every kernel, R runs (default 5) of each device
// stage, interleaved, median device time. Also reported: samples, segments,
// the gather loads ((K+1)^3 voxels x 4 channels per sample) against the
// ~9 G loads/s floor of POCL.md, the bytes the fused kernel must touch, and
// the X-Net reads of the reference (remote stencil voxels). --kernels also
// prints, per view, each kernel of the frame path's sum' (median ms).
//
//   simdvol-bench-frame --whole [--pes P] [--order K] [--runs R] [--brain PATH]
//
// Whole frames (issue 5): the 256^3 phantom (preset ct) to 256^2 and 512^2
// and brainsmall.den (preset volpack; --brain PATH, else in
// $SIMDVOL_DATA_DIR where set, else in the source tree's data/, from any
// working directory; skipped where absent) to 256^2, direct compositing, voxel
// sampling, view (0, 30, 0): the serial reference (one frame after a
// warm-up, its freed memory kept: bench_common.hpp's time_warm), one-shot
// render_opencl (fresh buffers each frame) and a warm RenderEngine (buffers
// and the layout reused, as a turntable), interleaved, R frames each
// (median), with the engine's per-stage times of the median warm frame.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bench_args.hpp"
#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;
using simdvol::bench::Args;
using simdvol::bench::argument_error;
using simdvol::bench::Clock;
using simdvol::bench::data_dir;
using simdvol::bench::ms_since;
using simdvol::bench::note_brainsmall_missing;
using simdvol::bench::time_warm;

namespace {

// The median, the mean of the middle two for an even count, as every tool
// reports it (it was the upper of the two here).
using simdvol::bench::median;
// The value named `name` in a list kept in first-seen order (added if new).
template <class V>
V& slot(std::vector<std::pair<std::string, V>>& list, const std::string& name) {
  for (auto& [n, v] : list)
    if (n == name) return v;
  return list.emplace_back(name, V{}).second;
}

double ev_ms(const cl::Event& e) {
  return static_cast<double>(event_ns(e)) * 1e-6;
}

constexpr const char* kProgram = "simdvol-bench-frame";
constexpr const char* kUsage =
    "usage: simdvol-bench-frame [--size N] [--pes P] [--order K] [--runs R] [--views a,b,c]\n"
    "                           [--no-reference] [--kernels]\n"
    "       simdvol-bench-frame --whole [--pes P] [--order K] [--runs R] [--brain PATH]\n"
    "  N: 8..1024 (the N^3 phantom to N x N); P: a power of two in 1..1048576; K: 0..3;\n"
    "  R: 1..1000; views: angles phi in -360..360 (degrees); PATH: brainsmall.den (default:\n"
    "  in $SIMDVOL_DATA_DIR where set, else in the source tree's data/)\n";

struct Options {
  bool whole = false;
  int size = 256, runs = 5, order = 1;
  int64_t pes = 8192;
  bool reference = true, kernels = false;
  std::vector<double> views{0, 30, 45};
  std::string brain;  // --brain; else brainsmall.den in bench::data_dir()
};

Options parse_args(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) o.whole = o.whole || !std::strcmp(argv[i], "--whole");
  Args args(argc, argv);
  while (args.next()) {
    if (args.help()) {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (args.is("--whole")) {
      // seen above: it decides which options apply
    } else if (args.is("--pes")) {
      o.pes = args.pes();
    } else if (args.is("--order")) {
      o.order = static_cast<int>(args.integer(0, 3));
    } else if (args.is("--runs")) {
      o.runs = static_cast<int>(args.integer(1, 1000));
    } else if (args.is("--brain")) {
      if (!o.whole) throw ArgumentError(args.option(), "only used with --whole");
      o.brain = args.existing_file();
    } else if (args.is("--size") || args.is("--views") || args.is("--no-reference") ||
               args.is("--kernels")) {
      if (o.whole) throw ArgumentError(args.option(), "not used with --whole");
      if (args.is("--size"))
        o.size = static_cast<int>(args.integer(8, 1024));
      else if (args.is("--views"))
        o.views = args.number_list(-360, 360);
      else if (args.is("--kernels"))
        o.kernels = true;
      else
        o.reference = false;
    } else {
      args.unknown();
    }
  }
  return o;
}

}  // namespace

// `swap_stages`: the binary swap's stages (log2 P); EngineTimes has one
// time per launch, and a launch runs up to kSwapFusedStages of them.
std::string stages(const EngineTimes& t, int swap_stages) {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "layout %.2f, shade+classify %.2f, match %.2f, balance %.2f, resample+local %.2f, "
                "plan %.2f (host), swap %.2f (%zu launch%s, %d stages), display %.2f, warp %.2f",
                t.layout_ms, t.shade_ms + t.classify_ms, t.match_ms, t.balance_ms,
                t.resample_local_ms, t.plan_ms, t.swap_ms, t.swap_stage_ms.size(),
                t.swap_stage_ms.size() == 1 ? "" : "es", swap_stages, t.display_ms, t.warp_ms);
  return buf;
}

int whole_frames(int64_t pes, int order, int runs, std::string brain) {
  Device device;
  std::printf(
      "device: %s (%u compute units); whole frames, order %d, %lld PEs, direct, voxel "
      "sampling, %d frames each (median ms)\n",
      device.info().name.c_str(), device.info().compute_units, order, static_cast<long long>(pes),
      runs);
  struct Case {
    std::string name;
    const Volume* vol;
    Classifier cls;
    int size;
  };
  const Volume phantom = shepp_logan(256, 4);
  std::optional<Volume> brainvol;
  std::vector<Case> cases{{"phantom 256^3 -> 256^2", &phantom, classifier_preset("ct"), 256},
                          {"phantom 256^3 -> 512^2", &phantom, classifier_preset("ct"), 512}};
  if (brain.empty()) brain = (data_dir() / "brainsmall.den").string();
  if (std::filesystem::exists(brain)) {
    brainvol = load_volume(brain);
    cases.push_back({"brainsmall -> 256^2", &*brainvol, classifier_preset("volpack"), 256});
  } else {
    note_brainsmall_missing(brain);
  }
  for (const Case& c : cases) {
    RenderOptions opt;
    opt.width = opt.height = c.size;
    opt.order = order;
    opt.view = {0, 30, 0};
    opt.classifier = c.cls;
    EngineOptions eo;
    eo.pes = pes;
    eo.fused = true;
    eo.reuse_layout = true;
    double ref_ms = 0;  // warm, as the engine's frames (bench_common.hpp)
    const Image ref = time_warm(
        1, [&] { return render_reference(*c.vol, opt); }, ref_ms);
    auto t0 = Clock::now();
    RenderEngine engine(device, eo);
    EngineOptions oneshot_eo = eo;
    oneshot_eo.reuse_layout = false;
    engine.render(*c.vol, opt);                      // warm-up: builds, first launches
    render_opencl(device, *c.vol, opt, oneshot_eo);  // warm-up
    std::vector<double> one, warm;
    std::vector<std::pair<double, EngineTimes>> warm_times;
    double psnr_db = 0;
    for (int r = 0; r < runs; ++r) {
      opt.view.phi = 30.0 + r;  // a turntable
      t0 = Clock::now();
      render_opencl(device, *c.vol, opt, oneshot_eo);
      one.push_back(ms_since(t0));
      EngineTimes t;
      t0 = Clock::now();
      const Image img = engine.render(*c.vol, opt, &t);
      warm.push_back(ms_since(t0));
      warm_times.push_back({warm.back(), t});
      if (r == 0) {
        opt.view.phi = 30.0;
        psnr_db = psnr(engine.render(*c.vol, opt), ref);
      }
    }
    std::sort(warm_times.begin(), warm_times.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    const double w = median(warm), o = median(one);
    std::printf(
        "%s: reference %.1f ms (phi 30), one-shot render_opencl %.1f ms, RenderEngine (warm) "
        "%.1f ms (phi 30 .. %d, a turntable); ratio reference/warm %.2f, one-shot/warm %.2f; "
        "PSNR vs reference %.1f dB (phi 30)\n"
        "  warm stages (ms): %s\n",
        c.name.c_str(), ref_ms, o, w, 30 + runs - 1, ref_ms / w, o / w, psnr_db,
        stages(warm_times[warm_times.size() / 2].second, kd_split(c.vol->dims(), pes).bits)
            .c_str());
  }
  return 0;
}

int main(int argc, char** argv) try {
  Options o;
  try {
    o = parse_args(argc, argv);
  } catch (const ArgumentError& e) {
    return argument_error(kProgram, e, kUsage);
  }
  if (o.whole) return whole_frames(o.pes, o.order, o.runs, o.brain);
  const int size = o.size, runs = o.runs, order = o.order;
  const int64_t pes = o.pes;
  const bool reference = o.reference;
  const std::vector<double>& views = o.views;

  Device device;
  std::printf("device: %s (%u compute units)\n", device.info().name.c_str(),
              device.info().compute_units);
  const Volume vol = shepp_logan(size, 4);
  const Classifier cls = classifier_preset("ct");
  const ShadeParams shp{};
  PeArray array(device, pe_grid(pes));
  CellBuffer cells = array.layout(vol, 1);
  const VoxelLayout L = make_voxel_layout(cells.layout());
  VoxelBuffer rgba(device, L);
  // The engine's fused path writes interleaved cells (stages.hpp): column
  // `ordered4`, the same voxels in that layout.
  const VoxelLayout L4 = make_voxel_layout(cells.layout(), true);
  VoxelBuffer rgba4(device, L4);
  std::vector<Rgba> flat;
  std::printf(
      "volume %d^3 Shepp-Logan (s = 4), preset ct, %lld PEs, cell %lldx%lldx%lld, order %d, "
      "%d runs (median)\n\n",
      size, static_cast<long long>(pes), static_cast<long long>(L.cell()[0]),
      static_cast<long long>(L.cell()[1]), static_cast<long long>(L.cell()[2]), order, runs);
  std::printf(
      "%5s %9s %9s %7s | %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s | %9s %9s %9s %7s | %8s %8s | "
      "%7s %8s %8s %8s %8s | %8s %8s\n",
      "view", "samples", "segments", "util", "match", "balance", "resample", "local", "zero",
      "fused", "fused1", "occ", "skip", "ordered", "ordered4", "ref m+b", "ref r+l", "ref/dev",
      "Gld/s", "xnet rd", "xnet max", "occ'", "active", "match'", "balance'", "rsloc'", "sum",
      "sum'");
  std::string kernel_lines;  // --kernels, printed after the table
  for (const double phi : views) {
    const ViewAngles angles{0.0, phi, 0.0};
    const ViewGeometry view = make_view(vol, angles, size, size, Sampling::voxel);
    // Classified voxels for this view (the shading depends on the view).
    const sv_shade_params sp = shade_params(make_shade_frame(vol, view, shp), shp);
    const sv_classify_params cp = classify_params(cls, ValueRange{}, view.step);
    {
      enqueue_shade_classify(device, cells, sp, cp, rgba);
      enqueue_shade_classify(device, cells, sp, cp, rgba4);
      flat.resize(vol.voxel_count());
      gather_rgba(device, rgba, flat.data());
    }
    const KdSplit split = kd_split(vol.dims(), pes);
    // The serial references timed warm (bench_common.hpp's time_warm).
    double ref_match = 0, ref_balance = 0;
    const Matching m0 = time_warm(
        1, [&] { return match_reference(view, split); }, ref_match);
    const Matching m = time_warm(
        1, [&] { return balance_reference(m0, view, split); }, ref_balance);

    // Device match + balance (warm-up, then timed with the other stages).
    // Each run's buffers come back from the previous run's (Device::
    // ReuseScope, as RenderEngine::render opens one per frame): the stages
    // are timed without the page faults of fresh buffers, as in a frame.
    std::vector<double> t_match, t_bal;
    for (int r = 0; r <= runs; ++r) {
      Device::ReuseScope reuse(device);
      DeviceMatching dm = enqueue_match(device, view, split);
      enqueue_balance(device, dm, view, split);
      device.finish();
      if (r == 0) {
        const Matching got = dm.read(device);
        if (got.segments.size() != m.segments.size() || got.loads != m.loads)
          throw Error("device match/balance differs from the reference");
        continue;
      }
      t_match.push_back(static_cast<double>(events_ns(dm.match_events)) * 1e-6);
      t_bal.push_back(static_cast<double>(events_ns(dm.balance_events)) * 1e-6);
    }
    const LocalSegments segs = upload_segments(device, m);
    const ResampleTables tables = make_resample_tables(device, L, view);
    const ResampleTables tables4 = make_resample_tables(device, L4, view);
    const cl::Buffer soff = upload_sample_offsets(device, m);
    const int64_t nsamples = sample_offsets(m).back();
    cl::Buffer samples = device.buffer(
        CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16, nullptr,
        "samples");
    DeviceFootprints fp = make_footprints(device, m.rects);
    // Warm-up (compiles every kernel for this local size; touches the buffers).
    enqueue_zero_footprints(device, fp);
    enqueue_resample(device, segs, soff, tables, rgba, order, samples);
    enqueue_local(device, segs, soff, samples, fp);
    enqueue_resample_local(device, segs, tables, rgba, order, fp);
    device.finish();
    enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::segment);
    device.finish();
    // Empty-space skipping must give the same footprints, bit for bit.
    const Footprints plain = read_footprints(device, fp);
    {
      const DeviceOccupancy occ = enqueue_occupancy(device, rgba, order);
      enqueue_zero_footprints(device, fp);
      enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::vector8, &occ);
      const Footprints skipped = read_footprints(device, fp);
      if (skipped.pixels.size() != plain.pixels.size() ||
          std::memcmp(skipped.pixels.data(), plain.pixels.data(),
                      plain.pixels.size() * sizeof(Rgba)) != 0)
        throw Error("empty-space skipping changed the footprints");
    }
    // The lane order must give the same footprints too.
    {
      const DeviceOccupancy occ = enqueue_occupancy(device, rgba, order);
      const SegmentOrder lanes = enqueue_segment_order(device, segs);
      enqueue_zero_footprints(device, fp);
      enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::vector8, &occ,
                             &lanes);
      const Footprints ordered = read_footprints(device, fp);
      if (ordered.pixels.size() != plain.pixels.size() ||
          std::memcmp(ordered.pixels.data(), plain.pixels.data(),
                      plain.pixels.size() * sizeof(Rgba)) != 0)
        throw Error("the lane order changed the footprints");
      enqueue_zero_footprints(device, fp);
      enqueue_resample_local(device, segs, tables4, rgba4, order, fp, LocalKernel::vector8, &occ,
                             &lanes);
      const Footprints il = read_footprints(device, fp);
      if (il.pixels.size() != plain.pixels.size() ||
          std::memcmp(il.pixels.data(), plain.pixels.data(), plain.pixels.size() * sizeof(Rgba)) !=
              0)
        throw Error("the interleaved cells changed the footprints");
    }
    std::vector<double> t_res, t_loc, t_zero, t_fused, t_fused1, t_occ, t_skip, t_ord, t_ord4;
    for (int r = 0; r < runs; ++r) {
      const cl::Event ez = enqueue_zero_footprints(device, fp);
      const cl::Event er = enqueue_resample(device, segs, soff, tables, rgba, order, samples);
      const cl::Event el = enqueue_local(device, segs, soff, samples, fp);
      const cl::Event ez2 = enqueue_zero_footprints(device, fp);
      const cl::Event ef = enqueue_resample_local(device, segs, tables, rgba, order, fp);
      const cl::Event ef1 =
          enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::segment);
      const DeviceOccupancy occ = enqueue_occupancy(device, rgba, order);
      const cl::Event es =
          enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::vector8, &occ);
      const SegmentOrder lanes = enqueue_segment_order(device, segs);
      const cl::Event eo = enqueue_resample_local(device, segs, tables, rgba, order, fp,
                                                  LocalKernel::vector8, &occ, &lanes);
      const cl::Event eo4 = enqueue_resample_local(device, segs, tables4, rgba4, order, fp,
                                                   LocalKernel::vector8, &occ, &lanes);
      device.finish();
      t_ord.push_back(ev_ms(lanes.event) + ev_ms(eo));
      t_ord4.push_back(ev_ms(lanes.event) + ev_ms(eo4));
      double occ_ms = 0;
      for (const cl::Event& e : occ.events) occ_ms += ev_ms(e);
      t_occ.push_back(occ_ms);
      t_skip.push_back(ev_ms(es));
      t_fused1.push_back(ev_ms(ef1));
      t_zero.push_back(0.5 * (ev_ms(ez) + ev_ms(ez2)));
      t_res.push_back(ev_ms(er));
      t_loc.push_back(ev_ms(el));
      t_fused.push_back(ev_ms(ef));
    }
    // The frame path with EngineOptions::skip_pes: the brick reach before
    // the matching, the PEs with nothing in reach left out (checked against
    // the references with the device's mask, then timed).
    // The brick occupancy as the frame makes it (engine.cpp): marked by the
    // fused shade + classify as it writes the interleaved voxels, then the
    // reach kernel. occ' = what the marking adds to that kernel (the same
    // kernel without marking runs just before it, each run) + the zero fill
    // and the reach.
    std::vector<double> t_match2, t_bal2, t_rl2, t_occ2;
    std::vector<std::pair<std::string, std::vector<double>>> kernel_ms;  // --kernels
    double active = 0;
    for (int r = 0; r <= runs; ++r) {
      Device::ReuseScope reuse(device);  // as above
      const cl::Event e_plain = enqueue_shade_classify(device, cells, sp, cp, rgba4);
      DeviceOccupancy occ = make_occupancy(device, L4, order);
      const cl::Event e_mark =
          enqueue_shade_classify(device, cells, sp, cp, rgba4, ShadeKernel::vec16, &occ);
      enqueue_occupancy_reach(device, occ);
      DeviceMatching dm = enqueue_match(device, view, split, BrickReach{&occ.reach, occ.bricks});
      // as the engine's direct frames: the order and the fused kernel read
      // the balanced bounds, no unpack
      enqueue_balance(device, dm, view, split, kBalanceSweeps, BalanceBounds::automatic,
                      BalanceUnpack::deferred);
      const LocalSegments ls = device_segments(device, dm);
      const SegmentOrder lanes = enqueue_segment_order(device, ls);
      DeviceFootprints fp2 = make_footprints(device, ls.host_rects);
      const cl::Event ez = enqueue_zero_uncovered(device, dm, fp2);
      const cl::Event eo = enqueue_resample_local(device, ls, tables4, rgba4, order, fp2,
                                                  LocalKernel::vector8, &occ, &lanes);
      device.finish();
      if (r == 0) {
        const Matching got = dm.read(device);
        const Matching want =
            balance_reference(match_reference(view, split, got.active), view, split);
        if (got.loads != want.loads || got.segments.size() != want.segments.size())
          throw Error("device match/balance with the PE mask differs from the reference");
        active = static_cast<double>(std::count(got.active.begin(), got.active.end(), 1)) /
                 static_cast<double>(got.active.size());
        continue;
      }
      double occ_ms = 0;
      for (const cl::Event& e : occ.events) occ_ms += ev_ms(e);
      t_match2.push_back(static_cast<double>(events_ns(dm.match_events)) * 1e-6);
      t_bal2.push_back(static_cast<double>(events_ns(dm.balance_events)) * 1e-6);
      const double mark = std::max(0.0, ev_ms(e_mark) - ev_ms(e_plain));
      if (o.kernels) {
        // each kernel's time in this run (a name's launches summed)
        std::vector<std::pair<std::string, double>> run;
        const auto add = [&run](const std::string& name, double ms) { slot(run, name) += ms; };
        add("marks", mark);
        add("occupancy fill", ev_ms(occ.events.at(0)));
        add("occupancy_reach", ev_ms(occ.events.at(1)));
        for (const auto* evs : {&dm.match_events, &dm.balance_events})
          for (const StageEvent& se : *evs) add(se.name, ev_ms(se.event));
        add("segment_order", ev_ms(lanes.event));
        add("zero_uncovered", ev_ms(ez));
        add("resample_local", ev_ms(eo));
        for (const auto& [n, t] : run) slot(kernel_ms, n).push_back(t);
      }
      const double occ2 = mark + occ_ms;
      t_occ2.push_back(occ2);
      t_rl2.push_back(occ2 + ev_ms(lanes.event) + ev_ms(ez) + ev_ms(eo));
    }
    double ref_rl = 0;
    if (reference) {
      time_warm(
          1, [&] { return local_reference(m, flat, vol.dims(), view, order); }, ref_rl);
    }
    const XnetReads x = xnet_reads(m, split, view, order);
    const double M = order + 1;
    const double loads = static_cast<double>(nsamples) * M * M * M * 4;
    const double fused = median(t_fused) + median(t_zero);
    // With --no-reference: "-", not 0.0, where nothing was measured.
    char ref_rl_text[32] = "-", ref_dev_text[32] = "-";
    if (reference) {
      std::snprintf(ref_rl_text, sizeof ref_rl_text, "%.1f", ref_rl);
      std::snprintf(ref_dev_text, sizeof ref_dev_text, "%.1f", ref_rl / fused);
    }
    std::printf(
        "%5.0f %9lld %9lld %7.3f | %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f "
        "%8.2f | "
        "%9.1f "
        "%9s %9s "
        "%7.2f "
        "| "
        "%8.3g %8lld | %7.2f %7.3f %8.2f %8.2f %8.2f | %8.1f %8.1f\n",
        phi, static_cast<long long>(nsamples), static_cast<long long>(m.segments.size()),
        m.utilisation(), median(t_match), median(t_bal), median(t_res), median(t_loc),
        median(t_zero), median(t_fused), median(t_fused1), median(t_occ), median(t_skip),
        median(t_ord), median(t_ord4), ref_match + ref_balance, ref_rl_text, ref_dev_text,
        loads / (median(t_fused) * 1e6), static_cast<double>(x.total_reads()),
        static_cast<long long>(x.max_voxels()), median(t_occ2), active, median(t_match2),
        median(t_bal2), median(t_rl2),
        median(t_match) + median(t_bal) + median(t_occ2) + median(t_ord4) + median(t_zero),
        median(t_match2) + median(t_bal2) + median(t_rl2));
    if (o.kernels) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "\nview %.0f, sum' by kernel (median ms over the runs):", phi);
      kernel_lines += buf;
      double total = 0;
      for (std::size_t k = 0; k < kernel_ms.size(); ++k) {
        const double t = median(kernel_ms[k].second);
        std::snprintf(buf, sizeof buf, "%s %s %.2f", k == 0 ? "" : ",", kernel_ms[k].first.c_str(),
                      t);
        kernel_lines += buf;
        total += t;
      }
      std::snprintf(buf, sizeof buf, " (sum of the medians %.1f)", total);
      kernel_lines += buf;
    }
  }
  std::printf(
      "\nms from profiling events; match/balance: device stages (enqueue_match, enqueue_balance, "
      "all their kernels); ref m+b: "
      "match_reference + balance_reference. ref r+l: serial local_reference (resample + sub-ray "
      "composite); ref/dev: against fused + zero (both - with --no-reference). fused: 8 segments "
      "per work-item in float8 lanes without skipping; fused1: one segment per work-item; occ: the "
      "brick occupancy by a scan "
      "of the voxels (simdvol_occupancy); skip: fused "
      "skipping samples of empty bricks; ordered: skip with the lanes' segment order (the frame "
      "path until the cells were interleaved: simdvol_segment_order + the fused kernel; the same "
      "footprints, checked); ordered4: the same on interleaved cells, the frame's path now "
      "(simdvol_resample_local_v8_il; the same footprints, checked). Gld/s: "
      "gather loads of the fused "
      "kernel per "
      "second. xnet rd: remote stencil reads in all; xnet max: distinct remote voxels of the "
      "busiest PE. occ': the brick occupancy as the frame makes it: what marking adds to the "
      "fused shade + classify (the kernel with marking minus the kernel without, run in turn), "
      "the zero fill and simdvol_occupancy_reach. The frame path, every PE matched: sum = match + "
      "balance + occ' + ordered4 + zero. With EngineOptions::skip_pes (the frame's default): "
      "active = the fraction of PEs whose cell has something in reach; match', balance' = their "
      "matching and balancing (its unpack deferred, as in the engine's direct frames: the order "
      "and the fused kernel read the balanced bounds; `balance` unpacks); rsloc' = occ' + order + "
      "the zero fill of the footprint pixels without a segment (simdvol_zero_uncovered) + the "
      "fused kernel on their segments; sum' = the three.\n");
  if (o.kernels)
    std::printf(
        "%s\n(marks: what marking adds to the fused shade + classify; balance_round: "
        "all the rounds)\n",
        kernel_lines.c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "%s: %s\n", kProgram, e.what());
  return 1;
}
