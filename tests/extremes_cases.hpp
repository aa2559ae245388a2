// Extreme but valid inputs shared by tests/core/test_extremes.cpp (the
// reference renderer) and tests/cl/test_extremes_cl.cpp (render_opencl
// against the reference): degenerate dims, dims no cell size divides, views
// on the axes and at 45 degrees, constant volumes and NaN voxels.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/render.hpp"
#include "simdvol/volume.hpp"

namespace simdvol::extremes {

/// Unlit transfer function: every value has opacity `alpha` and colour
/// (r, g, b) (premultiplied by the classifier); NaN voxels are transparent.
inline RenderOptions unlit(float alpha, float r = 1.0f, float g = 0.5f, float b = 0.25f) {
  RenderOptions o;
  o.width = o.height = 24;
  o.shade.enabled = false;
  o.classifier.kind = Classifier::Kind::transfer;
  o.classifier.transfer.density = {{0.0f}, {alpha}};
  o.classifier.transfer.red = {{0.0f}, {r}};
  o.classifier.transfer.green = {{0.0f}, {g}};
  o.classifier.transfer.blue = {{0.0f}, {b}};
  return o;
}

inline Volume constant_volume(std::array<int64_t, 3> dims, float v, VoxelType t = VoxelType::f32) {
  Volume vol(dims, t);
  std::fill(vol.data().begin(), vol.data().end(), v);
  return vol;
}

/// A smooth non-constant volume (so shading and the mixture classifier see
/// gradients): a radial ramp 0..200 about the centre.
inline Volume ramp_volume(std::array<int64_t, 3> dims) {
  Volume vol(dims, VoxelType::f32);
  const double cx = (dims[0] - 1) / 2.0, cy = (dims[1] - 1) / 2.0, cz = (dims[2] - 1) / 2.0;
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x) {
        const double r = std::sqrt((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz));
        vol.at(x, y, z) = static_cast<float>(std::max(0.0, 200.0 - 30.0 * r));
      }
  return vol;
}

/// The views of the extreme cases: on each axis, 45 degrees about each axis
/// and about two at once.
inline std::vector<ViewAngles> extreme_views() {
  return {{0, 0, 0},  {0, 90, 0}, {90, 0, 0}, {0, 0, 90},  {0, 180, 0},
          {0, 45, 0}, {45, 0, 0}, {0, 0, 45}, {45, 45, 0}, {45, 45, 45}};
}

/// 1 - (1 - a)^n: the opacity of n samples of opacity a composited with over.
inline float stacked_alpha(float a, int n) {
  return static_cast<float>(1.0 - std::pow(1.0 - static_cast<double>(a), n));
}

inline float max_alpha(const Image& img) {
  float m = 0.0f;
  for (const Rgba& p : img.pixels()) m = std::max(m, p.a);
  return m;
}

/// Empty string when every pixel is finite, alpha in [0, 1] and each colour
/// in [0, alpha] (premultiplied, colours <= 1); else the first violation.
inline std::string image_problem(const Image& img, float eps = 1e-5f) {
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      const Rgba p = img.at(x, y);
      const std::string where = " at pixel " + std::to_string(x) + "," + std::to_string(y);
      for (float c : {p.r, p.g, p.b, p.a})
        if (!std::isfinite(c)) return "non-finite channel" + where;
      if (p.a < -eps || p.a > 1.0f + eps) return "alpha " + std::to_string(p.a) + where;
      for (float c : {p.r, p.g, p.b})
        if (c < -eps || c > p.a + eps) return "colour " + std::to_string(c) + " > alpha" + where;
    }
  return {};
}

/// A transparent layer between opaque slabs, where Aitken orders 2 and 3
/// (weights below 0 and above 1) sample negative opacities: x in the middle
/// half 1000, else 100 (37 x 14 x 14, spacing 0.5, 1, 0.7); every value
/// fully dense, and the gradient ramp makes the slab's faces (|g| of 225
/// to 900 per voxel) nearly transparent: alpha 1, 1, ~0, ~0, 1, 1 across
/// each face. Seen at (45, 180, -178.095), pixel sampling, the whole volume
/// in 137 x 133, rays graze those layers: before the samples were clamped
/// to valid opacities (clamp_sample) the reference composited pixels of
/// alpha -171.7 (found by a randomised sweep; docs/HARDENING.md).
inline Volume thin_gap_volume() {
  Volume vol({37, 14, 14}, VoxelType::f32, {0.5, 1.0, 0.7});
  for (int64_t z = 0; z < 14; ++z)
    for (int64_t y = 0; y < 14; ++y)
      for (int64_t x = 0; x < 37; ++x)
        vol.at(x, y, z) = std::fabs(static_cast<double>(x) - 18.5) < 9.25 ? 1000.0f : 100.0f;
  return vol;
}

inline RenderOptions thin_gap_options() {
  RenderOptions opt;
  opt.classifier.kind = Classifier::Kind::transfer;
  TransferFunction& t = opt.classifier.transfer;
  t.density = {{1199, 1219, 1347}, {1, 0.4798f, 0}};
  t.gradient = {{54, 345, 1554, 1739}, {1, 0.01734f, 0, 0}};
  t.red = {{1199, 1219, 1347}, {0.137f, 0.917f, 0.543f}};
  t.green = {{1199, 1219, 1347}, {0.471f, 0.949f, 0.005f}};
  t.blue = {{1199, 1219, 1347}, {0.419f, 0.098f, 0.653f}};
  opt.view = {45, 180, -178.095};
  opt.width = 137;
  opt.height = 133;
  opt.sampling = Sampling::pixel;
  opt.framing = Framing::diagonal;
  return opt;
}

}  // namespace simdvol::extremes
