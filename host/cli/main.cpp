// simdvol: the command-line program, a thin layer over the library.
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>
#include <initializer_list>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "../core/output_checks.hpp"
#include "cli_commands.hpp"
#include "mismatch_cmd.hpp"
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"

namespace fs = std::filesystem;
using namespace simdvol;

namespace {

// The phantoms' grid sizes, N of an N^3 grid (render --phantom-size, phantom --size).
constexpr int kPhantomMin = 2, kPhantomMax = 1024;
const std::string kPhantomRange = std::to_string(kPhantomMin) + ".." + std::to_string(kPhantomMax);

// For the uint64_t options: CLI11 would wrap "-1" round to 2^64 - 1.
const CLI::Validator kNotNegative(
    [](std::string& v) {
      const auto first = v.find_first_not_of(" \t");
      return first != std::string::npos && v[first] == '-' ? "must not be negative (got " + v + ")"
                                                           : std::string();
    },
    "", "not negative");

// For the 64-bit integer options: CLI11 takes a whole number past the
// type's range as its largest (--seed 18446744073709551616 as 2^64 - 1, a
// seed other than the one given): refused instead. Other text is left to
// CLI11's own conversion.
template <class T>
CLI::Validator in_range() {
  return CLI::Validator(
      [](std::string& v) {
        std::string_view s = trim_blanks(v);
        if (!s.empty() && s.front() == '+') s.remove_prefix(1);
        const std::size_t digits =
            s.find_first_not_of("0123456789", s.empty() || s[0] != '-' ? 0 : 1);
        if (s.empty() || digits != std::string_view::npos) return std::string();
        T x{};
        if (std::from_chars(s.data(), s.data() + s.size(), x).ec == std::errc::result_out_of_range)
          return v + " is outside " + std::to_string(std::numeric_limits<T>::min()) + " .. " +
                 std::to_string(std::numeric_limits<T>::max());
        return std::string();
      },
      "", "in range");
}

std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(item);
  return out;
}

// A whole number in a list (--size WxH, --raw-dims), by the rule of the
// options CLI11 reads (decimal_integer): "010" was taken as 10 here and
// refused there.
int64_t parse_int(const std::string& s, const std::string& arg) {
  if (const std::string why = decimal_problem(s); !why.empty()) throw ArgumentError(arg, why);
  const double v = parse_number(s, arg);
  if (std::fabs(v) > 9.0e15) throw ArgumentError(arg, "'" + s + "' is beyond 9e15");
  return static_cast<int64_t>(v);
}

ViewAngles parse_view(const std::string& s) {
  const auto a = parse_angles(s, "--view");
  return {a[0], a[1], a[2]};
}

std::array<int, 2> parse_size(const std::string& s) {
  const auto parts = split(s, 'x');
  // ("32x" splits as "32" alone.)
  if (s.find('x') == std::string::npos) {
    const int64_t n = parse_int(parts[0], "--size");
    if (n <= 0 || n > 16384) throw ArgumentError("--size", s + " is outside 1 .. 16384");
    return {static_cast<int>(n), static_cast<int>(n)};
  }
  if (parts.size() != 2)
    throw ArgumentError("--size", "expected WxH, e.g. 256x256, not '" + s + "'");
  const int64_t w = parse_int(parts[0], "--size"), h = parse_int(parts[1], "--size");
  if (w <= 0 || h <= 0 || w > 16384 || h > 16384)
    throw ArgumentError("--size", s + " is outside 1x1 .. 16384x16384");
  return {static_cast<int>(w), static_cast<int>(h)};
}

struct VolumeArgs {
  std::string path;
  std::string raw_dims, raw_type = "u8", raw_endian = "little", raw_spacing;
  uint64_t raw_header = 0;
  int64_t volume_index = 0;
  std::string orient;
  CLI::App* app = nullptr;

  void add(CLI::App* a) {
    app = a;
    app->add_option("--raw-dims", raw_dims, "raw volumes: NX,NY,NZ");
    app->add_option("--raw-type", raw_type, "raw volumes: u8, u16, i16 or f32")
        ->capture_default_str();
    app->add_option("--raw-endian", raw_endian, "raw volumes: little or big")
        ->capture_default_str();
    app->add_option("--raw-spacing", raw_spacing, "raw volumes: SX,SY,SZ (default 1,1,1)");
    app->add_option("--raw-header", raw_header, "raw volumes: bytes to skip before the voxels")
        ->check(decimal_integer())
        ->check(kNotNegative)
        ->check(in_range<uint64_t>());
    app->add_option("--volume-index", volume_index,
                    "4-D NIfTI, NRRD, MetaImage, MGH and MINC files (a time or diffusion "
                    "series of 3-D volumes), and DICOM series with several images at each "
                    "position (time points, echoes): which volume, from 0")
        ->check(decimal_integer())
        ->check(in_range<int64_t>());
    app->add_option("--orient", orient,
                    "turn the volume's axes to point this way in the patient, as its NIfTI, "
                    "NRRD, DICOM, MetaImage, MGH or MINC header says they lie: CODE is three "
                    "letters, one each of R/L, A/P, S/I (RAS: x to the right, y to the front, "
                    "z up); by default the voxels keep the file's order");
  }

  // The kind of file (by name, by being a directory or by DICOM's marker);
  // unknown for the phantom (no path).
  VolumeFileKind kind() const {
    return path.empty() ? VolumeFileKind::unknown : volume_file_kind(path);
  }

