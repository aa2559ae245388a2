// Test volumes generated from formulas, so their true values are known.
#pragma once

#include "simdvol/volume.hpp"

namespace simdvol {

/// 3-D Shepp–Logan head phantom (Kak & Slaney's ten ellipsoids) on an n^3
/// grid spanning [-1, 1]^3, in Hounsfield units: air -1000 outside the head,
/// bone (skull) about 1000, soft tissue (brain) about 40, fat-like ventricles
/// about -100, small tumours about 60. Type i16.
Volume shepp_logan(int n);

/// Hounsfield value of the Shepp–Logan phantom at (x, y, z) in [-1, 1]^3.
float shepp_logan_hu(double x, double y, double z);

/// The Marschner–Lobb signal (1994) on an n^3 grid spanning [-1, 1]^3,
/// fM = 6, alpha = 0.25, values in [0, 1]. Type f32.
Volume marschner_lobb(int n);

/// The analytic Marschner–Lobb signal at (x, y, z) in [-1, 1]^3.
double marschner_lobb_value(double x, double y, double z);

/// Maps grid index i of an n-point axis to [-1, 1] (voxel centres).
inline double phantom_coord(int64_t i, int64_t n) {
  return n <= 1 ? 0.0 : -1.0 + 2.0 * static_cast<double>(i) / static_cast<double>(n - 1);
}

}  // namespace simdvol
