// The classify stage, serial reference (thesis ch. 4.4, eq 4.4), the
// classifier presets and the classifier file format.
//
// Conventions (the OpenCL kernel implements exactly these formulas):
//
//  Ramp r(v), points (x_k, y_k) with x non-decreasing:
//      v <= x_0            -> y_0
//      v >= x_last         -> y_last
//      x_k <= v < x_{k+1}  -> y_k + (v - x_k) * (y_{k+1} - y_k) / (x_{k+1} - x_k)
//  (k is the last point with x_k <= v, so equal x give a step and never a
//  division by zero). An empty ramp is the constant 1. NaN -> y_0.
//
//  Material mixture (eq 4.4, two materials at most, as thesis fig 4.2).
//  Materials must be sorted by strictly ascending mean (presets and
//  load_classifier sort them; a Classifier built by hand that is not sorted
//  is rejected with ArgumentError rather than silently re-sorted per voxel).
//      I = v                                   (absolute)
//      I = (v - range.min) * s, s = 1 / (range.max - range.min), 0 if
//          max == min, in float as the kernel computes it (relative;
//          mixture_index: the pair below jumps at each mean, so both sides
//          take it on the same I)
//      I <= mean_0     : p_0 = 1                (pure first material)
//      I >= mean_last  : p_last = 1             (pure last material)
//      otherwise, i = last material with mean_i <= I, j = i + 1:
//          L_m = -(I - mean_m)^2 / (2 sigma_m^2) - ln(sigma_m)   (log N(mean, sigma))
//          p_i = 1 / (1 + exp(L_j - L_i)),  p_j = 1 - p_i
//          (L_j - L_i as mixture_pair's quadratic about the pair's c)
//      (= P_i / (P_i + P_j) for Gaussian P, without overflow or 0/0).
//      alpha     = p_i a_i + p_j a_j
//      colour[c] = p_i a_i col_i[c] + p_j a_j col_j[c]     (premultiplied)
//      Where alpha >= 1/2 it is taken as 1 - t, t = p_i (1 - a_i) + p_j
//      (1 - a_j) (the transparency, = 1 - alpha as p_i + p_j = 1), and t
//      is what the opacity step below raises to its power: alpha rounds
//      to float in steps of 2^-24, so 1 - alpha near 1 kept only the
//      first digits of t (an opaque material's t of 1e-6, 6 % off), and
//      (1 - a)^0.4 turned rounding into differences of 1e-4 and more
//      between the kernels' float and this double (fig. in HARDENING.md).
//
//  Transfer function (VolPack's example):
//      alpha     = density(v) * gradient(|g|)
//      colour[c] = alpha * colour_c(v)      (empty colour ramps: white)
//
//  A NaN voxel value classifies as transparent (alpha 0, colour 0).
//
//  The classify stage, per voxel, with (Id, Is, |g|) from the shade stage:
//      a  = classify_voxel(v, |g|), t its transparency (the mixture's t
//           where a >= 1/2, else 1 - a)
//      a' = a                          if opacity_step == 1 exactly
//           1 - t^opacity_step         otherwise (opacity of a sample
//                                      opacity_step voxels long)
//      a <= 0:  output (0, 0, 0, 0)
//      else:    C_c = min(1, (colour_c / a) * Id + Is)
//               output (a' C_r, a' C_g, a' C_b, a')    (premultiplied)
#include "simdvol/classify.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>

#include "file_checks.hpp"
#include "number_text.hpp"
#include "simdvol/error.hpp"

