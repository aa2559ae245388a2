// simdvol-bench-shade: the shade and classify stages on the PE array.
//
//   simdvol-bench-shade [--size N | --volume FILE] [--pes P] [--runs R]
//                       [--classifier NAME] [--no-reference] [--sweep]
//
// The N^3 Shepp-Logan CT phantom (default 256), or a volume file (e.g.
// brainsmall.den with --classifier volpack), on P PEs (default 8192), laid
// out once; then, after a warm-up launch of every kernel (the first launch of
// each local size compiles), R runs (default 7) of each variant, interleaved,
// reporting the median device time (profiling events) and the median wall
// time (enqueue + clFinish). Also: the serial reference's shade + classify on
// the same volume (each timed once after a warm-up: time_warm), bytes moved
// per stage against the machine's triad bandwidth measured here (two threads,
// 256 MiB per array), and flat (x-fastest, non-PE-major) variants for the
// PE-major/flat ratio (the fused one's kernel takes rows of a multiple of 16
// voxels: for other widths its ratio is n/a, and --sweep's scalar flat
// fused kernel gives one). The in-place classify (the engine's two-launch path)
// writes over a copy of the shading made before each run (untimed). --sweep
// also times the work-group sizes 64/256/1024 (16/64/256 chunks of 16 voxels
// for the float16 kernels), the float16 kernels with non-temporal stores, and
// the scalar kernels (shade decompositions, classify, fused, flat fused) that
// the float16 defaults replaced.
//
// PoCL compiles kernels into its cache (POCL_CACHE_DIR, default
// ~/.cache/pocl); the environment is left to the user. Timings on these
// shared 2-core machines vary up to 2x from run to run: compare variants
// within one run.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/io.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;
using namespace simdvol::bench;

namespace {

struct Result {
  std::string name;
  double device_ms = 0, wall_ms = 0, bytes = 0;
};

// Runs `enqueue` (which returns the events whose device times add up) R
// times with a finish after each, returns medians. `prepare` (if any) runs
// before each, untimed.
Result time_variant(Device& dev, const std::string& name, int runs, double bytes,
                    const std::function<std::vector<cl::Event>()>& enqueue,
                    const std::function<void()>& prepare) {
  std::vector<double> d, w;
  for (int r = 0; r < runs; ++r) {
    if (prepare) {
      prepare();
      dev.finish();
    }
    const auto t0 = Clock::now();
    std::vector<cl::Event> ev = enqueue();
    dev.finish();
    w.push_back(ms_since(t0));
    double ns = 0;
    for (auto& e : ev) ns += static_cast<double>(event_ns(e));
    d.push_back(ns * 1e-6);
  }
  return {name, median(d), median(w), bytes};
}

constexpr const char* kUsage =
    "usage: simdvol-bench-shade [--size N | --volume FILE] [--pes P] [--runs R]\n"
    "                           [--classifier NAME] [--no-reference] [--sweep]\n"
    "  N: 8..1024 (the N^3 phantom); FILE: a 3-D volume instead of the phantom (.den, .nrrd,\n"
    "  .nhdr, .nii, .nii.gz, .hdr/.img, .mha, .mhd, .mgh, .mgz, .mnc, DICOM: a .dcm, a file of\n"
    "  any name or a directory of one series); P: a power of two in 1..1048576; R: 1..1000;\n"
    "  NAME: a classifier preset or file (default ct)\n";

}  // namespace

