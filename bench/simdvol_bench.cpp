// simdvol-bench: the benchmark harness (issue 6, items 1-3). Whole frames of
// the OpenCL engine (RenderEngine, every stage on the device) over a set of
// cases, with the serial reference and VolPack as peers in the same run and
// core scaling through child processes.
//
//   simdvol-bench [--volumes LIST] [--sizes LIST] [--orders LIST]
//                 [--compositing LIST] [--pes LIST] [--balance-sweeps LIST]
//                 [--skip-pes LIST] [--layout once|every]
//                 [--view T,P,V] [--sampling voxel|pixel] [--repeat R] [--turntable F]
//                 [--no-reference] [--reference-runs R] [--no-volpack] [--volpack-runs R]
//                 [--scaling LIST] [--data DIR] [--json FILE] [--quick]
//
// Cases: the product volumes x sizes x orders x compositing x P x balance
// sweeps (EngineOptions::balance_sweeps, default 8; a case with another
// count has "/bN" at the end of its id) x skip-pes (on, off:
// EngineOptions::skip_pes, default on; an off case's id ends in "/allpe").
// Layout: once (default): the engines keep the volume's cells from frame to
// frame (EngineOptions::reuse_layout, as `simdvol render --frames` and the
// turntables do: the thesis's distribution of the volume is preprocessing,
// ch. 4), so the warm-up frame lays the volume out and the timed frames
// start at shading; the layout column and "layout_once_ms" give that one
// layout's time. every: each frame lays the volume out again (the harness's
// frames before 2026-12-02), its median in the layout column.
// Volumes:
// phantomN (the N^3 Shepp-Logan CT phantom, shepp_logan(N, 4), preset ct),
// brainsmall (data/brainsmall.den, preset volpack: VolPack's example
// classification), ch2 (data/ch2.nii.gz, preset mri), or a volume file of
// the user's (.nrrd, .nhdr, .nii, .nii.gz, .hdr/.img, .mha, .mhd, .mgh, .mgz, .mnc, .den,
// DICOM: named by its file name in the cases, preset ct for Hounsfield data,
// mri otherwise, as `simdvol render --classify auto`). Compositing: direct,
// adaptive (threshold 0.95), mcN (Monte Carlo, N walks per whole ray) or
// mcNsub (per sub-ray, ch. 7.4; its reference is render_subray_reference
// at the case's PE count and sweeps). Per case a fresh RenderEngine renders one
// warm-up frame (timed as "first": page faults of fresh buffers, program
// builds not yet cached) and R timed frames; the cases of one volume, size,
// order and compositing (every P, sweeps and skip-pes; as many at once as
// their voxel buffers fit in half the device's memory) take their timed
// frames in turn, one each per round, so that a busy spell of the shared
// machine falls on all of them alike and their ratios hold; per stage the
// profiling-event
// times (EngineTimes), median / min / max over the R frames; the frame's
// samples (sum of the PE loads after balancing), the SIMD utilisation
// (mean load / max load) and the binary swap's X-Net traffic (swap_cost:
// 16 bytes per pixel moved) from EngineStats. The serial reference renders
// the same frame (cached per volume, size, order, view, compositing within
// the run), timed as the engines are: a warm-up render, then R timed ones
// (--reference-runs, default 2; their median) with its freed memory kept
// in the heap (bench_common.hpp's time_warm: the cold render's page faults
// moved it from 1.2 to 2.5 s between runs on these VMs); its time, the
// warm-up's, the speed-up, PSNR and max abs difference.
// Turntable (--turntable F, default 36): F frames at 5-degree steps about
// the vertical axis through one RenderEngine with reuse_layout, on each
// volume at the first size, order, compositing, P and sweeps; PSNR against the
// reference at frames 0, F/4, F/2, 3F/4.
// VolPack (when built with it, brainsmall selected, not --no-volpack): its
// example pipeline (volpack_peer.hpp) at every size, brute-force and
// classified modes beside the reference and the engine at every order,
// ms per frame and ratios; PSNR of every image against the reference at
// order 3, direct compositing, same transfer function and view; the
// turntable in VolPack's classified mode beside ours; what cannot be
// matched exactly is printed.
// Scaling (--scaling 1,2): the selected cases again in child processes
// (this executable, POCL_MAX_PTHREAD_COUNT=n, results through a temporary
// JSON file), per stage the medians at each n and the parallel efficiency
// t1 / (n tn).
// Defaults: phantom128, phantom256, brainsmall, ch2, cranium to 256^2 and 512^2,
// order 1, direct, adaptive and mc16, P = 8192, 5 repeats, a 36-frame
// turntable (a few minutes on 2 cores). --quick: phantom128 and brainsmall
// to 256^2, order 1, direct, adaptive and mc8, 3 repeats (under a minute).
// Errors: a bad option value exits 2 naming the option; a missing data file
// skips its cases with a message, or exits 1 when --volumes named it. A case
// that fails (an engine error, memory) is skipped, saying why on its line and
// in the JSON, and the run, its JSON written, then exits 1.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../host/core/output_checks.hpp"
#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/error.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap.hpp"
#ifdef SIMDVOL_BENCH_VOLPACK
#include "volpack_peer.hpp"
#endif

extern char** environ;

using namespace simdvol;
using namespace simdvol::bench;
using json = nlohmann::json;