namespace simdvol {
namespace {

using detail::number_text;

void validate_ramp(const Ramp& r, const std::string& what) {
  if (r.x.size() != r.y.size())
    throw ArgumentError(what, "ramp has " + std::to_string(r.x.size()) + " x values but " +
                                  std::to_string(r.y.size()) + " y values");
  for (std::size_t k = 0; k < r.x.size(); ++k) {
    if (!std::isfinite(r.x[k]) || !std::isfinite(r.y[k]))
      throw ArgumentError(what, "ramp point " + std::to_string(k) + " is not finite");
    if (r.y[k] < 0.0f || r.y[k] > 1.0f)
      throw ArgumentError(what, "ramp value " + number_text(r.y[k]) +
                                    " at x = " + number_text(r.x[k]) + " is outside [0, 1]");
    if (k > 0 && r.x[k] < r.x[k - 1])
      throw ArgumentError(what, "ramp x values must be ascending (" + number_text(r.x[k]) +
                                    " after " + number_text(r.x[k - 1]) + ")");
    if (k > 0 && !std::isfinite(r.x[k] - r.x[k - 1]))
      throw ArgumentError(what, "ramp x values " + number_text(r.x[k - 1]) + " and " +
                                    number_text(r.x[k]) +
                                    " are too far apart for float arithmetic");
  }
}

// MaterialMixture::top_percentile lies in (0, 100] (also a classifier
// file's `relative P`).
bool top_percentile_valid(float p) {
  return p > 0.0f && p <= 100.0f;
}

void check_top_percentile(float p) {
  if (!top_percentile_valid(p))
    throw ArgumentError("classifier.top_percentile",
                        "must lie in (0, 100] (got " + number_text(p) + ")");
}

// 1 / (2 sigma^2) as the kernels keep it, in float.
float half_inv_var(const Material& m) {
  const double sigma = m.sigma;
  return static_cast<float>(1.0 / (2.0 * sigma * sigma));
}

// The kernels take a pair's L_j - L_i as (qa x + qb) x + qc in float
// (mixture_pair; x = I - c, |x| at most the means' difference d for I
// between them), the reference in double: it must stay finite in float at
// the far mean (means of -3e38 and 3e38 made NaN fractions on the device,
// and the two engines' images 0.3 apart). Half of FLT_MAX leaves room for
// the float roundings.
bool pair_fits_float(const Material& a, const Material& b) {
  const double d = static_cast<double>(b.mean) - static_cast<double>(a.mean);
  const MixturePair q = mixture_pair(a, b);
  const double limit = 0.5 * std::numeric_limits<float>::max();
  return d <= limit && std::fabs(q.c) <= limit &&
         std::fabs(q.qa) * d * d + std::fabs(q.qb) * d + std::fabs(q.qc) <= limit;
}

std::string too_far_apart(const Material& a, const Material& b) {
  return "materials '" + a.name + "' (mean " + number_text(a.mean) + ", sigma " +
         number_text(a.sigma) + ") and '" + b.name + "' (mean " + number_text(b.mean) + ", sigma " +
         number_text(b.sigma) +
         ") are too far apart for their sigmas in float arithmetic ((difference of the means)^2 "
         "/ (2 sigma^2) overflows)";
}

void validate(const Classifier& c) {
  if (c.kind == Classifier::Kind::transfer) {
    validate_ramp(c.transfer.density, "classifier.density");
    validate_ramp(c.transfer.gradient, "classifier.gradient");
    validate_ramp(c.transfer.red, "classifier.red");
    validate_ramp(c.transfer.green, "classifier.green");
    validate_ramp(c.transfer.blue, "classifier.blue");
    return;
  }
  const auto& m = c.mixture.materials;
  if (m.empty()) throw ArgumentError("classifier", "the material mixture has no materials");
  check_top_percentile(c.mixture.top_percentile);
  for (std::size_t i = 0; i < m.size(); ++i) {
    const Material& mat = m[i];
    const std::string what = "classifier.material '" + mat.name + "'";
    if (!std::isfinite(mat.mean)) throw ArgumentError(what, "mean is not finite");
    if (!(mat.sigma > 0.0f) || !std::isfinite(mat.sigma))
      throw ArgumentError(what, "sigma must be > 0 (got " + number_text(mat.sigma) + ")");
    // (The reference's double would take it; the kernels' float cannot.)
    if (!std::isfinite(half_inv_var(mat)))
      throw ArgumentError(what,
                          "sigma " + number_text(mat.sigma) + " is too small for float arithmetic");
    for (float v : {mat.r, mat.g, mat.b})
      if (!(v >= 0.0f && v <= 1.0f))
        throw ArgumentError(what, "colour component " + number_text(v) + " is outside [0, 1]");
    if (!(mat.opacity >= 0.0f && mat.opacity <= 1.0f))
      throw ArgumentError(what, "opacity " + number_text(mat.opacity) + " is outside [0, 1]");
    if (i > 0 && !(m[i - 1].mean < mat.mean))
      throw ArgumentError("classifier", "material means must be strictly ascending ('" +
                                            m[i - 1].name + "' " + number_text(m[i - 1].mean) +
                                            ", then '" + mat.name + "' " + number_text(mat.mean) +
                                            ")");
    if (i > 0 && !pair_fits_float(m[i - 1], mat))
      throw ArgumentError("classifier", too_far_apart(m[i - 1], mat));
  }
}

float classify_mixture(const MaterialMixture& mix, const ValueRange& range, float value,
                       float colour[3], double& transparency) {
  const double I = mixture_index(mix, range, value);
  const auto& m = mix.materials;
  std::size_t i = 0, j = 0;   // the bracketing pair
  double pi = 1.0, pj = 0.0;  // fractions of materials i and j (pi + pj = 1)
  if (I <= m.front().mean) {
    i = j = 0;
  } else if (I >= m.back().mean) {
    i = j = m.size() - 1;
  } else {
    // i = last material with mean_i <= I (exists and is not the last one).
    i = static_cast<std::size_t>(
            std::upper_bound(m.begin(), m.end(), I,
                             [](double v, const Material& mm) { return v < mm.mean; }) -
            m.begin()) -
        1;
    j = i + 1;
    // p_i = 1 / (1 + e^dl), p_j = e^dl / (1 + e^dl) = 1 - p_i: the smaller
    // of the two is e^-|dl| / (1 + e^-|dl|), not 1 minus the larger, so a
    // fraction far below 1e-16 keeps its value (1 - p_i would round it to 0,
    // in float below 6e-8: the device's zero voxels would not be ours).
    const MixturePair q = mixture_pair(m[i], m[j]);
    const double x = I - q.c;
    const double dl = (q.qa * x + q.qb) * x + q.qc;
    const double e = std::exp(-std::fabs(dl));
    const double big = 1.0 / (1.0 + e), small = e * big;
    pi = dl <= 0.0 ? big : small;
    pj = dl <= 0.0 ? small : big;
  }
  const double ai = pi * m[i].opacity, aj = pj * m[j].opacity;
  colour[0] = static_cast<float>(ai * m[i].r + aj * m[j].r);
  colour[1] = static_cast<float>(ai * m[i].g + aj * m[j].g);
  colour[2] = static_cast<float>(ai * m[i].b + aj * m[j].b);
  // Near-opaque voxels by their transparency (the conventions above).
  const double t = pi * (1.0 - static_cast<double>(m[i].opacity)) +
                   pj * (1.0 - static_cast<double>(m[j].opacity));
  const float a = static_cast<float>(ai + aj >= 0.5 ? 1.0 - t : ai + aj);
  transparency = a >= 0.5f ? t : 1.0 - static_cast<double>(a);
  return a;
}

float classify_transfer(const TransferFunction& t, float value, float grad_mag, float colour[3],
                        double& transparency) {
  const float alpha = t.density(value) * t.gradient(grad_mag);
  colour[0] = alpha * t.red(value);
  colour[1] = alpha * t.green(value);
  colour[2] = alpha * t.blue(value);
  transparency = 1.0 - static_cast<double>(alpha);  // exact
  return alpha;
}

// classify_voxel without the validation (done once per volume by
// classify()); `transparency` is the t of the conventions above.
float classify_unchecked(const Classifier& c, const ValueRange& range, float value, float grad_mag,
                         float colour[3], double& transparency) {
  if (std::isnan(value)) {
    colour[0] = colour[1] = colour[2] = 0.0f;
    transparency = 1.0;
    return 0.0f;
  }
  if (c.kind == Classifier::Kind::transfer)
    return classify_transfer(c.transfer, value, grad_mag, colour, transparency);
  return classify_mixture(c.mixture, range, value, colour, transparency);
}

void sort_materials(std::vector<Material>& m) {
  std::stable_sort(m.begin(), m.end(),
                   [](const Material& a, const Material& b) { return a.mean < b.mean; });
}

Ramp ramp(std::vector<float> x, std::vector<float> y) {
  Ramp r;
  r.x = std::move(x);
  r.y = std::move(y);
  return r;
}

Classifier mixture_of(std::vector<Material> m, bool relative) {
  Classifier c;
  c.kind = Classifier::Kind::mixture;
  sort_materials(m);
  c.mixture.materials = std::move(m);
  c.mixture.relative = relative;
  return c;
}

}  // namespace

float Ramp::operator()(float v) const {
  if (x.size() != y.size())
    throw ArgumentError("ramp", "has " + std::to_string(x.size()) + " x values but " +
                                    std::to_string(y.size()) + " y values");
  if (x.empty()) return 1.0f;
  if (std::isnan(v) || v <= x.front()) return y.front();
  if (v >= x.back()) return y.back();
  // k = last point with x_k <= v; here 0 <= k < size - 1 and x_{k+1} > v >= x_k.
  const std::size_t k =
      static_cast<std::size_t>(std::upper_bound(x.begin(), x.end(), v) - x.begin()) - 1;
  const float t = (v - x[k]) / (x[k + 1] - x[k]);
  return y[k] + t * (y[k + 1] - y[k]);
}

MixturePair mixture_pair(const Material& lo, const Material& hi) {
  const double slo = lo.sigma, shi = hi.sigma;
  const double hlo = 1.0 / (2.0 * slo * slo), hhi = 1.0 / (2.0 * shi * shi);
  const double d = static_cast<double>(hi.mean) - static_cast<double>(lo.mean);
  // c - mean_lo and mean_hi - c in the ratio of the sigmas (sqrt(h) is 1 /
  // (sqrt(2) sigma))
  const double ulo = d * slo / (slo + shi), uhi = d * shi / (slo + shi);
  MixturePair q;
  q.c = static_cast<double>(lo.mean) + ulo;
  q.qa = hlo - hhi;
  q.qb = 2.0 * (hlo * ulo + hhi * uhi);
  q.qc = std::log(slo) - std::log(shi);
  return q;
}

ValueRange mixture_range(const Volume& vol, const MaterialMixture& mix) {
  return mixture_range(vol, mix, vol.range());
}

ValueRange mixture_range(const Volume& vol, const MaterialMixture& mix, const ValueRange& full) {
  if (!mix.relative) return full;
  check_top_percentile(mix.top_percentile);
  if (mix.top_percentile == 100.0f) return full;
  vol.check_voxel_count();
  // The foreground: finite voxels above a tenth of the range (a head's
  // background, zeros and noise, is half of ch2 and most of brainsmall).
  const double floor = static_cast<double>(full.min) +
                       (static_cast<double>(full.max) - static_cast<double>(full.min)) / 10.0;
  const auto above = [floor](float v) {
    return std::isfinite(v) && static_cast<double>(v) > floor;
  };
  const double q = static_cast<double>(mix.top_percentile) / 100.0;
  float top = full.max;
  // Integer voxels (u8, u16, i16 files unscaled) are counted, exactly, in
  // one pass; other values (or a count that meets a fraction) are selected.
  bool counted = false;
  if (full.min >= -65536.0f && full.max <= 65536.0f) {
    const auto lo = static_cast<int64_t>(std::floor(full.min));
    std::vector<std::size_t> count(
        static_cast<std::size_t>(static_cast<int64_t>(std::floor(full.max)) - lo + 1), 0);
    std::size_t n = 0;
    counted = true;
    for (float v : vol.data()) {
      if (!above(v)) continue;
      // (a fraction, or a value outside `full`, which a caller's stale
      // range can leave: selected below, not counted past the array's end)
      if (v != std::floor(v) || v < full.min || v > full.max) {
        counted = false;
        break;
      }
      ++count[static_cast<std::size_t>(static_cast<int64_t>(v) - lo)];
      ++n;
    }
    if (counted && n > 0) {
      const auto k = static_cast<std::size_t>(q * static_cast<double>(n - 1));
      std::size_t seen = 0;
      for (std::size_t b = 0; b < count.size(); ++b) {
        seen += count[b];
        if (seen > k) {
          top = static_cast<float>(lo + static_cast<int64_t>(b));
          break;
        }
      }
    }
  }
  if (!counted) {
    std::vector<float> fg;
    for (float v : vol.data())
      if (above(v)) fg.push_back(v);
    if (!fg.empty()) {
      const auto k = static_cast<std::size_t>(q * static_cast<double>(fg.size() - 1));
      std::nth_element(fg.begin(), fg.begin() + static_cast<std::ptrdiff_t>(k), fg.end());
      top = fg[k];
    }
  }
  return top > full.min ? ValueRange{full.min, top} : full;
}

ValueRange classify_range(const Volume& vol, const Classifier& c) {
  return c.kind == Classifier::Kind::mixture && c.mixture.relative ? mixture_range(vol, c.mixture)
                                                                   : ValueRange{};
}

float mixture_range_scale(const ValueRange& range) {
  const double span = static_cast<double>(range.max) - static_cast<double>(range.min);
  return span > 0.0 ? static_cast<float>(1.0 / span) : 0.0f;
}

float mixture_index(const MaterialMixture& mix, const ValueRange& range, float value) {
  if (!mix.relative) return value;
  const float scale = mixture_range_scale(range);
  // Two float operations, each rounded, as sv_mixture / sv_mixture_index16.
  const float d = value - range.min;
  return scale > 0.0f ? d * scale : 0.0f;
}

float classify_voxel(const Classifier& c, const ValueRange& range, float value, float grad_mag,
                     float colour[3]) {
  validate(c);
  double t = 1.0;
  return classify_unchecked(c, range, value, grad_mag, colour, t);
}

std::vector<Rgba> classify(const Volume& vol, const std::vector<ShadeSample>& shading,
                           const Classifier& c, double opacity_step) {
  vol.check_voxel_count();
  if (shading.size() != vol.voxel_count())
    throw ArgumentError("shading", "has " + std::to_string(shading.size()) +
                                       " samples for a volume of " +
                                       std::to_string(vol.voxel_count()) + " voxels");
  if (!(opacity_step > 0.0) || !std::isfinite(opacity_step))
    throw ArgumentError("opacity_step",
                        "must be positive and finite (got " + number_text(opacity_step) + ")");
  validate(c);
  const ValueRange range = classify_range(vol, c);

  const double step = static_cast<float>(opacity_step);
  std::vector<Rgba> out(vol.voxel_count());
  const auto& data = vol.data();
  for (std::size_t n = 0; n < data.size(); ++n) {
    float col[3];
    double t = 1.0;
    const float a = classify_unchecked(c, range, data[n], shading[n].gradient, col, t);
    // out[n] stays (0, 0, 0, 0), also for a subnormal alpha: the device's
    // float exp stops at 2^-126, so it has none, and a voxel the reference
    // keeps while the device drops it would key Monte Carlo's draws apart.
    if (!(a >= std::numeric_limits<float>::min())) continue;
    // 1 - t^step, t = 1 - a without the cancellation of 1 - a for small a,
    // and the mixture's own t for a near-opaque voxel (log(0) = -inf: 1);
    // the step as the kernels take it, in float.
    const double a1 = opacity_step == 1.0 ? static_cast<double>(a)
                      : a >= 0.5f         ? -std::expm1(step * std::log(t))
                                          : -std::expm1(step * std::log1p(-static_cast<double>(a)));
    double C[3];
    for (int k = 0; k < 3; ++k)
      C[k] =
          std::min(1.0, static_cast<double>(col[k]) / a * shading[n].diffuse + shading[n].specular);
    out[n] = Rgba{static_cast<float>(a1 * C[0]), static_cast<float>(a1 * C[1]),
                  static_cast<float>(a1 * C[2]), static_cast<float>(a1)};
  }
  return out;
}

// ---------------------------------------------------------------- presets

std::vector<std::string> classifier_preset_names() {
  return {"ct", "ct-bone", "mri", "volpack"};
}

Classifier classifier_preset(std::string_view name) {
  if (name == "ct") {
    // Hounsfield units; opacities per voxel-length sample. A ray through a
    // 256^3 head crosses ~200 voxels of brain, so soft tissue must be nearly
    // transparent per voxel (0.005: ~0.6 over the whole brain), and a skull
    // 3-6 voxels thick at 0.12 per voxel is half transparent face-on and
    // opaque at its silhouette: a skull with a faint brain inside (tuned on
    // the Shepp-Logan phantom, whose ventricles are fat-like -100 HU).
    return mixture_of({{"air", -1000.0f, 120.0f, 0.0f, 0.0f, 0.0f, 0.0f},
                       {"fat", -100.0f, 60.0f, 0.95f, 0.8f, 0.55f, 0.0025f},
                       {"soft tissue", 40.0f, 60.0f, 0.85f, 0.45f, 0.4f, 0.005f},
                       {"bone", 1000.0f, 250.0f, 1.0f, 0.97f, 0.9f, 0.12f}},
                      false);
  }
  if (name == "ct-bone") {
    return mixture_of({{"air", -1000.0f, 120.0f, 0.0f, 0.0f, 0.0f, 0.0f},
                       {"fat", -100.0f, 60.0f, 0.95f, 0.8f, 0.55f, 0.0f},
                       {"soft tissue", 40.0f, 60.0f, 0.85f, 0.45f, 0.4f, 0.0f},
                       {"bone", 1000.0f, 250.0f, 1.0f, 0.97f, 0.9f, 1.0f}},
                      false);
  }
  if (name == "mri") {
    // T1-weighted head, intensities relative to the volume's range, from
    // its minimum to the 99th percentile of its foreground.
    Classifier c = mixture_of({{"background", 0.0f, 0.05f, 0.0f, 0.0f, 0.0f, 0.0f},
                               {"csf", 0.15f, 0.05f, 0.3f, 0.4f, 0.8f, 0.0f},
                               {"grey matter", 0.45f, 0.07f, 0.8f, 0.6f, 0.55f, 0.01f},
                               {"white matter", 0.6f, 0.06f, 0.95f, 0.9f, 0.85f, 0.02f},
                               {"fat/skin", 0.85f, 0.1f, 1.0f, 0.8f, 0.65f, 0.15f}},
                              true);
    c.mixture.top_percentile = 99.0f;  // (the maximum left ch2 and brainsmall a dark haze)
    return c;
  }
  if (name == "volpack") {
    // VolPack's examples/classifyvolume.c for brainsmall.den (u8 densities,
    // gradient magnitudes 0..VP_GRAD_MAX = 221): the density ramp
    // {0, 24, 255} -> {0, 1, 1}, the gradient ramp {0, 5, 20, 221} ->
    // {0, 0, 1, 1}, white (a luminance image). Its shading (rendervolume.c:
    // ambient 0.18, diffuse 0.35, specular 0.39, shininess 10, light
    // (0.3, 0.3, 1), depth cue 1.4 / 1.5) is a ShadeParams matter.
    Classifier c;
    c.kind = Classifier::Kind::transfer;
    c.transfer.density = ramp({0.0f, 24.0f, 255.0f}, {0.0f, 1.0f, 1.0f});
    c.transfer.gradient = ramp({0.0f, 5.0f, 20.0f, 221.0f}, {0.0f, 0.0f, 1.0f, 1.0f});
    return c;
  }
  std::string names;
  for (const auto& n : classifier_preset_names()) names += (names.empty() ? "" : ", ") + n;
  throw ArgumentError("classifier",
                      "unknown preset '" + std::string(name) + "' (presets: " + names + ")");
}

// ------------------------------------------------------------ file format
//
// One directive per line; '#' starts a comment; blank lines are ignored.
//   density  x y [x y ...]          opacity of the value (transfer function)
//   gradient x y [x y ...]          opacity factor of |grad| (transfer function)
//   color    x r g b [x r g b ...]  colour of the value (transfer function)
//   material NAME MEAN SIGMA R G B OPACITY     (mixture; any order, sorted by mean)
//   relative [P]                    mixture means/sigmas are fractions of the range
//                                   (from the minimum to the P-th percentile of the
//                                   foreground, MaterialMixture::top_percentile;
//                                   without P the maximum)
// A ramp directive may be repeated: its points are appended, x strictly
// ascending across the lines. Ramp values, colours and opacities lie in
// [0, 1]; sigma > 0; material means are distinct. Material lines and ramp
// lines cannot be mixed.

namespace {

struct Parser {
  const std::filesystem::path& path;
  int line = 0;

