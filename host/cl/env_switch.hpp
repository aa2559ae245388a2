// Values read from the environment. The benchmarking switches
// (SIMDVOL_NT_STORES, SIMDVOL_HUGE_PAGES, SIMDVOL_MATCH_SAVED,
// SIMDVOL_VOXEL_WGS): a value they do not take is an ArgumentError naming
// the variable, not the default taken without a word (SIMDVOL_HUGE_PAGES=true
// was read as unset). The counts (SIMDVOL_DEVICE, POCL_MAX_PTHREAD_COUNT,
// SIMDVOL_FAIL_ALLOCATION's N) by one rule, whole_number.
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

// A whole number 0 .. max written in decimal digits, blanks (space, tab)
// either side allowed; nullopt for anything else (a sign, other characters,
// no digits, past max: strtol's "-1", "2x" and LONG_MAX for
// 99999999999999999999 are all refused here). max at most LONG_MAX / 10 - 9,
// so that the value does not overflow before the test.
inline std::optional<long> whole_number(std::string_view text, long max) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  if (text.empty() || text.find_first_not_of("0123456789") != std::string_view::npos)
    return std::nullopt;
  long value = 0;
  for (const char c : text) {
    value = value * 10 + (c - '0');
    if (value > max) return std::nullopt;
  }
  return value;
}

}  // namespace simdvol::detail
