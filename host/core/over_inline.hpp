// over() inline, for the library's own loops (composite.cpp, local.cpp,
// swap.cpp). Not installed: the public over() (composite.hpp) is this body
// compiled once in the library, under the library's -ffp-contract=off, so
// that a program built with FMA contraction (-march=native, -mfma) that
// calls it gets the bits of the references and the kernels.
#pragma once

#include "simdvol/image.hpp"

namespace simdvol::detail {

inline Rgba over_inline(const Rgba& f, const Rgba& b) {
  const float t = 1.0f - f.a;
  return {f.r + t * b.r, f.g + t * b.g, f.b + t * b.b, f.a + t * b.a};
}

}  // namespace simdvol::detail
