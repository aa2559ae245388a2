// A caller of the public headers built with FMA contraction: tests/CMakeLists.txt
// compiles this file alone with -mfma -ffp-contract=fast (x86-64, GCC or
// Clang), as an embedding program built with -march=native is (GCC's
// default is fast). PublicHeaders.SameBitsInACallerBuiltWithFma
// (test_composite.cpp) compares what it gets with the library's bits.
#include "fma_caller.hpp"

#include "simdvol/composite.hpp"
#include "simdvol/phantom.hpp"

namespace simdvol_test {

simdvol::Rgba over_in_fma_caller(const simdvol::Rgba& f, const simdvol::Rgba& b) {
  return simdvol::over(f, b);
}

double phantom_subsample_in_fma_caller(int64_t i, int64_t n, int m, int s) {
  return simdvol::phantom_subsample(i, n, m, s);
}

}  // namespace simdvol_test
