// Strict command-line parsing of the bench tools (bench_args.hpp).
#include "bench_args.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "../host/core/output_checks.hpp"
#include "simdvol/pe_array.hpp"

namespace simdvol::bench {

namespace {

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

}  // namespace

int64_t parse_int(const std::string& s, const std::string& option) {
  int64_t v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
    throw ArgumentError(option, "'" + s + "' is not an integer");
  return v;
}

int64_t parse_int(const std::string& s, const std::string& option, int64_t lo, int64_t hi) {
  const int64_t v = parse_int(s, option);
  if (v < lo || v > hi)
    throw ArgumentError(option, std::to_string(v) + " is outside " + std::to_string(lo) + ".." +
                                    std::to_string(hi));
  return v;
}

uint64_t parse_uint64(const std::string& s, const std::string& option) {
  uint64_t v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
    throw ArgumentError(
        option, "'" + s + "' is not an integer in 0.." + std::to_string(static_cast<uint64_t>(-1)));
  return v;
}

double parse_double(const std::string& s, const std::string& option) {
  double v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size() || !std::isfinite(v))
    throw ArgumentError(option, "'" + s + "' is not a finite number");
  return v;
}

double parse_double(const std::string& s, const std::string& option, double lo, double hi) {
  const double v = parse_double(s, option);
  if (!(v >= lo && v <= hi))
    throw ArgumentError(option, s + " is outside " + num(lo) + ".." + num(hi));
  return v;
}

std::vector<std::string> split_list(const std::string& s, const std::string& option) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string tok; std::getline(ss, tok, ',');) {
    if (tok.empty()) throw ArgumentError(option, "empty item in '" + s + "'");
    out.push_back(tok);
  }
  if (out.empty() || s.back() == ',') throw ArgumentError(option, "empty list '" + s + "'");
  return out;
}

std::vector<int64_t> parse_int_list(const std::string& s, const std::string& option, int64_t lo,
                                    int64_t hi) {
  std::vector<int64_t> out;
  for (const std::string& tok : split_list(s, option))
    out.push_back(parse_int(tok, option, lo, hi));
  return out;
}

std::vector<double> parse_double_list(const std::string& s, const std::string& option, double lo,
                                      double hi) {
  std::vector<double> out;
  for (const std::string& tok : split_list(s, option))
    out.push_back(parse_double(tok, option, lo, hi));
  return out;
}

int64_t parse_pes(const std::string& s, const std::string& option) {
  const int64_t v = parse_int(s, option);
  pe_grid(v, option);  // ArgumentError unless a power of two in 1..kMaxPes
  return v;
}

void check_output_file(const std::filesystem::path& file, const std::string& option,
                       const std::vector<std::filesystem::path>& inputs) {
  namespace fs = std::filesystem;
  if (file.empty()) throw ArgumentError(option, "needs a name, not an empty one");
  // simdvol render's rule for its outputs: a directory, a FIFO, a missing
  // directory, or one in which no file can be made (found after every case
  // had run) refused now.
  check_output_path(file, option.c_str());
  std::vector<fs::path> read;
  for (const fs::path& in : inputs) {
    read.push_back(in);
    if (in.extension() == ".hdr") read.push_back(fs::path(in).replace_extension(".img"));
  }
  check_not_an_input(file, read, {}, option.c_str());
}

void check_output_dir(const std::filesystem::path& dir, const std::string& option) {
  namespace fs = std::filesystem;
  if (dir.empty()) throw ArgumentError(option, "needs a name, not an empty one");
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw ArgumentError(option, "'" + dir.string() + "' exists and is not a directory");
}

void make_output_dir(const std::filesystem::path& dir, const std::string& option) {
  check_output_dir(dir, option);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    throw ArgumentError(option,
                        "cannot make the directory '" + dir.string() + "': " + ec.message());
  check_can_make_files_in(dir, option.c_str());
}

bool Args::next() {
  if (++i_ >= argc_) return false;
  option_ = argv_[i_];
  return true;
}

std::string Args::value() {
  if (i_ + 1 >= argc_) throw ArgumentError(option_, "needs a value");
  return argv_[++i_];
}

std::string Args::name() {
  std::string v = value();
  if (v.empty()) throw ArgumentError(option_, "needs a name, not an empty one");
  return v;
}

std::string Args::existing_file() {
  std::string v = name();
  std::error_code ec;
  if (!std::filesystem::exists(v, ec)) throw ArgumentError(option_, "'" + v + "' does not exist");
  return v;
}

int64_t Args::integer(int64_t lo, int64_t hi) {
  return parse_int(value(), option_, lo, hi);
}

int64_t Args::pes() {
  return parse_pes(value(), option_);
}

uint64_t Args::uint64() {
  return parse_uint64(value(), option_);
}

double Args::number(double lo, double hi) {
  return parse_double(value(), option_, lo, hi);
}

std::vector<int64_t> Args::int_list(int64_t lo, int64_t hi) {
  return parse_int_list(value(), option_, lo, hi);
}

std::vector<double> Args::number_list(double lo, double hi) {
  return parse_double_list(value(), option_, lo, hi);
}

ViewAngles Args::view() {
  const std::vector<double> v = number_list(-360, 360);
  if (v.size() != 3)
    throw ArgumentError(option_,
                        "needs three angles theta,phi,varphi, got " + std::to_string(v.size()));
  return {v[0], v[1], v[2]};
}

void Args::unknown() const {
  throw ArgumentError(option_, "unknown option");
}

int argument_error(const char* program, const ArgumentError& e, const char* usage) {
  std::fprintf(stderr, "%s: %s\n%s", program, e.what(), usage);
  return 2;
}

}  // namespace simdvol::bench
