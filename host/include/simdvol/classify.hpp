// Classification (thesis eq 4.4): a maximum-likelihood mixture of materials,
// or a piecewise-linear transfer function of density and gradient magnitude
// (VolPack's example). Output: premultiplied (associative) RGBA per voxel,
// already lit by the shade stage's diffuse and specular terms.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

/// A material: Gaussian intensity distribution P_i(I) = N(mean, sigma), a
/// colour and an opacity.
struct Material {
  std::string name;
  float mean = 0, sigma = 1;
  float r = 1, g = 1, b = 1;
  float opacity = 0;
};

/// Maximum-likelihood mixture: materials sorted by mean; a voxel of
/// intensity I mixes at most the two materials whose means bracket I, with
/// fractions p_i = P_i(I) / (P_i(I) + P_j(I)); below the first mean it is
/// the first material, above the last the last. alpha = sum p_i a_i,
/// colour' = sum p_i a_i c_i.
struct MaterialMixture {
  std::vector<Material> materials;
  /// When true, means and sigmas are fractions of the volume's value range
  /// (I is mapped to (v - min) / (top - min) first, mixture_range): used by
  /// MRI presets, whose units depend on the scanner.
  bool relative = false;
  /// A relative mixture's top: 100 takes the volume's maximum; below 100,
  /// that percentile of the volume's foreground, its finite voxels above
  /// min + (max - min) / 10 (the lower rank: the value at rank
  /// floor(q (n - 1)) of the n sorted, q = top_percentile / 100), or the
  /// maximum where there is no foreground. The "mri" preset takes 99: a few
  /// bright voxels (vessels, fat, noise) no longer push the tissues to the
  /// bottom of the range (ch2's maximum is 254 where 99 % of its head lies
  /// below 177, and its white matter near 90 fell below the preset's grey
  /// matter: a dark haze). In (0, 100].
  float top_percentile = 100.0f;
};

/// A piecewise-linear function given by points (x ascending); constant
/// beyond the ends.
struct Ramp {
  std::vector<float> x, y;
  float operator()(float v) const;
};

/// alpha = density(v) * gradient(|grad|); colour from colour ramps of
/// density (white when empty).
struct TransferFunction {
  Ramp density, gradient;
  Ramp red, green, blue;
};

struct Classifier {
  enum class Kind { mixture, transfer } kind = Kind::mixture;
  MaterialMixture mixture;
  TransferFunction transfer;
};

/// Presets: "ct" (air, fat, soft tissue, bone in HU), "ct-bone", "mri"
/// (relative), "volpack" (VolPack's example transfer function for
/// brainsmall.den: density ramp 0->0, 24->1; gradient ramp 0, 5, 20, 221 ->
/// 0, 0, 1, 1). Throws ArgumentError naming the preset otherwise.
Classifier classifier_preset(std::string_view name);
std::vector<std::string> classifier_preset_names();

/// Reads a transfer-function text file (see README: lines "density x y ...",
/// "gradient x y ...", "color x r g b ...", or "material name mean sigma r g b
/// opacity" lines, '#' comments). Throws FileError naming the file and line.
Classifier load_classifier(const std::filesystem::path& path);

/// Looks `spec` up as a preset, else loads it as a file.
Classifier classifier_from_spec(const std::string& spec);

/// The range a mixture's fractions are of, to give classify_params and
/// classify_voxel: the volume's range, or for a relative mixture whose
/// top_percentile is below 100, from its minimum to that percentile of its
/// foreground (MaterialMixture::top_percentile). `full` is vol.range()
/// where the caller has it. classify() and the engines take it so; an
/// embedder who passes vol.range() to classify_params with the "mri"
/// preset classifies apart from them.
ValueRange mixture_range(const Volume& vol, const MaterialMixture& mix);
ValueRange mixture_range(const Volume& vol, const MaterialMixture& mix, const ValueRange& full);

/// The range classify_params and classify_voxel take for `c` on `vol`:
/// mixture_range(vol, c.mixture) for a relative mixture, else none (an
/// absolute mixture and a transfer function read no range; {}).
ValueRange classify_range(const Volume& vol, const Classifier& c);

/// A relative mixture's scale 1 / (max - min) of `range` in float, 0 when
/// max == min: what the kernels multiply by (sv_classify_params::range_scale).
float mixture_range_scale(const ValueRange& range);

/// The mixture's index I of `value`: the value itself (absolute), or, for a
/// relative mixture, (value - range.min) * mixture_range_scale(range) in
/// float, as the kernels compute it (0 when max == min). The mixture jumps
/// at each material's mean (it mixes only the two materials whose means
/// bracket I), so the reference decides the bracketing pair on the same
/// float I as the device: a double (value - min) / (max - min) can fall on
/// the other side of a mean (value 153 of 0 .. 255 at the "mri" preset's
/// 0.6: alpha 0.0192 against 0.0234).
float mixture_index(const MaterialMixture& mix, const ValueRange& range, float value);

/// The log-likelihood difference of two neighbouring materials (lo's mean
/// below hi's), L_hi - L_lo, as a quadratic in x = I - c about the point c
/// between their means where sqrt(h_lo) (c - mean_lo) = sqrt(h_hi) (mean_hi
/// - c), h = 1 / (2 sigma^2):
///     L_hi - L_lo = (qa x + qb) x + qc,
///     qa = h_lo - h_hi, qb = 2 (h_lo (c - mean_lo) + h_hi (mean_hi - c)),
///     qc = ln sigma_lo - ln sigma_hi
/// (the constant h_lo (c - mean_lo)^2 - h_hi (mean_hi - c)^2 is 0). The
/// same value as the Gaussians' L_m = -(I - mean_m)^2 h_m - ln sigma_m
/// subtracted, without their cancellation: between means 2e9 apart (sigma
/// 1) the terms are 1e18, so float lost the fraction's place by tens of
/// intensity units and the device's image parted from the reference's
/// (0.04 at 1e9, 0.25 at 1e18); about c only the float rounding of c and I
/// is left. The reference takes it in double, the kernels in float
/// (sv_materials' pair_c, pair_qa, pair_qb, pair_qc).
struct MixturePair {
  double c = 0, qa = 0, qb = 0, qc = 0;
};
MixturePair mixture_pair(const Material& lo, const Material& hi);

/// Opacity of one voxel before lighting (mixture or transfer function).
/// Also returns premultiplied material colour in colour[0..2].
float classify_voxel(const Classifier& c, const ValueRange& range, float value, float grad_mag,
                     float colour[3]);

/// The classify stage (reference, serial): for each voxel, alpha from the
/// classifier, corrected for the sampling step (alpha' = 1 - (1 - alpha)^step),
/// colour C = min(1, c * Id + Is), output (alpha' C, alpha').
std::vector<Rgba> classify(const Volume& vol, const std::vector<ShadeSample>& shading,
                           const Classifier& c, double opacity_step);

}  // namespace simdvol
