// Pieces of the CLI kept apart from main() so they stay small and testable.
#pragma once

#include <CLI/CLI.hpp>

#include <array>
#include <filesystem>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

#include "simdvol/engine.hpp"

#include "simdvol/volume.hpp"

namespace simdvol {

/// For every whole-number option: CLI11 2.1 converts whole numbers in base
/// 0, so "010" was 8 and "0x10" 16, a number other than the one meant and
/// no word said. Refuses any text but optional blanks and sign, then
/// decimal digits without a leading zero ("0" itself is fine).
/// Why `v` is not a whole number in plain decimal (digits, a sign, blanks
/// either side; no leading zero, exponent or point), or empty where it is.
std::string decimal_problem(const std::string& v);
CLI::Validator decimal_integer();

/// `s` without its leading and trailing blanks (spaces, tabs), as the
/// options' validators read a value.
std::string_view trim_blanks(std::string_view s);

/// A number for `arg` (finite, the whole text used); ArgumentError else.
double parse_number(const std::string& s, const std::string& arg);

/// N comma-separated numbers for `arg` ("expected FORM" where there are
/// more or fewer, or a trailing comma).
std::vector<double> parse_numbers(const std::string& s, std::size_t n, const std::string& arg,
                                  const std::string& form);

/// THETA,PHI,VARPHI in degrees for `arg`, each in -360 .. 360 (the bench
/// tools' bounds: 1e300 degrees is no angle anyone means).
std::array<double, 3> parse_angles(const std::string& s, const std::string& arg);

/// `render --trace`: the frames' kernels as a Chrome trace (the JSON object
/// format of chrome://tracing and ui.perfetto.dev): one complete event
/// ("ph": "X") per kernel, microseconds from the first frame's first kernel
/// on the device's clock, "args" holding the frame's index. Kernels without
/// profiling times are left out.
std::string kernel_trace_json(const std::vector<std::vector<KernelSpan>>& frames);

/// `simdvol info`: dims, type, spacing, value range, histogram summary.
void print_info(std::ostream& os, const std::filesystem::path& path, const Volume& vol);

/// `simdvol devices`: OpenCL platforms and devices; returns the exit code.
int print_devices(std::ostream& os);

}  // namespace simdvol