  // A NIfTI, NRRD, MetaImage, MGH, MINC or DICOM file: the formats that
  // may hold several 3-D volumes, and whose headers say where their axes
  // point.
  static bool series(VolumeFileKind k) {
    return k == VolumeFileKind::nifti || k == VolumeFileKind::nrrd ||
           k == VolumeFileKind::metaimage || k == VolumeFileKind::mgh ||
           k == VolumeFileKind::minc || k == VolumeFileKind::dicom;
  }

  // The raw layout options, and --volume-index, do nothing for another kind
  // of file (or for the built-in phantom): refused, not ignored.
  void check_format_options() const {
    const std::string which =
        path.empty() ? std::string(" (no volume given)") : " (" + path + " is not one)";
    const VolumeFileKind k = kind();
    for (const char* name :
         {"--raw-dims", "--raw-type", "--raw-endian", "--raw-spacing", "--raw-header"})
      if (k != VolumeFileKind::raw && app && app->count(name) > 0)
        throw ArgumentError(name, "applies only to .raw volumes" + which);
    if (!series(k) && app && app->count("--volume-index") > 0)
      throw ArgumentError("--volume-index",
                          "applies only to NIfTI, NRRD, MetaImage, MGH, MINC and DICOM volumes (" +
                              std::string(kSeriesFileNames) + ")" + which);
    if (volume_index < 0)
      throw ArgumentError("--volume-index", std::to_string(volume_index) + " is negative");
    if (app && app->count("--orient") > 0 && !series(k))
      throw ArgumentError("--orient",
                          "applies only to NIfTI, NRRD, MetaImage, MGH, MINC and DICOM volumes, "
                          "whose "
                          "headers say "
                          "where their axes point (" +
                              std::string(kSeriesFileNames) + ")" + which);
    if (app && app->count("--orient") > 0 && !valid_orientation(upper(orient)))
      throw ArgumentError("--orient", "'" + orient +
                                          "' is not three letters, one each of R/L, A/P and "
                                          "S/I (such as RAS or LPS)");
  }

  // `first_of_series`: a 4-D file (NIfTI, NRRD, MetaImage, MGH, MINC, DICOM)
  // without --volume-index loads its volume 0 (`info`), instead of the
  // error that says how many it holds;
  // `volumes` receives how many (1 for a 3-D file).
  Volume load(bool first_of_series = false, int64_t* volumes = nullptr) const {
    check_format_options();
    std::optional<RawLayout> raw;
    if (!raw_dims.empty()) {
      RawLayout l;
      const auto d = split(raw_dims, ',');
      if (d.size() != 3 || raw_dims.back() == ',')
        throw ArgumentError("--raw-dims", "expected NX,NY,NZ, not '" + raw_dims + "'");
      for (int a = 0; a < 3; ++a) l.dims[a] = parse_int(d[a], "--raw-dims");
      l.type = parse_voxel_type(raw_type, "--raw-type");
      if (raw_endian == "little")
        l.endian = Endian::little;
      else if (raw_endian == "big")
        l.endian = Endian::big;
      else
        throw ArgumentError("--raw-endian", "expected little or big, not '" + raw_endian + "'");
      if (!raw_spacing.empty()) {
        const auto sp = parse_numbers(raw_spacing, 3, "--raw-spacing", "SX,SY,SZ");
        for (int a = 0; a < 3; ++a) l.spacing[a] = sp[a];
      }
      l.header_bytes = raw_header;
      raw = l;
    }
    std::optional<int64_t> index;
    if (app && app->count("--volume-index") > 0)
      index = volume_index;
    else if (first_of_series && series(kind()))
      index = 0;
    Volume vol = load_volume(path, raw, index, volumes);
    if (app && app->count("--orient") > 0) {
      if (vol.orientation().empty())
        throw ArgumentError("--orient", path +
                                            ": the file does not say where its axes point in the "
                                            "patient (no NIfTI sform or qform, no NRRD anatomical "
                                            "space and directions, no DICOM Image Orientation "
                                            "(Patient) or frame positions, a MetaImage "
                                            "TransformMatrix of zeros, no MGH direction cosines "
                                            "flagged valid, no MINC spatial dimensions), so they "
                                            "cannot be turned");
      vol = reorient(vol, upper(orient), "--orient");
    }
    return vol;
  }
};

// name_0000.ext ...: at least 4 digits, more where the last frame's number
// needs them (name_00000 ... name_10000 for 10,001 frames), so that the
// names sort in frame order and take one printf pattern (%05d).
fs::path numbered(const fs::path& out, int frame, int frames) {
  if (frames <= 1) return out;
  int digits = 4;
  for (int n = frames - 1; n >= 10000; n /= 10) ++digits;
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%0*d", digits, frame);
  fs::path p = out;
  const std::string ext = p.extension().string();
  return p.replace_filename(p.stem().string() + buf + ext);
}