int main(int argc, char** argv) {
  int size = 256, runs = 7;
  int64_t pes = 8192;
  std::string cname = "ct";
  std::string volume_file;
  bool size_given = false;
  Classifier cls;
  std::optional<Volume> loaded;
  bool reference = true, sweep = false;
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::fputs(kUsage, stdout);
        return 0;
      } else if (args.is("--size")) {
        size = static_cast<int>(args.integer(8, 1024));
        size_given = true;
      } else if (args.is("--volume")) {
        volume_file = args.name();
      } else if (args.is("--pes")) {
        pes = args.pes();
      } else if (args.is("--runs")) {
        runs = static_cast<int>(args.integer(1, 1000));
      } else if (args.is("--classifier")) {
        cname = args.value();
      } else if (args.is("--no-reference")) {
        reference = false;
      } else if (args.is("--sweep")) {
        sweep = true;
      } else {
        args.unknown();
      }
    }
    try {  // a preset or a file, loaded now rather than after the device starts
      cls = classifier_from_spec(cname);
    } catch (const std::exception& e) {
      throw ArgumentError("--classifier", e.what());
    }
    if (!volume_file.empty()) {
      if (size_given) throw ArgumentError("--volume", "give either --size or --volume, not both");
      try {
        loaded.emplace(load_volume(volume_file));
      } catch (const std::exception& e) {
        throw ArgumentError("--volume", e.what());
      }
      if (loaded->voxel_count() == 0) throw ArgumentError("--volume", volume_file + " is empty");
    }
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-shade", e, kUsage);
  }
  try {
    Device dev;
    std::printf("device: %s (%s), %u compute units\n", dev.info().name.c_str(),
                dev.info().version.c_str(), dev.info().compute_units);
    auto t0 = Clock::now();
    const Volume vol = loaded ? std::move(*loaded) : shepp_logan(size);
    if (loaded)
      std::printf("volume: %s, %lld x %lld x %lld, %lld PEs, classifier %s\n", volume_file.c_str(),
                  static_cast<long long>(vol.nx()), static_cast<long long>(vol.ny()),
                  static_cast<long long>(vol.nz()), static_cast<long long>(pes), cname.c_str());
    else
      std::printf("volume: Shepp-Logan %d^3 (%.0f ms to build), %lld PEs, classifier %s\n", size,
                  ms_since(t0), static_cast<long long>(pes), cname.c_str());
    const double voxels = static_cast<double>(vol.voxel_count());
    const int image = static_cast<int>(std::max({vol.nx(), vol.ny(), vol.nz()}));
    const ViewGeometry view = make_view(vol, {30, 45, 10}, image, image, Sampling::voxel);
    const ShadeParams shp{};
    const sv_shade_params sp = shade_params(make_shade_frame(vol, view, shp), shp);
    const sv_classify_params cp = classify_params(cls, classify_range(vol, cls), view.step);

    const double triad = triad_gbs(std::size_t(256) << 20);
    std::printf("triad bandwidth (host, %u threads, 3 x 256 MiB): %.1f GB/s\n\n",
                std::max(1u, std::thread::hardware_concurrency()), triad);

    PeArray array(dev, pe_grid(pes));
    t0 = Clock::now();
    cl::Event e_layout;
    CellBuffer cells = array.layout(vol, 1, LayoutKernel::rows, &e_layout);
    const VoxelLayout L = make_voxel_layout(cells.layout());
    VoxelBuffer shading(dev, L), rgba(dev, L);
    // The frame's own kernel writes interleaved cells (a position's RGBA in
    // 16 bytes, for the resample's corner loads).
    VoxelBuffer rgba_il(dev, make_voxel_layout(cells.layout(), true));
    const std::size_t n = vol.voxel_count();
    cl::Buffer flat_vol = dev.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, n * sizeof(float),
                                     const_cast<float*>(vol.data().data()), "flat volume");
    cl::Buffer flat_rgba = dev.buffer(CL_MEM_READ_WRITE, n * 16, nullptr, "flat rgba");
    // Flat variants: with one PE the voxel cells are the flat volume (planar),
    // so "flat classify" is the classify kernel on a 1-PE voxel buffer; the
    // flat fused kernel reads the flat volume itself (clamped neighbours).
    PeArray one(dev, pe_grid(1));
    CellBuffer cells1 = one.layout(vol, 1);
    const VoxelLayout L1 = make_voxel_layout(cells1.layout());
    VoxelBuffer shading1(dev, L1), rgba1(dev, L1);
    // In-place classify overwrites its input: each run first copies the
    // shading into these (untimed).
    VoxelBuffer work(dev, L), work1(dev, L1);
    // The frame's fused kernel also marks the brick occupancy for
    // empty-space skipping (zeroed before each run, untimed).
    DeviceOccupancy occ = make_occupancy(dev, L, 1);
    Defines defs = classify_defines(cp);
    for (auto& d : shade_defines(sp)) defs.push_back(std::move(d));
    cl::Buffer cbuf = dev.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof cp,
                                 const_cast<sv_classify_params*>(&cp), "classify parameters");
    cl::Buffer sbuf = dev.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof sp,
                                 const_cast<sv_shade_params*>(&sp), "shade parameters");
    const std::string fused_src = program_source("shade", defs, {"classify"});
    cl::Program fused_prog = dev.build(fused_src);
    cl::Kernel k_flat_fused(fused_prog, "simdvol_shade_classify_flat");
    cl::Kernel k_flat_fused16(fused_prog, "simdvol_shade_classify_flat16");
    const cl_int4 dims{{static_cast<cl_int>(vol.nx()), static_cast<cl_int>(vol.ny()),
                        static_cast<cl_int>(vol.nz()), 0}};
    set_args(k_flat_fused, "flat fused", flat_vol, flat_rgba, dims, sbuf, cbuf);
    set_args(k_flat_fused16, "flat fused float16", flat_vol, flat_rgba, dims, sbuf, cbuf);
    const std::size_t lx = std::min<std::size_t>(64, round_up(vol.nx(), 8));
    const cl::NDRange flat3(vol.nx(), vol.ny(), vol.nz()), flat3_local(lx, 256 / lx, 1);
    // float16 flat kernel: 16 voxels of a row per work-item (nx % 16 == 0).
    const bool flat16_ok = vol.nx() % 16 == 0;
    const std::size_t l16 = std::clamp<std::size_t>(vol.nx() / 16, 1, 16), ly16 = 64 / l16;
    const cl::NDRange flat16(round_up(std::max<std::size_t>(1, vol.nx() / 16), l16),
                             round_up(vol.ny(), ly16), vol.nz()),
        flat16_local(l16, ly16, 1);
    enqueue_shade(dev, cells1, sp, shading1);
    dev.finish();
    std::printf("set-up (layout, buffers, builds): %.0f ms; layout kernel %.2f ms\n", ms_since(t0),
                event_ns(e_layout) * 1e-6);

    const double cells_bytes = static_cast<double>(cells.layout().bytes());
    const double vox_bytes = static_cast<double>(L.bytes());
    const double flat4 = 16.0 * voxels;
    struct Variant {
      std::string name;
      double bytes;
      std::function<std::vector<cl::Event>()> run;
      std::function<void()> prepare = {};
    };
    auto copy_into = [&](const VoxelBuffer& from, VoxelBuffer& to) {
      return [&dev, &from, &to] {
        cl_check(
            dev.queue().enqueueCopyBuffer(from.buffer(), to.buffer(), 0, 0, from.layout().bytes()),
            "clEnqueueCopyBuffer(shading)");
      };
    };
    // The marking variants' untimed preparation: the occupancy zeroed.
    auto zero_occupancy = [&] {
      cl_check(dev.queue().enqueueFillBuffer(occ.occupied, cl_uint(0), 0,
                                             static_cast<std::size_t>(occ.count()) * 4),
               "clEnqueueFillBuffer(brick occupancy)");
    };
    std::vector<Variant> variants = {
        {"shade", cells_bytes + vox_bytes,
         [&] { return std::vector{enqueue_shade(dev, cells, sp, shading)}; }},
        {"classify", 2 * vox_bytes,
         [&] { return std::vector{enqueue_classify(dev, shading, cp, rgba)}; }},
        {"shade+classify (2 launches)", cells_bytes + 3 * vox_bytes,
         [&] {
           return std::vector{enqueue_shade(dev, cells, sp, shading),
                              enqueue_classify(dev, shading, cp, rgba)};
         }},
        {"classify (in place)", 2 * vox_bytes,
         [&] { return std::vector{enqueue_classify_in_place(dev, work, cp)}; },
         copy_into(shading, work)},
        {"shade+classify in place (2 launches)", cells_bytes + 3 * vox_bytes,
         [&] {
           return std::vector{enqueue_shade(dev, cells, sp, work),
                              enqueue_classify_in_place(dev, work, cp)};
         }},
        {"shade+classify fused", cells_bytes + vox_bytes,
         [&] { return std::vector{enqueue_shade_classify(dev, cells, sp, cp, rgba)}; }},
        {"shade+classify fused, marking", cells_bytes + vox_bytes,
         [&] {
           return std::vector{
               enqueue_shade_classify(dev, cells, sp, cp, rgba, ShadeKernel::vec16, &occ)};
         },
         zero_occupancy},
        {"shade+classify fused, interleaved, marking (the frame's)", cells_bytes + vox_bytes,
         [&] {
           return std::vector{
               enqueue_shade_classify(dev, cells, sp, cp, rgba_il, ShadeKernel::vec16, &occ)};
         },
         zero_occupancy},
        {"flat classify (1 PE)", 2 * flat4,
         [&] { return std::vector{enqueue_classify(dev, shading1, cp, rgba1)}; }},
        {"flat classify in place (1 PE)", 2 * flat4,
         [&] { return std::vector{enqueue_classify_in_place(dev, work1, cp)}; },
         copy_into(shading1, work1)},
        {"flat shade (1 PE)", 4.0 * voxels + flat4,
         [&] { return std::vector{enqueue_shade(dev, cells1, sp, shading1)}; }},
    };
    if (flat16_ok)
      variants.push_back({"flat shade+classify fused", 4.0 * voxels + flat4, [&] {
                            return std::vector{dev.run(k_flat_fused16, "flat fused float16", flat16,
                                                       flat16_local, LocalSize::at_most)};
                          }});
    if (sweep) {
      // The float16 kernels with every store non-temporal (SV_NT). By
      // default only the fused kernel's into voxel cells stored before are
      // (kc_mode & 8): its variants above after their first run.
      auto nt = [&](auto enqueue) {
        return [enqueue] {
          setenv("SIMDVOL_NT_STORES", "1", 1);
          std::vector<cl::Event> e{enqueue()};
          unsetenv("SIMDVOL_NT_STORES");
          return e;
        };
      };
      variants.push_back({"shade (NT stores)", cells_bytes + vox_bytes,
                          nt([&] { return enqueue_shade(dev, cells, sp, shading); })});
      variants.push_back({"classify (NT stores)", 2 * vox_bytes,
                          nt([&] { return enqueue_classify(dev, shading, cp, rgba); })});
      variants.push_back({"shade+classify fused (NT stores)", cells_bytes + vox_bytes,
                          nt([&] { return enqueue_shade_classify(dev, cells, sp, cp, rgba); })});
      // The scalar kernels (one work-item per voxel or per row), which PoCL
      // 3.1 did not vectorise here: the comparison for the float16 defaults.
      variants.push_back(
          {"shade (scalar rows)", cells_bytes + vox_bytes,
           [&] { return std::vector{enqueue_shade(dev, cells, sp, shading, ShadeKernel::rows)}; }});
      variants.push_back({"classify (scalar)", 2 * vox_bytes, [&] {
                            return std::vector{
                                enqueue_classify(dev, shading, cp, rgba, ClassifyKernel::scalar)};
                          }});
      variants.push_back({"shade+classify fused (scalar)", cells_bytes + vox_bytes, [&] {
                            return std::vector{enqueue_shade_classify(dev, cells, sp, cp, rgba,
                                                                      ShadeKernel::range3d)};
                          }});
      variants.push_back({"flat shade+classify fused (scalar)", 4.0 * voxels + flat4, [&] {
                            return std::vector{dev.run(k_flat_fused, "flat fused", flat3,
                                                       flat3_local, LocalSize::at_most)};
                          }});
      variants.push_back({"shade (1-D, divisions)", cells_bytes + vox_bytes, [&] {
                            return std::vector{
                                enqueue_shade(dev, cells, sp, shading, ShadeKernel::voxel)};
                          }});
      variants.push_back({"shade (3-D range)", cells_bytes + vox_bytes, [&] {
                            return std::vector{
                                enqueue_shade(dev, cells, sp, shading, ShadeKernel::range3d)};
                          }});
    }
    // The flat side of the comparison must compute the same voxels: its
    // output against the PE-major fused kernel's, gathered, bit for bit.
    if (flat16_ok) {
      enqueue_shade_classify(dev, cells, sp, cp, rgba);
      std::vector<Rgba> pe(n), flat(n);
      gather_rgba(dev, rgba, pe.data());
      dev.run(k_flat_fused16, "flat fused float16", flat16, flat16_local, LocalSize::at_most);
      std::vector<float> planes(4 * n);
      cl_check(dev.queue().enqueueReadBuffer(flat_rgba, CL_TRUE, 0, n * 16, planes.data()),
               "clEnqueueReadBuffer(flat rgba)");
      std::size_t differ = 0;
      for (std::size_t v = 0; v < n; ++v) {
        const Rgba f{planes[v], planes[n + v], planes[2 * n + v], planes[3 * n + v]};
        differ += std::memcmp(&f, &pe[v], sizeof f) != 0;
      }
      std::printf(
          "flat fused float16 against the PE-major fused kernel: %zu of %zu voxels differ\n",
          differ, n);
      if (differ) throw Error("the flat fused kernel's voxels differ from the PE-major kernel's");
    }
    std::vector<const char*> wgs = {"256"};
    if (sweep) wgs = {"64", "256", "1024"};
    const char* old_wgs = std::getenv("SIMDVOL_VOXEL_WGS");
    const std::string saved = old_wgs ? old_wgs : "";

    std::vector<std::vector<Result>> results(wgs.size());
    for (std::size_t w = 0; w < wgs.size(); ++w) {
      setenv("SIMDVOL_VOXEL_WGS", wgs[w], 1);
      for (auto& v : variants) {  // warm-up: compiles each local size
        if (v.prepare) v.prepare();
        v.run();
        dev.finish();
      }
      results[w].resize(variants.size());
    }
    // Interleave: one run of every (wgs, variant) per round.
    std::vector<std::vector<std::vector<double>>> dms(wgs.size()), wms(wgs.size());
    for (std::size_t w = 0; w < wgs.size(); ++w) {
      dms[w].resize(variants.size());
      wms[w].resize(variants.size());
    }
    for (int r = 0; r < runs; ++r)
      for (std::size_t w = 0; w < wgs.size(); ++w) {
        setenv("SIMDVOL_VOXEL_WGS", wgs[w], 1);
        for (std::size_t i = 0; i < variants.size(); ++i) {
          const Result one = time_variant(dev, variants[i].name, 1, variants[i].bytes,
                                          variants[i].run, variants[i].prepare);
          dms[w][i].push_back(one.device_ms);
          wms[w][i].push_back(one.wall_ms);
        }
      }
    if (old_wgs)
      setenv("SIMDVOL_VOXEL_WGS", saved.c_str(), 1);
    else
      unsetenv("SIMDVOL_VOXEL_WGS");

    double ref_ms = 0;
    if (reference) {
      // Warm, as the device's runs (bench_common.hpp's time_warm).
      double shade_ref = 0, cls_ref = 0;
      const auto s = time_warm(
          1, [&] { return shade(vol, view, shp); }, shade_ref);
      time_warm(
          1, [&] { return classify(vol, s, cls, view.step); }, cls_ref);
      ref_ms = shade_ref + cls_ref;
      std::printf(
          "serial reference: shade %.0f ms, classify %.0f ms, total %.0f ms "
          "(%.1f Mvoxel/s)\n",
          shade_ref, cls_ref, ref_ms, voxels / (ref_ms * 1e-3) / 1e6);
    }

    std::printf("\n%-36s %6s %10s %10s %9s %9s %8s %9s\n", "variant", "wgs", "device ms", "wall ms",
                "Gvox/s", "GB/s", "%triad", "x serial");
    double pe_cls = 0, flat_cls = 0, pe_cls_ip = 0, flat_cls_ip = 0, pe_fused = 0, flat_fused = 0,
           pe_fused_s = 0, flat_fused_s = 0;
    for (std::size_t w = 0; w < wgs.size(); ++w)
      for (std::size_t i = 0; i < variants.size(); ++i) {
        const double d = median(dms[w][i]), wall = median(wms[w][i]);
        const double gbs = variants[i].bytes / (d * 1e-3) / 1e9;
        const bool both = variants[i].name.find("shade+classify") != std::string::npos;
        char ratio[32] = "";
        if (both && ref_ms > 0) std::snprintf(ratio, sizeof ratio, "%.1f", ref_ms / d);
        std::printf("%-36s %6s %10.2f %10.2f %9.2f %9.1f %7.0f%% %9s\n", variants[i].name.c_str(),
                    wgs[w], d, wall, voxels / (d * 1e-3) / 1e9, gbs, 100.0 * gbs / triad, ratio);
        if (std::strcmp(wgs[w], "256") == 0) {
          if (variants[i].name == "classify") pe_cls = d;
          if (variants[i].name == "flat classify (1 PE)") flat_cls = d;
          if (variants[i].name == "classify (in place)") pe_cls_ip = d;
          if (variants[i].name == "flat classify in place (1 PE)") flat_cls_ip = d;
          if (variants[i].name == "shade+classify fused") pe_fused = d;
          if (variants[i].name == "flat shade+classify fused") flat_fused = d;
          if (variants[i].name == "shade+classify fused (scalar)") pe_fused_s = d;
          if (variants[i].name == "flat shade+classify fused (scalar)") flat_fused_s = d;
        }
      }
    // The flat fused ratio only where its kernel ran (nx a multiple of 16):
    // not a 0.00 that reads as the goal met.
    char fused_ratio[160];
    if (flat16_ok)
      std::snprintf(fused_ratio, sizeof fused_ratio, "%.2f (goal <= 1.5)", pe_fused / flat_fused);
    else
      std::snprintf(fused_ratio, sizeof fused_ratio,
                    "n/a (the flat fused kernel takes rows of a multiple of 16 voxels; this "
                    "volume's rows are %lld%s)",
                    static_cast<long long>(vol.nx()),
                    sweep ? "" : "; --sweep compares the scalar kernels");
    std::printf("\nPE-major / flat: classify %.2f, in place %.2f, fused shade+classify %s\n",
                pe_cls / flat_cls, pe_cls_ip / flat_cls_ip, fused_ratio);
    if (pe_fused_s > 0 && flat_fused_s > 0)
      std::printf("PE-major / flat, scalar kernels: fused shade+classify %.2f\n",
                  pe_fused_s / flat_fused_s);
    std::printf(
        "bytes counted: reads + writes of each kernel's buffers (cells with halo: "
        "%.0f MiB, voxel cells: %.0f MiB); write-allocate traffic not counted (out of place "
        "a classified voxel moves 48 bytes, in place 32); nominal: "
        "classify reads only the value plane of a chunk that is empty before the mixture, so "
        "its GB/s can pass the triad\n",
        cells_bytes / 1048576.0, vox_bytes / 1048576.0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "simdvol-bench-shade: %s\n", e.what());
    return 1;
  }
  return 0;
}