  [[noreturn]] void fail(const std::string& problem) const {
    throw FileError(path, "line " + std::to_string(line) + ": " + problem);
  }

  float number(const std::string& tok) const {
    const char* s = tok.c_str();
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(s, &end);
    if (end == s || *end != '\0') fail("'" + tok + "' is not a number");
    if (errno == ERANGE || !std::isfinite(v) || std::fabs(v) > 3.0e38)
      fail("'" + tok + "' is out of range");
    return static_cast<float>(v);
  }

  float unit(const std::string& tok, const char* what) const {
    const float v = number(tok);
    if (v < 0.0f || v > 1.0f) fail(std::string(what) + " " + tok + " is outside [0, 1]");
    return v;
  }

  void append_x(std::vector<float>& xs, float x, const std::string& directive) const {
    if (!xs.empty() && !(x > xs.back()))
      fail(directive + " x values must be ascending (" + number_text(x) + " after " +
           number_text(xs.back()) + ")");
    if (!xs.empty() && !std::isfinite(x - xs.back()))
      fail(directive + " x values " + number_text(xs.back()) + " and " + number_text(x) +
           " are too far apart for float arithmetic (their difference overflows)");
    xs.push_back(x);
  }
};

}  // namespace

Classifier load_classifier(const std::filesystem::path& path) {
  refuse_non_regular_file(path, "a classifier file");
  std::ifstream in(path);
  if (!in) throw FileError(path, "cannot open classifier file");

  Classifier c;
  Parser ps{path};
  bool any_transfer = false, any_material = false;
  int relative_line = 0;
  std::vector<int> material_lines;  // parallel to c.mixture.materials before sorting
  TransferFunction& t = c.transfer;
  std::vector<float> colour_x;

  std::string text;
  while (std::getline(in, text)) {
    ++ps.line;
    // A UTF-8 byte-order mark (editors on Windows write one) is not text.
    if (ps.line == 1 && text.starts_with("\xEF\xBB\xBF")) text.erase(0, 3);
    if (const auto hash = text.find('#'); hash != std::string::npos) text.erase(hash);
    std::istringstream ss(text);
    std::vector<std::string> tok;
    for (std::string w; ss >> w;) tok.push_back(w);
    if (tok.empty()) continue;
    const std::string& d = tok[0];
    const std::size_t nv = tok.size() - 1;

    if (d == "density" || d == "gradient") {
      if (any_material) ps.fail("'" + d + "' cannot be mixed with material lines");
      if (nv == 0 || nv % 2 != 0)
        ps.fail(d + " needs pairs of values (x y ...), got " + std::to_string(nv) + " values");
      Ramp& r = d == "density" ? t.density : t.gradient;
      for (std::size_t k = 1; k < tok.size(); k += 2) {
        ps.append_x(r.x, ps.number(tok[k]), d);
        r.y.push_back(ps.unit(tok[k + 1], (d + " value").c_str()));
      }
      any_transfer = true;
    } else if (d == "color" || d == "colour") {
      if (any_material) ps.fail("'" + d + "' cannot be mixed with material lines");
      if (nv == 0 || nv % 4 != 0)
        ps.fail(d + " needs groups of four values (x r g b ...), got " + std::to_string(nv) +
                " values");
      for (std::size_t k = 1; k < tok.size(); k += 4) {
        ps.append_x(colour_x, ps.number(tok[k]), d);
        t.red.y.push_back(ps.unit(tok[k + 1], "red"));
        t.green.y.push_back(ps.unit(tok[k + 2], "green"));
        t.blue.y.push_back(ps.unit(tok[k + 3], "blue"));
      }
      any_transfer = true;
    } else if (d == "material") {
      if (any_transfer) ps.fail("material lines cannot be mixed with density/gradient/color lines");
      if (nv != 7)
        ps.fail("material needs NAME MEAN SIGMA R G B OPACITY (7 values), got " +
                std::to_string(nv));
      Material m;
      m.name = tok[1];
      m.mean = ps.number(tok[2]);
      m.sigma = ps.number(tok[3]);
      if (!(m.sigma > 0.0f)) ps.fail("sigma " + tok[3] + " of '" + m.name + "' must be > 0");
      m.r = ps.unit(tok[4], "red");
      m.g = ps.unit(tok[5], "green");
      m.b = ps.unit(tok[6], "blue");
      m.opacity = ps.unit(tok[7], "opacity");
      c.mixture.materials.push_back(m);
      material_lines.push_back(ps.line);
      any_material = true;
    } else if (d == "relative") {
      if (relative_line != 0)  // ('relative 99' then 'relative' took 99)
        ps.fail("relative is given again (first on line " + std::to_string(relative_line) + ")");
      if (nv > 1) ps.fail("relative takes at most one value (the top's percentile)");
      if (any_transfer) ps.fail("relative applies only to material lines");
      if (nv == 1) {
        const float pct = ps.number(tok[1]);
        if (!top_percentile_valid(pct))
          ps.fail("relative's percentile " + tok[1] + " must lie in (0, 100]");
        c.mixture.top_percentile = pct;
      }
      relative_line = ps.line;
    } else {
      ps.fail("unknown directive '" + d +
              "' (expected density, gradient, color, material or relative)");
    }
  }
  if (in.bad()) throw FileError(path, "read error");
  if (!any_transfer && !any_material) throw FileError(path, "no directives");
  if (any_transfer && relative_line != 0) {
    ps.line = relative_line;
    ps.fail("relative applies only to material lines");
  }

  if (any_transfer) {
    c.kind = Classifier::Kind::transfer;
    t.red.x = t.green.x = t.blue.x = colour_x;
    return c;
  }
  c.kind = Classifier::Kind::mixture;
  c.mixture.relative = relative_line != 0;
  // The kernels keep 1 / (2 sigma^2) in float, a relative sigma as an
  // absolute one (a relative mixture maps the intensity to [0, 1] and keeps
  // its means and sigmas as they are): validate's checks, here with the
  // line.
  for (std::size_t k = 0; k < c.mixture.materials.size(); ++k) {
    if (!std::isfinite(half_inv_var(c.mixture.materials[k]))) {
      ps.line = material_lines[k];
      ps.fail("sigma " + number_text(c.mixture.materials[k].sigma) + " of '" +
              c.mixture.materials[k].name + "' is too small for float arithmetic");
    }
  }
  // Sort by mean, keeping each material's line number for the messages.
  std::vector<std::size_t> order(c.mixture.materials.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  auto& mats = c.mixture.materials;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return mats[a].mean < mats[b].mean; });
  std::vector<Material> sorted;
  for (std::size_t k = 0; k < order.size(); ++k) {
    if (k > 0 && mats[order[k]].mean == mats[order[k - 1]].mean) {
      ps.line = std::max(material_lines[order[k]], material_lines[order[k - 1]]);
      ps.fail("materials '" + mats[order[k - 1]].name + "' and '" + mats[order[k]].name +
              "' have the same mean " + number_text(mats[order[k]].mean));
    }
    if (k > 0 && !pair_fits_float(mats[order[k - 1]], mats[order[k]])) {
      ps.line = std::max(material_lines[order[k]], material_lines[order[k - 1]]);
      ps.fail(too_far_apart(mats[order[k - 1]], mats[order[k]]));
    }
    sorted.push_back(mats[order[k]]);
  }
  mats = std::move(sorted);
  return c;
}

Classifier classifier_from_spec(const std::string& spec) {
  const auto names = classifier_preset_names();
  if (std::find(names.begin(), names.end(), spec) != names.end()) return classifier_preset(spec);
  const std::filesystem::path p(spec);
  std::error_code ec;
  if (!std::filesystem::exists(p, ec)) {
    // (A loop of symbolic links, or no permission, is that, not a missing file.)
    if (ec && ec != std::errc::no_such_file_or_directory) throw FileError(p, ec.message());
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw FileError(p, "no such classifier file, and not a preset (" + list + ")");
  }
  return load_classifier(p);
}

}  // namespace simdvol
