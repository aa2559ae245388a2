// The rotation T(theta, phi, varphi) of thesis eq 5.2 and the viewing grid:
// where each viewing-space sample p_H lands in the volume (eq 5.5).
#pragma once

#include <array>
#include <cstdint>

#include "simdvol/volume.hpp"

#include "simdvol_shared.h"

namespace simdvol {

using Vec3 = std::array<double, 3>;
using Mat3 = std::array<std::array<double, 3>, 3>;  // row-major

Mat3 multiply(const Mat3& a, const Mat3& b);
Vec3 multiply(const Mat3& a, const Vec3& v);
Mat3 transpose(const Mat3& a);
double determinant(const Mat3& a);

/// Thesis eq 5.2, angles in degrees. Maps object space to viewing space
/// (x, y on the image plane, z into the scene). T(0, 0, 0) is the identity;
/// varying phi alone rotates about the viewing y (vertical) axis.
Mat3 rotation(double theta_deg, double phi_deg, double varphi_deg);

struct ViewAngles {
  double theta = 0.0, phi = 0.0, varphi = 0.0;  // degrees
};

enum class Sampling {
  voxel,  ///< viewing space sampled at voxel spacing (rotation only), then a 2-D scale
  pixel,  ///< viewing space sampled at pixel spacing (affine map with scaling)
};

/// How the volume fills the image (`render --fit`).
enum class Framing {
  longest,   ///< its longest side spans min(width, height), centred (VolPack's
             ///< example); an oblique view loses the corners that stick out
  diagonal,  ///< its diagonal spans min(width, height), centred: the whole
             ///< volume is in the image at every view, at one scale (VTK's
             ///< ResetCamera fits the bounding sphere the same way)
};

/// Everything about where samples go, for one view of one volume at one
/// output size. The volume fits the image by its longest side (VolPack's
/// example) or by its diagonal (Framing): that length spans min(width,
/// height), centred.
struct ViewGeometry {
  Mat3 rot{};            ///< T (object -> viewing), physical units
  double step = 1.0;     ///< viewing-grid spacing in units of the smallest voxel spacing
  double radius = 0.0;   ///< half the volume's diagonal, same units
  double longest = 0.0;  ///< longest side, same units
  double span = 0.0;     ///< the length that spans min(out_width, out_height): longest or 2 radius
  int out_width = 0, out_height = 0;  ///< final image
  sv_view grid{};                     ///< fixed-point map from (i, j, k) to voxel coordinates
  /// The samples' direction of travel (viewing +z) in object index space,
  /// unit length in physical units; light and view vectors in object space.
  Vec3 view_dir_obj{};
  Sampling sampling = Sampling::voxel;

  int width() const { return grid.grid[0]; }   ///< intermediate image width
  int height() const { return grid.grid[1]; }  ///< intermediate image height
  int depth() const { return grid.grid[2]; }   ///< samples per ray (before clipping)

  /// Fixed-point voxel coordinate of viewing sample (i, j, k) along axis a.
  int64_t fixed(int a, int64_t i, int64_t j, int64_t k) const {
    return grid.origin[a] + i * grid.step[a][0] + j * grid.step[a][1] + k * grid.step[a][2];
  }
  /// True iff floor of every coordinate lies inside the volume.
  bool inside(int64_t i, int64_t j, int64_t k) const;
  /// Depth range [k0, k1) of ray (i, j) whose samples lie inside the volume
  /// (empty when k0 >= k1). Exact: equals testing every k with inside().
  std::array<int64_t, 2> ray_range(int64_t i, int64_t j) const;

  /// Where output pixel (x, y) samples the intermediate image, in
  /// intermediate pixel coordinates (pixel centres at integers).
  std::array<double, 2> output_to_intermediate(int x, int y) const;
};

/// The viewing map X = o + M (i, j, k) in double (exact copies of the
/// fixed-point values): returns M^-1 and sets `origin` to o. Throws
/// ArgumentError("view", "singular viewing map") if M is singular.
Mat3 inverse_viewing_map(const ViewGeometry& view, Vec3& origin);

/// Builds the geometry. Throws ArgumentError for non-positive sizes.
ViewGeometry make_view(const Volume& vol, ViewAngles angles, int out_width, int out_height,
                       Sampling sampling, Framing framing = Framing::longest);
/// The same from the volume's dims and spacing alone (no voxel data needed:
/// the geometry depends on nothing else). Throws ArgumentError for
/// non-positive dims or spacing.
ViewGeometry make_view(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                       ViewAngles angles, int out_width, int out_height, Sampling sampling,
                       Framing framing = Framing::longest);

/// Splits a fixed-point coordinate into floor and fraction in [0, 1).
inline int64_t fixed_floor(int64_t x) {
  return x >> SV_FRAC_BITS;
}
inline float fixed_frac(int64_t x) {
  return static_cast<float>(static_cast<uint32_t>(x & (SV_ONE - 1))) * (1.0f / 4294967296.0f);
}

}  // namespace simdvol