namespace {

constexpr const char* kUsage =
    "usage: simdvol-bench [--volumes LIST] [--sizes LIST] [--orders LIST] [--compositing LIST]\n"
    "                     [--pes LIST] [--balance-sweeps LIST] [--skip-pes on,off]\n"
    "                     [--layout once|every]\n"
    "                     [--view T,P,V]\n"
    "                     [--sampling voxel|pixel] [--repeat R]\n"
    "                     [--turntable F] [--no-reference] [--reference-runs R]\n"
    "                     [--no-volpack] [--volpack-runs R]\n"
    "                     [--scaling LIST] [--data DIR] [--json FILE] [--quick]\n"
    "                     [--volume-index N]\n"
    "  volumes: phantomN (N^3 Shepp-Logan, 8..1024), brainsmall, ch2, cranium (InVesalius's\n"
    "    head CT, data/ct/cranium.nhdr), or a volume file\n"
    "    (.nrrd, .nhdr, .nii, .nii.gz, .hdr/.img, .mha, .mhd, .mgh, .mgz, .mnc, .den, a DICOM\n"
    "    series; classified as `simdvol "
    "render --classify "
    "auto`:\n"
    "    ct for Hounsfield data, mri otherwise); --volume-index N: volume N of every file\n"
    "    given, each of which must hold it (4-D NIfTI, NRRD, MetaImage, MGH, MINC, a DICOM\n"
    "    series of time points; a 3-D file holds volume 0 alone), its cases\n"
    "    named FILE@N (files of one name by their directories too); brainsmall and ch2 are\n"
    "    looked for in --data DIR, else $SIMDVOL_DATA_DIR where set, else the source tree's data/\n"
    "  compositing: direct, adaptive, mcN (N walks, whole ray), mcNx (exact opacity), mcNs (exact\n"
    "    opacity, stratified picks), each with sub for per sub-ray (mcNsub, mcNxsub, mcNssub)\n";

// A volume by name, loaded once.
struct VolumeSpec {
  std::string name;
  std::string classifier;      // a preset; "auto" for a file given: ct or mri once loaded
  std::filesystem::path file;  // empty for phantoms
  int phantom = 0;
  bool given = false;  // a volume file named on the command line (not brainsmall or ch2)
  std::optional<int64_t> index = std::nullopt;  // its volume, of a 4-D file (--volume-index)
};

struct Options {
  std::vector<std::string> volumes{"phantom128", "phantom256", "brainsmall", "ch2", "cranium"};
  bool volumes_explicit = false;
  std::vector<int64_t> sizes{256, 512};
  std::vector<int64_t> orders{1};
  std::vector<std::string> compositing{"direct", "adaptive", "mc16"};
  std::vector<int64_t> pes{8192};
  std::vector<int64_t> sweeps{kBalanceSweeps};
  std::vector<bool> skip_pes{true};
  bool layout_once = true;  // --layout once: the engines keep the cells
  ViewAngles view{20, 35, 10};
  Sampling sampling = Sampling::voxel;
  int repeat = 5;
  int turntable = 36;
  bool reference = true, volpack = true;
  int volpack_runs = 2;    // brute-force renders (slow)
  int reference_runs = 2;  // timed after a warm-up (time_warm)
  std::vector<int64_t> scaling;
  std::filesystem::path data = data_dir();  // $SIMDVOL_DATA_DIR, else the source tree's data/
  std::optional<std::filesystem::path> json;
  std::optional<int64_t> volume_index;  // of the volume files given (4-D)
  std::vector<VolumeSpec> specs;        // the volumes, named apart (volume_specs)
  bool child = false;                   // a --scaling child: no peers, no triad
};

struct Comp {
  std::string name;
  CompositeParams params;
  McScope scope = McScope::whole;
};

Comp parse_comp(const std::string& s) {
  Comp c;
  c.name = s;
  if (s == "direct") return c;
  if (s == "adaptive") {
    c.params.mode = CompositeMode::adaptive;
    return c;
  }
  if (s.rfind("mc", 0) == 0) {
    std::string n = s.substr(2);
    if (n.size() > 3 && n.compare(n.size() - 3, 3, "sub") == 0) {
      c.scope = McScope::subray;
      n.resize(n.size() - 3);
    }
    c.params.mode = CompositeMode::mc;
    // x: exact opacity (ch. 7.5 (a)); s: exact opacity, stratified picks.
    if (!n.empty() && (n.back() == 'x' || n.back() == 's')) {
      c.params.exact_opacity = true;
      c.params.stratified = n.back() == 's';
      n.pop_back();
    }
    if (n.empty())
      throw ArgumentError("--compositing", "'" + s + "': no walk count (mcN, e.g. mc16)");
    const int64_t walks = parse_int(n, "--compositing");
    if (walks < 1 || walks > 4096)
      throw ArgumentError("--compositing", "'" + s + "': walks must lie in 1..4096");
    c.params.samples = static_cast<int>(walks);
    // Named as written plainly (mc016 is mc16: the same case, once)
    c.name = "mc" + std::to_string(walks) +
             (c.params.exact_opacity ? (c.params.stratified ? "s" : "x") : "") +
             (c.scope == McScope::subray ? "sub" : "");
    return c;
  }
  throw ArgumentError("--compositing",
                      "'" + s +
                          "' is not direct, adaptive or mcN[x|s][sub] (e.g. mc16, mc16s, mc16sub: "
                          "x exact opacity, s stratified, sub per sub-ray)");
}

VolumeSpec parse_volume(const std::string& s, const std::filesystem::path& data,
                        std::optional<int64_t> index = std::nullopt) {
  if (s.rfind("phantom", 0) == 0) {
    // ("phantom" alone said only "'' is not an integer")
    if (s.size() == 7 || s.find_first_not_of("0123456789", 7) != std::string::npos)
      throw ArgumentError("--volumes",
                          "'" + s + "': give the phantom's size, phantomN (N in 8..1024)");
    const int64_t n = parse_int(s.substr(7), "--volumes");
    if (n < 8 || n > 1024) throw ArgumentError("--volumes", "'" + s + "': N must lie in 8..1024");
    // (named by its size: phantom016 is phantom16)
    return {"phantom" + std::to_string(n), "ct", {}, static_cast<int>(n)};
  }
  if (s == "brainsmall") return {s, "volpack", data / "brainsmall.den", 0};
  if (s == "ch2") return {s, "mri", data / "ch2.nii.gz", 0};
  if (s == "cranium") return {s, "ct", data / "ct" / "cranium.nhdr", 0};  // a real head CT
  // A volume file of the user's: named in the cases by its file name.
  const std::filesystem::path p(s);
  const VolumeFileKind kind = volume_file_kind(p);
  if (kind != VolumeFileKind::unknown && kind != VolumeFileKind::raw) {
    // (a DICOM directory given as "ct/" is named "ct")
    const std::string name =
        p.filename().empty() ? p.parent_path().filename().string() : p.filename().string();
    return {index ? name + "@" + std::to_string(*index) : name, "auto", p, 0, true, index};
  }
  throw ArgumentError("--volumes",
                      "'" + s +
                          "' is not phantomN, brainsmall, ch2, cranium or a volume file "
                          "(.nrrd, .nhdr, .nii, .nii.gz, .hdr/.img, .mha, .mhd, .mgh, "
                          ".mgz, .mnc, .den, "
                          "DICOM)");
}

// Where a volume file lies (absolute, normal, without a trailing
// separator: a DICOM directory given as "ct/").
std::filesystem::path volume_place(const std::filesystem::path& file) {
  std::error_code ec;
  std::filesystem::path p = std::filesystem::absolute(file, ec).lexically_normal();
  if (p.filename().empty() && p.has_parent_path()) p = p.parent_path();
  return p;
}

// The volumes of --volumes, each once, named so that no two share a name.
// A case's id begins with the name, and the reference images are kept by
// it: sub1/T1.nii.gz and sub2/T1.nii.gz were both "T1.nii.gz", two cases
// had one id, and the second volume's frames were compared with the first
// one's reference images (18.3 dB where 165.5 was due). Files of one name
// are named by as many of their directories as tell them apart
// ("sub1/T1.nii.gz"); one volume given twice (phantom16 and phantom016,
// brainsmall and the path of its file, a file by two paths or a link) is
// refused, as a case given twice is.
std::vector<VolumeSpec> volume_specs(const Options& o) {
  namespace fs = std::filesystem;
  std::vector<VolumeSpec> specs;
  std::vector<fs::path> places;
  for (const std::string& v : o.volumes) {
    specs.push_back(parse_volume(v, o.data, o.volume_index));
    places.push_back(specs.back().file.empty() ? fs::path() : volume_place(specs.back().file));
  }
  for (std::size_t i = 0; i < specs.size(); ++i)
    for (std::size_t j = 0; j < i; ++j) {
      std::error_code ec;
      const bool same = specs[i].phantom > 0 ? specs[i].phantom == specs[j].phantom
                                             : !places[i].empty() && !places[j].empty() &&
                                                   (places[i] == places[j] ||
                                                    fs::equivalent(places[i], places[j], ec));
      if (same)
        throw ArgumentError("--volumes", "'" + o.volumes[i] + "' is '" + o.volumes[j] +
                                             "' again: give each volume once");
    }
  // Each given file's name: its last `depth` path components, one more
  // for every file whose name is another's, until none is.
  std::vector<std::vector<std::string>> parts(specs.size());
  std::vector<std::size_t> depth(specs.size(), 1);
  for (std::size_t i = 0; i < specs.size(); ++i)
    if (specs[i].given)
      for (const fs::path& part : places[i])
        if (part != part.root_path() && part != "/") parts[i].push_back(part.string());
  const auto name = [&](std::size_t i) {
    if (!specs[i].given || parts[i].empty()) return specs[i].name;
    std::string n;
    for (std::size_t k = parts[i].size() - std::min(depth[i], parts[i].size()); k < parts[i].size();
         ++k)
      n += (n.empty() ? "" : "/") + parts[i][k];
    return specs[i].index ? n + "@" + std::to_string(*specs[i].index) : n;
  };
  for (bool longer = true; longer;) {
    longer = false;
    std::vector<std::string> names;
    for (std::size_t i = 0; i < specs.size(); ++i) names.push_back(name(i));
    for (std::size_t i = 0; i < specs.size(); ++i)
      for (std::size_t j = 0; j < specs.size(); ++j)
        if (i != j && names[i] == names[j] && specs[i].given && depth[i] < parts[i].size()) {
          ++depth[i];
          longer = true;
          break;
        }
  }
  for (std::size_t i = 0; i < specs.size(); ++i) specs[i].name = name(i);
  return specs;
}

Options parse_args(int argc, char** argv) {
  Options o;
  bool quick = false;
  std::optional<std::vector<std::string>> vols, comps;
  std::optional<std::vector<int64_t>> sizes, orders;
  std::optional<int> repeat, turntable;
  bool reference_runs_given = false, volpack_runs_given = false, data_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw ArgumentError(a, "needs a value");
      return argv[++i];
    };
    if (a == "--volumes") {
      vols = split_list(next(), a);
    } else if (a == "--sizes") {
      sizes = parse_int_list(next(), a, 8, 4096);
    } else if (a == "--orders") {
      orders = parse_int_list(next(), a, 0, 3);
    } else if (a == "--compositing") {
      const std::vector<std::string> given = split_list(next(), a);
      comps.emplace();
      for (std::size_t i = 0; i < given.size(); ++i) {
        comps->push_back(parse_comp(given[i]).name);
        for (std::size_t k = 0; k < i; ++k)  // (mc016,mc16: "'mc16' is given twice")
          if ((*comps)[k] == (*comps)[i] && given[k] != given[i])
            throw ArgumentError(
                a, "'" + given[i] + "' is '" + given[k] + "' again: give each compositing once");
      }
    } else if (a == "--pes") {
      o.pes = parse_int_list(next(), a, 1, int64_t(1) << 20);
      for (int64_t p : o.pes) pe_grid(p, "--pes");
    } else if (a == "--balance-sweeps") {
      o.sweeps = parse_int_list(next(), a, 0, kMaxBalanceSweeps);
    } else if (a == "--skip-pes") {
      o.skip_pes.clear();
      for (const std::string& v : split_list(next(), a)) {
        if (v != "on" && v != "off") throw ArgumentError(a, "'" + v + "' is neither on nor off");
        for (bool b : o.skip_pes)
          if (b == (v == "on")) throw ArgumentError(a, "'" + v + "' is given twice");
        o.skip_pes.push_back(v == "on");
      }
    } else if (a == "--layout") {
      const std::string v = next();
      if (v != "once" && v != "every")
        throw ArgumentError(a, "'" + v + "' is neither once nor every");
      o.layout_once = v == "once";
    } else if (a == "--view") {
      const std::string v = next();
      const auto parts = split_list(v, a);
      if (parts.size() != 3) throw ArgumentError(a, "'" + v + "' is not THETA,PHI,VARPHI");
      // (-360..360, as the other tools' --view: 1e300 was taken)
      o.view = {parse_double(parts[0], a, -360, 360), parse_double(parts[1], a, -360, 360),
                parse_double(parts[2], a, -360, 360)};
    } else if (a == "--sampling") {
      const std::string v = next();
      if (v == "voxel")
        o.sampling = Sampling::voxel;
      else if (v == "pixel")
        o.sampling = Sampling::pixel;
      else
        throw ArgumentError(a, "'" + v + "' is not voxel or pixel");
    } else if (a == "--repeat") {
      repeat = static_cast<int>(parse_int(next(), a, 1, 1000));
    } else if (a == "--turntable") {
      turntable = static_cast<int>(parse_int(next(), a, 0, 720));
      // (frame 0 is the warm-up: one frame timed none, and 0 ms/frame was
      // printed)
      if (*turntable == 1)
        throw ArgumentError(a, "1 frame times none (the first is the warm-up): give 0 or 2..720");
    } else if (a == "--no-reference") {
      o.reference = false;
    } else if (a == "--reference-runs") {
      o.reference_runs = static_cast<int>(parse_int(next(), a, 1, 100));
      reference_runs_given = true;
    } else if (a == "--no-volpack") {
      o.volpack = false;
    } else if (a == "--volpack-runs") {
      o.volpack_runs = static_cast<int>(parse_int(next(), a, 1, 100));
      volpack_runs_given = true;
    } else if (a == "--scaling") {
      o.scaling = parse_int_list(next(), a, 1, 256);
    } else if (a == "--data") {
      o.data = next();
      data_given = true;
    } else if (a == "--volume-index") {
      o.volume_index = parse_int(next(), a, 0, std::numeric_limits<int32_t>::max());
    } else if (a == "--json") {
      o.json = next();
      check_output_file(*o.json, a);  // now, not after minutes of frames
    } else if (a == "--quick") {
      quick = true;
    } else if (a == "--child") {
      o.child = true;
    } else if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else {
      throw ArgumentError(a, "unknown option");
    }
  }
  if (quick) {
    o.volumes = {"phantom128", "brainsmall"};
    o.sizes = {256};
    o.orders = {1};
    o.compositing = {"direct", "adaptive", "mc8"};
    o.repeat = 3;
    o.turntable = 36;
    if (!volpack_runs_given) o.volpack_runs = 1;  // (it overrode --volpack-runs 5)
  }
  if (vols) o.volumes = *vols, o.volumes_explicit = true;
  // A case twice (--sizes 256,256) made two cases of one id in the JSON.
  const auto once = [](const auto& list, const char* option) {
    for (std::size_t i = 0; i < list.size(); ++i)
      for (std::size_t j = 0; j < i; ++j)
        if (list[i] == list[j]) {
          std::ostringstream v;
          v << list[i];
          throw ArgumentError(option, "'" + v.str() + "' is given twice");
        }
  };
  if (vols) once(*vols, "--volumes");
  if (sizes) once(*sizes, "--sizes");
  if (orders) once(*orders, "--orders");
  if (comps) once(*comps, "--compositing");
  once(o.pes, "--pes");
  once(o.sweeps, "--balance-sweeps");
  once(o.scaling, "--scaling");
  // Options that would do nothing are refused, not ignored.
  if (!o.reference && reference_runs_given)
    throw ArgumentError("--reference-runs", "does nothing with --no-reference");
  if (!o.volpack && volpack_runs_given)
    throw ArgumentError("--volpack-runs", "does nothing with --no-volpack");
  if (data_given && std::none_of(o.volumes.begin(), o.volumes.end(), [](const std::string& v) {
        return v == "brainsmall" || v == "ch2" || v == "cranium";
      }))
    throw ArgumentError("--data",
                        "does nothing: it holds brainsmall, ch2 and cranium, and "
                        "--volumes names none of them");
  if (sizes) o.sizes = *sizes;
  if (orders) o.orders = *orders;
  if (comps) o.compositing = *comps;
  if (repeat) o.repeat = *repeat;
  if (turntable) o.turntable = *turntable;
  bool given = false;
  std::vector<std::filesystem::path> inputs;
  o.specs = volume_specs(o);
  for (const VolumeSpec& spec : o.specs) {
    given = spec.given || given;
    if (!spec.file.empty()) inputs.push_back(spec.file);
  }
  if (o.json) check_output_file(*o.json, "--json", inputs);
  if (o.volume_index && !given)
    throw ArgumentError("--volume-index",
                        "applies only to volume files given in --volumes (NIfTI, NRRD, DICOM), "
                        "not to phantomN, brainsmall or ch2");
  return o;
}

