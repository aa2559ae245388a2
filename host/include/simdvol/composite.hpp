// Compositing along a ray in premultiplied (associative) colour (thesis ch. 7).
#pragma once

#include <cstdint>
#include <span>

#include "simdvol/image.hpp"

namespace simdvol {

/// over(front, back): C' = C'_f + (1 - a_f) C'_b, a = a_f + (1 - a_f) a_b.
/// Associative. (The thesis's diamond, eq 7.8–7.10, takes the front second.)
/// Each product and sum rounded on its own, as in the references and the
/// kernels (FP_CONTRACT OFF): compiled in the library, not inline here, so
/// that a caller built with FMA contraction (-march=native) gets the same bits.
Rgba over(const Rgba& f, const Rgba& b);

enum class CompositeMode {
  direct,    ///< front-to-back over every sample (eq 7.2)
  adaptive,  ///< direct, stopping once accumulated alpha >= threshold (Levoy)
  mc,        ///< Monte Carlo (eq 7.3, 7.12, 7.13)
};

enum class RandomStreams {
  per_ray,  ///< decorrelated: Philox4x32-10 keyed by the seed, counter (ray, walk / 4, step) —
            ///< default
  shared,   ///< the thesis's single front-end sequence shared by all rays
};

struct CompositeParams {
  CompositeMode mode = CompositeMode::direct;
  float threshold = 0.95f;  ///< adaptive termination
  int samples = 32;         ///< Monte Carlo walks per ray
  uint64_t seed = 1;
  RandomStreams streams = RandomStreams::per_ray;
  /// Monte Carlo, thesis ch. 7.5 (a): opacity exact (the over recurrence
  /// a <- a + (1 - a) alpha_s, bitwise composite_direct's alpha), colour
  /// C' = a * mean of the colours C'_s / alpha_s that the walks which stopped
  /// picked. When no walk stops (and alpha > 0) one sample is picked from the
  /// conditional distribution p_s / alpha by inverting the cumulative opacity
  /// (one draw, keyed as walk n at the depth of the first sample with
  /// alpha > 0, so that transparent samples before it change no draw; see
  /// composite.cpp): colour alpha * C_pick. The estimator stays unbiased.
  bool exact_opacity = false;
  /// Monte Carlo, ch. 7.5 (c): samples with alpha <= 0 draw no random number
  /// (they can never stop a walk). With the generator keyed by the absolute
  /// depth index this changes no result, only the number of draws.
  bool drop_transparent = true;
  /// Monte Carlo, beyond the thesis (with exact_opacity only): stratified
  /// picks. Walk m draws one u_m = sv_uniform(seed, key, m, the depth of the
  /// first sample with alpha > 0) and
  /// picks from the conditional distribution p_s / alpha by inverting the
  /// cumulative opacity at t_m = ((m + u_m) / n) * alpha (the rule of the
  /// fallback above); colour alpha * mean of the picks. Unbiased (each
  /// stratum [m/n, (m+1)/n) is sampled uniformly), one draw per walk, and
  /// for n walks the error falls like 1/n rather than 1/sqrt(n) where the
  /// colour varies smoothly along the ray.
  bool stratified = false;
};

/// Work counters of the Monte Carlo estimator (summed over rays / sub-rays).
struct McStats {
  int64_t walks = 0;      ///< walks started
  int64_t draws = 0;      ///< random numbers drawn
  int64_t skipped = 0;    ///< transparent samples passed without a draw
  int64_t fallbacks = 0;  ///< exact opacity: estimates where no walk stopped (conditional pick)
  McStats& operator+=(const McStats& o) {
    walks += o.walks;
    draws += o.draws;
    skipped += o.skipped;
    fallbacks += o.fallbacks;
    return *this;
  }
  bool operator==(const McStats&) const = default;
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
/// The same estimator with `walks` walks (0 allowed: plain MC gives 0, exact
/// opacity its conditional pick) instead of p.samples, honouring
/// p.exact_opacity and p.drop_transparent, adding its work to `stats`.
/// Walk m draws sv_uniform(p.seed, key, m, first_step + s), key = ray_id or
/// SV_SHARED_RAY (p.streams).
Rgba composite_mc_walks(const RaySamples& ray, uint32_t ray_id, int walks, const CompositeParams& p,
                        McStats* stats = nullptr);

/// The stratified estimator (CompositeParams::stratified; `key` = ray_id or
/// SV_SHARED_RAY). ArgumentError without p.exact_opacity. composite_mc_walks
/// calls it when p.stratified is set.
Rgba composite_mc_stratified(const RaySamples& ray, uint32_t key, int walks,
                             const CompositeParams& p, McStats* stats = nullptr);

Rgba composite(const RaySamples& ray, uint32_t ray_id, const CompositeParams& p);

}  // namespace simdvol
