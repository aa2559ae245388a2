// Pieces of the CLI kept apart from main() so they stay small and testable.
#pragma once

#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

#include "simdvol/engine.hpp"

#include "simdvol/volume.hpp"

namespace simdvol {

/// Throws ArgumentError (naming `arg`) if the output's directory is missing,
/// the path is a directory, or it cannot be looked up (e.g. a name too long
/// for the file system), before any work is done.
void check_output_path(const std::filesystem::path& p, const char* arg);

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
