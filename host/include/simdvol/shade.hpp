// Shading (thesis eq 4.1–4.3): central-difference gradients and Phong
// lighting with depth cueing, for a constant parallel light and an
// orthographic view. Lighting is two-sided (|N.L|, |N.H|), so the sign
// convention of eq 4.3's normal does not matter.
#pragma once

#include <vector>

#include "simdvol/view.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

struct ShadeParams {
  bool enabled = true;           ///< false: Id = 1, Is = 0 everywhere (unlit)
  Vec3 light{-0.4, -0.5, -1.0};  ///< direction towards the light, viewing space (normalised)
  double ka = 0.25;              ///< ambient
  double kd = 0.75;              ///< diffuse
  double ks = 0.35;              ///< specular
  double shininess = 24.0;       ///< Phong exponent n
  double k1 = 1.0;               ///< depth cue 1 / (k1 + k2 * d), d in [0, 1] front to back
  double k2 = 0.6;
};

/// The specular term's floor: |N.H| below it makes |N.H|^n count as 0,
/// where the power would be below 2^-100 (7.9e-31: no image holds it).
/// The float arithmetic of the kernels would otherwise carry such powers
/// down into denormal numbers, which the CPU handles by microcode at about
/// a hundred times the cost of a normal multiplication (ch2's shade +
/// classify spent about a quarter of its time there). 2^(-100 / n) for
/// n > 0, at least FLT_MIN (an |N.H| below it counts as 0 at every n > 0);
/// 0 for n = 0 (x^0 = 1). The reference and the kernels both take it.
float specular_floor(double shininess);

/// Per-voxel result of the shade stage.
struct ShadeSample {
  float diffuse = 0;   ///< Id = ka + cue * kd * |N.L|
  float specular = 0;  ///< Is = cue * ks * |N.H|^n
  float gradient = 0;  ///< |grad f| (value units per smallest voxel spacing)
  /// 0 in the reference's shade(); the device's shading (the shade kernels'
  /// fourth channel, read back as ShadeSample by VoxelBuffer::read) holds the
  /// voxel's value here instead, which the classify kernels read. To compare
  /// the two, compare it with the volume's value, not with the reference's 0;
  /// to feed the reference's shading to the classify kernels, set it to the
  /// value first (docs/KERNELS.md, "Voxel cells").
  float pad = 0;
};

/// Quantities derived once per view, in object (index-aligned) space.
struct ShadeFrame {
  Vec3 light_obj{}, halfway_obj{};  ///< unit L and H in object space
  Vec3 depth_dir{};  ///< viewing z in object index units: d = dot(depth_dir, x) + depth_offset
  double depth_offset = 0;
  Vec3 grad_scale{};  ///< multiply index-space differences by this (min spacing / spacing)
  /// The volume's range (max - min >= 1e19) allows a gradient whose squared
  /// length overflows float (|g| above about 1.8e19): the kernels then take
  /// such lengths rescaled (shade.cl, sv_grad_len), as the reference's
  /// double does.
  bool grad_over = false;
  /// |g|^2 below it: no surface (N = 0, ambient light only):
  /// surface_threshold(max - min) of the volume's value range.
  double surface_g2 = 1e-12;
};

/// The squared gradient length below which a voxel counts as no surface, for
/// a volume whose values span `span` (max - min): (1e-6 s)^2, s = span
/// clamped to [1e-10, 1]. So 1e-12 for a span of 1 or more (every volume
/// in value units of order one and up, as before), and for a smaller span
/// the same test as on the volume scaled to a span of 1: a volume in small
/// units (1e-9, say) is lit as the same volume in larger ones, where an
/// absolute 1e-12 left it ambient only. Below a span of 1e-10 the squares of
/// the kernels' float gradients would leave float's normal range, so the
/// threshold stays at 1e-32 there. A span that is not finite counts as 1.
double surface_threshold(double span);

/// Checks the parameters (finite; a non-zero light; ka, kd, ks, n >= 0; k1 > 0
/// and k1 + k2 > 0); ArgumentError naming the render option (--light,
/// --phong KA,KD,KS,N or --depth-cue K1,K2).
void validate(const ShadeParams& p);

/// Throws as validate(p) first. Takes the volume's value range (for
/// grad_over and surface_g2) from `range`, or, without it, from vol.range() (a pass over
/// the voxels: callers that render many frames keep the range).
ShadeFrame make_shade_frame(const Volume& vol, const ViewGeometry& view, const ShadeParams& p);
ShadeFrame make_shade_frame(const Volume& vol, const ViewGeometry& view, const ShadeParams& p,
                            const ValueRange& range);

/// Central-difference gradient at voxel (x, y, z), neighbours clamped at the
/// volume's edges, in value units per smallest voxel spacing; a component is
/// infinite where the two neighbours' float difference overflows (as in the
/// kernels), NaN next to a NaN. ArgumentError for a voxel outside the
/// volume or a volume whose data() was resized apart from its dims.
Vec3 gradient(const Volume& vol, int64_t x, int64_t y, int64_t z, const Vec3& grad_scale);

/// The shade stage over the whole volume (reference, serial).
std::vector<ShadeSample> shade(const Volume& vol, const ViewGeometry& view, const ShadeParams& p);

}  // namespace simdvol
