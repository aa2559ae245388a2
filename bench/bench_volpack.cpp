// simdvol-bench-volpack: VolPack (Debian's libvolpack1-dev 1.0b3) as a peer
// renderer beside simdvol (issue 6, item 2). brainsmall.den with VolPack's
// example pipeline (makevolume.c: vpVolumeNormals; classifyvolume.c: density
// and gradient ramps, minimum voxel opacity 0.05; rendervolume.c: shading
// table, light, depth cueing, view rotate y 130 / x -15, 256x256, maximum ray
// opacity 0.95), rendered
//   - by VolPack: vpBruteForceRender (its debugging ray caster), vpRenderRawVolume
//     (no octree: rendervolume with no flag), vpRenderClassifiedVolume after
//     a one-time vpClassifyVolume; per frame vpShadeTable + the render;
//   - by simdvol: the serial reference (render_reference, order 3, direct
//     compositing) and the OpenCL engine (8192 PEs, order 1: one RenderEngine
//     for each image size, kept across its frames, with the fused shade +
//     classify and the volume's layout made once, as simdvol-bench and
//     `simdvol render --frames` run it),
//     with the "volpack" classifier preset, the example's Phong constants and
//     light, the view mapped exactly from VolPack's model matrix
//     (volpack_peer.hpp) and its depth cue fitted.
// Per renderer: ms per frame (warm: one warm-up render, then the median, min
// and max of --runs renders per frame), the ratio to VolPack's classified
// mode, the PSNR against the reference's image; and a "matched" PSNR with
// what VolPack can switch off switched off in both (depth cueing, minimum
// voxel opacity, early ray termination). What cannot be matched is printed.
//
//   simdvol-bench-volpack [--data FILE] [--sizes 256,512] [--runs N]
//                         [--ref-runs N] [--bf-runs N] [--turntable F]
//                         [--order K] [--cl-order K] [--pes P]
//                         [--no-opencl] [--no-brute-force] [--no-matched]
//                         [--pixel-centre C] [--json FILE]
//                         [--write-images DIR] [--quick]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../host/core/output_checks.hpp"
#include "bench_args.hpp"
#include "bench_common.hpp"
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/error.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/render.hpp"
#include "volpack_peer.hpp"

using namespace simdvol;
using simdvol::bench::Args;
using simdvol::bench::argument_error;
using simdvol::bench::check_output_dir;
using simdvol::bench::check_output_file;
using simdvol::bench::make_output_dir;
namespace vp = simdvol::volpack;
using simdvol::bench::Clock;
using simdvol::bench::ms_since;
using simdvol::bench::summarize;
using simdvol::bench::Summary;

namespace {

struct Row {
  std::string name;
  std::vector<double> ms;  // per timed call (median, min, max: bench_common's summarize)
  std::vector<double> psnr, psnr_matched;  // per frame
  double first_ms = 0.0;                   // first (cold) call
};

double mean(const std::vector<double>& v) {
  if (v.empty()) return std::nan("");
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}
double min_of(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::min_element(v.begin(), v.end());
}

using Json = nlohmann::json;
// A figure, or null where there is none (NaN is not JSON).
Json json_num(double x) {
  return std::isfinite(x) ? Json(x) : Json(nullptr);
}

constexpr const char* kUsage =
    "usage: simdvol-bench-volpack [--data FILE] [--sizes 256,512] [--runs N] [--ref-runs N]\n"
    "                             [--bf-runs N] [--turntable F] [--order K] [--cl-order K]\n"
    "                             [--pes P] [--no-opencl] [--no-brute-force] [--no-matched]\n"
    "                             [--pixel-centre C] [--json FILE] [--write-images DIR] [--quick]\n"
    "  sizes: 8..4096; runs: 0..1000 (0: the warm-up render only); F: 1..720 frames;\n"
    "  K: 0..3; P: a power of two in 1..1048576; C: 0..1 (pixels); FILE: brainsmall.den\n"
    "  (default: in $SIMDVOL_DATA_DIR where set, else in the source tree's data/)\n";

// Times `render` (returning an image): one warm-up call (its time kept as
// the cold time, its image returned), then `runs` timed calls.
Image timed(Row& row, int runs, const std::function<Image()>& render) {
  auto t0 = Clock::now();
  Image img = render();
  const double first = ms_since(t0);
  if (row.first_ms == 0.0) row.first_ms = first;
  for (int r = 0; r < runs; ++r) {
    t0 = Clock::now();
    Image again = render();
    row.ms.push_back(ms_since(t0));
  }
  if (runs == 0) row.ms.push_back(first);
  return img;
}

}  // namespace

