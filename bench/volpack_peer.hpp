// VolPack (Lacroute's shear-warp renderer, Debian's libvolpack1-dev 1.0b3) as
// a peer renderer: the pipeline of its examples/ (makevolume.c,
// classifyvolume.c, rendervolume.c) for brainsmall.den, reproduced in C++,
// and the mapping of its view onto simdvol's T(theta, phi, varphi), its
// shading onto ShadeParams, its transfer function onto the "volpack" preset.
//
// The view, exactly. VolPack's object space is the volume scaled so its
// longest side is 1, centred: voxel index v sits at (v - n / 2) / maxdim
// (vp_view.c, VPComputeViewTransform), as simdvol's voxel v sits at v - n / 2.
// The model matrix M (VP_VIEW the identity) maps it to eye space; the
// window [-0.5, 0.5]^3 and the viewport map eye x to image columns and eye y
// to the image's scan lines in memory order (scan line 0 first), and eye
// z_e to image depth z_img = 0.5 - z_e, the largest z_img being the front
// (FactorAffineView composites slices in decreasing z_img; the depth cue
// table is front * exp(-density * (1 - z_img))). So in 1.0b3's code the
// viewer looks down +z_e (the man page says -z), and eye space is simdvol's
// viewing space (x right, y down the image, z into the scene) as it
// stands: T = M. Measured: rendering both and comparing, T = M with scan
// line 0 on top is the only one of the 16 combinations of proper axis
// flips and image mirrors that matches (bench --orientation output, test).
// One VolPack quirk follows: vpShadeTable's viewer vector is (0, 0, +1) in
// eye space, i.e. into the scene, so its halfway vector is
// H = norm(L + (0, 0, 1)); simdvol's is norm(L + (0, 0, -1)), so the light
// given to simdvol is -L (|N.L| and |N.H| then agree exactly).
// The window is set so that the longest side spans min(W, H) pixels in both
// renderers (the example's square window does that for square images) and
// pixel centres agree (see pixel_centre).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/render.hpp"
#include "simdvol/view.hpp"
#include "simdvol/volume.hpp"

struct _vp_context;  // volpack.h: typedef struct _vp_context vpContext

namespace simdvol::volpack {

/// The example's constants (examples/volume.h, classifyvolume.c,
/// rendervolume.c).
struct Example {
  static constexpr double rotate_y = 130.0, rotate_x = -15.0;  ///< vpRotate, VP_CONCAT_LEFT
  static constexpr double turntable_step = 5.0;                ///< degrees per frame about eye y
  static constexpr double ambient = 0.18, diffuse = 0.35, specular = 0.39, shininess = 10.0;
  static constexpr std::array<double, 3> light{0.3, 0.3, 1.0};  ///< eye space, set with M = I
  static constexpr double cue_front = 1.4,
                          cue_density = 1.5;       ///< T = front * exp(-density * depth)
  static constexpr double max_ray_opacity = 0.95;  ///< early ray termination
  static constexpr double min_voxel_opacity = 0.05;
  static constexpr int width = 256, height = 256;
};

struct Settings {
  int width = Example::width, height = Example::height;
  /// Extra rotation about the eye's vertical axis after the example's view
  /// (rendervolume.c's movie: vpRotate(VP_Y_AXIS, 5) per frame).
  double turntable_deg = 0.0;
  bool depth_cue = true;  ///< the example's vpSetDepthCueing(1.4, 1.5)
  double max_ray_opacity = Example::max_ray_opacity;
  double min_voxel_opacity = Example::min_voxel_opacity;
  /// Where VolPack samples pixel i within the window spanning [0, W)
  /// (image coordinates). simdvol samples i + 0.5; the window is shifted by
  /// (0.5 - pixel_centre) pixels so the two agree.
  double pixel_centre = 0.0;
};

enum class Mode {
  brute_force,  ///< vpBruteForceRender (VolPack's debugging ray caster)
  raw,          ///< vpRenderRawVolume, no octree (rendervolume with no flag)
  classified,   ///< vpRenderClassifiedVolume after vpClassifyVolume
};
const char* to_string(Mode m);

/// One VolPack context holding brainsmall-style voxels: {normal index
/// (VP_NORM_SIZE), density, gradient magnitude} per voxel, as
/// makevolume.c builds them with vpVolumeNormals.
class Renderer {
 public:
  /// `vol` must hold integers in [0, 255] (a u8 volume such as
  /// brainsmall.den) with isotropic spacing; throws ArgumentError otherwise.
  explicit Renderer(const Volume& vol);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// Classification tables, shading, view, image and thresholds. Throws
  /// ArgumentError for bad sizes, Error naming the failing VolPack call.
  /// Invalidates a classified volume.
  void configure(const Settings& s);
  const Settings& settings() const { return settings_; }

  double normals_ms() const { return normals_ms_; }  ///< vpVolumeNormals (once)
  /// vpClassifyVolume (the preclassified run-length volume); returns ms.
  double classify();
  bool classified() const { return classified_; }

  /// vpShadeTable + the mode's render (what rendervolume.c does per frame).
  /// Classified mode needs classify() first. Returns VolPack's image
  /// (scan line 0 as row 0), premultiplied grey.
  Image render(Mode m);

  /// The 3x3 of VP_MODEL (VP_VIEW is the identity).
  Mat3 model() const;

 private:
  struct RawVoxel {
    short normal;
    unsigned char density;
    unsigned char gradient;
  };
  _vp_context* vpc_ = nullptr;
  std::array<int64_t, 3> dims_{};
  std::vector<RawVoxel> voxels_;
  std::vector<float> density_ramp_, gradient_ramp_, shade_table_;
  std::vector<unsigned char> image_;
  Settings settings_{};
  bool configured_ = false, classified_ = false;
  double normals_ms_ = 0.0;
};

/// T = M: VolPack's eye space is simdvol's viewing space (see above).
Mat3 viewing_rotation(const Mat3& model);
/// The angles with rotation(angles) = viewing_rotation(model); throws
/// ArgumentError when the result does not reproduce T to 1e-9 (not a rotation).
ViewAngles angles_from_model(const Mat3& model);

/// The depth cue 1 / (k1 + k2 d) closest to VolPack's front * exp(-density D)
/// (D: VolPack's depth, 0 at the window's front plane z_eye = +maxdim / 2,
/// 1 at the back; d: simdvol's, 0 to 1 across the bounding sphere): least
/// squares on 1 / cue, relative, over the volume's depth range, kept
/// positive on d in [0, 1] as ShadeParams requires. Returns {k1, k2, the
/// largest relative error of the cue over the volume's range}.
std::array<double, 3> fit_depth_cue(const Volume& vol, const ViewGeometry& view);

/// simdvol's render options for the same picture: the view from `model`,
/// the "volpack" classifier preset, the example's Phong constants, the light
/// -L (see above; two-sided), the fitted depth cue (or none when !s.depth_cue), voxel
/// sampling, direct compositing, the given order.
RenderOptions matched_options(const Volume& vol, const Settings& s, const Mat3& model, int order);

/// What cannot be matched exactly, one line each (printed by the bench).
std::vector<std::string> unmatched();

/// Left-right mirror of an image (orientation checks).
Image mirror_x(const Image& img);
/// Top-bottom mirror of an image (orientation checks).
Image mirror_y(const Image& img);

}  // namespace simdvol::volpack
