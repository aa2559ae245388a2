// simdvol-bench-options: kernel build options compared frame by frame.
//
// These machines are shared and noisy: two runs of a bench minutes apart can
// differ by a third, more than most kernel changes gain. This tool renders
// the same frame through one RenderEngine (the layout kept, as a turntable)
// with each variant of SIMDVOL_CL_OPTIONS in turn, frame after frame, so a
// busy spell of the machine falls on every variant alike, and prints each
// variant's median per-stage device times. Every variant's image is compared
// with the first's: a variant that only steers prefetches or code generation
// must give the same image (max_abs_diff 0), and one that does not is named.
//
//   simdvol-bench-options --variant "" --variant "-DSV_VOX_PF=0"
//   simdvol-bench-options --volume data/ch2.nii.gz --classifier mri --view 0,45,0
//                         --variant "" --variant "-DSV_BAL_PF=0"
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/resample.hpp"

namespace {

using namespace simdvol;
using simdvol::bench::Args;
using simdvol::bench::argument_error;
using simdvol::bench::summarize;

const char kUsage[] =
    "usage: simdvol-bench-options [--volume FILE] [--classifier SPEC] [--view THETA,PHI,VARPHI]\n"
    "                             [--size N] [--order 0..3] [--sampling voxel|pixel]\n"
    "                             [--balance-sweeps N] [--frames N]\n"
    "                             --variant OPTIONS [--variant OPTIONS ...]\n"
    "Renders one frame again and again through one RenderEngine, each --variant's OpenCL\n"
    "build options (SIMDVOL_CL_OPTIONS, e.g. \"-DSV_VOX_PF=0\"; \"\" for none) in turn, after a\n"
    "warm-up frame each, and prints per variant the median stage times (device profiling\n"
    "events, ms) over --frames frames (default 20) and the largest difference of its image\n"
    "from the first variant's. Defaults: the 256^3 CT phantom, classifier auto, view\n"
    "20,35,10, 256x256, order 1, voxel sampling, 8 balance sweeps, 8192 PEs, direct\n"
    "compositing.\n";

struct Variant {
  std::string options;
  std::vector<double> shcls, match, balance, rsloc, swap, wall;
  Image first;
  double max_diff = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string volume, classifier = "auto";
  ViewAngles view{20, 35, 10};
  int size = 256, order = 1, sweeps = kBalanceSweeps, frames = 20;
  Sampling sampling = Sampling::voxel;
  std::vector<Variant> variants;
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::fputs(kUsage, stdout);
        return 0;
      } else if (args.is("--volume")) {
        volume = args.name();
      } else if (args.is("--classifier")) {
        classifier = args.value();
      } else if (args.is("--view")) {
        view = args.view();
      } else if (args.is("--size")) {
        size = static_cast<int>(args.integer(2, 4096));
      } else if (args.is("--order")) {
        order = static_cast<int>(args.integer(0, kMaxOrder));
      } else if (args.is("--sampling")) {
        const std::string v = args.value();
        if (v != "voxel" && v != "pixel")
          throw ArgumentError("--sampling", "expected voxel or pixel, not '" + v + "'");
        sampling = v == "voxel" ? Sampling::voxel : Sampling::pixel;
      } else if (args.is("--balance-sweeps")) {
        sweeps = static_cast<int>(args.integer(0, kMaxBalanceSweeps));
      } else if (args.is("--frames")) {
        frames = static_cast<int>(args.integer(1, 10000));
      } else if (args.is("--variant")) {
        variants.push_back(Variant{args.value(), {}, {}, {}, {}, {}, {}, {}, 0});
      } else {
        args.unknown();
      }
    }
    if (variants.empty()) throw ArgumentError("--variant", "give at least one (\"\" for none)");
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-options", e, kUsage);
  }
  // The volume and the classifier now, before the device starts: a bad file
  // or preset is a command-line error (exit 2) too.
  Volume vol;
  RenderOptions opt;
  try {
    if (volume.empty()) {
      vol = shepp_logan(256, 4);
    } else {
      try {
        vol = load_volume(volume);
      } catch (const std::exception& e) {
        throw ArgumentError("--volume", e.what());
      }
      if (vol.voxel_count() == 0) throw ArgumentError("--volume", volume + " is empty");
    }
    if (classifier == "auto") classifier = vol.range().min < -500.0f ? "ct" : "mri";
    try {
      opt.classifier = classifier_from_spec(classifier);
    } catch (const std::exception& e) {
      throw ArgumentError("--classifier", e.what());
    }
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-options", e, kUsage);
  }
  try {
    opt.view = view;
    opt.width = opt.height = size;
    opt.order = order;
    opt.sampling = sampling;
    EngineOptions eo;
    eo.fused = true;
    eo.reuse_layout = true;
    eo.balance_sweeps = sweeps;
    Device dev;
    RenderEngine engine(dev, eo);
    const char* env = std::getenv("SIMDVOL_CL_OPTIONS");
    const std::string base = env ? env : "";
    std::printf(
        "device: %s (%u compute units); %s, classifier %s, view (%g, %g, %g), %dx%d, "
        "order %d, %s sampling, %d sweeps; %d frames per variant after a warm-up, in turn\n",
        dev.info().name.c_str(), dev.info().compute_units,
        volume.empty() ? "256^3 phantom" : volume.c_str(), classifier.c_str(), view.theta, view.phi,
        view.varphi, size, size, order, sampling == Sampling::voxel ? "voxel" : "pixel", sweeps,
        frames);
    for (int f = -1; f < frames; ++f)
      for (Variant& v : variants) {
        const std::string o = base.empty() ? v.options : base + " " + v.options;
        setenv("SIMDVOL_CL_OPTIONS", o.c_str(), 1);
        EngineTimes t;
        Image img = engine.render(vol, opt, &t);
        if (f < 0) {
          if (&v != &variants[0]) v.max_diff = max_abs_diff(variants[0].first, img);
          v.first = std::move(img);
          continue;
        }
        v.shcls.push_back(t.shade_ms + t.classify_ms);
        v.match.push_back(t.match_ms);
        v.balance.push_back(t.balance_ms);
        v.rsloc.push_back(t.resample_local_ms);
        v.swap.push_back(t.swap_ms);
        v.wall.push_back(t.device_wall_ms);
      }
    std::printf("%-32s %8s %8s %8s %8s %8s %8s  %s\n", "variant", "shcls", "match", "bal", "rs+loc",
                "swap", "wall", "image vs first");
    for (const Variant& v : variants) {
      std::printf("%-32s", v.options.empty() ? "(none)" : v.options.c_str());
      for (const auto* s : {&v.shcls, &v.match, &v.balance, &v.rsloc, &v.swap, &v.wall})
        std::printf(" %8.2f", summarize(*s).median);
      std::printf("  max_abs_diff %g\n", v.max_diff);
    }
    std::printf("(median ms over the frames; wall: the frame's device wall time)\n");
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "simdvol-bench-options: %s\n", e.what());
    return 1;
  }
}
