// Pieces of the CLI kept apart from main() so they stay small and testable.
#pragma once

#include <filesystem>
#include <ostream>

#include "simdvol/volume.hpp"

namespace simdvol {

/// Throws ArgumentError (naming `arg`) if the output's directory is missing,
/// the path is a directory, or it cannot be looked up (e.g. a name too long
/// for the file system), before any work is done.
void check_output_path(const std::filesystem::path& p, const char* arg);

/// `simdvol info`: dims, type, spacing, value range, histogram summary.
void print_info(std::ostream& os, const std::filesystem::path& path, const Volume& vol);

/// `simdvol devices`: OpenCL platforms and devices; returns the exit code.
int print_devices(std::ostream& os);

}  // namespace simdvol
