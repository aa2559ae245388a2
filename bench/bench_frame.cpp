// simdvol-bench-frame: the per-frame stages after classification on the PE
// array (issue 4): match, balance, resample, local and the fused
// resample + local, ms per stage from the profiling events, against the
// serial reference doing the same work in the same run.
//
//   simdvol-bench-frame [--size N] [--pes P] [--order K] [--runs R]
//                       [--views 0,30,45] [--no-reference]
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
// the X-Net reads of the reference (remote stencil voxels).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;
using Clock = std::chrono::steady_clock;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}
double ev_ms(const cl::Event& e) {
  return static_cast<double>(event_ns(e)) * 1e-6;
}

int usage(const char* msg) {
  std::fprintf(stderr,
               "%s\nusage: simdvol-bench-frame [--size N] [--pes P] [--order K] [--runs R] "
               "[--views a,b,c] [--no-reference]\n",
               msg);
  return 2;
}

}  // namespace

int main(int argc, char** argv) try {
  int size = 256, runs = 5, order = 1;
  int64_t pes = 8192;
  bool reference = true;
  std::vector<double> views{0, 30, 45};
  for (int i = 1; i < argc; ++i) {
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) throw ArgumentError(argv[i], "needs a value");
      return argv[++i];
    };
    if (!std::strcmp(argv[i], "--size")) {
      size = std::atoi(next());
    } else if (!std::strcmp(argv[i], "--pes")) {
      pes = std::atoll(next());
    } else if (!std::strcmp(argv[i], "--order")) {
      order = std::atoi(next());
    } else if (!std::strcmp(argv[i], "--runs")) {
      runs = std::atoi(next());
    } else if (!std::strcmp(argv[i], "--views")) {
      views.clear();
      std::stringstream ss(next());
      std::string tok;
      while (std::getline(ss, tok, ',')) views.push_back(std::stod(tok));
    } else if (!std::strcmp(argv[i], "--no-reference")) {
      reference = false;
    } else {
      return usage(("unknown argument " + std::string(argv[i])).c_str());
    }
  }
  if (size < 2 || runs < 1 || order < 0 || order > 3 || views.empty()) return usage("bad value");

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
  std::vector<Rgba> flat;
  std::printf(
      "volume %d^3 Shepp-Logan (s = 4), preset ct, %lld PEs, cell %lldx%lldx%lld, order %d, "
      "%d runs (median)\n\n",
      size, static_cast<long long>(pes), static_cast<long long>(L.cell()[0]),
      static_cast<long long>(L.cell()[1]), static_cast<long long>(L.cell()[2]), order, runs);
  std::printf("%5s %9s %9s %7s | %8s %8s %8s %8s %8s %8s %8s | %9s %9s %9s %7s | %8s %8s\n", "view",
              "samples", "segments", "util", "match", "balance", "resample", "local", "zero",
              "fused", "fused1", "ref m+b", "ref r+l", "ref/dev", "Gld/s", "xnet rd", "xnet max");
  for (const double phi : views) {
    const ViewAngles angles{0.0, phi, 0.0};
    const ViewGeometry view = make_view(vol, angles, size, size, Sampling::voxel);
    // Classified voxels for this view (the shading depends on the view).
    {
      const sv_shade_params sp = shade_params(make_shade_frame(vol, view, shp), shp);
      const sv_classify_params cp = classify_params(cls, ValueRange{}, view.step);
      enqueue_shade_classify(device, cells, sp, cp, rgba);
      flat.resize(vol.voxel_count());
      gather_rgba(device, rgba, flat.data());
    }
    const KdSplit split = kd_split(vol.dims(), pes);
    auto t0 = Clock::now();
    const Matching m0 = match_reference(view, split);
    const double ref_match = ms_since(t0);
    t0 = Clock::now();
    const Matching m = balance_reference(m0, view, split);
    const double ref_balance = ms_since(t0);

    // Device match + balance (warm-up, then timed with the other stages).
    std::vector<double> t_match, t_bal;
    for (int r = 0; r <= runs; ++r) {
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
    std::vector<double> t_res, t_loc, t_zero, t_fused, t_fused1;
    for (int r = 0; r < runs; ++r) {
      const cl::Event ez = enqueue_zero_footprints(device, fp);
      const cl::Event er = enqueue_resample(device, segs, soff, tables, rgba, order, samples);
      const cl::Event el = enqueue_local(device, segs, soff, samples, fp);
      const cl::Event ez2 = enqueue_zero_footprints(device, fp);
      const cl::Event ef = enqueue_resample_local(device, segs, tables, rgba, order, fp);
      const cl::Event ef1 =
          enqueue_resample_local(device, segs, tables, rgba, order, fp, LocalKernel::segment);
      device.finish();
      t_fused1.push_back(ev_ms(ef1));
      t_zero.push_back(0.5 * (ev_ms(ez) + ev_ms(ez2)));
      t_res.push_back(ev_ms(er));
      t_loc.push_back(ev_ms(el));
      t_fused.push_back(ev_ms(ef));
    }
    double ref_rl = 0;
    if (reference) {
      t0 = Clock::now();
      const std::vector<Rgba> comp = local_reference(m, flat, vol.dims(), view, order);
      ref_rl = ms_since(t0);
    }
    const XnetReads x = xnet_reads(m, split, view, order);
    const double M = order + 1;
    const double loads = static_cast<double>(nsamples) * M * M * M * 4;
    const double fused = median(t_fused) + median(t_zero);
    std::printf(
        "%5.0f %9lld %9lld %7.3f | %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f | %9.1f %9.1f %9.1f "
        "%7.2f "
        "| "
        "%8.3g %8lld\n",
        phi, static_cast<long long>(nsamples), static_cast<long long>(m.segments.size()),
        m.utilisation(), median(t_match), median(t_bal), median(t_res), median(t_loc),
        median(t_zero), median(t_fused), median(t_fused1), ref_match + ref_balance, ref_rl,
        reference ? ref_rl / fused : 0.0, loads / (median(t_fused) * 1e6),
        static_cast<double>(x.total_reads()), static_cast<long long>(x.max_voxels()));
  }
  std::printf(
      "\nms from profiling events; match/balance: device stages (enqueue_match, enqueue_balance, "
      "all their kernels); ref m+b: "
      "match_reference + balance_reference. ref r+l: serial local_reference (resample + sub-ray "
      "composite); ref/dev: against fused + zero. fused: 8 segments per work-item in float8 lanes "
      "(the frame path); fused1: one segment per work-item. Gld/s: gather loads of the fused "
      "kernel per "
      "second. xnet rd: remote stencil reads in all; xnet max: distinct remote voxels of the "
      "busiest PE.\n");
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "simdvol-bench-frame: %s\n", e.what());
  return 1;
}
