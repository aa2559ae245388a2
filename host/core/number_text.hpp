// Numbers in messages, as %g writes them: six significant digits, 1e+40
// rather than the forty digits std::to_string gives (shared by the
// classifier's and the shading's checks).
#pragma once

#include <cstdio>
#include <string>

namespace simdvol::detail {

inline std::string number_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

}  // namespace simdvol::detail
