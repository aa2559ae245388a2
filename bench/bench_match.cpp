// simdvol-bench-match: the match and balance stages on the device (OpenCL
// profiling events) against the serial references, for the 256^3 volume at
// 256^2 voxel sampling, and the SIMD utilisation table (mean load / max load)
// before and after balancing. Only the dims and the view matter, so no voxel
// data is made.
//
// The table is printed for both framings (render --fit longest, the
// default, whose 258^2 grid clips an oblique view's corners, and --fit
// diagonal, whose 446^2 grid holds the whole volume), with the smallest
// figures over --random V views (three angles uniform in [-180, 180)
// degrees, seed 5; default 200: the whole run about 2 minutes on 2 cores).
//
//   simdvol-bench-match [--pes N] [--repeat R] [--sweeps S] [--random V] [--no-table]
#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "bench_args.hpp"
#include "bench_common.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/match_cl.hpp"

using namespace simdvol;
using simdvol::bench::Args;
using simdvol::bench::argument_error;
using simdvol::bench::median;
using simdvol::bench::time_warm;

namespace {

struct NamedView {
  const char* name;
  ViewAngles angles;
};

constexpr const char* kUsage =
    "usage: simdvol-bench-match [--pes N] [--repeat R] [--sweeps S] [--random V] [--no-table]\n"
    "  N: a power of two in 1..1048576; R: 1..1000; S: 0..64 (balance sweeps);\n"
    "  V: 0..10000 random views in the utilisation table (default 200)\n";

}  // namespace

