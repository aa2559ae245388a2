// Monte Carlo compositing on the PE array (thesis ch. 7.2-7.5): serial
// references of the whole-ray and the per-sub-ray estimators from a
// matching's segments, the sub-ray walk allocation by opacity, and the
// helpers the device stages (mc_cl.hpp) and the fig 7.2/7.3 reproduction use.
//
// Every estimator is composite_mc_walks (composite.hpp): walk m of ray
// (i, j) draws u = sv_uniform(seed, key, m, k) at ABSOLUTE depth index k,
// key = j * width + i (per-ray streams) or SV_SHARED_RAY (the thesis's shared
// sequence). Because the key is absolute, a whole-ray walk stops at the first
// k along the whole ray with u(m, k) < alpha_k, whichever PE holds sample k:
// the whole-ray estimate from the segments equals composite_mc on the ray's
// samples (render_reference with CompositeMode::mc) bit for bit.
//
// Whole ray: per pixel, the ray's non-empty segments in increasing k0
// (ray_segments) give its samples front to back; composite_mc_walks with
// p.samples walks.
// Per sub-ray (ch. 7.4, eq 7.15): each segment is estimated on its own
// samples with n_s walks (n_s = p.samples, or allocate_walks below), keyed
// by the same absolute k, then the segments of a pixel are combined with
// over in increasing k0 (composite_segments; on the device, the swap).
//
// Allocation by opacity (ch. 7.5 (b)), allocate_walks(alpha, n): per ray,
// the sub-rays' exact opacities alpha_s (over's alpha recurrence over the
// segment's samples) in depth order. With P = {s : alpha_s > 0}, c = |P|:
//   c == 0: every n_s = 0 (nothing can stop a walk);
//   n <= c: n_s = 1 for s in P (then the ray takes c > n walks when n < c:
//           the "at least one" rule wins over the budget);
//   n >  c: r = n - c extra walks, shared by integer weights
//           w_s = allocation_weight(alpha_s) = ceil(256 min(alpha_s, 1)), the
//           opacity in 256 steps: W = sum of w_s over P, f_s = floor(r w_s /
//           W), L = r - sum f_s walks go one each to the L sub-rays with the
//           largest remainder (r w_s mod W; ties: the front one first);
//           n_s = 1 + f_s (+1). Sum over the ray = n exactly. In integers,
//           the device's allocation equals the reference's wherever their
//           opacities fall in the same step: with float shares
//           r alpha_s / A, a last-bit difference between the two engines'
//           opacities moved walks between tied sub-rays (a
//           piecewise-constant volume has many), 0.3 apart in a pixel's
//           alpha. A difference across a step's edge still moves them
//           (rarely: about 256 times the difference, per sub-ray).
//   alpha_s <= 0: n_s = 0.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "simdvol/composite.hpp"
#include "simdvol/image.hpp"
#include "simdvol/match.hpp"

namespace simdvol {

/// Per pixel (j * width + i) the indices of its non-empty segments in
/// increasing k0 (CSR).
struct RaySegments {
  int width = 0, height = 0;
  std::vector<int64_t> offset;  ///< width * height + 1 entries
  std::vector<int64_t> items;   ///< segment indices
};
/// Throws ArgumentError if a non-empty segment lies outside the image.
RaySegments ray_segments(const Matching& m, int width, int height);

/// A sub-ray's weight in the allocation: its opacity in 256 steps,
/// ceil(256 min(alpha, 1)), 1..256 for alpha > 0; 0 for alpha <= 0.
int32_t allocation_weight(float alpha);

/// The walk allocation rule of the file comment for one ray.
std::vector<int32_t> allocate_walks(std::span<const float> alphas, int budget);

/// Exact opacity of every segment (the over recurrence over its samples;
/// 0 for an empty segment). `samples` in segment order (resample_reference).
std::vector<float> segment_alphas(const Matching& m, const std::vector<Rgba>& samples);

/// Walks per segment under allocate_walks(alphas of the ray's segments in
/// depth order, budget) for every ray (0 for empty segments).
std::vector<int32_t> allocation_reference(const Matching& m, const std::vector<Rgba>& samples,
                                          const RaySegments& rays, int budget);

/// Whole-ray Monte Carlo: the intermediate image (width x height) with
/// p.samples walks per ray (p.exact_opacity, p.drop_transparent, p.streams
/// honoured; p.mode ignored).
Image mc_whole_reference(const Matching& m, const std::vector<Rgba>& samples,
                         const RaySegments& rays, const CompositeParams& p,
                         McStats* stats = nullptr);

/// Per sub-ray Monte Carlo: one (C', a) per segment, with `walks[s]` walks
/// (allocation_reference) or, if `walks` is empty, p.samples each.
std::vector<Rgba> mc_sub_reference(const Matching& m, const std::vector<Rgba>& samples,
                                   const RaySegments& rays, const CompositeParams& p,
                                   const std::vector<int32_t>& walks = {},
                                   McStats* stats = nullptr);

/// Ray id of pixel (i, j) of a width-wide viewing grid.
inline uint32_t mc_ray_id(int i, int j, int width) {
  return static_cast<uint32_t>(j) * static_cast<uint32_t>(width) + static_cast<uint32_t>(i);
}

}  // namespace simdvol
