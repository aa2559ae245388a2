// Resampling by Aitken's progressive scheme (thesis eq 5.13–5.17), orders
// 0–3, in 1-D and, axis by axis, in 3-D.
//
// Stencils are nested so that order k is built from order k-1 (one matching
// serves every order): with f = floor(x) and t = x - f,
//   order 0: {n}, n = ceil(x - 1/2) (eq 5.10, nearest)
//   order 1: {n, the other of f, f+1}                     (linear, eq 5.11)
//   order 2: order 1 plus f-1 if t <= 1/2, else f+2       (centred quadratic)
//   order 3: {f-1, f, f+1, f+2}                           (cubic)
// Values are combined with Neville's recurrence in insertion order:
//   P_{i..j}(x) = ((x - x_i) P_{i+1..j} - (x - x_j) P_{i..j-1}) / (x_j - x_i).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

constexpr int kMaxOrder = 3;

/// The stencil's integer positions in insertion order (order + 1 of them).
std::array<int64_t, 4> aitken_stencil(int64_t floor_x, float frac, int order);

/// Aitken/Neville interpolation at x = floor_x + frac of values f[0..order]
/// taken at the stencil positions. `levels`, if given, receives the result of
/// every order 0..order (levels[k] = order-k estimate).
float aitken(const float* f, const int64_t* xs, int order, int64_t floor_x, float frac,
             float* levels = nullptr);

/// 1-D convenience: samples `values` (clamped at the ends) at x.
float aitken_1d(const std::vector<float>& values, double x, int order);

/// Reference 3-D resampling of a scalar volume at fixed-point coordinates
/// (see view.hpp), neighbours clamped at the edges. ArgumentError for an
/// empty volume or one whose data() was resized apart from its dims.
float resample_scalar(const Volume& vol, const std::array<int64_t, 3>& fixed_pos, int order);

/// Reference 3-D resampling of classified RGBA voxels (dims as `dims`).
Rgba resample_rgba(const std::vector<Rgba>& voxels, const std::array<int64_t, 3>& dims,
                   const std::array<int64_t, 3>& fixed_pos, int order);

/// A resampled sample as compositing takes it. Aitken orders 2 and 3 use
/// weights below 0 and above 1 (Lagrange's), so near a sharp edge a sample's
/// alpha leaves [0, 1]; over() then amplifies where it should attenuate
/// ((1 - a) > 1 where a < 0), and a ray grazing a thin transparent gap
/// composited to alpha -166 (docs/HARDENING.md). So at orders >= 2 alpha
/// is clamped to [0, 1] and each premultiplied colour to [0, alpha] (a
/// NaN to 0); orders 0 and 1 (weights in [0, 1]) are returned as they are.
/// Every compositing path takes its samples through this (render_reference,
/// resample_reference, local_reference; the kernels' sv_clamp_sample).
Rgba clamp_sample(const Rgba& s, int order);

/// Same, at a real-valued position (for tests against polynomials).
float resample_scalar_at(const Volume& vol, double x, double y, double z, int order);

}  // namespace simdvol