void progress(int done, int total) {
  if (!isatty(fileno(stderr))) return;
  const int width = 40;
  const int filled = total > 0 ? done * width / total : width;
  std::fprintf(stderr, "\r[%s%s] %d/%d frames", std::string(filled, '#').c_str(),
               std::string(width - filled, '.').c_str(), done, total);
  if (done == total) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

// --sampling pixel takes a sample a pixel apart along each axis: at an
// image much larger than the volume, a frame's samples grow as the cube of
// the ratio (2048x2048 of a 64^3 volume: 8.6e9, 18 s a frame here). Said
// before the first frame, with what voxel sampling takes: the viewing
// grid's points inside the volume, its physical volume over step^3 (the
// step in units of the smallest voxel spacing; before empty space is
// skipped).
void pixel_sampling_note(const Volume& vol, const RenderOptions& opt) {
  const double smallest = std::min({vol.spacing()[0], vol.spacing()[1], vol.spacing()[2]});
  double inside = 1;
  for (int a = 0; a < 3; ++a)
    inside *= static_cast<double>(vol.dims()[a]) * vol.spacing()[a] / smallest;
  const auto samples = [&](Sampling s) {
    const double step = make_view(vol, opt.view, opt.width, opt.height, s, opt.framing).step;
    return inside / (step * step * step);
  };
  const double pixel = samples(Sampling::pixel);
  if (pixel < 1e9) return;
  std::ostringstream os;
  os.precision(2);
  os << "simdvol: note: --sampling pixel at " << opt.width << "x" << opt.height << " takes about "
     << pixel << " samples a frame (--sampling voxel: about " << samples(Sampling::voxel)
     << "): a slow frame\n";
  std::cerr << os.str();
}

// render --times: one line a frame on stderr.
std::string opencl_times_line(int f, const PeGrid& pes, const EngineTimes& t,
                              const EngineStats& st) {
  std::ostringstream os;
  os << "frame " << f << " (opencl, " << pes.width << "x" << pes.height << " PEs): layout "
     << t.layout_ms << " ms, ";
  // The engine here fuses shade and classify (EngineTimes: shade 0, both in
  // classify): "shade 0 ms" read as shading for free.
  if (t.shade_ms == 0.0)
    os << "shade + classify (one kernel) " << t.classify_ms;
  else
    os << "shade " << t.shade_ms << " ms, classify " << t.classify_ms;
  os << " ms, match " << t.match_ms << " ms, balance " << t.balance_ms << " ms, resample+local "
     << t.resample_local_ms << " ms (brick occupancy " << t.occupancy_ms << " ms), offsets "
     << t.offsets_ms << " ms, ray lists " << t.rays_ms << " ms, walks " << t.walk_ms << " ms, plan "
     << t.plan_ms << " ms (host), swap " << t.swap_ms << " ms";
  if (!t.swap_stage_ms.empty()) {  // (whole-ray frames swap nothing: "()")
    os << " (";
    for (std::size_t k = 0; k < t.swap_stage_ms.size(); ++k)
      os << (k ? " " : "") << t.swap_stage_ms[k];
    os << ")";
  }
  const auto busy =
      std::count_if(st.loads.begin(), st.loads.end(), [](int64_t l) { return l > 0; });
  os << ", display " << t.display_ms << " ms, warp " << t.warp_ms << " ms; frame wall "
     << t.device_wall_ms << " ms; kernels " << t.kernels_ms << " ms in a " << t.span_ms
     << " ms span";
  if (t.longest_wait_ms > 0)
    os << " (longest wait " << t.longest_wait_ms << " ms, before " << t.longest_wait_before << ")";
  os << "; " << st.samples << " samples on " << busy << " of " << st.loads.size()
     << " PEs, utilisation " << st.utilisation();
  if (st.unshaded_pes > 0) os << ", shade left out " << st.unshaded_pes << " PEs";
  if (st.classification_kept) os << ", classification kept";
  if (st.classification_let_go) os << ", classification let go (memory ran out)";
  os << "\n";
  return os.str();
}

std::string reference_times_line(int f, const RenderTimes& t) {
  std::ostringstream os;
  os << "frame " << f << " (reference): shade " << t.shade_ms << " ms, classify " << t.classify_ms
     << " ms, resample+composite " << t.resample_composite_ms << " ms, warp " << t.warp_ms
     << " ms\n";
  return os.str();
}

}  // namespace