// ---------------------------------------------------------------------------
// Stages of EngineTimes, in pipeline order.
struct StageField {
  const char* name;
  double EngineTimes::*field;
};
constexpr StageField kStages[] = {
    {"layout", &EngineTimes::layout_ms},     {"shade", &EngineTimes::shade_ms},
    {"classify", &EngineTimes::classify_ms}, {"match", &EngineTimes::match_ms},
    {"balance", &EngineTimes::balance_ms},   {"resample_local", &EngineTimes::resample_local_ms},
    {"offsets", &EngineTimes::offsets_ms},   {"rays", &EngineTimes::rays_ms},
    {"walk", &EngineTimes::walk_ms},         {"plan", &EngineTimes::plan_ms},
    {"swap", &EngineTimes::swap_ms},         {"display", &EngineTimes::display_ms},
    {"warp", &EngineTimes::warp_ms},
};
// Device time of a frame: every profiled stage (plan is host time and
// overlaps the device).
double device_sum(const EngineTimes& t) {
  double s = 0;
  for (const auto& st : kStages)
    if (std::string(st.name) != "plan") s += t.*st.field;
  return s;
}

json summary_json(const Summary& s) {
  return {{"median", s.median}, {"min", s.min}, {"max", s.max}};
}

json psnr_json(double p) {
  return std::isfinite(p) ? json(p) : json(nullptr);
}

