// Compositing along a ray in premultiplied (associative) colour (thesis ch. 7).
#pragma once

#include <cstdint>
#include <span>

#include "simdvol/image.hpp"

namespace simdvol {

/// over(front, back): C' = C'_f + (1 - a_f) C'_b, a = a_f + (1 - a_f) a_b.
/// Associative. (The thesis's diamond, eq 7.8–7.10, takes the front second.)
inline Rgba over(const Rgba& f, const Rgba& b) {
  const float t = 1.0f - f.a;
  return {f.r + t * b.r, f.g + t * b.g, f.b + t * b.b, f.a + t * b.a};
}

enum class CompositeMode {
  direct,    ///< front-to-back over every sample (eq 7.2)
  adaptive,  ///< direct, stopping once accumulated alpha >= threshold (Levoy)
  mc,        ///< Monte Carlo (eq 7.3, 7.12, 7.13)
};

enum class RandomStreams {
  per_ray,  ///< decorrelated: Philox keyed by (seed, ray, sample, step) — default
  shared,   ///< the thesis's single front-end sequence shared by all rays
};

struct CompositeParams {
  CompositeMode mode = CompositeMode::direct;
  float threshold = 0.95f;  ///< adaptive termination
  int samples = 32;         ///< Monte Carlo walks per ray
  uint64_t seed = 1;
  RandomStreams streams = RandomStreams::per_ray;
};

/// A ray's samples front to back (premultiplied) and the depth index of each
/// (the k of the viewing grid, used to key the random stream).
struct RaySamples {
  std::span<const Rgba> rgba;
  int64_t first_step = 0;  ///< depth index of rgba[0]; rgba[s] has step first_step + s
};

Rgba composite_direct(const RaySamples& ray);
Rgba composite_adaptive(const RaySamples& ray, float threshold);
/// Monte Carlo: `samples` walks; walk m stops at sample s with probability
/// alpha_s (uniform u < alpha_s), picking the unpremultiplied colour C'_s /
/// alpha_s; a walk that passes every sample picks black. Colour = mean of
/// picks, alpha = fraction of walks that stopped.
Rgba composite_mc(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p);

Rgba composite(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p);

}  // namespace simdvol