int main(int argc, char** argv) {
  simdvol::remove_temporary_files_on_signals();
  CLI::App app{
      "simdvol: data-parallel volume rendering (Zou 1995) on OpenCL, with a serial reference"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "simdvol 0.1.0");
  // CLI11's own refusals (an unknown option, a value its validators turn
  // down) carry the prefix every other error of simdvol's has; their exit
  // codes stay CLI11's (105-109).
  app.failure_message([](const CLI::App*, const CLI::Error& e) {
    return std::string("simdvol: error: ") + e.what() + "\nRun with --help for more information.\n";
  });

  // render
  auto* render = app.add_subcommand("render", "render a volume (the built-in CT phantom if none)");
  VolumeArgs rv;
  std::string view = "0,0,0", size = "256x256", sampling = "voxel", fit = "longest",
              composite = "direct", streams = "per-ray", classify = "auto", engine = "opencl",
              out = "simdvol.png";
  int order = 1, samples = 32, frames = 1, phantom_size = 256, balance_sweeps = kBalanceSweeps;
  uint64_t seed = 1;
  double step = 5.0;
  float threshold = 0.95f;
  std::string light, phong, depth_cue;
  {
    const ShadeParams d;
    const auto num = [](double v) {
      std::ostringstream o;
      o << v;
      return o.str();
    };
    light = num(d.light[0]) + "," + num(d.light[1]) + "," + num(d.light[2]);
    phong = num(d.ka) + "," + num(d.kd) + "," + num(d.ks) + "," + num(d.shininess);
    depth_cue = num(d.k1) + "," + num(d.k2);
  }
  bool no_shade = false, no_skip_empty = false, no_skip_pes = false, show_times = false,
       exact_opacity = false, allocate = false;
  bool stratified = false;
  std::string swap_layout = "cut-and-stack", mc_scope = "whole";
  render->add_option("volume", rv.path, "volume file (" + std::string(kVolumeFileNames) + ")");
  rv.add(render);
  render->add_option("--view", view, "THETA,PHI,VARPHI in degrees (thesis eq 5.2)")
      ->capture_default_str();
  render->add_option("--size", size, "output WxH")->capture_default_str();
  render->add_option("--sampling", sampling, "voxel or pixel")->capture_default_str();
  render
      ->add_option("--fit", fit,
                   "longest: the volume's longest side spans the image (VolPack's framing; "
                   "an oblique view loses the corners); diagonal: its diagonal does (the whole "
                   "volume at every view)")
      ->capture_default_str();
  render->add_option("--order", order, "interpolation order 0..3 (Aitken)")
      ->check(decimal_integer())
      ->capture_default_str();
  render->add_option("--composite", composite, "direct, adaptive or mc")->capture_default_str();
  render
      ->add_option("--samples", samples,
                   "Monte Carlo walks per ray (--mc-scope subray: per sub-ray, or with "
                   "--allocate the ray's budget shared by its sub-rays)")
      ->check(decimal_integer())
      ->capture_default_str();
  render->add_option("--seed", seed, "Monte Carlo seed")
      ->check(decimal_integer())
      ->check(kNotNegative)
      ->check(in_range<uint64_t>())
      ->capture_default_str();
  render->add_option("--streams", streams, "Monte Carlo random streams: per-ray or shared")
      ->capture_default_str();
  render->add_option("--threshold", threshold, "adaptive termination opacity")
      ->capture_default_str();
  render
      ->add_option("--classify", classify,
                   "preset (ct, ct-bone, mri, volpack) or transfer-function file; auto: ct for "
                   "Hounsfield data, mri otherwise")
      ->capture_default_str();
  render->add_flag("--no-shade", no_shade, "skip lighting (colour = material colour)");
  render
      ->add_option("--light", light,
                   "X,Y,Z: direction towards the light in viewing space (x right, y down the "
                   "image, z into the scene); two-sided Phong lighting")
      ->capture_default_str();
  render
      ->add_option("--phong", phong,
                   "KA,KD,KS,N: ambient, diffuse, specular coefficients and the specular "
                   "exponent (thesis eq 4.1)")
      ->capture_default_str();
  render
      ->add_option("--depth-cue", depth_cue,
                   "K1,K2: diffuse and specular light times 1 / (K1 + K2 d), d the voxel's "
                   "depth across the sphere around the volume (radius half its diagonal): 0 "
                   "at its nearest point, 1 at its farthest (1,0: no cueing)")
      ->capture_default_str();
  render->add_flag("--no-skip-empty", no_skip_empty,
                   "opencl: resample every sample, also those whose stencil reads only "
                   "transparent voxels, and match every PE (as --no-skip-pes; the same image; "
                   "for direct with balancing, to float rounding; for timing comparisons)");
  render->add_flag(
      "--no-skip-pes", no_skip_pes,
      "opencl, direct, adaptive, whole-ray mc, per sub-ray mc with --balance-sweeps 0: "
      "match every PE, also those whose cell has nothing in reach (the same image; "
      "for direct with balancing, to float rounding)");
  render->add_flag("--exact-opacity", exact_opacity,
                   "Monte Carlo: exact opacity, Monte Carlo colour (ch. 7.5 (a))");
  render->add_flag("--mc-stratified", stratified,
                   "Monte Carlo with --exact-opacity: stratified picks (one draw per walk, "
                   "walk m in the m-th n-th of the cumulative opacity)");
  render
      ->add_option("--mc-scope", mc_scope,
                   "Monte Carlo: walks over whole rays (whole: after the swap) or per sub-ray "
                   "(subray: in local compositing, then the swap; the reference engine cuts "
                   "the rays at the same PE cells, so --pe and --balance-sweeps apply to both)")
      ->capture_default_str();
  render->add_flag("--allocate", allocate,
                   "Monte Carlo per sub-ray: the ray's --samples walks allocated to its sub-rays "
                   "by opacity (ch. 7.5 (b))");
  render
      ->add_option("--layout", swap_layout,
                   "opencl engine: the binary swap's final layout, cut-and-stack or hierarchical "
                   "(same image)")
      ->capture_default_str();
  render
      ->add_option("--balance-sweeps", balance_sweeps,
                   "opencl engine (and the reference's --mc-scope subray): load-balancing "
                   "sweeps after the matching (ch. 5; 0: none). "
                   "The thesis's SIMD PEs wait for the busiest; PoCL's work-items do not, so 0 "
                   "is faster on a CPU (the same image to float rounding, but for per sub-ray "
                   "Monte Carlo, whose sub-rays the balance cuts)")
      ->check(decimal_integer())
      ->capture_default_str();
  render->add_option("--engine", engine, "reference (serial CPU) or opencl (the PE array)")
      ->capture_default_str();
  std::string pe_spec = "128x64";
  int device_index = -1;
  render
      ->add_option("--pe", pe_spec,
                   "opencl engine (and the reference's --mc-scope subray): PE count N or grid "
                   "WxH (a power of two)")
      ->capture_default_str();
  auto* device_opt =
      render
          ->add_option("--device", device_index,
                       "opencl engine: device index as `simdvol devices` lists (default: "
                       "SIMDVOL_DEVICE, else the first CPU device)")
          ->check(decimal_integer());
  render
      ->add_option("--phantom-size", phantom_size,
                   "size of the built-in CT phantom, N of an N^3 grid, " + kPhantomRange)
      ->check(decimal_integer())
      ->capture_default_str();
  render->add_option("--frames", frames, "turntable: number of frames")
      ->check(decimal_integer())
      ->capture_default_str();
  render->add_option("--step", step, "turntable: degrees of PHI per frame")->capture_default_str();
  render->add_flag("--times", show_times, "print per-stage times");
  std::string trace;
  render->add_option("--trace", trace,
                     "opencl: write every frame's kernels, in order on the device's clock, as a "
                     "Chrome trace (.json; chrome://tracing, ui.perfetto.dev)");
  render->add_option("-o,--output", out, "output image (.png, .exr, .tif)")->capture_default_str();

  // info
  auto* info = app.add_subcommand(
      "info",
      "describe a volume: dims, type, spacing, orientation, value range, histogram, percentiles "
      "(pQ: the finite value of rank floor(Q/100 (n - 1)), the lower one)");
  VolumeArgs iv;
  info->add_option("volume", iv.path, "volume file")->required();
  iv.add(info);

  // phantom
  auto* phantom = app.add_subcommand("phantom", "write a generated test volume");
  std::string phantom_kind, phantom_out;
  int phantom_n = 128, phantom_ss = 4;
  phantom->add_option("kind", phantom_kind, "shepp-logan or marschner-lobb")
      ->required()
      ->check(CLI::IsMember({"shepp-logan", "marschner-lobb"}));
  phantom->add_option("--size", phantom_n, "N (an N^3 grid), " + kPhantomRange)
      ->check(decimal_integer())
      ->capture_default_str();
  phantom
      ->add_option("--supersample", phantom_ss, "shepp-logan partial-volume sub-samples per axis")
      ->check(decimal_integer())
      ->check(CLI::Range(1, 8))
      ->capture_default_str();
  phantom->add_option("-o,--output", phantom_out, "output .nrrd")->required();

  // compare
  auto* compare = app.add_subcommand(
      "compare",
      "PSNR over RGB (psnr_db, peak 1) and the largest difference over RGBA (max_abs_diff) of "
      "two images; exit 0 whenever both were read (the figures are the caller's to judge)");
  std::string img_a, img_b;
  compare->add_option("a", img_a, "first image")->required();
  compare->add_option("b", img_b, "second image")->required();
  float compare_tol = -1.0f;
  compare
      ->add_option("--tolerance", compare_tol,
                   "also print how many pixels differ by more than T in some channel "
                   "(pixels_over_tolerance), how many in alpha (alpha_pixels_over_tolerance) "
                   "and where the largest difference is (worst_pixel X,Y)")
      ->check(kNotNegative);
  bool compare_rgba = false;
  compare->add_flag("--check-rgba", compare_rgba,
                    "also print how many pixels of each image are not premultiplied RGBA "
                    "(invalid_rgba_a, invalid_rgba_b): alpha outside [0, 1] or a colour outside "
                    "[0, alpha], beyond 1e-6, or NaN");

  // devices
  auto* devices = app.add_subcommand("devices", "list OpenCL platforms and devices");

  // mismatch
  auto* mm = add_mismatch_command(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    if (*render) {
      RenderOptions opt;
      opt.view = parse_view(view);
      const auto wh = parse_size(size);
      opt.width = wh[0];
      opt.height = wh[1];
      if (sampling == "voxel")
        opt.sampling = Sampling::voxel;
      else if (sampling == "pixel")
        opt.sampling = Sampling::pixel;
      else
        throw ArgumentError("--sampling", "expected voxel or pixel, not '" + sampling + "'");
      if (fit == "longest")
        opt.framing = Framing::longest;
      else if (fit == "diagonal")
        opt.framing = Framing::diagonal;
      else
        throw ArgumentError("--fit", "expected longest or diagonal, not '" + fit + "'");
      opt.order = order;
      if (composite == "direct")
        opt.composite.mode = CompositeMode::direct;
      else if (composite == "adaptive")
        opt.composite.mode = CompositeMode::adaptive;
      else if (composite == "mc")
        opt.composite.mode = CompositeMode::mc;
      else
        throw ArgumentError("--composite",
                            "expected direct, adaptive or mc, not '" + composite + "'");
      opt.composite.samples = samples;
      opt.composite.seed = seed;
      opt.composite.threshold = threshold;
      if (streams == "per-ray")
        opt.composite.streams = RandomStreams::per_ray;
      else if (streams == "shared")
        opt.composite.streams = RandomStreams::shared;
      else
        throw ArgumentError("--streams", "expected per-ray or shared, not '" + streams + "'");
      opt.shade.enabled = !no_shade;
      const auto l = parse_numbers(light, 3, "--light", "X,Y,Z");
      opt.shade.light = {l[0], l[1], l[2]};
      const auto ph = parse_numbers(phong, 4, "--phong", "KA,KD,KS,N");
      opt.shade.ka = ph[0];
      opt.shade.kd = ph[1];
      opt.shade.ks = ph[2];
      opt.shade.shininess = ph[3];
      const auto dc = parse_numbers(depth_cue, 2, "--depth-cue", "K1,K2");
      opt.shade.k1 = dc[0];
      opt.shade.k2 = dc[1];
      validate(opt.shade);
      if (frames < 1 || frames > 100000)
        throw ArgumentError("--frames", std::to_string(frames) + " is outside 1..100000");
      // Degrees per frame, bounded as --view's angles are (1e300 was taken).
      if (!(step >= -360.0 && step <= 360.0))
        throw ArgumentError("--step", "must be in -360 .. 360 degrees per frame");
      // The last frame's angle, before any frame is rendered.
      if (!std::isfinite(opt.view.phi + (frames - 1) * step))
        throw ArgumentError("--step", "the last frame's angle (--view's PHI + " +
                                          std::to_string(frames - 1) + " x --step) is not finite");
      if (device_opt->count() > 0 && device_index < 0)
        throw ArgumentError("--device", std::to_string(device_index) +
                                            " is negative (an index as `simdvol devices` lists)");
      opt.composite.exact_opacity = exact_opacity;
      opt.composite.stratified = stratified;
      if (engine != "reference" && engine != "opencl")
        throw ArgumentError("--engine",
                            "unknown engine '" + engine + "' (available: reference, opencl)");
      const PeGrid pes = parse_pe_grid(pe_spec, "--pe");
      // The engine lays its PEs out as pe_grid(count) does: another shape
      // was taken as its count alone (and named by --times as given).
      if (const PeGrid used = pe_grid(pes.count(), "--pe");
          used.width != pes.width || used.height != pes.height)
        throw ArgumentError(
            "--pe", pe_spec + ": the engine arranges " + std::to_string(pes.count()) + " PEs as " +
                        std::to_string(used.width) + "x" + std::to_string(used.height) + " (give " +
                        std::to_string(pes.count()) + " or that shape)");
      EngineOptions eo;
      eo.pes = pes.count();
      eo.fused = true;
      eo.reuse_layout = true;  // the volume does not change between frames
      // The kept classification pays from the second frame on; a single
      // frame would only write it (and hold as much memory again as the
      // RGBA voxel cells).
      eo.keep_classification = frames > 1;
      eo.skip_empty = !no_skip_empty;
      eo.skip_pes = !no_skip_pes;
      eo.balance_sweeps = balance_sweeps;
      if (swap_layout == "cut-and-stack")
        eo.layout = SwapLayout::cut_and_stack;
      else if (swap_layout == "hierarchical")
        eo.layout = SwapLayout::hierarchical;
      else
        throw ArgumentError("--layout",
                            "expected cut-and-stack or hierarchical, not '" + swap_layout + "'");
      if (mc_scope == "whole")
        eo.mc_scope = McScope::whole;
      else if (mc_scope == "subray")
        eo.mc_scope = McScope::subray;
      else
        throw ArgumentError("--mc-scope", "expected whole or subray, not '" + mc_scope + "'");
      eo.mc_allocate = allocate;
      validate(eo, opt);
      // Options that do nothing with the chosen compositing or engine are
      // refused, not ignored (as --mc-stratified without --exact-opacity).
      const auto refuse_unless = [&](bool applies, std::initializer_list<const char*> names,
                                     const char* where) {
        for (const char* name : names)
          if (!applies && render->count(name) > 0)
            throw ArgumentError(name, std::string("applies only to ") + where);
      };
      refuse_unless(
          opt.composite.mode == CompositeMode::mc,
          {"--samples", "--seed", "--streams", "--exact-opacity", "--mc-stratified", "--mc-scope"},
          "--composite mc");
      refuse_unless(opt.composite.mode == CompositeMode::adaptive, {"--threshold"},
                    "--composite adaptive");
      // The reference's per sub-ray Monte Carlo cuts the rays at the PE
      // cells and balances as the engine does: --pe and --balance-sweeps
      // decide its image too.
      const bool subray_reference = engine == "reference" && eo.mc_scope == McScope::subray;
      refuse_unless(engine == "opencl" || subray_reference, {"--pe", "--balance-sweeps"},
                    "--engine opencl, and --engine reference with --mc-scope subray");
      refuse_unless(engine == "opencl",
                    {"--device", "--layout", "--no-skip-empty", "--no-skip-pes", "--trace"},
                    "--engine opencl");
      // The PEs are left out only where the engine can (engine.cpp: mask_pes),
      // and only where the empty samples are skipped too.
      {
        const CompositeMode m = opt.composite.mode;
        refuse_unless(m == CompositeMode::direct || m == CompositeMode::adaptive ||
                          eo.mc_scope == McScope::whole || balance_sweeps == 0,
                      {"--no-skip-pes"},
                      "direct, adaptive, whole-ray Monte Carlo, and per sub-ray Monte Carlo "
                      "with --balance-sweeps 0 (with balancing every PE is matched already)");
        refuse_unless(!no_skip_empty, {"--no-skip-pes"},
                      "renders that skip the empty samples (--no-skip-empty matches every PE "
                      "already)");
      }
      refuse_unless(!no_shade, {"--light", "--phong", "--depth-cue"},
                    "lit renders (not with --no-shade)");
      refuse_unless(frames > 1, {"--step"}, "turntables (--frames 2 or more)");
      if (frames > 1 && std::fmod(step, 360.0) == 0.0)  // (for timing the same view, say)
        std::cerr << "simdvol: note: --step " << step
                  << " turns the view a whole number of turns a frame: the " << frames
                  << " frames show one view\n";
      // An empty name (render "$VOL" with VOL unset) is not the phantom.
      if (render->count("volume") > 0 && rv.path.empty())
        throw ArgumentError("volume", "empty name (give no volume for the built-in phantom)");
      const fs::path outp = out;
      // A turntable writes the numbered names, not -o's: each is checked
      // before the first frame, so that none is replaced before one that
      // cannot be written stops the run.
      check_image_extension(outp);
      {
        std::vector<fs::path> outputs;
        for (int f = 0; f < frames; ++f) outputs.push_back(numbered(outp, f, frames));
        check_output_paths(outputs, "-o");
      }
      const fs::path tracep = trace;
      if (render->count("--trace") > 0) {
        check_output_path(tracep, "--trace");
        if (tracep.extension() != ".json")
          throw ArgumentError("--trace", tracep.string() +
                                             ": the trace is JSON: give a name "
                                             "ending in .json");
        if (tracep.lexically_normal() == outp.lexically_normal())
          throw ArgumentError("--trace", "names the same file as -o");
      }
      std::vector<std::vector<KernelSpan>> traced;

      Volume vol;
      if (rv.path.empty()) {
        rv.check_format_options();
        if (phantom_size < kPhantomMin || phantom_size > kPhantomMax)
          throw ArgumentError("--phantom-size",
                              std::to_string(phantom_size) + " is outside " + kPhantomRange);
        vol = shepp_logan(phantom_size, 4);  // partial-volume boundaries
      } else {
        if (render->count("--phantom-size") > 0)
          throw ArgumentError("--phantom-size",
                              "applies only to the built-in phantom (a volume file is given)");
        vol = rv.load();
        for (const std::string& n : vol.notes()) std::cerr << "simdvol: note: " << n << "\n";
      }
      // No output may replace what the render reads, once the volume is
      // read and before any frame: the volume (a link named out.png
      // pointing at it; a DICOM slice named slice.tif, or another of its
      // series), the files its loader read beside it (a pair's other half,
      // a detached header's data files), or the --classify file.
      {
        ReadFiles read = read_files(vol, rv.path);
        if (std::error_code ec; fs::is_regular_file(classify, ec)) read.files.push_back(classify);
        for (int f = 0; f < frames; ++f)
          check_not_an_input(numbered(outp, f, frames), read.files, read.dicom_dir, "-o");
        if (render->count("--trace") > 0)
          check_not_an_input(tracep, read.files, read.dicom_dir, "--trace");
      }
      if (classify == "auto") classify = vol.range().min < -500.0f ? "ct" : "mri";
      // A preset's name is the preset, even where a file of that name lies
      // here: said, so that nobody takes the preset for their file.
      if (const auto names = classifier_preset_names();
          render->count("--classify") > 0 &&
          std::find(names.begin(), names.end(), classify) != names.end()) {
        std::error_code ec;
        if (fs::exists(classify, ec))
          std::cerr << "simdvol: note: --classify " << classify << " is the preset; for the file "
                    << classify << " here, give ./" << classify << "\n";
      }
      opt.classifier = classifier_from_spec(classify);
      if (opt.sampling == Sampling::pixel) pixel_sampling_note(vol, opt);

      std::optional<Device> device;
      std::optional<RenderEngine> gpu;  // its buffers are reused from frame to frame
      if (engine == "opencl") {
        device.emplace(device_index >= 0 ? std::optional<int>(device_index) : std::nullopt);
        gpu.emplace(*device, eo);
        if (const std::optional<std::string> p = program_cache_problem())
          std::cerr << "simdvol: note: " << *p << "\n";
      }
      const double phi0 = opt.view.phi;
      // The frames replace their files together: each is written to a
      // temporary file beside its name, and only once every frame has
      // rendered and been written are they renamed into place. A render,
      // write or signal that ends the run before then leaves every file of
      // an earlier run as it was (the batch's destructor, or the signal
      // handler, removes the temporary files); the renames are the one
      // window left (ImageBatch::commit names the frames replaced).
      ImageBatch frames_written(static_cast<std::size_t>(frames));
      // A turntable writes frame f while frame f + 1 renders (one write in
      // flight): get() waits for it and rethrows its error; on an error
      // elsewhere the future's destructor waits for the write to finish
      // before the batch (declared before it) removes the temporary files.
      std::future<void> writing;
      // A frame that fails (out of memory, a frame it cannot write) still
      // leaves the trace of the frames rendered before it: that is where
      // one looks for why.
      const auto write_trace_of_frames_before_error = [&] {
        if (trace.empty() || traced.empty()) return;
        try {
          write_file_atomically(tracep, {kernel_trace_json(traced)});
          std::cerr << "simdvol: note: --trace " << tracep.string() << " holds the "
                    << (traced.size() == 1 ? std::string("frame")
                                           : std::to_string(traced.size()) + " frames")
                    << " rendered before the error\n";
        } catch (const std::exception& e) {
          std::cerr << "simdvol: note: --trace not written: " << e.what() << "\n";
        }
      };
      try {
        for (int f = 0; f < frames; ++f) {
          opt.view.phi = phi0 + f * step;
          Image img;
          if (device) {
            EngineTimes t;
            EngineStats st;
            img = gpu->render(vol, opt, &t, show_times ? &st : nullptr);
            if (!trace.empty()) traced.push_back(std::move(t.kernels));
            if (show_times) std::cerr << opencl_times_line(f, pes, t, st);
          } else {
            RenderTimes t;
            img = eo.mc_scope == McScope::subray
                      ? render_subray_reference(vol, opt, eo.pes, eo.balance_sweeps, allocate, &t)
                      : render_reference(vol, opt, &t);
            if (show_times) std::cerr << reference_times_line(f, t);
          }
          if (writing.valid()) {
            writing.get();
            progress(f, frames);
          }
          writing = std::async(std::launch::async,
                               [&frames_written, im = std::move(img),
                                p = numbered(outp, f, frames)] { frames_written.write(im, p); });
        }
        writing.get();
        frames_written.commit();
      } catch (...) {
        if (writing.valid()) writing.wait();  // (its write done before the trace)
        write_trace_of_frames_before_error();
        throw;
      }
      progress(frames, frames);
      if (!trace.empty()) write_file_atomically(tracep, {kernel_trace_json(traced)});
      if (frames == 1) std::cout << "wrote " << fs::absolute(outp).string() << "\n";
      if (frames > 1)
        std::cout << "wrote " << frames
                  << " frames: " << fs::absolute(numbered(outp, 0, frames)).string() << " .. "
                  << numbered(outp, frames - 1, frames).filename().string() << "\n";
    } else if (*info) {
      if (iv.path.empty()) throw ArgumentError("volume", "empty name");
      int64_t volumes = 1;
      print_info(std::cout, iv.path, iv.load(true, &volumes));
      if (volumes > 1)
        std::cout << "volumes:  " << volumes << " in the "
                  << (iv.kind() == VolumeFileKind::dicom ? "series" : "file")
                  << " (4-D); the figures above are volume "
                  << (info->count("--volume-index") > 0 ? iv.volume_index : 0)
                  << "'s (--volume-index N describes another)\n";
    } else if (*phantom) {
      if (phantom_n < kPhantomMin || phantom_n > kPhantomMax)
        throw ArgumentError("--size", std::to_string(phantom_n) + " is outside " + kPhantomRange);
      if (phantom_kind != "shepp-logan" && phantom->count("--supersample") > 0)
        throw ArgumentError("--supersample",
                            "applies only to shepp-logan (marschner-lobb is sampled at the grid "
                            "points)");
      const fs::path p = phantom_out;
      check_output_path(p, "-o");
      // Any case, as the loader reads it; ".nrrd" alone is a hidden file's
      // name with no ending.
      if (upper(p.extension().string()) != ".NRRD")
        throw ArgumentError("-o", p.string() +
                                      ": the phantom is written as an attached-header NRRD: give "
                                      "a name ending in .nrrd (such as phantom.nrrd)");
      const Volume vol = phantom_kind == "shepp-logan" ? shepp_logan(phantom_n, phantom_ss)
                                                       : marschner_lobb(phantom_n);
      save_nrrd(vol, p);
      std::cout << "wrote " << fs::absolute(p).string() << "\n";
    } else if (*compare) {
      if (compare->count("--tolerance") != 0 && !(compare_tol >= 0.0f))
        throw ArgumentError(
            "--tolerance", "must be a number, 0 or more (got " + std::to_string(compare_tol) + ")");
      bool alpha_a = true, alpha_b = true;
      const Image a = read_image_with_alpha(img_a, &alpha_a),
                  b = read_image_with_alpha(img_b, &alpha_b);
      if (a.width() != b.width() || a.height() != b.height())
        throw ArgumentError(img_a + " and " + img_b,
                            "image sizes differ: " + std::to_string(a.width()) + "x" +
                                std::to_string(a.height()) + " against " +
                                std::to_string(b.width()) + "x" + std::to_string(b.height()));
      // Both figures before any output: an error prints nothing on stdout.
      const double db = psnr(a, b);
      const float diff = max_abs_diff(a, b);
      std::string extra;
      if (compare->count("--tolerance") != 0) {
        const PixelsOver over = pixels_over(a, b, compare_tol);
        extra += "pixels_over_tolerance " + std::to_string(over.count) +
                 "\nalpha_pixels_over_tolerance " + std::to_string(over.alpha_count) +
                 "\nworst_pixel " + std::to_string(over.worst_x) + "," +
                 std::to_string(over.worst_y) + "\n";
      }
      if (compare_rgba)
        extra += "invalid_rgba_a " + std::to_string(invalid_premultiplied(a)) +
                 "\ninvalid_rgba_b " + std::to_string(invalid_premultiplied(b)) + "\n";
      // A PNG (RGB over black) against a file with alpha: its alpha reads
      // as 1, and max_abs_diff is that difference, not the colours'.
      if (alpha_a != alpha_b) {
        Image opaque_as_other = alpha_a ? b : a;
        const Image& other = alpha_a ? a : b;
        for (std::size_t i = 0; i < other.pixels().size(); ++i)
          opaque_as_other.pixels()[i].a = other.pixels()[i].a;
        std::cerr << "simdvol: note: " << (alpha_a ? img_b : img_a)
                  << " has no alpha channel (it reads as opaque, alpha 1) where "
                  << (alpha_a ? img_a : img_b)
                  << " has one: max_abs_diff and the alpha counts include alpha's difference; "
                     "over RGB alone the largest difference is "
                  << max_abs_diff(opaque_as_other, other) << " (psnr_db is over RGB)\n";
      }
      // psnr_db is over RGB, max_abs_diff over RGBA: "inf" beside a
      // difference read as the same image with a fault in max_abs_diff.
      if (alpha_a == alpha_b && std::isinf(db) && diff > 0.0f)
        std::cerr << "simdvol: note: the colours are equal (psnr_db, over RGB, is inf); the "
                     "images differ in alpha alone, by up to "
                  << diff << " (max_abs_diff is over RGBA)\n";
      std::cout << "psnr_db " << db << "\nmax_abs_diff " << diff << "\n" << extra;
    } else if (*devices) {
      return print_devices(std::cout);
    } else if (*mm) {
      return run_mismatch_command(std::cout);
    }
  } catch (const Error& e) {
    std::cerr << "simdvol: error: " << e.what() << "\n";
    return 1;
  } catch (const fs::filesystem_error& e) {
    // A file-system call outside the checks (its message names the path).
    std::cerr << "simdvol: error: " << e.what() << "\n";
    return 1;
  } catch (const std::bad_alloc&) {
    // A host allocation outside the OpenCL buffers (theirs are CLErrors
    // naming the buffer) found no memory left.
    std::cerr << "simdvol: error: out of memory: the host has no memory left for this render "
                 "(a smaller volume, image or PE count needs less)\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "simdvol: unexpected error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