int main(int argc, char** argv) try {
  simdvol::remove_temporary_files_on_signals();
  std::filesystem::path data = simdvol::bench::data_dir() / "brainsmall.den";
  std::vector<int> sizes{256, 512};
  int runs = 5, ref_runs = 3, bf_runs = 2, frames = 1, order = 3, cl_order = 1;
  int64_t pes = 8192;
  bool opencl = true, brute = true, matched = true;
  double pixel_centre = 0.0;
  std::optional<std::filesystem::path> json, images;
  bool quick = false;
  std::optional<std::vector<int>> sizes_given;
  std::optional<int> runs_given, ref_runs_given, bf_runs_given;
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::printf("simdvol-bench-volpack: VolPack beside simdvol on brainsmall.den\n%s", kUsage);
        return 0;
      } else if (args.is("--data")) {
        data = args.value();
        if (!std::filesystem::exists(data))
          throw ArgumentError(args.option(), "'" + data.string() + "' does not exist");
      } else if (args.is("--sizes")) {
        sizes_given.emplace();
        for (int64_t v : args.int_list(8, 4096)) sizes_given->push_back(static_cast<int>(v));
      } else if (args.is("--runs")) {
        runs_given = static_cast<int>(args.integer(0, 1000));
      } else if (args.is("--ref-runs")) {
        ref_runs_given = static_cast<int>(args.integer(0, 1000));
      } else if (args.is("--bf-runs")) {
        bf_runs_given = static_cast<int>(args.integer(0, 1000));
      } else if (args.is("--turntable")) {
        frames = static_cast<int>(args.integer(1, 720));
      } else if (args.is("--order")) {
        order = static_cast<int>(args.integer(0, 3));
      } else if (args.is("--cl-order")) {
        cl_order = static_cast<int>(args.integer(0, 3));
      } else if (args.is("--pes")) {
        pes = args.pes();
      } else if (args.is("--no-opencl")) {
        opencl = false;
      } else if (args.is("--no-brute-force")) {
        brute = false;
      } else if (args.is("--no-matched")) {
        matched = false;
      } else if (args.is("--pixel-centre")) {
        pixel_centre = args.number(0, 1);
      } else if (args.is("--json")) {
        json = args.value();
        check_output_file(*json, args.option());  // (and against --data below)
      } else if (args.is("--write-images")) {
        images = args.name();
        check_output_dir(*images, args.option());
      } else if (args.is("--quick")) {
        quick = true;
      } else {
        args.unknown();
      }
    }
    // --quick's values, then the ones given, whatever their order (--sizes
    // 16 --quick rendered 256 x 256).
    if (quick) sizes = {256}, runs = 2, ref_runs = 1, bf_runs = 1;
    if (sizes_given) sizes = *sizes_given;
    if (runs_given) runs = *runs_given;
    if (ref_runs_given) ref_runs = *ref_runs_given;
    if (bf_runs_given) bf_runs = *bf_runs_given;
    if (json) check_output_file(*json, "--json", {data});
    if (images) make_output_dir(*images, "--write-images");
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-bench-volpack", e, kUsage);
  }

  const Volume vol = load_volume(data);
  // Nor the files read beside it (--json x.raw replaced the voxels of the
  // x.nhdr given as --data).
  if (json) {
    const simdvol::ReadFiles read = simdvol::read_files(vol, data);
    try {
      simdvol::check_not_an_input(*json, read.files, read.dicom_dir, "--json");
    } catch (const ArgumentError& e) {
      return argument_error("simdvol-bench-volpack", e, kUsage);
    }
  }
  std::printf("volume %s: %lldx%lldx%lld\n", data.filename().string().c_str(),
              static_cast<long long>(vol.nx()), static_cast<long long>(vol.ny()),
              static_cast<long long>(vol.nz()));

  // Two VolPack contexts: the example's settings, and "matched" (cueing,
  // minimum voxel opacity and early termination off).
  vp::Renderer example(vol);
  std::unique_ptr<vp::Renderer> match;
  vp::Settings s0;
  s0.pixel_centre = pixel_centre;
  example.configure(s0);
  const double classify_ms = example.classify();
  double match_classify_ms = 0.0;
  vp::Settings m0 = s0;
  m0.depth_cue = false;
  m0.max_ray_opacity = 1.0;
  m0.min_voxel_opacity = 0.0;
  if (matched) {
    match = std::make_unique<vp::Renderer>(vol);
    match->configure(m0);
    match_classify_ms = match->classify();
  }
  std::printf("VolPack 1.0b3: vpVolumeNormals %.1f ms (once), vpClassifyVolume %.1f ms (once",
              example.normals_ms(), classify_ms);
  if (matched) std::printf("; %.1f ms with minimum opacity 0", match_classify_ms);
  std::printf(")\n");

  std::unique_ptr<Device> device;
  if (opencl) {
    device = std::make_unique<Device>();
    std::printf("OpenCL device: %s (%u compute units), %lld PEs, order %d\n",
                device->info().name.c_str(), device->info().compute_units,
                static_cast<long long>(pes), cl_order);
  }
  const Mat3 model0 = example.model();
  const ViewAngles a0 = vp::angles_from_model(model0);
  std::printf(
      "view: VolPack model = Rx(%g) Ry(%g) (VP_CONCAT_LEFT)%s -> T(theta %.4f, phi %.4f, varphi "
      "%.4f) = M\n",
      vp::Example::rotate_x, vp::Example::rotate_y, frames > 1 ? ", then Ry(5 k) per frame" : "",
      a0.theta, a0.phi, a0.varphi);

  Json json_cases = Json::array();
  Json json_view;
  for (const int size : sizes) {
    Row bf, raw, cls, ref, ocl;
    bf.name = "VolPack brute force";
    raw.name = "VolPack raw (no octree)";
    cls.name = "VolPack classified";
    ref.name = "simdvol reference";
    ocl.name = "simdvol OpenCL";
    std::array<double, 3> cue_fit{};
    double mirror_psnr_x = 0, mirror_psnr_y = 0;
    // One engine per size: a fresh one each frame (render_opencl) timed new
    // buffers, the layout and the unfused shade + classify every frame
    // (49.7 ms against simdvol-bench's 17.2 for the same 64^2 frame).
    std::optional<RenderEngine> engine;
    if (opencl) {
      EngineOptions eo;
      eo.pes = pes;
      eo.fused = true;
      eo.reuse_layout = true;
      engine.emplace(*device, eo);
    }
    for (int f = 0; f < frames; ++f) {
      vp::Settings s = s0;
      s.width = s.height = size;
      s.turntable_deg = vp::Example::turntable_step * f;
      example.configure(s);
      const Mat3 model = example.model();
      const RenderOptions opt = vp::matched_options(vol, s, model, order);
      RenderOptions cl_opt = opt;
      cl_opt.order = cl_order;
      if (f == 0)
        cue_fit = vp::fit_depth_cue(vol, make_view(vol, opt.view, size, size, Sampling::voxel));

      std::map<std::string, Image> imgs;
      if (brute)
        imgs["volpack_brute_force"] =
            timed(bf, bf_runs, [&] { return example.render(vp::Mode::brute_force); });
      imgs["volpack_raw"] = timed(raw, runs, [&] { return example.render(vp::Mode::raw); });
      imgs["volpack_classified"] =
          timed(cls, runs, [&] { return example.render(vp::Mode::classified); });
      {
        simdvol::bench::KeepHeap keep;  // its freed volumes stay in the heap (bench_common.hpp)
        imgs["simdvol_reference"] =
            timed(ref, ref_runs, [&] { return render_reference(vol, opt); });
      }
      if (opencl)
        imgs["simdvol_opencl"] = timed(ocl, runs, [&] {
          EngineTimes t;
          return engine->render(vol, cl_opt, &t);
        });
      const Image& r = imgs["simdvol_reference"];
      if (brute) bf.psnr.push_back(psnr(imgs["volpack_brute_force"], r));
      raw.psnr.push_back(psnr(imgs["volpack_raw"], r));
      cls.psnr.push_back(psnr(imgs["volpack_classified"], r));
      if (opencl) ocl.psnr.push_back(psnr(imgs["simdvol_opencl"], r));
      if (f == 0) {
        mirror_psnr_x = psnr(imgs["volpack_classified"], vp::mirror_x(r));
        mirror_psnr_y = psnr(imgs["volpack_classified"], vp::mirror_y(r));
      }

      if (matched && f == 0) {
        vp::Settings ms = m0;
        ms.width = ms.height = size;
        ms.turntable_deg = s.turntable_deg;
        match->configure(ms);
        const RenderOptions mopt = vp::matched_options(vol, ms, match->model(), order);
        const Image mref = render_reference(vol, mopt);
        imgs["matched_simdvol_reference"] = mref;
        if (brute) {
          imgs["matched_volpack_brute_force"] = match->render(vp::Mode::brute_force);
          bf.psnr_matched.push_back(psnr(imgs["matched_volpack_brute_force"], mref));
        }
        imgs["matched_volpack_raw"] = match->render(vp::Mode::raw);
        raw.psnr_matched.push_back(psnr(imgs["matched_volpack_raw"], mref));
        imgs["matched_volpack_classified"] = match->render(vp::Mode::classified);
        cls.psnr_matched.push_back(psnr(imgs["matched_volpack_classified"], mref));
        if (opencl) {
          RenderOptions mcl = mopt;
          mcl.order = cl_order;
          EngineTimes t;
          imgs["matched_simdvol_opencl"] = render_opencl(*device, vol, mcl, &t, pes);
          ocl.psnr_matched.push_back(psnr(imgs["matched_simdvol_opencl"], mref));
        }
      }
      if (images && (f == 0 || frames > 1)) {
        for (const auto& [name, img] : imgs) {
          const std::string file = name + "_" + std::to_string(size) +
                                   (frames > 1 ? "_f" + std::to_string(f) : "") + ".png";
          write_image(img, *images / file);
        }
      }
    }

    std::printf(
        "\n%dx%d, %d frame%s%s; reference order %d, direct; depth cue 1/(%.4f + %.4f d) "
        "(max rel. error %.1f%% against VolPack's)\n",
        size, size, frames, frames > 1 ? "s" : "", frames > 1 ? " (turntable, 5 deg)" : "", order,
        cue_fit[0], cue_fit[1], 100.0 * cue_fit[2]);
    std::printf("%-26s %10s %10s %10s %10s %11s %10s %12s\n", "renderer", "ms/frame", "min", "max",
                "first", "x VP clsfd", "PSNR dB", "matched dB");
    const double base = summarize(cls.ms).median;
    std::vector<const Row*> rows;
    if (brute) rows.push_back(&bf);
    rows.push_back(&raw);
    rows.push_back(&cls);
    rows.push_back(&ref);
    if (opencl) rows.push_back(&ocl);
    for (const Row* row : rows) {
      const bool is_ref = row == &ref;
      char p[32] = "(reference)", pm[32] = "-";
      if (!is_ref) std::snprintf(p, sizeof p, "%.2f", frames > 1 ? mean(row->psnr) : row->psnr[0]);
      if (!is_ref && !row->psnr_matched.empty())
        std::snprintf(pm, sizeof pm, "%.2f", row->psnr_matched[0]);
      const Summary t = summarize(row->ms);
      std::printf("%-26s %10.2f %10.2f %10.2f %10.2f %11.2f %10s %12s\n", row->name.c_str(),
                  t.median, t.min, t.max, row->first_ms, t.median / base, p, pm);
      json_cases.push_back(
          {{"size", size},
           {"frames", frames},
           {"renderer", row->name},
           {"ms_median", json_num(t.median)},
           {"ms_min", json_num(t.min)},
           {"ms_max", json_num(t.max)},
           {"ms_first", json_num(row->first_ms)},
           {"timed_renders", row->ms.size()},
           {"ratio_to_volpack_classified", json_num(t.median / base)},
           {"psnr_db", is_ref ? Json(nullptr) : json_num(mean(row->psnr))},
           {"psnr_min_db", is_ref ? Json(nullptr) : json_num(min_of(row->psnr))},
           {"psnr_matched_db",
            row->psnr_matched.empty() ? Json(nullptr) : json_num(row->psnr_matched[0])}});
    }
    if (frames > 1) {
      std::printf("PSNR over the %d frames, min (frame):", frames);
      for (const Row* row : rows) {
        if (row == &ref) continue;
        const auto it = std::min_element(row->psnr.begin(), row->psnr.end());
        std::printf("  %s %.2f (%d)", row->name.c_str(), *it,
                    static_cast<int>(it - row->psnr.begin()));
      }
      std::printf("\n");
    }
    std::printf(
        "orientation check (frame 0): VolPack classified against the reference mirrored "
        "left-right %.2f dB, top-bottom %.2f dB (against the reference itself: %.2f dB)\n",
        mirror_psnr_x, mirror_psnr_y, cls.psnr[0]);
    if (json_view.is_null())
      json_view = {{"theta", json_num(a0.theta)},
                   {"phi", json_num(a0.phi)},
                   {"varphi", json_num(a0.varphi)},
                   {"cue_k1", json_num(cue_fit[0])},
                   {"cue_k2", json_num(cue_fit[1])},
                   {"cue_max_rel_error", json_num(cue_fit[2])},
                   {"mirror_x_psnr_db", json_num(mirror_psnr_x)},
                   {"mirror_y_psnr_db", json_num(mirror_psnr_y)}};
  }

  std::printf("\nnot matched exactly between VolPack and simdvol:\n");
  for (const auto& line : vp::unmatched()) std::printf("  - %s\n", line.c_str());
  std::printf(
      "(PSNR: RGB over black, peak 1, against simdvol's reference at order %d; 'matched' = "
      "VolPack without depth cueing, minimum voxel opacity 0 and ray opacity limit 1, simdvol "
      "without depth cue; ratio = ms/frame over VolPack classified's)\n",
      order);

  if (json) {
    // (Written by hand, the JSON took a file name's tab or a byte that is
    // not UTF-8 as it was: not JSON. nlohmann escapes them and makes such
    // bytes U+FFFD, as simdvol-bench's JSON does.)
    Json root = {{"volume", data.filename().string()},
                 {"dims", {vol.nx(), vol.ny(), vol.nz()}},
                 {"volpack",
                  {{"version", "1.0b3"},
                   {"normals_ms", json_num(example.normals_ms())},
                   {"classify_ms", json_num(classify_ms)}}}};
    if (device)
      root["opencl"] = {{"device", device->info().name},
                        {"compute_units", device->info().compute_units},
                        {"pes", pes},
                        {"order", cl_order}};
    root["reference_order"] = order;
    root["runs"] = runs;
    root["ref_runs"] = ref_runs;
    root["bf_runs"] = bf_runs;
    root["view"] = json_view;
    root["cases"] = json_cases;
    root["unmatched"] = vp::unmatched();
    const std::string text = root.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
    write_file_atomically(*json, {text});
    std::printf("wrote %s\n", json->string().c_str());
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "simdvol-bench-volpack: %s\n", e.what());
  return 1;
}
