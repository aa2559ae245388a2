#include "cli_commands.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <locale>
#include <sstream>
#include <vector>

#include "../core/file_checks.hpp"
#include "simdvol/device.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace fs = std::filesystem;

namespace simdvol {

std::string_view trim_blanks(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::string decimal_problem(const std::string& v) {
  std::string_view s = trim_blanks(v);
  if (!s.empty() && (s.front() == '+' || s.front() == '-')) s.remove_prefix(1);
  if (s.empty() || s.find_first_not_of("0123456789") != std::string_view::npos)
    return "expected a whole number in decimal, not '" + v + "'";
  if (s.size() > 1 && s.front() == '0')
    return "'" + v + "' has a leading zero (it would be read as octal): write it without";
  return std::string();
}

CLI::Validator decimal_integer() {
  return CLI::Validator([](std::string& v) { return decimal_problem(v); }, "", "decimal");
}

double parse_number(const std::string& s, const std::string& arg) {
  // strtod, not stod: stod throws on any ERANGE, so 5e-324 (a subnormal)
  // was "not a number".
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  // (Hexadecimal, 0x1p3 for 8, is C's, not a number a user writes: refused.)
  if (s.empty() || end != s.c_str() + s.size() || std::isnan(v) ||
      s.find_first_of("xX") != std::string::npos)
    throw ArgumentError(arg, "'" + s + "' is not a number");
  if (!std::isfinite(v) || (errno == ERANGE && std::fabs(v) > 1.0))
    throw ArgumentError(arg, "'" + s + "' is beyond the largest number (about 1.8e308)");
  return v;
}

std::vector<double> parse_numbers(const std::string& s, std::size_t n, const std::string& arg,
                                  const std::string& form) {
  std::vector<std::string> parts;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');) parts.push_back(item);
  if (parts.size() != n || (!s.empty() && s.back() == ','))
    throw ArgumentError(arg, "expected " + form + ", not '" + s + "'");
  std::vector<double> v;
  for (const auto& p : parts) v.push_back(parse_number(p, arg));
  return v;
}

std::array<double, 3> parse_angles(const std::string& s, const std::string& arg) {
  const auto a = parse_numbers(s, 3, arg, "THETA,PHI,VARPHI in degrees");
  for (double x : a)
    if (x < -360.0 || x > 360.0)
      throw ArgumentError(arg, "'" + s + "': each angle must be in -360 .. 360 degrees");
  return {a[0], a[1], a[2]};
}

namespace {

/// "left, front, top" for "LAS".
std::string anatomical_words(const std::string& code) {
  std::string words;
  for (char c : code) {
    if (!words.empty()) words += ", ";
    switch (c) {
      case 'R':
        words += "right";
        break;
      case 'L':
        words += "left";
        break;
      case 'A':
        words += "front";
        break;
      case 'P':
        words += "back";
        break;
      case 'S':
        words += "top";
        break;
      default:
        words += "bottom";
        break;
    }
  }
  return words;
}

}  // namespace

void print_info(std::ostream& os, const fs::path& path, const Volume& vol) {
  const auto& d = vol.dims();
  const auto& s = vol.spacing();
  const ValueRange r = vol.range();
  os << "file:     " << path.string() << "\n";
  os << "dims:     " << d[0] << " x " << d[1] << " x " << d[2] << " (" << vol.voxel_count()
     << " voxels)\n";
  os << "type:     " << to_string(vol.type()) << "\n";
  os << "spacing:  " << s[0] << " x " << s[1] << " x " << s[2] << "\n";
  if (vol.orientation().empty())
    os << "axes:     the file does not say where they point in the patient\n";
  else
    os << "axes:     " << vol.orientation() << " (x, y, z point to the patient's "
       << anatomical_words(vol.orientation()) << ")\n";
  for (const std::string& n : vol.notes()) os << "note:     " << n << "\n";
  os << "range:    " << r.min << " .. " << r.max << "\n";
  std::size_t nonfinite = 0;
  double sum = 0;
  for (float v : vol.data()) {
    if (!std::isfinite(v))
      ++nonfinite;
    else
      sum += v;
  }
  const std::size_t finite = vol.voxel_count() - nonfinite;
  os << "mean:     " << (finite ? sum / static_cast<double>(finite) : 0.0) << "\n";
  if (nonfinite) os << "nonfinite voxels: " << nonfinite << "\n";
  // Histogram summary: 16 equal bins over the range, and percentiles.
  constexpr int kBins = 16;
  std::vector<std::size_t> bins(kBins, 0);
  const double width = r.max > r.min ? (double(r.max) - r.min) / kBins : 1.0;
  for (float v : vol.data()) {
    if (!std::isfinite(v)) continue;
    int b = static_cast<int>((v - r.min) / width);
    bins[std::clamp(b, 0, kBins - 1)]++;
  }
  os << "histogram (" << kBins << " bins):\n";
  const std::size_t most = *std::max_element(bins.begin(), bins.end());
  for (int b = 0; b < kBins; ++b) {
    const double lo = r.min + b * width;
    const int bar = most ? static_cast<int>(40.0 * bins[b] / most) : 0;
    os << "  " << std::setw(12) << lo << " " << std::setw(10) << bins[b] << " "
       << std::string(bar, '#') << "\n";
  }
  std::vector<float> sorted;
  sorted.reserve(finite);
  for (float v : vol.data())
    if (std::isfinite(v)) sorted.push_back(v);
  if (!sorted.empty()) {
    os << "percentiles:";
    // Each selection searches only above the last: what lies past it is no
    // smaller, so the rank is the same as in the whole.
    std::size_t from = 0;
    for (double q : {0.01, 0.5, 0.99}) {
      const auto k = static_cast<std::size_t>(q * static_cast<double>(sorted.size() - 1));
      // (a rank already selected, as 1 of 3 values gives twice, is in place:
      // nth_element with its nth before its first was undefined)
      if (k >= from)
        std::nth_element(sorted.begin() + static_cast<std::ptrdiff_t>(from),
                         sorted.begin() + static_cast<std::ptrdiff_t>(k), sorted.end());
      os << " p" << static_cast<int>(q * 100) << "=" << sorted[k];
      from = std::max(from, k + 1);
    }
    os << "\n";
  }
}

int print_devices(std::ostream& os) {
  // NoDeviceError (no platform: names the package to install) propagates to
  // main(), which prints it and exits non-zero.
  const std::vector<DeviceInfo> devices = list_devices();
  // A bad SIMDVOL_DEVICE: the list all the same (the error points here for
  // it), none marked, then the error and a non-zero exit.
  try {
    os << describe_devices(devices, choose_device(devices));
  } catch (const ArgumentError& e) {
    os << describe_devices(devices, -1);
    std::cerr << "simdvol: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

std::string kernel_trace_json(const std::vector<std::vector<KernelSpan>>& frames) {
  std::uint64_t t0 = 0;
  bool any = false;
  for (const auto& f : frames)
    for (const KernelSpan& k : f)
      if (k.end_ns != 0 && (!any || k.start_ns < t0)) {
        t0 = k.start_ns;
        any = true;
      }
  std::ostringstream os;
  os.imbue(std::locale::classic());
  os << std::fixed << std::setprecision(3);
  os << "{\"displayTimeUnit\": \"ms\", \"traceEvents\": [";
  const char* sep = "\n";
  for (std::size_t f = 0; f < frames.size(); ++f)
    for (const KernelSpan& k : frames[f]) {
      if (k.end_ns == 0) continue;
      // Kernel names are C identifiers: nothing to escape.
      os << sep << "{\"name\": \"" << k.kernel << "\", \"cat\": \"kernel\", \"ph\": \"X\", \"ts\": "
         << static_cast<double>(k.start_ns - t0) * 1e-3
         << ", \"dur\": " << static_cast<double>(k.end_ns - k.start_ns) * 1e-3
         << ", \"pid\": 1, \"tid\": 1, \"args\": {\"frame\": " << f << "}}";
      sep = ",\n";
    }
  os << "\n]}\n";
  return os.str();
}

}  // namespace simdvol
