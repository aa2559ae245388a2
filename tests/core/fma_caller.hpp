// fma_caller.cpp: the public headers' float code as a caller built with
// -mfma -ffp-contract=fast gets it.
#pragma once

#include <cstdint>

#include "simdvol/image.hpp"

namespace simdvol_test {

simdvol::Rgba over_in_fma_caller(const simdvol::Rgba& f, const simdvol::Rgba& b);
double phantom_subsample_in_fma_caller(int64_t i, int64_t n, int m, int s);

}  // namespace simdvol_test
