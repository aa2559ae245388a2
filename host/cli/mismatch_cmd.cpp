// `simdvol mismatch` (see mismatch_cmd.hpp): the multi-pass shear rotation
// against the minimum-mismatch mapping (thesis 5.3.4, 5.4, 5.7).
#include "mismatch_cmd.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "../core/file_checks.hpp"
#include "../core/output_checks.hpp"
#include "cli_commands.hpp"
#include "simdvol/error.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/mismatch.hpp"
#include "simdvol/view.hpp"

namespace fs = std::filesystem;

namespace simdvol {

namespace {

struct Options {
  double theta = 30.0;
  std::string view = "30,20,10";
  int size = 256;
  int size3 = 64;
  std::string plot, csv;
};
Options g_opt;
CLI::App* g_cmd = nullptr;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

void print_stats_header(std::ostream& os) {
  os << "  method                   mean     p50     p90     p99     max   |coord| mean   max\n";
}
void print_stats(std::ostream& os, const MismatchStats& s) {
  char buf[200];
  std::snprintf(buf, sizeof buf, "  %-22s %7.4f %7.4f %7.4f %7.4f %7.4f   %7.4f %7.4f\n",
                s.method.c_str(), s.mean, s.p50, s.p90, s.p99, s.max, s.coord_mean, s.coord_max);
  os << buf;
}

void print_report(std::ostream& os, const MismatchReport& r) {
  os << "  shear route: " << r.description << "\n";
  print_stats_header(os);
  print_stats(os, r.shear);
  print_stats(os, r.floor);
  print_stats(os, r.nearest);
  // (not a ratio of rounding noise: at 90 degrees both are about 1e-16)
  if (r.nearest.max > 1e-9 && r.nearest.mean > 1e-9)
    os << "  shear max / nearest max = " << fmt("%.3f", r.shear.max / r.nearest.max)
       << ", shear mean / nearest mean = " << fmt("%.3f", r.shear.mean / r.nearest.mean) << "\n";
}

std::string ops_str(const OpCount& c) {
  char buf[96];
  const auto r3 = [](double v) { return std::round(v * 1000) / 1000; };  // 3 decimals
  std::snprintf(buf, sizeof buf, "%5gM %5gA %4gR", r3(c.mul_per()), r3(c.add_per()),
                r3(c.rnd_per()));
  return buf;
}

void print_ops(std::ostream& os, const ViewAngles& view) {
  const int n = 32;  // per-sample counts do not depend on n (bar the one direct start)
  const Mat3 tinv = transpose(rotation(view.theta, view.phi, view.varphi));
  const ShearRoute r7 = shear_route_3d(tinv);
  const ShearRoute r5 = shear_route_zy(30, 20);
  const ShearRoute r2 = paeth_2d(30);
  struct Row {
    std::string name;
    OpCount c;
    std::string thesis, note;
  };
  const std::vector<Row> rows = {
      {"min-mismatch, direct T^-1 p, nearest", count_min_mismatch(tinv, n, Interp::nearest, false),
       "9M + 3A + R", "9M+6A for T^-1 p (3 dot products of 3), 3 roundings, one per axis"},
      {"min-mismatch, incremental, nearest", count_min_mismatch(tinv, n, Interp::nearest, true),
       "9M + 3A + R", "p += column of T^-1 (3A); 9M+6A once per volume"},
      {"min-mismatch, direct, trilinear", count_min_mismatch(tinv, n, Interp::linear, false),
       "23M + 10A + 9R",
       "9M+6A + 3 floors + 3 fractions (3A) + 3 (1-f) (3A) + 7 lerps (1-f)a+fb (14M+7A)"},
      {"min-mismatch, incremental, trilinear", count_min_mismatch(tinv, n, Interp::linear, true),
       "23M + 10A + 9R", "as above with 3A for T^-1 p"},
      {"shear 2-D eq 5.4 (3 passes), nearest", count_shear(r2, 128, 2, Interp::nearest), "-",
       "per pass 1M (offset) + 1R + 1A (move)"},
      {"shear 2-D eq 5.4 (3 passes), linear", count_shear(r2, 128, 2, Interp::linear), "-",
       "per pass + fraction, 1-f (2A) and a lerp (2M+1A)"},
      {"shear 3-D Rz Ry (5 passes), nearest", count_shear(r5, n, 3, Interp::nearest), "-",
       "4 x (1M+1A+1R) + (2M+2A+1R)"},
      {"shear 3-D Rz Ry (5 passes), linear", count_shear(r5, n, 3, Interp::linear),
       "20M + 11A + 9R", "4 x (3M+4A+1R) + (4M+5A+1R); every pass resamples along one axis"},
      {"shear 3-D this view (" + std::to_string(r7.passes.size()) + " passes), nearest",
       count_shear(r7, n, 3, Interp::nearest), "-", "one-coordinate and two-coordinate passes"},
      {"shear 3-D this view (" + std::to_string(r7.passes.size()) + " passes), linear",
       count_shear(r7, n, 3, Interp::linear), "20M + 11A + 9R",
       "one-coordinate pass 3M+4A+1R, two-coordinate pass 4M+5A+1R"},
  };
  os << "\nOperation counts per sample (counting implementation on a " << n
     << "^3 volume / 128^2 image;\nM = multiplications, A = additions and subtractions, R = "
        "roundings/floors):\n";
  char buf[300];
  std::snprintf(buf, sizeof buf, "  %-42s %-26s %-16s %s\n", "path", "measured", "thesis 5.7.2",
                "what is counted");
  os << buf;
  for (const Row& row : rows) {
    std::snprintf(buf, sizeof buf, "  %-42s %-26s %-16s %s\n", row.name.c_str(),
                  ops_str(row.c).c_str(), row.thesis.c_str(), row.note.c_str());
    os << buf;
  }
  os << R"(  Where we agree and differ with thesis 5.7.2:
  - min-mismatch nearest: the thesis's 9M + 3A + R mixes the direct rotation's 9M with the
    incremental one's 3A; a direct T^-1 p costs 9M + 6A (the thesis itself says "9
    multiplications and 6 additions" for one rotation), an incremental one 3A and no M.
    Finding the grid point needs one rounding per axis, 3R, not 1R.
  - min-mismatch trilinear: 23M agrees (9M rotation + 14M for 7 lerps written (1-f)a + fb). The
    lerps' 7A agree; we also count the 3 fractions x - floor(x) and the 3 (1 - f), and the
    rotation's 6A, giving 19A where the thesis has 10A. We need 3 floors, the thesis 9R.
  - Schroeder & Salem (4 one-coordinate + 1 two-coordinate pass, linear): 20M in the thesis =
    4 x (1M shear + 2M lerp) + (2M shear + 6M bilinear); every one of our passes moves a single
    coordinate, so its resampling is 1-D (2M) even when the offset depends on two coordinates
    (x += a y + b z shifts whole x-beams), giving 16M. We round once per pass (5R, thesis 9R)
    and count the fraction, 1 - f and address update per pass (21A, thesis 11A).
  - A general three-angle rotation needs 7 of our passes (5 + 2); Schroeder & Salem's 5-pass
    count holds for two-angle rotations (see the route descriptions above).
)";
}

// Bar chart: one panel per dimension, bins of 0.05 in Euclidean mismatch.
Image draw_plot(const MismatchReport& r2, const MismatchReport& r3, int* bins_out) {
  double maxd = 0;
  for (const MismatchReport* r : {&r2, &r3})
    maxd = std::max({maxd, r->shear.max, r->floor.max, r->nearest.max});
  const double w = r2.shear.bin_width;
  const int bins = std::max(1, static_cast<int>(std::ceil(maxd / w - 1e-12)));
  *bins_out = bins;
  const int bar = 4, gap = 3, bin_px = 3 * bar + gap, margin = 20, panel_h = 200;
  const int width = 2 * margin + bins * bin_px, height = 2 * (panel_h + 2 * margin);
  Image img(width, height);
  const Rgba colour[3] = {{0.9f, 0.2f, 0.1f, 1}, {0.2f, 0.4f, 1.0f, 1}, {0.2f, 0.8f, 0.3f, 1}};
  const Rgba axis{0.8f, 0.8f, 0.8f, 1};
  auto fill = [&](int x0, int y0, int x1, int y1, Rgba c) {
    for (int y = std::max(0, y0); y < std::min(height, y1); ++y)
      for (int x = std::max(0, x0); x < std::min(width, x1); ++x) img.at(x, y) = c;
  };
  int p = 0;
  for (const MismatchReport* r : {&r2, &r3}) {
    const int base = (p + 1) * (panel_h + 2 * margin) - margin;  // baseline row
    const MismatchStats* m[3] = {&r->shear, &r->floor, &r->nearest};
    double top = 0;
    for (const MismatchStats* s : m)
      for (int64_t c : s->hist) top = std::max(top, static_cast<double>(c) / s->samples);
    for (int k = 0; k < 3; ++k)
      for (int b = 0; b < bins && b < static_cast<int>(m[k]->hist.size()); ++b) {
        const double frac = static_cast<double>(m[k]->hist[b]) / m[k]->samples;
        const int hgt = static_cast<int>(std::lround(frac / top * panel_h));
        const int x0 = margin + b * bin_px + k * bar;
        fill(x0, base - hgt, x0 + bar, base, colour[k]);
      }
    fill(margin, base, width - margin, base + 1, axis);
    for (int b = 0; b <= bins; ++b) {  // ticks: 0.25 short, 0.5 long
      const double x = b * w;
      const bool half = std::fabs(x * 2 - std::round(x * 2)) < 1e-9;
      const bool quarter = std::fabs(x * 4 - std::round(x * 4)) < 1e-9;
      if (!quarter) continue;
      const int tx = margin + b * bin_px - 1;
      fill(tx, base + 1, tx + 1, base + (half ? 9 : 5), axis);
    }
    ++p;
  }
  return img;
}

void write_csv(const fs::path& path, const MismatchReport& r2, const MismatchReport& r3) {
  std::ostringstream out;
  out << "dims,method,measure,bin_lo,bin_hi,count,fraction\n";
  for (const MismatchReport* r : {&r2, &r3})
    for (const MismatchStats* s : {&r->shear, &r->floor, &r->nearest})
      for (int measure = 0; measure < 2; ++measure) {
        const auto& h = measure == 0 ? s->hist : s->coord_hist;
        const double total = static_cast<double>(measure == 0 ? s->samples : s->samples * r->dims);
        for (std::size_t b = 0; b < h.size(); ++b)
          out << r->dims << "," << s->method << "," << (measure == 0 ? "euclidean" : "coordinate")
              << "," << b * s->bin_width << "," << (b + 1) * s->bin_width << "," << h[b] << ","
              << h[b] / total << "\n";
      }
  write_file_atomically(path, {out.str()});
}

}  // namespace

