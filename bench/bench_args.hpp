// Strict parsing of the bench tools' command lines: every value is parsed
// whole and checked against its range, and every problem is an
// ArgumentError naming the option ("--runs: 0 is outside 1..1000"), which
// a tool's main reports with argument_error() (program name, the error, the
// usage text, exit status 2) before any device work starts. No OpenCL
// (simdvol_bench_args needs only simdvol_core), so simdvol-repro-tables
// uses it too; bench_common.hpp includes it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "simdvol/error.hpp"
#include "simdvol/view.hpp"

namespace simdvol::bench {

/// Parses a whole decimal integer; ArgumentError(option, "'s' is not an integer").
int64_t parse_int(const std::string& s, const std::string& option);
/// parse_int, then in [lo, hi]: ArgumentError(option, "v is outside lo..hi").
int64_t parse_int(const std::string& s, const std::string& option, int64_t lo, int64_t hi);
/// A whole unsigned decimal integer (a seed): 0 .. 2^64 - 1, no sign.
uint64_t parse_uint64(const std::string& s, const std::string& option);
/// Parses a whole finite decimal number (no leading space, no inf / nan);
/// ArgumentError(option, ...) otherwise.
double parse_double(const std::string& s, const std::string& option);
/// parse_double, then in [lo, hi].
double parse_double(const std::string& s, const std::string& option, double lo, double hi);
/// Splits a comma-separated list (empty items rejected: ArgumentError).
std::vector<std::string> split_list(const std::string& s, const std::string& option);
/// A comma-separated list of integers, each in [lo, hi].
std::vector<int64_t> parse_int_list(const std::string& s, const std::string& option, int64_t lo,
                                    int64_t hi);
/// A comma-separated list of numbers, each finite and in [lo, hi].
std::vector<double> parse_double_list(const std::string& s, const std::string& option, double lo,
                                      double hi);
/// A PE count: an integer that pe_grid accepts (a power of two in 1..kMaxPes).
int64_t parse_pes(const std::string& s, const std::string& option);
/// A file to be written later, checked now, not after minutes of frames
/// (ArgumentError naming the option), by `simdvol render`'s rule for its
/// outputs (check_output_path: a name, not a directory or FIFO, in a
/// directory that exists and in which a file can be made); and none of
/// `inputs` (the files the run reads, through symbolic links: --json naming
/// one replaced it with JSON), nor an Analyze .hdr's .img.
void check_output_file(const std::filesystem::path& file, const std::string& option,
                       const std::vector<std::filesystem::path>& inputs = {});
/// A directory to be written into later (made if missing): a name, and
/// not an existing file that is not a directory.
void check_output_dir(const std::filesystem::path& dir, const std::string& option);
/// check_output_dir, then the directory made (with its parents) if missing:
/// ArgumentError naming the option and the system's reason where it cannot
/// be (a file in the way of a parent, no permission), not a bare
/// "filesystem error", or where no file can be made in it.
void make_output_dir(const std::filesystem::path& dir, const std::string& option);

/// Walks a tool's argv: next() moves to each argument in turn, option() is
/// it, and the value readers take the argument after it (ArgumentError
/// "needs a value" when there is none) and parse it strictly, the errors
/// naming option().
class Args {
 public:
  Args(int argc, char** argv) : argc_(argc), argv_(argv) {}
  /// To the next argument; false when there are no more.
  bool next();
  /// The current argument.
  const std::string& option() const { return option_; }
  bool is(const char* name) const { return option_ == name; }
  /// --help or -h (the tools print their usage on stdout and exit 0).
  bool help() const { return option_ == "--help" || option_ == "-h"; }
  /// The argument after the current one, taken.
  std::string value();
  /// value(), a file or directory name: ArgumentError (option(), "needs a
  /// name, not an empty one") for "" (--volume "" rendered the phantom).
  std::string name();
  /// name(), a file that must exist (--brain: a missing one was skipped).
  std::string existing_file();
  int64_t integer(int64_t lo, int64_t hi);
  int64_t pes();
  uint64_t uint64();
  double number(double lo, double hi);
  std::vector<int64_t> int_list(int64_t lo, int64_t hi);
  std::vector<double> number_list(double lo, double hi);
  /// A view THETA,PHI,VARPHI in degrees, each in -360..360; ArgumentError
  /// (option(), "needs three angles theta,phi,varphi, got N") otherwise.
  ViewAngles view();
  /// ArgumentError(option(), "unknown option").
  [[noreturn]] void unknown() const;

 private:
  int argc_;
  char** argv_;
  int i_ = 0;
  std::string option_;
};

/// Reports a bad command line: "<program>: <e.what()>" and then `usage` on
/// stderr; returns 2 (main's exit status).
int argument_error(const char* program, const ArgumentError& e, const char* usage);

}  // namespace simdvol::bench
