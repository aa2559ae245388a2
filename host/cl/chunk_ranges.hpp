// Internal: the NDRange and row width of the float16 per-voxel kernels
// (simdvol_shade16, simdvol_classify16, simdvol_shade_classify16): one
// work-item per chunk of 16 positions of a PE's voxel cell.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <string>

#include "env_switch.hpp"
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

/// Whether the float16 kernels' buffers `outs` can take non-temporal
/// stores of float16 (which need their natural, 64-byte alignment; every
/// chunk and plane starts on a multiple of 16 floats from the buffer's
/// start): not a buffer over the caller's host memory (CL_MEM_USE_HOST_PTR)
/// that is not 64-byte aligned. Null entries are skipped.
inline bool nt_aligned(std::initializer_list<const cl::Buffer*> outs) {
  for (const cl::Buffer* b : outs) {
    if (!b || !(*b)()) continue;
    cl_mem_flags flags = 0;
    void* host = nullptr;
    if (clGetMemObjectInfo((*b)(), CL_MEM_FLAGS, sizeof flags, &flags, nullptr) != CL_SUCCESS)
      return false;
    if ((flags & CL_MEM_USE_HOST_PTR) == 0) continue;
    if (clGetMemObjectInfo((*b)(), CL_MEM_HOST_PTR, sizeof host, &host, nullptr) != CL_SUCCESS ||
        reinterpret_cast<std::uintptr_t>(host) % 64 != 0)
      return false;
  }
  return true;
}

/// Whether every store of the float16 kernels is non-temporal (define
/// SV_NT): SIMDVOL_NT_STORES=1, for benchmarking. Off by default: the
/// separate shade and classify measured the same either way (2-core Intel
/// Xeon, 2026-12-05, simdvol-bench-shade --sweep: 16.2 / 20.8 ms with and
/// without), in 2026-11 on a 2-core AMD EPYC with planar cells 15-30 %
/// slower, and on fresh memory they cost (nt_out).
inline bool nt_stores() {
  return detail::env_switch("SIMDVOL_NT_STORES").value_or(false);
}

/// Whether the fused shade + classify stores its voxel cells of `bytes`
/// non-temporally (kc_mode & 8: no read-for-ownership of the lines it
/// writes), given that they were stored before (VoxelBuffer::stored) and
/// are nt_aligned: where they are at least 64 MiB. SIMDVOL_NT_STORES=0
/// turns it off. On the 2-core Intel Xeon (2026-12-05, scripts/bench-ab
/// with SIMDVOL_NT_STORES=0 against it, 4 pairs) a later frame's shade +
/// classify of the 256^3 phantom (268 MB of cells) took 0.78 of the time,
/// ch2's (114 MB) 0.89, with the resample that reads the cells the same;
/// brainsmall's (22 MB, which the last-level cache holds: about 64 MB
/// measured, where the virtual machine reports 480 MiB) 1.08, its resample
/// 1.03. Into fresh memory (a first frame: the host zeroes each page into
/// the cache as it is first touched, which ordinary stores then hit) it
/// took the phantom's first frame 45 ms longer, so not there.
inline bool nt_out(std::uint64_t bytes) {
  constexpr std::uint64_t kMinBytes = 64ull << 20;
  return bytes >= kMinBytes && detail::env_switch("SIMDVOL_NT_STORES").value_or(true);
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
