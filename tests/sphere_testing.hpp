// A ball sampled at unequal voxel spacings, and the measures of its image:
// whatever the spacing, a ball must render as a disc (not an ellipse) from
// every view, as large as the isotropic ball's and lit as it is. Used by the
// reference's and the OpenCL engine's tests of anisotropic spacing.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "simdvol/classify.hpp"
#include "simdvol/image.hpp"
#include "simdvol/volume.hpp"

namespace simdvol::testing {

/// A cube of side `extent` mm sampled at `spacing` (extent / spacing voxels
/// along each axis, a whole number), Hounsfield-like: air (-1000) around a
/// ball of soft tissue (500) of radius `radius` mm with a linear edge
/// `edge` mm wide, and with `inner`, inside it, off the centre at (8, -6, 7)
/// mm, a denser ball (+800) of radius 10 mm, so that the shading has a
/// structure that turns with the view. Both balls are functions of the physical
/// position of voxel i, i * spacing, about the volume's centre n / 2 *
/// spacing (README "Where the samples lie"), so every spacing samples the
/// same scene.
inline Volume sphere_volume(std::array<double, 3> spacing, bool inner, double extent = 60.0,
                            double radius = 20.0, double edge = 6.0) {
  std::array<int64_t, 3> dims{};
  for (int a = 0; a < 3; ++a) dims[a] = static_cast<int64_t>(std::lround(extent / spacing[a]));
  Volume vol(dims, VoxelType::f32, spacing);
  auto ramp = [edge](double r, double d) { return std::clamp((r - d) / edge + 0.5, 0.0, 1.0); };
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x) {
        const double p[3] = {
            (static_cast<double>(x) - 0.5 * static_cast<double>(dims[0])) * spacing[0],
            (static_cast<double>(y) - 0.5 * static_cast<double>(dims[1])) * spacing[1],
            (static_cast<double>(z) - 0.5 * static_cast<double>(dims[2])) * spacing[2]};
        const double d = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        const double d2 =
            std::sqrt((p[0] - 8) * (p[0] - 8) + (p[1] + 6) * (p[1] + 6) + (p[2] - 7) * (p[2] - 7));
        vol.at(x, y, z) = static_cast<float>(-1000.0 + 1500.0 * ramp(radius, d) +
                                             (inner ? 800.0 * ramp(10.0, d2) : 0.0));
      }
  return vol;
}

/// The mixture the ball is classified with: the soft tissue translucent
/// (opacity 0.06 per smallest spacing), the inner ball denser.
inline Classifier sphere_classifier() {
  Classifier c;
  c.kind = Classifier::Kind::mixture;
  c.mixture.materials = {{"air", -1000, 150, 0, 0, 0, 0},
                         {"soft", 500, 150, 0.9f, 0.7f, 0.5f, 0.06f},
                         {"dense", 1300, 150, 1, 1, 1, 0.5f}};
  return c;
}

/// The shape of an image's opacity, its pixels weighted by their alpha:
/// the radius of a disc of the same total alpha, the centroid (pixel
/// centres at x + 0.5) and the elongation sqrt(lambda_max / lambda_min) of
/// the second moments (1 for anything round; an ellipse of axes a and b
/// gives a / b).
struct DiscShape {
  double radius = 0, cx = 0, cy = 0, elongation = 0, total = 0;
};

inline DiscShape disc_shape(const Image& im) {
  double n = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  for (int y = 0; y < im.height(); ++y)
    for (int x = 0; x < im.width(); ++x) {
      const double w = im.at(x, y).a, px = x + 0.5, py = y + 0.5;
      n += w, sx += w * px, sy += w * py, sxx += w * px * px, syy += w * py * py,
          sxy += w * px * py;
    }
  DiscShape s;
  s.total = n;
  if (!(n > 0)) return s;
  s.cx = sx / n, s.cy = sy / n;
  const double vxx = sxx / n - s.cx * s.cx, vyy = syy / n - s.cy * s.cy;
  const double vxy = sxy / n - s.cx * s.cy;
  const double m = 0.5 * (vxx + vyy), q = std::sqrt(0.25 * (vxx - vyy) * (vxx - vyy) + vxy * vxy);
  s.elongation = std::sqrt((m + q) / (m - q));
  s.radius = std::sqrt(n / M_PI);
  return s;
}

/// PSNR over the alpha channel alone (peak 1): psnr() takes RGB.
inline double psnr_alpha(const Image& a, const Image& b) {
  double se = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      const double d = static_cast<double>(a.at(x, y).a) - static_cast<double>(b.at(x, y).a);
      se += d * d;
    }
  const double mse = se / (static_cast<double>(a.width()) * a.height());
  return mse > 0 ? -10.0 * std::log10(mse) : INFINITY;
}

}  // namespace simdvol::testing
