// Internal: the NDRanges of the per-voxel kernels (shade, classify, gather).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <string>

#include "simdvol/error.hpp"
#include "simdvol/stages.hpp"

namespace simdvol::detail {

/// The kernel `name` for voxel cells of layout `L`: its `_il` twin on
/// interleaved cells (stages.hpp).
inline std::string voxel_kernel(const std::string& name, const VoxelLayout& L) {
  return L.interleaved ? name + "_il" : name;
}

/// Work-items per work-group of the per-voxel kernels. 64, 256 and 1024
/// measured within noise of each other (PoCL 3.1, 2 cores, 256^3, 8192 PEs;
/// bench/bench_shade_classify.cpp --sweep); 256 keeps >= 64 groups down to
/// small volumes. SIMDVOL_VOXEL_WGS overrides it (for benchmarking).
inline std::size_t voxel_wgs() {
  if (const char* e = std::getenv("SIMDVOL_VOXEL_WGS"); e && *e) {  // benchmarking knob
    char* end = nullptr;
    const long v = std::strtol(e, &end, 10);
    if (*end == '\0' && v >= 8 && v <= 4096 && (v & (v - 1)) == 0)
      return static_cast<std::size_t>(v);
    // (100 or -256 fell back to 256 without a word.)
    throw ArgumentError("SIMDVOL_VOXEL_WGS",
                        std::string("\"") + e + "\" is not a power of two 8 .. 4096");
  }
  return 256;
}

inline std::size_t pow2_at_least(std::size_t n) {
  std::size_t p = 1;
  while (p < n) p <<= 1;
  return p;
}

/// The 3-D range (x, row, PE) over the interiors of `L`'s cells: x rounded up
/// to LX in {8, 16, 32, 64}, rows = cy * cz rounded up to LY, all PEs; local
/// size (LX, LY, LZ) with LX * LY * LZ <= voxel_wgs() (a few distinct local
/// sizes only, since PoCL compiles each one).
struct CellRange {
  cl::NDRange global, local;
};
inline CellRange cell_range(const VoxelLayout& L) {
  const std::size_t wg = voxel_wgs();
  const std::size_t cx = static_cast<std::size_t>(L.cell()[0]);
  const std::size_t rows = static_cast<std::size_t>(L.cell()[1] * L.cell()[2]);
  const std::size_t pes = static_cast<std::size_t>(L.pes());
  const std::size_t lx =
      std::min<std::size_t>(std::clamp<std::size_t>(pow2_at_least(cx), 8, 64), wg);
  // At least 16 work-items per PE (the kernels zero a plane's tail of up to
  // 15 floats with one work-item each, from get_global_size(0)): the range
  // is rounded up to (LX, LY) here, so that where Device::run launches with
  // a smaller local size (LocalSize::at_most: a device that takes fewer
  // work-items) the range, and the work-items per PE, stay the same.
  const std::size_t ly = std::max<std::size_t>(std::max<std::size_t>(1, 16 / lx),
                                               std::min(wg / lx, pow2_at_least(rows)));
  const std::size_t lz = std::max<std::size_t>(1, std::min(wg / (lx * ly), pes));
  return {cl::NDRange(round_up(cx, lx), round_up(rows, ly), pes), cl::NDRange(lx, ly, lz)};
}

/// The 2-D range (position in a plane, PE) of the classify kernel: local
/// size (L0, L1) with L0 = min(voxel_wgs(), 2^k >= stride), L1 filling the
/// group with PEs.
struct PlaneRange {
  cl::NDRange global, local;
};
inline PlaneRange plane_range(const VoxelLayout& L) {
  const std::size_t wg = voxel_wgs();
  const std::size_t stride = static_cast<std::size_t>(L.stride);
  const std::size_t pes = static_cast<std::size_t>(L.pes());
  const std::size_t l0 = std::min(wg, pow2_at_least(stride));
  const std::size_t l1 = std::max<std::size_t>(1, std::min(wg / l0, pes));
  return {cl::NDRange(round_up(stride, l0), pes), cl::NDRange(l0, l1)};
}

}  // namespace simdvol::detail