// A figure of the table in as many digits as it needs (a 0.4 ms reference
// was "0", beside a speed-up of 0.1), "-" where it was not measured
// (--no-reference: "nan").
std::string fmt_figure(double v) {
  if (std::isnan(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b,
                std::fabs(v) >= 100  ? "%.0f"
                : std::fabs(v) >= 10 ? "%.1f"
                                     : "%.2f",
                v);
  return b;
}

std::string fmt_psnr(double p) {
  if (std::isinf(p)) return "inf";
  if (std::isnan(p)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", p);
  return b;
}

// The reference image of one frame, cached within the run; timed (as
// time_warm) where its time is reported, rendered once where only its image
// is compared (the turntables' frames: times.count 0 until a timed get).
struct RefResult {
  Image image;
  Summary times;          // the timed renders' median, min, max and count
  double first_ms = NAN;  // the warm-up render
};
class RefCache {
 public:
  explicit RefCache(int runs) : runs_(runs) {}
  enum class Use { timed, image };
  /// `subray_pes` > 0: the per sub-ray Monte Carlo reference at those PE
  /// cells and `subray_sweeps` balance sweeps (render_subray_reference),
  /// the estimator a case mcNsub runs; 0: render_reference.
  const RefResult& get(const std::string& volume, const Volume& vol, const RenderOptions& opt,
                       Use use = Use::timed, int64_t subray_pes = 0, int subray_sweeps = 0) {
    // (A fixed buffer cut the key of a long volume name, and frames of other
    // views or options shared a reference image.)
    const CompositeParams& c = opt.composite;
    char numbers[320];
    std::snprintf(numbers, sizeof numbers,
                  "|%d|%d|%d|%.6f,%.6f,%.6f|%d|%d|%.4f|%llu|%d|%d%d%d%d|%.4f,%.4f|sub%lld/%d",
                  opt.width, opt.height, opt.order, opt.view.theta, opt.view.phi, opt.view.varphi,
                  static_cast<int>(opt.sampling), static_cast<int>(c.mode), c.threshold,
                  static_cast<unsigned long long>(c.seed), c.samples, static_cast<int>(c.streams),
                  c.exact_opacity, c.stratified, c.drop_transparent, opt.shade.k1, opt.shade.k2,
                  static_cast<long long>(subray_pes), subray_sweeps);
    const std::string k = volume + numbers;
    const auto render = [&] {
      return subray_pes > 0 ? render_subray_reference(vol, opt, subray_pes, subray_sweeps, false)
                            : render_reference(vol, opt);
    };
    RefResult& r = cache_[k];
    if (use == Use::timed && r.times.count == 0) {
      double median_ms = 0;
      r.image = time_warm(runs_, render, median_ms, &r.first_ms, &r.times);
    } else if (r.image.width() == 0)
      r.image = render();
    return r;
  }

 private:
  int runs_;
  std::map<std::string, RefResult> cache_;
};

struct Loaded {
  VolumeSpec spec;
  std::unique_ptr<Volume> vol;
};

// ---------------------------------------------------------------------------

struct Harness {
  Options o;
  Device* dev = nullptr;
  RefCache refs{2};
  json cases = json::array();
  json turntables = json::array();
  std::vector<std::string> failed;  // cases and turntables that threw (skipped, saying why)

  RenderOptions render_options(const VolumeSpec& spec, int size, int order, const Comp& c,
                               ViewAngles view) const {
    RenderOptions opt;
    opt.view = view;
    opt.width = opt.height = size;
    opt.sampling = o.sampling;
    opt.order = order;
    opt.composite = c.params;
    opt.classifier = classifier_preset(spec.classifier);
    return opt;
  }

  static std::string case_id(const std::string& vol, int size, int order, const std::string& comp,
                             int64_t pes, int sweeps, bool skip_pes) {
    return vol + "/" + std::to_string(size) + "/o" + std::to_string(order) + "/" + comp + "/P" +
           std::to_string(pes) + (sweeps == kBalanceSweeps ? "" : "/b" + std::to_string(sweeps)) +
           (skip_pes ? "" : "/allpe");
  }

  void print_case_header() const {
    std::printf(
        "\n%-34s %8s %8s %8s %8s %6s %8s | %6s %6s %6s %6s %6s %6s %6s %6s %6s %6s | %5s %7s | "
        "%8s %7s %6s\n",
        "case (volume/size/order/comp/P)", "first", "wall_ms", "min", "max", "fps", "Msmp/s",
        "layout", "shcls", "match", "bal", "rs+loc", "ofs+ry", "walk", "plan", "swap", "dsp+wp",
        "util", "XNet_MB", "ref_ms", "speedup", "PSNR");
  }

  // One case between its warm-up frame and its report. The cases of a
  // group (one volume, size, order and compositing; every PE count,
  // balancing and PE skipping) take their timed frames in turn, one frame
  // each per round, so a busy spell of the machine falls on all of them
  // alike and their ratios within a run hold (run one after the other, one
  // case could take all of it).
  struct Running {
    const Loaded* L = nullptr;
    int64_t pes = 0;
    int subray_sweeps = -1;  // a per sub-ray case's sweeps (its reference's), else -1
    std::string id;
    RenderOptions opt;
    json j;
    std::unique_ptr<RenderEngine> engine;
    Image img;
    EngineStats st;
    double first = 0;
    double first_layout = 0;  // the warm-up frame's layout (ms)
    std::size_t built = 0;
    std::vector<double> wall, devsum;
    std::map<std::string, std::vector<double>> stage;
    std::vector<std::vector<double>> swap_stages;
    std::string error;  // skipped: why
  };

  Running start_case(const Loaded& L, int size, int order, const Comp& c, int64_t pes, int sweeps,
                     bool skip_pes) {
    Running r;
    r.L = &L;
    r.pes = pes;
    if (c.scope == McScope::subray) r.subray_sweeps = sweeps;
    r.id = case_id(L.spec.name, size, order, c.name, pes, sweeps, skip_pes);
    r.opt = render_options(L.spec, size, order, c, o.view);
    EngineOptions eo;
    eo.pes = pes;
    eo.fused = true;
    eo.mc_scope = c.scope;
    eo.balance_sweeps = sweeps;
    eo.skip_pes = skip_pes;
    eo.reuse_layout = o.layout_once;
    json& j = r.j;
    j["id"] = r.id;
    j["volume"] = L.spec.name;
    j["dims"] = {L.vol->nx(), L.vol->ny(), L.vol->nz()};
    j["classifier"] = L.spec.classifier;
    j["size"] = size;
    j["order"] = order;
    j["compositing"] = c.name;
    j["pes"] = pes;
    j["balance_sweeps"] = sweeps;
    j["skip_pes"] = skip_pes;
    j["sampling"] = o.sampling == Sampling::voxel ? "voxel" : "pixel";
    j["view"] = {o.view.theta, o.view.phi, o.view.varphi};
    try {
      validate(eo, r.opt);
      r.engine = std::make_unique<RenderEngine>(*dev, eo);
      EngineTimes t;
      const std::size_t programs0 = dev->cached_programs();
      const auto t0 = Clock::now();
      r.img = r.engine->render(*L.vol, r.opt, &t, &r.st);  // warm-up: the first frame
      r.first = ms_since(t0);
      r.first_layout = t.layout_ms;
      r.built = dev->cached_programs() - programs0;
    } catch (const std::exception& e) {
      r.error = e.what();
      r.engine.reset();
    }
    return r;
  }

  void frame(Running& r) {
    if (!r.error.empty()) return;
    try {
      EngineTimes t;
      const auto t0 = Clock::now();
      r.img = r.engine->render(*r.L->vol, r.opt, &t);
      r.wall.push_back(ms_since(t0));
      r.devsum.push_back(device_sum(t));
      for (const auto& s : kStages) r.stage[s.name].push_back(t.*s.field);
      r.stage["occupancy"].push_back(t.occupancy_ms);  // inside resample_local
      r.stage["kernels"].push_back(t.kernels_ms);      // EngineTimes::kernels
      r.stage["span"].push_back(t.span_ms);
      r.stage["longest_wait"].push_back(t.longest_wait_ms);
      r.swap_stages.resize(t.swap_stage_ms.size());
      for (std::size_t k = 0; k < t.swap_stage_ms.size(); ++k)
        r.swap_stages[k].push_back(t.swap_stage_ms[k]);
    } catch (const std::exception& e) {
      r.error = e.what();
      r.engine.reset();
    }
  }

  void finish_case(Running& r) {
    r.engine.reset();  // its buffers back before the next group
    const Loaded& L = *r.L;
    const int64_t pes = r.pes;
    const std::string& id = r.id;
    const RenderOptions& opt = r.opt;
    const Image& img = r.img;
    const EngineStats& st = r.st;
    const double first = r.first;
    auto& stage = r.stage;
    json& j = r.j;
    try {
      if (!r.error.empty()) throw std::runtime_error(r.error);
      const Summary w = summarize(r.wall);
      j["first_frame_ms"] = first;
      j["layout"] = o.layout_once ? "once" : "every";
      if (o.layout_once) j["layout_once_ms"] = r.first_layout;
      j["programs_built_in_first_frame"] = r.built;
      j["repeat"] = o.repeat;
      j["wall_ms"] = summary_json(w);
      j["device_ms"] = summary_json(summarize(r.devsum));
      j["fps"] = 1000.0 / w.median;
      j["samples"] = st.samples;
      j["segments"] = st.segments;
      j["samples_per_s"] = static_cast<double>(st.samples) / (w.median * 1e-3);
      json js;
      for (const auto& s : kStages) js[s.name] = summary_json(summarize(stage[s.name]));
      j["stages_ms"] = js;
      // Empty-space skipping's brick occupancy: part of resample_local.
      j["occupancy_ms"] = summary_json(summarize(stage["occupancy"]));
      // The frame's kernels summed, their span (first start to last end)
      // and the longest wait between two (EngineTimes): how much of the
      // frame the device spent idle.
      j["kernels_ms"] = summary_json(summarize(stage["kernels"]));
      j["kernel_span_ms"] = summary_json(summarize(stage["span"]));
      j["longest_wait_ms"] = summary_json(summarize(stage["longest_wait"]));
      json sw = json::array();
      for (const auto& v : r.swap_stages) sw.push_back(median(v));
      j["swap_stage_ms"] = sw;
      j["utilisation"] = st.utilisation();
      j["max_load"] = st.max_load();
      j["mean_load"] =
          st.loads.empty() ? 0.0 : double(st.samples) / static_cast<double>(st.loads.size());
      json x;
      x["swapped"] = st.swapped;
      x["swap_bytes"] = st.swap.moved * st.swap.bytes_per_pixel;
      x["max_pe_sent_bytes"] = st.swap.max_pe_sent * st.swap.bytes_per_pixel;
      x["swap_stages"] = st.swap.stages.size();
      x["bound_sum_px"] = st.swap.bound_sum();
      // The halo exchange of the raw voxel cells (width 1, 4-byte voxels: what
      // shading reads from neighbour PEs) on the PE mesh, as the SIMD machine
      // would move it (pe_array.hpp's halo_cost). The resample stage's reads
      // of neighbour cells are not counted here (bench-frame and
      // simdvol-repro-tables count them).
      const HaloCost hc = halo_cost(make_cell_layout(L.vol->dims(), pes, 1), pe_grid(pes));
      x["halo_bytes"] = hc.bytes;
      x["halo_max_pe_bytes"] = hc.max_pe_bytes;
      x["halo_max_distance"] = hc.max_distance;
      j["xnet"] = x;
      double ref_ms = NAN, q = NAN, diff = NAN;
      if (o.reference) {
        const RefResult& ref =
            r.subray_sweeps >= 0
                ? refs.get(L.spec.name, *L.vol, opt, RefCache::Use::timed, pes, r.subray_sweeps)
                : refs.get(L.spec.name, *L.vol, opt);
        ref_ms = ref.times.median;
        q = psnr(ref.image, img);
        diff = max_abs_diff(ref.image, img);
        j["reference"] = {{"ms", ref_ms},
                          {"first_ms", ref.first_ms},
                          {"runs", o.reference_runs},
                          {"speedup", ref_ms / w.median},
                          {"psnr_db", psnr_json(q)},
                          {"identical", std::isinf(q) && diff == 0.0f},
                          {"max_abs_diff", diff}};
      }
      auto med = [&](const char* n) { return median(stage[n]); };
      std::printf(
          "%-34s %8.1f %8.2f %8.2f %8.2f %6.2f %8.2f | %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f "
          "%6.2f %6.2f %6.2f | %5.3f %7.2f | %8s %7s %6s\n",
          id.c_str(), first, w.median, w.min, w.max, 1000.0 / w.median,
          double(st.samples) / (w.median * 1e-3) * 1e-6,
          o.layout_once ? r.first_layout : med("layout"), med("shade") + med("classify"),
          med("match"), med("balance"), med("resample_local"), med("offsets") + med("rays"),
          med("walk"), med("plan"), med("swap"), med("display") + med("warp"), st.utilisation(),
          double(st.swap.moved * st.swap.bytes_per_pixel) / 1e6, fmt_figure(ref_ms).c_str(),
          fmt_figure(ref_ms / w.median).c_str(), fmt_psnr(q).c_str());
    } catch (const std::exception& e) {
      std::printf("%-34s skipped: %s\n", id.c_str(), e.what());
      j["skipped"] = e.what();
      failed.push_back(id);
    }
    std::fflush(stdout);
    cases.push_back(j);
  }

  void run_turntable(const Loaded& L, int size, int order, const Comp& c, int64_t pes, int sweeps,
                     bool skip_pes) {
    const int F = o.turntable;
    EngineOptions eo;
    eo.pes = pes;
    eo.fused = true;
    eo.mc_scope = c.scope;
    eo.balance_sweeps = sweeps;
    eo.skip_pes = skip_pes;
    eo.reuse_layout = true;
    json j;
    j["volume"] = L.spec.name;
    j["size"] = size;
    j["order"] = order;
    j["compositing"] = c.name;
    j["pes"] = pes;
    j["balance_sweeps"] = sweeps;
    j["skip_pes"] = skip_pes;
    j["frames"] = F;
    j["step_deg"] = 5.0;
    try {
      RenderEngine engine(*dev, eo);
      std::vector<double> wall;
      std::vector<double> psnrs;
      json checked = json::array();
      double first = 0, total = 0;
      for (int f = 0; f < F; ++f) {
        ViewAngles v = o.view;
        v.phi += 5.0 * f;
        const RenderOptions opt = render_options(L.spec, size, order, c, v);
        const auto t0 = Clock::now();
        const Image img = engine.render(*L.vol, opt);
        const double ms = ms_since(t0);
        total += ms;
        if (f == 0)
          first = ms;  // lays the volume out: not a turntable frame's cost
        else
          wall.push_back(ms);
        if (o.reference && F >= 1 && (f % std::max(1, F / 4) == 0)) {
          const double q = psnr(refs.get(L.spec.name, *L.vol, opt, RefCache::Use::image,
                                         c.scope == McScope::subray ? pes : 0, sweeps)
                                    .image,
                                img);
          psnrs.push_back(q);
          checked.push_back({{"frame", f}, {"psnr_db", psnr_json(q)}});
        }
      }
      const Summary w = summarize(wall);
      j["first_frame_ms"] = first;
      j["frame_ms"] = summary_json(w);
      j["total_ms"] = total;
      j["fps"] = w.median > 0 ? 1000.0 / w.median : 0.0;
      j["psnr_checked"] = checked;
      double minq = INFINITY;
      for (double q : psnrs) minq = std::min(minq, q);
      std::printf(
          "turntable %-12s %4d^2 order %d %-8s P %-5lld: %d frames at 5 deg, first %.1f ms, then "
          "%.2f ms/frame (min %.2f, max %.2f) = %.2f fps, total %.2f s; PSNR min over %zu checked "
          "frames %s dB\n",
          L.spec.name.c_str(), size, order, c.name.c_str(), static_cast<long long>(pes), F, first,
          w.median, w.min, w.max, w.median > 0 ? 1000.0 / w.median : 0.0, total * 1e-3,
          psnrs.size(), psnrs.empty() ? "-" : fmt_psnr(minq).c_str());
    } catch (const std::exception& e) {
      std::printf("turntable %s skipped: %s\n", L.spec.name.c_str(), e.what());
      j["skipped"] = e.what();
      failed.push_back("turntable " + L.spec.name);
    }
    std::fflush(stdout);
    turntables.push_back(j);
  }

#ifdef SIMDVOL_BENCH_VOLPACK
  json run_volpack(const Volume& vol) {
    namespace vp = simdvol::volpack;
    json out;
    vp::Renderer example(vol);
    vp::Settings s0;
    example.configure(s0);
    const double classify_ms = example.classify();
    out["version"] = "1.0b3";
    out["normals_ms"] = example.normals_ms();
    out["classify_ms"] = classify_ms;
    const ViewAngles a0 = vp::angles_from_model(example.model());
    out["view"] = {a0.theta, a0.phi, a0.varphi};
    std::printf(
        "\nVolPack 1.0b3 peer: brainsmall.den, its example's classification, shading and view "
        "(T = (%.3f, %.3f, %.3f)); vpVolumeNormals %.1f ms, vpClassifyVolume %.1f ms (once)\n",
        a0.theta, a0.phi, a0.varphi, example.normals_ms(), classify_ms);
    json rows = json::array();
    for (const int64_t size64 : o.sizes) {
      const int size = static_cast<int>(size64);
      vp::Settings s = s0;
      s.width = s.height = size;
      example.configure(s);
      const RenderOptions ropt = vp::matched_options(vol, s, example.model(), 3);
      const RefResult& ref = refs.get("brainsmall-volpack", vol, ropt);
      struct Row {
        std::string name;
        Summary t;
        double first = 0, q = NAN;
      };
      // Every renderer warms up, then they take their timed frames in turn
      // (one each per round, while it has runs left), so that a busy spell
      // of the machine falls on all of them alike.
      struct Player {
        std::string name;
        int runs = 0;
        std::function<Image()> render;
        double first = 0;
        std::vector<double> ms;
        Image img;
      };
      std::vector<Player> players;
      auto add = [&players](std::string name, int runs, std::function<Image()> render) {
        Player p;
        p.name = std::move(name);
        p.runs = runs;
        p.render = std::move(render);
        players.push_back(std::move(p));
      };
      add("VolPack brute force", o.volpack_runs,
          [&] { return example.render(vp::Mode::brute_force); });
      add("VolPack classified", o.repeat, [&] { return example.render(vp::Mode::classified); });
      std::vector<std::unique_ptr<RenderEngine>> engines;
      std::deque<RenderOptions> opts;  // stable addresses for the players
      for (const int64_t pes : o.pes)
        for (const int64_t sweeps : o.sweeps)
          for (const bool skip_pes : o.skip_pes) {
            EngineOptions eo;
            eo.pes = pes;
            eo.fused = true;
            eo.balance_sweeps = static_cast<int>(sweeps);
            eo.skip_pes = skip_pes;
            eo.reuse_layout = o.layout_once;
            engines.push_back(std::make_unique<RenderEngine>(*dev, eo));
            RenderEngine* engine = engines.back().get();
            for (const int64_t order : o.orders) {
              opts.push_back(ropt);
              opts.back().order = static_cast<int>(order);
              const RenderOptions* opt = &opts.back();
              add("simdvol OpenCL order " + std::to_string(order) + " P " + std::to_string(pes) +
                      (sweeps == kBalanceSweeps ? "" : " b" + std::to_string(sweeps)) +
                      (skip_pes ? "" : " allpe"),
                  o.repeat, [&vol, engine, opt] { return engine->render(vol, *opt); });
            }
          }
      int rounds = 0;
      for (Player& p : players) {
        const auto t0 = Clock::now();
        p.img = p.render();
        p.first = ms_since(t0);
        rounds = std::max(rounds, p.runs);
      }
      for (int k = 0; k < rounds; ++k)
        for (Player& p : players) {
          if (k >= p.runs) continue;
          const auto t0 = Clock::now();
          p.img = p.render();
          p.ms.push_back(ms_since(t0));
        }
      std::vector<Row> table;
      for (const Player& p : players) {
        table.push_back({p.name, summarize(p.ms), p.first, psnr(p.img, ref.image)});
        if (table.size() == 2) {
          // Its own min and max (they were the median three times).
          Row refrow{"simdvol reference (order 3)", ref.times, ref.first_ms, INFINITY};
          table.push_back(refrow);
        }
      }
      const double cls = table[1].t.median, bf = table[0].t.median;
      std::printf("\n%dx%d: %-32s %9s %9s %9s %9s %9s %9s %8s\n", size, size, "renderer",
                  "ms/frame", "min", "max", "first", "x VPclsf", "x VPbrute", "PSNR dB");
      for (const Row& r : table) {
        std::printf("%9s %-32s %9.2f %9.2f %9.2f %9.2f %9.2f %9.3f %8s\n", "", r.name.c_str(),
                    r.t.median, r.t.min, r.t.max, r.first, r.t.median / cls, r.t.median / bf,
                    fmt_psnr(r.q).c_str());
        rows.push_back({{"size", size},
                        {"renderer", r.name},
                        {"ms", summary_json(r.t)},
                        {"first_ms", r.first},
                        {"ratio_to_volpack_classified", r.t.median / cls},
                        {"ratio_to_volpack_brute_force", r.t.median / bf},
                        {"psnr_db", psnr_json(r.q)}});
      }
    }
    out["cases"] = rows;
    // The example's turntable: VolPack classified against ours (order of
    // the first --orders entry), same views.
    if (o.turntable > 1) {
      const int size = static_cast<int>(o.sizes[0]);
      const int order = static_cast<int>(o.orders[0]);
      EngineOptions eo;
      eo.pes = o.pes[0];
      eo.fused = true;
      eo.reuse_layout = true;
      eo.balance_sweeps = static_cast<int>(o.sweeps[0]);
      eo.skip_pes = o.skip_pes[0];
      RenderEngine engine(*dev, eo);
      std::vector<double> tv, to;
      double minq_vp = INFINITY, minq_ours = INFINITY;
      for (int f = 0; f < o.turntable; ++f) {
        vp::Settings s = s0;
        s.width = s.height = size;
        s.turntable_deg = vp::Example::turntable_step * f;
        example.configure(s);
        RenderOptions opt = vp::matched_options(vol, s, example.model(), order);
        auto t0 = Clock::now();
        const Image vimg = example.render(vp::Mode::classified);
        tv.push_back(ms_since(t0));
        t0 = Clock::now();
        const Image oimg = engine.render(vol, opt);
        to.push_back(ms_since(t0));
        if (o.reference && f % std::max(1, o.turntable / 4) == 0) {
          opt.order = 3;
          const Image& r = refs.get("brainsmall-volpack", vol, opt, RefCache::Use::image).image;
          minq_vp = std::min(minq_vp, psnr(vimg, r));
          minq_ours = std::min(minq_ours, psnr(oimg, r));
        }
      }
      tv.erase(tv.begin());  // frame 0: warm-up (our layout, VolPack's caches)
      to.erase(to.begin());
      const Summary sv = summarize(tv), so = summarize(to);
      std::printf(
          "\nturntable (VolPack's example, %d frames at 5 deg, %dx%d): VolPack classified %.2f "
          "ms/frame, simdvol OpenCL order %d %.2f ms/frame (x %.2f); PSNR min over checked frames "
          "vs reference order 3: VolPack %s dB, simdvol %s dB\n",
          o.turntable, size, size, sv.median, order, so.median, so.median / sv.median,
          fmt_psnr(minq_vp).c_str(), fmt_psnr(minq_ours).c_str());
      out["turntable"] = {{"frames", o.turntable},
                          {"size", size},
                          {"order", order},
                          {"volpack_classified_ms", summary_json(sv)},
                          {"simdvol_ms", summary_json(so)},
                          {"ratio", so.median / sv.median},
                          {"psnr_min_volpack_db", psnr_json(minq_vp)},
                          {"psnr_min_simdvol_db", psnr_json(minq_ours)}};
    }
    std::printf("\nnot matched exactly between VolPack and simdvol:\n");
    json un = json::array();
    for (const auto& line : vp::unmatched()) {
      std::printf("  - %s\n", line.c_str());
      un.push_back(line);
    }
    out["unmatched"] = un;
    std::printf(
        "(PSNR: RGB over black, peak 1, against simdvol's reference at order 3, direct "
        "compositing, VolPack's example view, transfer function and shading; ratio = ms/frame "
        "over VolPack's)\n");
    return out;
  }
#endif
};

// ---------------------------------------------------------------------------
// Core scaling: this executable again per thread count.

std::string read_tail(const std::filesystem::path& p, std::size_t n) {
  std::ifstream in(p);
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return s.size() > n ? s.substr(s.size() - n) : s;
}

json run_child(int argc, char** argv, int threads, const std::filesystem::path& dir) {
  const std::filesystem::path out = dir / ("scaling_" + std::to_string(threads) + ".json");
  const std::filesystem::path log = dir / ("scaling_" + std::to_string(threads) + ".log");
  std::vector<std::string> args{"/proc/self/exe"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    // (--reference-runs and --volpack-runs, refused beside the child's
    // --no-reference and --no-volpack, failed the whole run after its cases)
    if (a == "--scaling" || a == "--json" || a == "--reference-runs" || a == "--volpack-runs") {
      ++i;
      continue;
    }
    args.push_back(a);
  }
  for (const char* a : {"--no-reference", "--no-volpack", "--child"}) args.push_back(a);
  args.push_back("--json");
  args.push_back(out.string());
  std::vector<char*> cargv;
  for (auto& a : args) cargv.push_back(a.data());
  cargv.push_back(nullptr);
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e)
    if (std::strncmp(*e, "POCL_MAX_PTHREAD_COUNT=", 23) != 0) env.emplace_back(*e);
  env.push_back("POCL_MAX_PTHREAD_COUNT=" + std::to_string(threads));
  std::vector<char*> cenv;
  for (auto& e : env) cenv.push_back(e.data());
  cenv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, "/proc/self/exe", &fa, nullptr, cargv.data(), cenv.data());
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw Error(std::string("posix_spawn(/proc/self/exe): ") + std::strerror(rc));
  int status = 0;
  waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw Error("the scaling run with POCL_MAX_PTHREAD_COUNT=" + std::to_string(threads) +
                " failed; its output ends:\n" + read_tail(log, 2000));
  std::ifstream in(out);
  return json::parse(in);
}

