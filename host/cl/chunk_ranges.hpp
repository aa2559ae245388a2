// Internal: the NDRange and row width of the float16 per-voxel kernels
// (simdvol_shade16, simdvol_classify16, simdvol_shade_classify16): one
// work-item per chunk of 16 positions of a PE's voxel cell.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <string>

#include "simdvol/stages.hpp"
#include "voxel_ranges.hpp"

namespace simdvol::detail {

/// Work-items (chunks of 16 voxels) per work-group: voxel_wgs() / 4, i.e.
/// 64 (1,024 voxels) by default. Measured with bench/bench_shade_classify.cpp
/// --sweep (SIMDVOL_VOXEL_WGS = 64/256/1024 gives 16/64/256 chunks).
inline std::size_t chunk_wgs() {
  return std::max<std::size_t>(2, voxel_wgs() / 4);
}

/// 2-D range (chunk, PE) = (stride / 16 rounded up to L0, pes), local size
/// (L0, L1) with L0 = min(chunk_wgs(), 2^k >= stride / 16), L1 filling the
/// group with PEs.
inline PlaneRange chunk_range(const VoxelLayout& L) {
  const std::size_t wg = chunk_wgs();
  const std::size_t chunks = static_cast<std::size_t>(L.stride / 16);
  const std::size_t pes = static_cast<std::size_t>(L.pes());
  const std::size_t l0 = std::min(wg, pow2_at_least(chunks));
  const std::size_t l1 = std::max<std::size_t>(1, std::min(wg / l0, pes));
  return {cl::NDRange(round_up(chunks, l0), round_up(pes, l1)), cl::NDRange(l0, l1)};
}

/// Whether the float16 kernels store their results with non-temporal
/// stores (define SV_NT). Off: measured 15-30% slower than ordinary stores
/// for shade, classify and the fused kernel (bench --sweep, 256^3, 8192
/// PEs, PoCL 3.1 on a 2-core AMD EPYC). SIMDVOL_NT_STORES=1 turns them on
/// (for benchmarking).
inline bool nt_stores() {
  if (const char* e = std::getenv("SIMDVOL_NT_STORES")) return std::string(e) != "0";
  return false;
}

/// The row width SV_RW of the float16 shade kernels for cells of x extent
/// cx: 16 when cx is a multiple of 16, cx when cx is 8 or 4 (contiguous
/// vector loads), else 1 (per-lane positions and gathered loads, any cx;
/// see kernels/shade.cl). Never 0 for cx >= 1.
inline int shade_row_width(int64_t cx) {
  if (cx % 16 == 0) return 16;
  if (cx == 8 || cx == 4) return static_cast<int>(cx);
  return 1;
}

}  // namespace simdvol::detail
