#include "simdvol/composite.hpp"

#include "simdvol/error.hpp"
#include "simdvol_shared.h"

namespace simdvol {

Rgba composite_direct(const RaySamples& ray) {
  // Eq 7.2 in associative colour: front to back, acc = over(acc, sample).
  Rgba acc{};
  for (const Rgba& s : ray.rgba) acc = over(acc, s);
  return acc;
}

Rgba composite_adaptive(const RaySamples& ray, float threshold) {
  Rgba acc{};
  for (const Rgba& s : ray.rgba) {
    if (acc.a >= threshold) break;  // Levoy's adaptive termination
    acc = over(acc, s);
  }
  return acc;
}

Rgba composite_mc(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p) {
  // Eq 7.3 / 7.12 / 7.13: walk m visits the samples front to back and stops at
  // sample s when u(m, s) < alpha_s, picking its colour C_s = C'_s / alpha_s.
  // A walk that passes every sample picks the black background. The mean of
  // the picks estimates C' and the fraction of walks that stop estimates
  // alpha. Expectation: sum_s C'_s prod_{j<s} (1 - alpha_j), i.e. over().
  if (p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  const uint32_t key = p.streams == RandomStreams::shared ? SV_SHARED_RAY : ray_id;
  double r = 0, g = 0, b = 0;
  int stopped = 0;
  for (int m = 0; m < p.samples; ++m) {
    for (std::size_t s = 0; s < ray.rgba.size(); ++s) {
      const Rgba& v = ray.rgba[s];
      if (v.a <= 0.0f) continue;
      const float u = sv_uniform(p.seed, key, static_cast<uint32_t>(m),
                                 static_cast<uint32_t>(ray.first_step + static_cast<int64_t>(s)));
      if (u < v.a) {
        r += v.r / v.a;
        g += v.g / v.a;
        b += v.b / v.a;
        ++stopped;
        break;
      }
    }
  }
  const double inv = 1.0 / p.samples;
  return {static_cast<float>(r * inv), static_cast<float>(g * inv), static_cast<float>(b * inv),
          static_cast<float>(stopped * inv)};
}

Rgba composite(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p) {
  switch (p.mode) {
    case CompositeMode::direct:
      return composite_direct(ray);
    case CompositeMode::adaptive:
      return composite_adaptive(ray, p.threshold);
    case CompositeMode::mc:
      return composite_mc(ray, ray_id, p);
  }
  return {};
}

}  // namespace simdvol