int main(int argc, char** argv) {
  int64_t pes = 8192;
  int repeat = 5, sweeps = kBalanceSweeps, nrandom = 200;
  bool random_given = false;
  bool table = true;
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::fputs(kUsage, stdout);
        return 0;
      } else if (args.is("--pes")) {
        pes = args.pes();
      } else if (args.is("--repeat")) {
        repeat = static_cast<int>(args.integer(1, 1000));
      } else if (args.is("--sweeps")) {
        sweeps = static_cast<int>(args.integer(0, kMaxBalanceSweeps));
      } else if (args.is("--random")) {
        nrandom = static_cast<int>(args.integer(0, 10000));
        random_given = true;
      } else if (args.is("--no-table")) {
        table = false;
      } else {
        args.unknown();
      }
    }
    if (random_given && !table)
      throw ArgumentError("--random", "counts the table's views: it does nothing with --no-table");
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-match", e, kUsage);
  }
  try {
    Device dev;
    std::printf("device: %s (%u compute units)\n", dev.info().name.c_str(),
                dev.info().compute_units);
    const Dims3 dims{256, 256, 256};
    const std::array<double, 3> spacing{1, 1, 1};
    const NamedView timed[] = {{"0", {0, 0, 0}}, {"30", {0, 30, 0}}, {"45", {0, 45, 0}}};
    std::printf("\n256^3, 256^2 voxel sampling, %lld PEs, %d balance sweeps, median of %d\n",
                static_cast<long long>(pes), sweeps, repeat);
    std::printf("%-5s %9s %8s %8s %8s %8s %9s %9s %9s %8s %8s\n", "view", "segments", "rows", "pe",
                "scan", "fill", "match", "balance", "m+b", "ref m", "ref b");
    const KdSplit split = kd_split(dims, pes);
    for (const NamedView& nv : timed) {
      const ViewGeometry v = make_view(dims, spacing, nv.angles, 256, 256, Sampling::voxel);
      std::vector<double> st[4], mt, bt;
      int64_t segs = 0;
      for (int r = 0; r < repeat + 1; ++r) {  // the first run builds the kernels
        // Buffers from the previous run's, as a frame's (no page faults).
        Device::ReuseScope reuse(dev);
        DeviceMatching dm = enqueue_match(dev, v, split);
        enqueue_balance(dev, dm, v, split, sweeps);
        dev.finish();
        if (r == 0) continue;
        for (int k = 0; k < 4; ++k) st[k].push_back(event_ns(dm.match_events[k].event) * 1e-6);
        mt.push_back(events_ns(dm.match_events) * 1e-6);
        bt.push_back(events_ns(dm.balance_events) * 1e-6);
        if (r == 1) segs = static_cast<int64_t>(dm.read(dev).segments.size());
      }
      // The serial references timed warm, as simdvol-bench-frame's
      // (bench_common.hpp's time_warm: a warm-up call, then the median of
      // max(1, R / 2) with the freed memory kept in the heap).
      const int ref_runs = std::max(1, repeat / 2);
      double ref_m = 0, ref_b = 0;
      const Matching m = time_warm(
          ref_runs, [&] { return match_reference(v, split); }, ref_m);
      time_warm(
          ref_runs, [&] { return balance_reference(m, v, split, sweeps); }, ref_b);
      std::printf("%-5s %9lld %8.2f %8.3f %8.3f %8.2f %9.2f %9.2f %9.2f %8.1f %8.1f\n", nv.name,
                  static_cast<long long>(segs), median(st[0]), median(st[1]), median(st[2]),
                  median(st[3]), median(mt), median(bt), median(mt) + median(bt), ref_m, ref_b);
    }
    std::printf(
        "(ms from profiling events; ref m / ref b: serial match_reference / "
        "balance_reference, one thread, timed warm: the median of max(1, R / 2) after a "
        "warm-up call)\n");
    if (!table) return 0;

    const NamedView views[] = {{"0", {0, 0, 0}},           {"90", {0, 90, 0}},
                               {"45", {0, 45, 0}},         {"30", {0, 30, 0}},
                               {"30,30,30", {30, 30, 30}}, {"oblique", {37.3, 112.9, -61.4}}};
    // The random views: three angles uniform in [-180, 180) degrees, one
    // fixed seed, the same views for both framings.
    std::vector<ViewAngles> randoms;
    {
      std::mt19937 rng(5);
      std::uniform_real_distribution<double> ang(-180.0, 180.0);
      for (int n = 0; n < nrandom; ++n) {
        const double t = ang(rng), ph = ang(rng);
        randoms.push_back({t, ph, ang(rng)});
      }
    }
    struct Util {
      double before, after, active;
    };
    const auto utilisation = [&](const ViewGeometry& v, int64_t p) {
      const KdSplit s = kd_split(dims, p);
      DeviceMatching dm = enqueue_match(dev, v, s);
      const Matching before = dm.read(dev);
      enqueue_balance(dev, dm, v, s, sweeps);
      const Matching after = dm.read(dev);
      int64_t active = 0;
      for (int64_t l : before.loads) active += l > 0;
      return Util{before.utilisation(), after.utilisation(),
                  static_cast<double>(active) / static_cast<double>(p)};
    };
    for (const Framing framing : {Framing::longest, Framing::diagonal}) {
      const bool whole = framing == Framing::diagonal;
      std::printf(
          "\nSIMD utilisation (mean load / max load), before -> after %d sweeps, %s;\n"
          "active = fraction of PEs with any sample (an upper bound: balancing never\n"
          "creates segments%s)\n",
          sweeps,
          whole ? "--fit diagonal (the whole volume in the 446^2 viewing grid)"
                : "--fit longest (the default framing: a 258^2 viewing grid)",
          whole ? "" : ", and this grid clips the rotated volume's corners");
      std::printf("%-9s", "view");
      for (int64_t p = 512; p <= 8192; p *= 2) std::printf(" %22lld", static_cast<long long>(p));
      std::printf("\n");
      for (const NamedView& nv : views) {
        const ViewGeometry v =
            make_view(dims, spacing, nv.angles, 256, 256, Sampling::voxel, framing);
        std::printf("%-9s", nv.name);
        for (int64_t p = 512; p <= 8192; p *= 2) {
          const Util u = utilisation(v, p);
          std::printf("  %.3f->%.3f (%.3f)", u.before, u.after, u.active);
        }
        std::printf("\n");
      }
      if (randoms.empty()) continue;
      // The random views: the smallest before, after and active over all.
      const std::string rnd = std::to_string(randoms.size()) + " rnd";
      std::printf("%-9s", rnd.c_str());
      for (int64_t p = 512; p <= 8192; p *= 2) {
        Util lo{1.0, 1.0, 1.0};
        for (const ViewAngles& a : randoms) {
          const Util u =
              utilisation(make_view(dims, spacing, a, 256, 256, Sampling::voxel, framing), p);
          lo = {std::min(lo.before, u.before), std::min(lo.after, u.after),
                std::min(lo.active, u.active)};
        }
        std::printf("  %.3f->%.3f (%.3f)", lo.before, lo.after, lo.active);
      }
      std::printf("\n(%s: the smallest of each figure over the random views)\n", rnd.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "simdvol-bench-match: %s\n", e.what());
    return 1;
  }
  return 0;
}
