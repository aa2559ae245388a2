// Access to the kernel sources embedded by cmake/EmbedKernels.cmake (the
// generated simdvol_kernel_files.cpp in the build directory). Internal.
#pragma once

#include <span>
#include <string_view>

namespace simdvol::detail {

struct EmbeddedKernelFile {
  std::string_view name;
  std::string_view source;
};

std::span<const EmbeddedKernelFile> embedded_kernel_files();

}  // namespace simdvol::detail