// "t2", "eff2" (GCC 12 warns falsely on "t" + std::to_string(n)).
std::string label(const char* prefix, int64_t n) {
  char b[32];
  std::snprintf(b, sizeof b, "%s%lld", prefix, static_cast<long long>(n));
  return b;
}

json scaling(int argc, char** argv, const Options& o) {
  char tmpl[] = "/tmp/simdvol-bench-XXXXXX";
  if (!mkdtemp(tmpl)) throw Error(std::string("mkdtemp: ") + std::strerror(errno));
  const std::filesystem::path dir = tmpl;
  // Removed also where a child fails (its log's end is in the error).
  struct RemoveDir {
    std::filesystem::path dir;
    ~RemoveDir() {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  } remove_dir{dir};
  std::map<int64_t, json> runs;
  for (const int64_t n : o.scaling) {
    std::printf("\nscaling: running the cases with POCL_MAX_PTHREAD_COUNT=%lld ...\n",
                static_cast<long long>(n));
    std::fflush(stdout);
    runs[n] = run_child(argc, argv, static_cast<int>(n), dir);
    std::printf("  the device reported %s compute units\n",
                runs[n]["device"]["compute_units"].dump().c_str());
  }
  const int64_t n1 = o.scaling.front();
  json out = json::array();
  std::printf(
      "\ncore scaling (POCL_MAX_PTHREAD_COUNT), medians in ms; efficiency = t%lld * %lld "
      "/ (n tn)\n",
      static_cast<long long>(n1), static_cast<long long>(n1));
  for (const json& c1 : runs[n1]["cases"]) {
    if (c1.contains("skipped")) continue;
    const std::string id = c1["id"];
    json jc;
    jc["id"] = id;
    for (const int64_t n : o.scaling)
      jc["compute_units"][label("t", n)] = runs[n]["device"]["compute_units"];
    std::printf("%s\n  %-16s", id.c_str(), "stage");
    for (const int64_t n : o.scaling) std::printf(" %9s", label("t", n).c_str());
    for (const int64_t n : o.scaling)
      if (n != n1) std::printf(" %9s", label("eff", n).c_str());
    std::printf("\n");
    std::vector<std::string> names;
    for (const auto& s : kStages) names.push_back(s.name);
    names.push_back("device");
    names.push_back("wall");
    for (const std::string& name : names) {
      auto value = [&](const json& c) -> double {
        if (name == "wall") return c["wall_ms"]["median"];
        if (name == "device") return c["device_ms"]["median"];
        return c["stages_ms"][name]["median"];
      };
      std::map<int64_t, double> t;
      for (const int64_t n : o.scaling)
        for (const json& c : runs[n]["cases"])
          if (c["id"] == id && !c.contains("skipped")) t[n] = value(c);
      if (t[n1] <= 0.0) continue;  // stage not run in this case
      json js;
      // plan: host time (one thread, overlapping the device), not PoCL's.
      std::printf("  %-16s", name == "plan" ? "plan (host)" : name.c_str());
      for (const int64_t n : o.scaling) {
        std::printf(" %9.2f", t[n]);
        js[label("t", n)] = t[n];
      }
      for (const int64_t n : o.scaling) {
        if (n == n1) continue;
        const double eff = t[n] > 0 ? t[n1] * double(n1) / (double(n) * t[n]) : NAN;
        std::printf(" %9.2f", eff);
        js[label("efficiency", n)] = eff;
      }
      std::printf("\n");
      jc["stages"][name] = js;
    }
    out.push_back(jc);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  simdvol::remove_temporary_files_on_signals();
  Options o;
  try {
    o = parse_args(argc, argv);
  } catch (const ArgumentError& e) {
    std::fprintf(stderr, "simdvol-bench: %s\n%s", e.what(), kUsage);
    return 2;
  }
  try {
    Harness h;
    h.o = o;
    h.refs = RefCache(o.reference_runs);
    json root;
    // Volumes: missing files skip their cases (or fail when asked for).
    std::vector<Loaded> vols;
    json jv = json::array();
    for (const VolumeSpec& spec : o.specs) {
      Loaded L;
      L.spec = spec;
      const std::string& name = L.spec.name;
      const auto t0 = Clock::now();
      if (L.spec.phantom) {
        L.vol = std::make_unique<Volume>(shepp_logan(L.spec.phantom, 4));
      } else if (L.spec.given) {
        L.vol = std::make_unique<Volume>(
            load_volume(L.spec.file, std::nullopt, L.spec.index));  // its errors name it
        // As `simdvol render --classify auto`: ct for Hounsfield data.
        L.spec.classifier = L.vol->range().min < -500.0f ? "ct" : "mri";
      } else {
        if (!std::filesystem::exists(L.spec.file)) {
          if (o.volumes_explicit) throw FileError(L.spec.file, "missing (run scripts/fetch-data)");
          std::printf("%s: %s is missing (scripts/fetch-data): its cases are skipped\n",
                      name.c_str(), L.spec.file.string().c_str());
          jv.push_back({{"name", name}, {"skipped", "missing " + L.spec.file.string()}});
          continue;
        }
        L.vol = std::make_unique<Volume>(load_volume(L.spec.file));
      }
      const double ms = ms_since(t0);
      // Nor the files read beside it (a detached header's data, a pair's
      // other half, a DICOM series' slices): --json x.raw replaced the voxels
      // of the x.nhdr the run read with its JSON.
      if (o.json) {
        const ReadFiles read = read_files(*L.vol, L.spec.file);
        check_not_an_input(*o.json, read.files, read.dicom_dir, "--json");
      }
      std::printf("volume %-12s %lldx%lldx%lld, classifier %s (%.0f ms to %s)\n", name.c_str(),
                  static_cast<long long>(L.vol->nx()), static_cast<long long>(L.vol->ny()),
                  static_cast<long long>(L.vol->nz()), L.spec.classifier.c_str(), ms,
                  L.spec.phantom ? "build" : "load");
      jv.push_back({{"name", name},
                    {"dims", {L.vol->nx(), L.vol->ny(), L.vol->nz()}},
                    {"classifier", L.spec.classifier},
                    {"file", L.spec.file.string()}});
      vols.push_back(std::move(L));
    }
    root["volumes"] = jv;

    auto t0 = Clock::now();
    Device dev;
    const double open_ms = ms_since(t0);
    h.dev = &dev;
    const HostInfo hi = host_info(dev);
    const DeviceInfo& di = dev.info();
    json jd = {
        {"name", di.name},
        {"platform", di.platform},
        {"platform_version", hi.platform_version},
        {"device_version", di.version},
        {"driver_version", di.driver_version},
        {"compute_units", di.compute_units},
        {"global_mem_bytes", di.global_mem_bytes},
        {"cpu_model", hi.cpu_model},
        {"hardware_threads", hi.hardware_threads},
        {"pocl_max_pthread_count",
         hi.pocl_max_pthread_count.empty() ? json(nullptr) : json(hi.pocl_max_pthread_count)},
        {"open_ms", open_ms}};
    std::printf("device: %s (%s; %s), %u compute units; CPU %s; POCL_MAX_PTHREAD_COUNT=%s\n",
                di.name.c_str(), hi.platform_version.c_str(), di.driver_version.c_str(),
                di.compute_units, hi.cpu_model.c_str(),
                hi.pocl_max_pthread_count.empty() ? "(unset)" : hi.pocl_max_pthread_count.c_str());
    if (!o.child) {
      const double triad = triad_gbs(std::size_t(128) << 20);
      jd["triad_gbs"] = triad;
      std::printf("triad bandwidth (host, %u threads, 3 x 128 MiB): %.1f GB/s\n",
                  std::max(1u, hi.hardware_threads), triad);
    }
    root["device"] = jd;
    root["options"] = {{"repeat", o.repeat},
                       {"turntable", o.turntable},
                       {"view", {o.view.theta, o.view.phi, o.view.varphi}},
                       {"layout", o.layout_once ? "once" : "every"},
                       {"reference", o.reference},
                       {"reference_runs", o.reference_runs}};

    std::vector<Comp> comps;
    for (const auto& c : o.compositing) comps.push_back(parse_comp(c));
    std::printf(
        "\nframes: %d repeats after one warm-up frame ('first'), the cases of each volume / "
        "size / order / compositing in turn, one frame each per round; times in ms, stage "
        "times from profiling events (median); view (%g, %g, %g), %s sampling; %s\n",
        o.repeat, o.view.theta, o.view.phi, o.view.varphi,
        o.sampling == Sampling::voxel ? "voxel" : "pixel",
        o.layout_once ? "layout once (the warm-up frame lays the volume out, the timed frames "
                        "keep its cells; the layout column is that one layout)"
                      : "layout every frame (the layout column: its median)");
    h.print_case_header();
    // A group's engines take their frames in turn (VolPack's table: also
    // every order): the pool keeps each one's buffers over the others'
    // frames.
    dev.set_reuse_keep(
        static_cast<int>(o.pes.size() * o.sweeps.size() * o.skip_pes.size() * o.orders.size()) + 2);
    // Engines alive at once: their voxel buffers (cells with halo, RGBA
    // voxel cells) within half the device's memory; a larger group takes
    // its turns in parts (one case alone, if need be, as before).
    const std::uint64_t budget = std::max<std::uint64_t>(dev.info().global_mem_bytes / 2, 1);
    struct Variant {
      int64_t pes;
      int sweeps;
      bool skip_pes;
    };
    for (const Loaded& L : vols)
      for (const int64_t size : o.sizes)
        for (const int64_t order : o.orders)
          for (const Comp& c : comps) {
            std::vector<Variant> variants;
            for (const int64_t pes : o.pes)
              for (const int64_t sweeps : o.sweeps)
                for (const bool skip_pes : o.skip_pes)
                  variants.push_back({pes, static_cast<int>(sweeps), skip_pes});
            std::size_t next = 0;
            while (next < variants.size()) {
              std::vector<Harness::Running> group;
              std::uint64_t bytes = 0;
              while (next < variants.size()) {
                const Variant& v = variants[next];
                std::uint64_t need = 0;
                try {
                  const CellLayout cl = make_cell_layout(L.vol->dims(), v.pes, 1);
                  need = cl.bytes() + make_voxel_layout(cl).bytes();
                } catch (const std::exception&) {  // start_case reports it
                }
                if (!group.empty() && bytes + need > budget) break;
                bytes += need;
                group.push_back(h.start_case(L, static_cast<int>(size), static_cast<int>(order), c,
                                             v.pes, v.sweeps, v.skip_pes));
                ++next;
              }
              for (int r = 0; r < o.repeat; ++r)
                for (Harness::Running& run : group) h.frame(run);
              for (Harness::Running& run : group) h.finish_case(run);
            }
          }
    std::printf(
        "(first: the warm-up frame, with fresh buffers and any program builds; util: mean / max "
        "PE load after balancing; XNet_MB: the binary swap's pixels moved x 16 B, in 10^6 B (the "
        "JSON adds "
        "the halo exchange of the voxel cells); speedup: the "
        "reference's ms / ours; mcNsub is compared with the reference's per sub-ray Monte Carlo "
        "at the same PE cells and balance sweeps)\n");
    root["cases"] = h.cases;
    if (o.turntable > 0 && !o.child) {
      std::printf("\n");
      for (const Loaded& L : vols)
        h.run_turntable(L, static_cast<int>(o.sizes[0]), static_cast<int>(o.orders[0]), comps[0],
                        o.pes[0], static_cast<int>(o.sweeps[0]), o.skip_pes[0]);
      root["turntables"] = h.turntables;
    }
    root["volpack"] = nullptr;
#ifdef SIMDVOL_BENCH_VOLPACK
    if (o.volpack && !o.child) {
      for (const Loaded& L : vols)
        if (L.spec.name == "brainsmall") root["volpack"] = h.run_volpack(*L.vol);
    }
#else
    if (o.volpack && !o.child)
      std::printf("\nVolPack peer: not built (libvolpack1-dev not found)\n");
#endif
    if (!o.scaling.empty() && !o.child) root["scaling"] = scaling(argc, argv, o);

    if (o.json) {
      // A temporary file renamed into place, removed where a write fails
      // (a full disk): the file given keeps what it held.
      // (A volume's name that is not UTF-8 threw here, after every case had
      // run, and no JSON was written: such bytes become U+FFFD.)
      write_file_atomically(
          *o.json, {root.dump(2, ' ', false, nlohmann::json::error_handler_t::replace), "\n"});
      std::printf("wrote %s\n", o.json->string().c_str());
    }
    // A case that threw is a failure, not a figure: a run of such cases
    // exited 0 (a missing data file, which skips its volume, is not one).
    // A --scaling child's JSON says so to the parent, whose own cases are
    // the same (its exit 1 lost the parent's whole run).
    if (!h.failed.empty() && !o.child) {
      std::string list;
      for (const std::string& id : h.failed) list += (list.empty() ? "" : ", ") + id;
      std::fprintf(stderr, "simdvol-bench: %zu case%s failed (skipped above, saying why): %s\n",
                   h.failed.size(), h.failed.size() == 1 ? "" : "s", list.c_str());
      return 1;
    }
  } catch (const ArgumentError& e) {
    std::fprintf(stderr, "simdvol-bench: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "simdvol-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
