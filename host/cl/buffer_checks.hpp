// The stages' checks of the buffers a caller hands them (stages.hpp: every
// enqueue_* validates its arguments before anything is enqueued): one
// clGetMemObjectInfo per buffer on the host, no wait, nothing enqueued, no
// string built unless the check fails.
#pragma once

#include <cstdint>
#include <string>

#include "simdvol/device.hpp"
#include "simdvol/error.hpp"

namespace simdvol::detail {

// ArgumentError naming `argument` where `buffer` is null or holds fewer than
// `count` `items` of `unit` bytes each:
// "samples: a buffer of 160 bytes holds fewer than 12 float4 samples of 16
// bytes (192 bytes)".
inline void check_buffer(const cl::Buffer& buffer, int64_t count, std::size_t unit,
                         const char* argument, const char* items) {
  const std::size_t need = static_cast<std::size_t>(count > 0 ? count : 0) * unit;
  const auto wanted = [&] {
    return std::to_string(count) + " " + items + " of " + std::to_string(unit) + " bytes (" +
           std::to_string(need) + " bytes)";
  };
  if (!buffer()) throw ArgumentError(argument, "no buffer (null) for " + wanted());
  const std::size_t have = buffer_size(buffer, "clGetMemObjectInfo(CL_MEM_SIZE)");
  if (have < need)
    throw ArgumentError(
        argument, "a buffer of " + std::to_string(have) + " bytes holds fewer than " + wanted());
}

}  // namespace simdvol::detail