CLI::App* add_mismatch_command(CLI::App& app) {
  g_cmd = app.add_subcommand(
      "mismatch",
      "multi-pass shear rotation vs minimum-mismatch mapping: mismatch histograms, op counts");
  g_cmd->add_option("--theta", g_opt.theta, "2-D rotation angle in degrees")->capture_default_str();
  g_cmd->add_option("--view", g_opt.view, "3-D rotation THETA,PHI,VARPHI in degrees (eq 5.2)")
      ->capture_default_str();
  g_cmd->add_option("--size", g_opt.size, "2-D viewing grid N x N")
      ->check(decimal_integer())
      ->capture_default_str();
  g_cmd->add_option("--size3", g_opt.size3, "3-D viewing grid N^3")
      ->check(decimal_integer())
      ->capture_default_str();
  g_cmd->add_option("--plot", g_opt.plot, "histogram bar chart (.png, .exr, .tif)");
  g_cmd->add_option("--csv", g_opt.csv, "histograms as CSV");
  return g_cmd;
}

int run_mismatch_command(std::ostream& os) {
  const Options& o = g_opt;
  if (!(o.theta >= -360.0 && o.theta <= 360.0))
    throw ArgumentError("--theta", "must be in -360 .. 360 degrees");
  if (o.size < 1 || o.size > 4096)
    throw ArgumentError("--size", std::to_string(o.size) + " is outside 1..4096");
  if (o.size3 < 1 || o.size3 > 256)
    throw ArgumentError("--size3", std::to_string(o.size3) + " is outside 1..256");
  const auto angles = parse_angles(o.view, "--view");
  const ViewAngles view{angles[0], angles[1], angles[2]};
  // Given but empty ('--csv ""') is a mistake, not "no CSV".
  if (g_cmd->count("--plot") > 0 && o.plot.empty())
    throw ArgumentError("--plot", "empty output path");
  if (g_cmd->count("--csv") > 0 && o.csv.empty()) throw ArgumentError("--csv", "empty output path");
  if (!o.plot.empty()) {
    check_output_path(o.plot, "--plot");
    check_image_extension(o.plot);
  }
  if (!o.csv.empty()) check_output_path(o.csv, "--csv");
  if (!o.plot.empty() && !o.csv.empty() &&
      fs::absolute(o.plot).lexically_normal() == fs::absolute(o.csv).lexically_normal())
    throw ArgumentError("--plot and --csv", "both name " + o.csv + ": give two files");

  os << "Mismatch distance = |grid point used - T^-1 p_H| for every viewing-grid point p_H "
        "(centred integer coordinates).\n"
        "shear: rounded after every pass; min-mismatch floor: floor(T^-1 p_H) (eq 5.5); "
        "nearest: round(T^-1 p_H).\n\n";
  const MismatchReport r2 = mismatch_2d(o.theta, o.size, o.size);
  os << "2-D, theta = " << o.theta << " deg, " << o.size << " x " << o.size << " grid:\n";
  print_report(os, r2);
  const MismatchReport r3 = mismatch_3d(view, o.size3);
  os << "\n3-D, T(" << view.theta << ", " << view.phi << ", " << view.varphi << ") (eq 5.2), "
     << o.size3 << "^3 grid:\n";
  print_report(os, r3);

  const PointError inv = paeth_point_error(30, 47, 181);
  const PointError fwd = paeth_forward_point_error(30, 47, 181);
  os << "\nThesis 5.7.1 case, theta = 30 deg, x = 47, y = 181 (thesis: x error 1.04):\n"
     << "  eq 5.4 as printed (x by -tan 15, y by sin 30, x by -tan 15; rounding half away from\n"
     << "  zero after each pass) maps p_H = (47, 181) back to (" << inv.rounded[0] << ", "
     << inv.rounded[1] << "); exact T^-1 p_H = (" << fmt("%.4f", inv.exact[0]) << ", "
     << fmt("%.4f", inv.exact[1]) << "): x error " << fmt("%+.4f", inv.dx) << ", y error "
     << fmt("%+.4f", inv.dy) << ", distance " << fmt("%.4f", inv.dist) << "\n"
     << "  forward reading (object (47, 181) sheared by T_theta itself): (" << fwd.rounded[0]
     << ", " << fwd.rounded[1] << ") vs (" << fmt("%.4f", fwd.exact[0]) << ", "
     << fmt("%.4f", fwd.exact[1]) << "): x error " << fmt("%+.4f", fwd.dx) << "\n"
     << R"(  Why not 1.04: eq 5.4's product is [[c, -s], [s, c]], the transpose of the T_theta it
  claims to equal, i.e. T_theta^-1 -- so it is read here as the inverse map p_H -> G, like
  eq 5.5. Pass by pass: x += round(-0.26795 * 181 = -48.4988) = -48 -> x = -1 (residual
  +0.4988); y += round(0.5 * -1): an exact tie, which in double (sin 30 = 0.49999999999999994)
  rounds to 0 -> y = 181 (residual +0.5; breaking the tie away from zero gives y = 180 and a y
  error of -0.2506 instead); x += round(-0.26795 * 181) = -48 -> x = -49 (residual +0.4988).
  The x error is 0.4988 - 0.26795 * 0.7494 + 0.4988 = +0.797 (+0.797 with either tie rule).
  No reading we tried gives 1.04: shear orders x-y-x and y-x-y, both signs of
  the tan and sin terms, forward and inverse maps, rounding half away / half up / half even /
  floor / ceil / truncate of the offsets or of the positions, rounding skipped in any subset
  of passes, and Wittenbrink's inverse transformation after the rounding. With floor
  rounding the x error is -1.203, with truncation +0.797 or -1.203 depending on direction;
  1.04 only appears with the centre moved to contrived points (e.g. (127.5, 127.5) with
  floor rounding gives 1.035). The thesis's point stands in kind: over the grid the shear
  route's per-coordinate error exceeds 1 (non-proximal) -- see |coord| max above.
)";
  print_ops(os, view);

  // Both outputs or neither: the plot goes to a temporary name beside it
  // and takes its own only after the CSV is written (a CSV that failed on
  // a full disk had left a new plot over the old one).
  int bins = 0;
  fs::path plot_tmp;
  if (!o.plot.empty()) {
    const fs::path target = write_target(o.plot);
    // (Short: a plot's name near the file system's limit leaves no room.)
    plot_tmp = target.parent_path() /
               (".simdvol-plot-" + std::to_string(::getpid()) + target.extension().string());
    try {
      write_image(draw_plot(r2, r3, &bins), plot_tmp);
    } catch (const FileError& e) {
      throw FileError(o.plot, e.problem());  // the user's name, not the temporary one
    }
    if (!o.csv.empty()) {
      try {
        write_csv(o.csv, r2, r3);
      } catch (...) {
        std::error_code ec;
        fs::remove(plot_tmp, ec);
        throw;
      }
    }
    std::error_code ec;
    fs::rename(plot_tmp, target, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove(plot_tmp, ec);
      throw FileError(o.plot, "cannot put the plot in place: " + why);
    }
  } else if (!o.csv.empty()) {
    write_csv(o.csv, r2, r3);
  }
  if (!o.plot.empty()) {
    os << "\nwrote " << fs::absolute(o.plot).string()
       << ": top panel 2-D, bottom panel 3-D; x axis: Euclidean mismatch distance from 0 to "
       << fmt("%.2f", bins * r2.shear.bin_width)
       << " in bins of 0.05 (long ticks every 0.5, short every 0.25); y axis: fraction of "
          "samples in the bin, scaled to each panel's tallest bar; bars per bin: red = shear, "
          "blue = min-mismatch floor, green = min-mismatch nearest.\n";
  }
  if (!o.csv.empty()) os << "wrote " << fs::absolute(o.csv).string() << "\n";
  return 0;
}

}  // namespace simdvol
