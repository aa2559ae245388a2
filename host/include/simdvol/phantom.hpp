// Test volumes generated from formulas, so their true values are known.
#pragma once

#include "simdvol/volume.hpp"

namespace simdvol {

/// 3-D Shepp–Logan head phantom (Kak & Slaney's ten ellipsoids) on an n^3
/// grid spanning [-1, 1]^3, in Hounsfield units: air -1000 outside the head,
/// bone (skull) about 1000, soft tissue (brain) about 40, fat-like ventricles
/// about -100, small tumours about 60. Type i16.
///
/// supersample = 1 samples the phantom at the voxel centres phantom_coord(i, n),
/// so boundaries are staircases of whole voxels. supersample = s > 1 models
/// the partial-volume effect of a real scanner: voxel (i, j, k) stands for
/// the cube of side h = 2 / (n - 1) centred on its grid point (the footprint
/// the centre spacing implies; h = 2, the whole cube, when n = 1), and holds
/// the mean of the phantom over the s^3 regular sub-samples
/// phantom_subsample(i, n, m, s), m = 0 .. s-1 per axis, rounded to the
/// nearest integer (halves away from zero). Voxels whose footprint lies wholly
/// inside one region keep that region's value exactly. Only voxels near an
/// ellipsoid's surface are sub-sampled, so s = 4 costs little more than s = 1.
/// Throws ArgumentError unless 1 <= supersample <= 16.
Volume shepp_logan(int n, int supersample = 1);

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

/// Coordinate of sub-sample m (0 <= m < s) of voxel i of an n-point axis:
/// the s points splitting the voxel's footprint [c - h/2, c + h/2] into equal
/// parts, at their midpoints (c = phantom_coord(i, n), h = 2 / (n - 1), or 2
/// when n = 1). shepp_logan(n, s) uses exactly these coordinates. Compiled
/// in the library (under -ffp-contract=off), not inline here: a caller built
/// with FMA contraction would fuse the product and the sum.
double phantom_subsample(int64_t i, int64_t n, int m, int s);

}  // namespace simdvol
