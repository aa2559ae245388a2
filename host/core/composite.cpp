#include "simdvol/composite.hpp"

#include "over_inline.hpp"
#include "simdvol/error.hpp"
#include "simdvol_shared.h"

namespace simdvol {

Rgba over(const Rgba& f, const Rgba& b) {
  return detail::over_inline(f, b);
}

namespace {
// Over's alpha recurrence along the ray (ch. 7.5 (a): the exact opacity).
float exact_alpha(const RaySamples& ray) {
  float acc = 0.0f;
  for (const Rgba& v : ray.rgba) acc = acc + (1.0f - acc) * v.a;
  return acc;
}
}  // namespace

Rgba composite_direct(const RaySamples& ray) {
  // Eq 7.2 in associative colour: front to back, acc = over(acc, sample).
  Rgba acc{};
  for (const Rgba& s : ray.rgba) acc = detail::over_inline(acc, s);
  return acc;
}

Rgba composite_adaptive(const RaySamples& ray, float threshold) {
  // (NaN composited every sample, a negative one none.)
  if (!(threshold > 0.0f && threshold <= 1.0f))
    throw ArgumentError("threshold", std::to_string(threshold) + " is outside (0, 1]");
  Rgba acc{};
  for (const Rgba& s : ray.rgba) {
    if (acc.a >= threshold) break;  // Levoy's adaptive termination
    acc = detail::over_inline(acc, s);
  }
  return acc;
}

Rgba composite_mc(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p) {
  if (p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  return composite_mc_walks(ray, ray_id, p.samples, p);
}

namespace {

// The depth index that keys the exact-opacity draws (the stratified walks'
// and the fallback pick's): that of the ray's first sample with alpha > 0
// (first_step if none; then no such draw is made). Samples of alpha 0 before
// it change nothing, so leaving them out (EngineOptions::skip_pes) keeps
// every draw.
uint32_t first_opaque_step(const RaySamples& ray) {
  for (std::size_t s = 0; s < ray.rgba.size(); ++s)
    if (ray.rgba[s].a > 0.0f)
      return static_cast<uint32_t>(ray.first_step + static_cast<int64_t>(s));
  return static_cast<uint32_t>(ray.first_step);
}

}  // namespace

Rgba composite_mc_stratified(const RaySamples& ray, uint32_t key, int walks,
                             const CompositeParams& p, McStats* stats) {
  // CompositeParams::stratified. Opacity exact (over's alpha recurrence);
  // walk m picks the first sample s with alpha_s > 0 whose cumulative
  // opacity c_s exceeds t_m = ((m + u_m) / n) * alpha (the last sample with
  // alpha_s > 0 if rounding leaves none). t_m grows with m and c_s with s,
  // so one pass serves every walk. kernels/mc.cl (STRAT) repeats this
  // operation for operation.
  if (!p.exact_opacity)
    throw ArgumentError("--mc-stratified", "needs exact opacity (--exact-opacity)");
  McStats st;
  st.walks = walks;
  const float acc = exact_alpha(ray);
  Rgba out;
  out.a = acc;
  if (walks > 0 && acc > 0.0f) {
    const uint32_t k0 = first_opaque_step(ray);
    const float inv_n = 1.0f / static_cast<float>(walks);
    auto target = [&](int m) {
      const float u = sv_uniform(p.seed, key, static_cast<uint32_t>(m), k0);
      return ((static_cast<float>(m) + u) * inv_n) * acc;
    };
    double r = 0, g = 0, b = 0;
    int m = 0;
    float t = target(0);
    float c = 0.0f;
    std::size_t last = ray.rgba.size();
    for (std::size_t s = 0; s < ray.rgba.size() && m < walks; ++s) {
      const Rgba& v = ray.rgba[s];
      if (v.a <= 0.0f) {
        ++st.skipped;
        continue;  // c is unchanged by alpha = 0 and it cannot be picked
      }
      last = s;
      c = c + (1.0f - c) * v.a;
      while (m < walks && c > t) {
        r += v.r / v.a;
        g += v.g / v.a;
        b += v.b / v.a;
        if (++m < walks) t = target(m);
      }
    }
    if (m < walks) {
      ++st.fallbacks;  // rounding left t above every c: the last sample with alpha > 0
      const Rgba& v = ray.rgba[last];
      for (; m < walks; ++m) {
        r += v.r / v.a;
        g += v.g / v.a;
        b += v.b / v.a;
      }
    }
    st.draws = walks;
    const double a = acc;
    const double inv = 1.0 / walks;
    out.r = static_cast<float>(a * (r * inv));
    out.g = static_cast<float>(a * (g * inv));
    out.b = static_cast<float>(a * (b * inv));
  }
  if (stats) *stats += st;
  return out;
}

Rgba composite_mc_walks(const RaySamples& ray, uint32_t ray_id, int walks, const CompositeParams& p,
                        McStats* stats) {
  // Eq 7.3 / 7.12 / 7.13: walk m visits the samples front to back and stops at
  // sample s when u(m, s) < alpha_s, picking its colour C_s = C'_s / alpha_s.
  // A walk that passes every sample picks the black background. The mean of
  // the picks estimates C' and the fraction of walks that stop estimates
  // alpha. Expectation: sum_s C'_s prod_{j<s} (1 - alpha_j), i.e. over().
  // kernels/mc.cl repeats this arithmetic operation for operation.
  if (walks < 0) throw ArgumentError("walks", "must not be negative");
  const uint32_t key = p.streams == RandomStreams::shared ? SV_SHARED_RAY : ray_id;
  if (p.stratified) return composite_mc_stratified(ray, key, walks, p, stats);
  double r = 0, g = 0, b = 0;
  int stopped = 0;
  McStats st;
  st.walks = walks;
  for (int m = 0; m < walks; ++m) {
    for (std::size_t s = 0; s < ray.rgba.size(); ++s) {
      const Rgba& v = ray.rgba[s];
      if (v.a <= 0.0f && p.drop_transparent) {
        ++st.skipped;
        continue;
      }
      ++st.draws;
      const float u = sv_uniform(p.seed, key, static_cast<uint32_t>(m),
                                 static_cast<uint32_t>(ray.first_step + static_cast<int64_t>(s)));
      if (u < v.a) {  // never for alpha <= 0 (u >= 0)
        r += v.r / v.a;
        g += v.g / v.a;
        b += v.b / v.a;
        ++stopped;
        break;
      }
    }
  }
  Rgba out;
  if (!p.exact_opacity) {
    if (walks > 0) {
      const double inv = 1.0 / walks;
      out = {static_cast<float>(r * inv), static_cast<float>(g * inv), static_cast<float>(b * inv),
             static_cast<float>(stopped * inv)};
    }
  } else {
    // Ch. 7.5 (a): exact opacity (over's alpha recurrence), Monte Carlo colour.
    const float acc = exact_alpha(ray);
    out.a = acc;
    if (stopped > 0) {
      const double a = acc;
      out.r = static_cast<float>(a * (r / stopped));
      out.g = static_cast<float>(a * (g / stopped));
      out.b = static_cast<float>(a * (b / stopped));
    } else if (acc > 0.0f) {
      // No walk stopped: one pick from the conditional distribution
      // p_s / alpha by inversion of the cumulative opacity (the recurrence
      // above): t = u * alpha, the first s whose cumulative opacity exceeds t
      // (the last sample with alpha_s > 0 if rounding leaves none). Keyed as
      // walk `walks` at the depth of the first sample with alpha > 0 (of
      // which there is one: acc > 0). E[alpha * C_pick] = C', so
      // the estimator stays unbiased; it costs one draw and one scan.
      ++st.fallbacks;
      ++st.draws;
      const float u = sv_uniform(p.seed, key, static_cast<uint32_t>(walks), first_opaque_step(ray));
      const float t = u * acc;
      float c = 0.0f;
      std::size_t pick = ray.rgba.size();
      for (std::size_t s = 0; s < ray.rgba.size(); ++s) {
        const float a = ray.rgba[s].a;
        if (a > 0.0f) pick = s;  // the last one with alpha > 0 so far
        c = c + (1.0f - c) * a;
        if (c > t && a > 0.0f) break;
      }
      if (pick < ray.rgba.size()) {
        const Rgba& v = ray.rgba[pick];
        const double a = acc;
        out.r = static_cast<float>(a * static_cast<double>(v.r / v.a));
        out.g = static_cast<float>(a * static_cast<double>(v.g / v.a));
        out.b = static_cast<float>(a * static_cast<double>(v.b / v.a));
      }
    } else {
      ++st.fallbacks;  // nothing to pick: the colour is 0 (alpha <= 0)
    }
  }
  if (stats) *stats += st;
  return out;
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
