// The benchmarking switches read from the environment (SIMDVOL_NT_STORES,
// SIMDVOL_HUGE_PAGES, SIMDVOL_MATCH_SAVED, SIMDVOL_VOXEL_WGS): a value they
// do not take is an ArgumentError naming the variable, not the default
// taken without a word (SIMDVOL_HUGE_PAGES=true was read as unset).
#pragma once

#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>

#include "simdvol/error.hpp"

namespace simdvol::detail {

// A 0 / 1 switch: nullopt where unset or empty.
inline std::optional<bool> env_switch(const char* name) {
  const char* e = std::getenv(name);
  if (!e || !*e) return std::nullopt;
  if (std::string_view(e) == "1") return true;
  if (std::string_view(e) == "0") return false;
  throw ArgumentError(name, std::string("\"") + e + "\" is not 0 or 1");
}

}  // namespace simdvol::detail
