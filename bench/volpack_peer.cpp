#include "volpack_peer.hpp"

#include <volpack.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstddef>
#include <numbers>

#include "simdvol/classify.hpp"
#include "simdvol/error.hpp"

namespace simdvol::volpack {

namespace {

// Voxel fields of examples/volume.h.
constexpr int kNormalField = 0, kDensityField = 1, kGradientField = 2;
constexpr int kDensityParam = 0, kGradientParam = 1;

void check(vpResult r, const char* call) {
  if (r != VP_OK) throw Error(std::string("VolPack ") + call + ": " + vpGetErrorString(r));
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

const char* to_string(Mode m) {
  switch (m) {
    case Mode::brute_force:
      return "brute force";
    case Mode::raw:
      return "raw";
    case Mode::classified:
      return "classified";
  }
  return "?";
}

Renderer::Renderer(const Volume& vol) : dims_(vol.dims()) {
  const auto& sp = vol.spacing();
  if (sp[0] != sp[1] || sp[0] != sp[2])
    throw ArgumentError("volume",
                        "VolPack's view assumes cubic voxels; the spacing is not isotropic");
  const std::size_t n = vol.voxel_count();
  if (n == 0) throw ArgumentError("volume", "the volume is empty");
  if (dims_[0] > INT_MAX || dims_[1] > INT_MAX || dims_[2] > INT_MAX ||
      n > static_cast<std::size_t>(INT_MAX) / sizeof(RawVoxel))
    throw ArgumentError("volume", "too large for VolPack's int sizes");
  std::vector<unsigned char> density(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float v = vol.data()[i];
    if (!(v >= 0.0f && v <= 255.0f) || v != std::floor(v))
      throw ArgumentError("volume", "VolPack's example needs 8-bit densities (integers 0..255)");
    density[i] = static_cast<unsigned char>(v);
  }
  voxels_.resize(n);

  vpc_ = vpCreateContext();
  if (vpc_ == nullptr) throw Error("VolPack vpCreateContext: out of memory");
  const int nx = static_cast<int>(dims_[0]), ny = static_cast<int>(dims_[1]),
            nz = static_cast<int>(dims_[2]);
  try {
    check(vpSetVolumeSize(vpc_, nx, ny, nz), "vpSetVolumeSize");
    // makevolume.c: 3 fields, the first 2 (normal, density) for shading,
    // 2 (density, gradient) for classification.
    check(vpSetVoxelSize(vpc_, sizeof(RawVoxel), 3, 2, 2), "vpSetVoxelSize");
    check(
        vpSetVoxelField(vpc_, kNormalField, sizeof(short), offsetof(RawVoxel, normal), VP_NORM_MAX),
        "vpSetVoxelField(normal)");
    check(vpSetVoxelField(vpc_, kDensityField, sizeof(unsigned char), offsetof(RawVoxel, density),
                          255),
          "vpSetVoxelField(density)");
    check(vpSetVoxelField(vpc_, kGradientField, sizeof(unsigned char), offsetof(RawVoxel, gradient),
                          VP_GRAD_MAX),
          "vpSetVoxelField(gradient)");
    const int vs = static_cast<int>(sizeof(RawVoxel));
    check(vpSetRawVoxels(vpc_, voxels_.data(), static_cast<int>(n * sizeof(RawVoxel)), vs, nx * vs,
                         nx * ny * vs),
          "vpSetRawVoxels");
    const auto t0 = std::chrono::steady_clock::now();
    check(vpVolumeNormals(vpc_, density.data(), static_cast<int>(n), kDensityField, kGradientField,
                          kNormalField),
          "vpVolumeNormals");
    normals_ms_ = ms_since(t0);
  } catch (...) {
    vpDestroyContext(vpc_);
    throw;
  }
}

Renderer::~Renderer() {
  if (vpc_ != nullptr) vpDestroyContext(vpc_);
}

void Renderer::configure(const Settings& s) {
  if (s.width <= 0 || s.height <= 0 || s.width > 16384 || s.height > 16384)
    throw ArgumentError("--size", std::to_string(s.width) + "x" + std::to_string(s.height) +
                                      " is outside 1..16384");
  if (!(s.max_ray_opacity > 0.0 && s.max_ray_opacity <= 1.0))
    throw ArgumentError("max_ray_opacity", "must lie in (0, 1]");
  if (!(s.min_voxel_opacity >= 0.0 && s.min_voxel_opacity < 1.0))
    throw ArgumentError("min_voxel_opacity", "must lie in [0, 1)");
  if (!std::isfinite(s.turntable_deg) || !std::isfinite(s.pixel_centre))
    throw ArgumentError("settings", "angles and offsets must be finite");
  if (configured_ && classified_ && s.min_voxel_opacity != settings_.min_voxel_opacity) {
    check(vpDestroyClassifiedVolume(vpc_), "vpDestroyClassifiedVolume");
    classified_ = false;
  }

  // Classification (classifyvolume.c / rendervolume.c).
  int density_x[] = {0, 24, 255};
  float density_y[] = {0.0f, 1.0f, 1.0f};
  int gradient_x[] = {0, 5, 20, 221};
  float gradient_y[] = {0.0f, 0.0f, 1.0f, 1.0f};
  density_ramp_.assign(256, 0.0f);
  gradient_ramp_.assign(VP_GRAD_MAX + 1, 0.0f);
  check(vpRamp(density_ramp_.data(), sizeof(float), 3, density_x, density_y), "vpRamp(density)");
  check(vpRamp(gradient_ramp_.data(), sizeof(float), 4, gradient_x, gradient_y),
        "vpRamp(gradient)");
  check(vpSetClassifierTable(vpc_, kDensityParam, kDensityField, density_ramp_.data(),
                             static_cast<int>(density_ramp_.size() * sizeof(float))),
        "vpSetClassifierTable(density)");
  check(vpSetClassifierTable(vpc_, kGradientParam, kGradientField, gradient_ramp_.data(),
                             static_cast<int>(gradient_ramp_.size() * sizeof(float))),
        "vpSetClassifierTable(gradient)");
  check(vpSetd(vpc_, VP_MIN_VOXEL_OPACITY, s.min_voxel_opacity), "vpSetd(VP_MIN_VOXEL_OPACITY)");

  // Shading (rendervolume.c): a grey lookup shader indexed by the normal.
  shade_table_.assign(VP_NORM_MAX + 1, 0.0f);
  check(vpSetLookupShader(vpc_, 1, 1, kNormalField, shade_table_.data(),
                          static_cast<int>(shade_table_.size() * sizeof(float)), 0, nullptr, 0),
        "vpSetLookupShader");
  check(vpSetMaterial(vpc_, VP_MATERIAL0, VP_AMBIENT, VP_BOTH_SIDES, Example::ambient,
                      Example::ambient, Example::ambient),
        "vpSetMaterial(ambient)");
  check(vpSetMaterial(vpc_, VP_MATERIAL0, VP_DIFFUSE, VP_BOTH_SIDES, Example::diffuse,
                      Example::diffuse, Example::diffuse),
        "vpSetMaterial(diffuse)");
  check(vpSetMaterial(vpc_, VP_MATERIAL0, VP_SPECULAR, VP_BOTH_SIDES, Example::specular,
                      Example::specular, Example::specular),
        "vpSetMaterial(specular)");
  check(
      vpSetMaterial(vpc_, VP_MATERIAL0, VP_SHINYNESS, VP_BOTH_SIDES, Example::shininess, 0.0, 0.0),
      "vpSetMaterial(shininess)");
  // The light is transformed by the model matrix current at vpSetLight:
  // the identity here, as in the example (it stays fixed in eye space).
  check(vpCurrentMatrix(vpc_, VP_VIEW), "vpCurrentMatrix(VP_VIEW)");
  check(vpIdentityMatrix(vpc_), "vpIdentityMatrix");
  check(vpCurrentMatrix(vpc_, VP_MODEL), "vpCurrentMatrix(VP_MODEL)");
  check(vpIdentityMatrix(vpc_), "vpIdentityMatrix");
  check(vpSetLight(vpc_, VP_LIGHT0, VP_DIRECTION, Example::light[0], Example::light[1],
                   Example::light[2]),
        "vpSetLight(direction)");
  check(vpSetLight(vpc_, VP_LIGHT0, VP_COLOR, 1.0, 1.0, 1.0), "vpSetLight(colour)");
  check(vpEnable(vpc_, VP_LIGHT0, 1), "vpEnable(VP_LIGHT0)");
  check(vpSetDepthCueing(vpc_, Example::cue_front, Example::cue_density), "vpSetDepthCueing");
  check(vpEnable(vpc_, VP_DEPTH_CUE, s.depth_cue ? 1 : 0), "vpEnable(VP_DEPTH_CUE)");

  // The view: rendervolume.c's rotations (pre-multiplied), then the
  // movie's turntable step about the eye's vertical axis.
  check(vpSeti(vpc_, VP_CONCAT_MODE, VP_CONCAT_LEFT), "vpSeti(VP_CONCAT_MODE)");
  check(vpRotate(vpc_, VP_Y_AXIS, Example::rotate_y), "vpRotate(y)");
  check(vpRotate(vpc_, VP_X_AXIS, Example::rotate_x), "vpRotate(x)");
  if (s.turntable_deg != 0.0) check(vpRotate(vpc_, VP_Y_AXIS, s.turntable_deg), "vpRotate(y)");
  // The window: the unit cube's side (the longest volume side) spans
  // min(W, H) pixels, shifted so that VolPack's pixel centres fall where
  // simdvol's do.
  const double m = std::min(s.width, s.height);
  const double shift = (0.5 - s.pixel_centre) / m;
  check(vpCurrentMatrix(vpc_, VP_PROJECT), "vpCurrentMatrix(VP_PROJECT)");
  check(vpIdentityMatrix(vpc_), "vpIdentityMatrix");
  check(vpWindow(vpc_, VP_PARALLEL, -0.5 * s.width / m + shift, 0.5 * s.width / m + shift,
                 -0.5 * s.height / m + shift, 0.5 * s.height / m + shift, -0.5, 0.5),
        "vpWindow");
  check(vpCurrentMatrix(vpc_, VP_MODEL), "vpCurrentMatrix(VP_MODEL)");

  // Grey plus alpha (the example writes VP_LUMINANCE; the alpha channel
  // costs nothing extra and gives the image's coverage).
  image_.assign(static_cast<std::size_t>(s.width) * s.height * 2, 0);
  check(vpSetImage(vpc_, image_.data(), s.width, s.height, s.width * 2, VP_LUMINANCEA),
        "vpSetImage");
  check(vpSetd(vpc_, VP_MAX_RAY_OPACITY, s.max_ray_opacity), "vpSetd(VP_MAX_RAY_OPACITY)");
  settings_ = s;
  configured_ = true;
}

double Renderer::classify() {
  if (!configured_) throw ArgumentError("VolPack", "configure() before classify()");
  const auto t0 = std::chrono::steady_clock::now();
  check(vpClassifyVolume(vpc_), "vpClassifyVolume");
  classified_ = true;
  return ms_since(t0);
}

Image Renderer::render(Mode mode) {
  if (!configured_) throw ArgumentError("VolPack", "configure() before render()");
  if (mode == Mode::classified && !classified_)
    throw ArgumentError("VolPack", "classify() before a classified render");
  check(vpShadeTable(vpc_), "vpShadeTable");
  switch (mode) {
    case Mode::brute_force:
      check(vpBruteForceRender(vpc_), "vpBruteForceRender");
      break;
    case Mode::raw:
      check(vpRenderRawVolume(vpc_), "vpRenderRawVolume");
      break;
    case Mode::classified:
      check(vpRenderClassifiedVolume(vpc_), "vpRenderClassifiedVolume");
      break;
  }
  const int w = settings_.width, h = settings_.height;
  Image img(w, h);
  for (int r = 0; r < h; ++r) {
    const unsigned char* row = image_.data() + static_cast<std::size_t>(r) * w * 2;
    for (int x = 0; x < w; ++x) {
      const float l = row[2 * x] / 255.0f, a = row[2 * x + 1] / 255.0f;
      img.at(x, r) = Rgba{l, l, l, a};
    }
  }
  return img;
}

Mat3 Renderer::model() const {
  vpMatrix4 m;
  check(vpGetMatrix(vpc_, VP_MODEL, m), "vpGetMatrix(VP_MODEL)");
  Mat3 r{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = m[i][j];
  return r;
}

Mat3 viewing_rotation(const Mat3& model) {
  return model;
}

ViewAngles angles_from_model(const Mat3& model) {
  // rotation(theta, phi, varphi) has row 0 = (cos phi cos theta,
  // cos phi sin theta, -sin phi), T[1][2] = -sin varphi cos phi,
  // T[2][2] = cos varphi cos phi.
  const Mat3 t = viewing_rotation(model);
  const double deg = 180.0 / std::numbers::pi;
  ViewAngles a;
  a.theta = std::atan2(t[0][1], t[0][0]) * deg;
  a.phi = std::atan2(-t[0][2], std::hypot(t[0][0], t[0][1])) * deg;
  a.varphi = std::atan2(-t[1][2], t[2][2]) * deg;
  const Mat3 back = rotation(a.theta, a.phi, a.varphi);
  double err = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) err = std::max(err, std::fabs(back[i][j] - t[i][j]));
  if (!(err < 1e-9))
    throw ArgumentError("VolPack model matrix",
                        "is not a rotation that T(theta, phi, varphi) reproduces (error " +
                            std::to_string(err) + ")");
  return a;
}

std::array<double, 3> fit_depth_cue(const Volume& vol, const ViewGeometry& view) {
  const auto& d = vol.dims();
  const double maxdim = static_cast<double>(std::max({d[0], d[1], d[2]}));
  const double two_r = 2.0 * view.radius;
  // Depth range of the volume's corners in simdvol's d.
  double zlo = 1e300, zhi = -1e300;
  for (int c = 0; c < 8; ++c) {
    double z = 0.0;
    for (int a = 0; a < 3; ++a) {
      const double p =
          ((c >> a) & 1) ? 0.5 * static_cast<double>(d[a]) : -0.5 * static_cast<double>(d[a]);
      z += view.rot[2][a] * p;
    }
    zlo = std::min(zlo, z);
    zhi = std::max(zhi, z);
  }
  // z (into the scene, voxels) -> d = (z + R) / 2R; VolPack's D = 0.5 + z / maxdim.
  // Least squares of k1 + k2 d against g = 1 / cue over the volume's depth
  // range, weighted by 1 / g^2 (relative error: the front, where the
  // visible surfaces are, counts as much as the back). ShadeParams needs
  // k1 + k2 d > 0 on all of d in [0, 1]: when the free line is not, the
  // best line on the violated boundary (k1 = eps or k1 + k2 = eps).
  const int n = 513;
  auto cue_at = [&](double dd) {
    const double z = dd * two_r - view.radius;
    return Example::cue_front * std::exp(-Example::cue_density * (0.5 + z / maxdim));
  };
  const double dlo = (zlo + view.radius) / two_r, dhi = (zhi + view.radius) / two_r;
  std::vector<double> ds(n), gs(n), ws(n);
  double s0 = 0, s1 = 0, s2 = 0, t0 = 0, t1 = 0;
  for (int i = 0; i < n; ++i) {
    ds[i] = dlo + (dhi - dlo) * i / (n - 1);
    gs[i] = 1.0 / cue_at(ds[i]);
    ws[i] = 1.0 / (gs[i] * gs[i]);
    s0 += ws[i];
    s1 += ws[i] * ds[i];
    s2 += ws[i] * ds[i] * ds[i];
    t0 += ws[i] * gs[i];
    t1 += ws[i] * ds[i] * gs[i];
  }
  double k2 = (s0 * t1 - s1 * t0) / (s0 * s2 - s1 * s1);
  double k1 = (t0 - k2 * s1) / s0;
  const double eps = 0.01;
  if (!(k1 >= eps)) {
    double num = 0, den = 0;
    for (int i = 0; i < n; ++i) {
      num += ws[i] * ds[i] * (gs[i] - eps);
      den += ws[i] * ds[i] * ds[i];
    }
    k1 = eps;
    k2 = num / den;
  }
  if (!(k1 + k2 >= eps)) {
    double num = 0, den = 0;
    for (int i = 0; i < n; ++i) {
      num += ws[i] * (ds[i] - 1.0) * (gs[i] - eps);
      den += ws[i] * (ds[i] - 1.0) * (ds[i] - 1.0);
    }
    k2 = num / den;
    k1 = eps - k2;
  }
  double err = 0.0;
  for (int i = 0; i < n; ++i) {
    const double dd = dlo + (dhi - dlo) * i / (n - 1);
    const double c = cue_at(dd);
    err = std::max(err, std::fabs(1.0 / (k1 + k2 * dd) - c) / c);
  }
  return {k1, k2, err};
}

RenderOptions matched_options(const Volume& vol, const Settings& s, const Mat3& model, int order) {
  RenderOptions o;
  o.view = angles_from_model(model);
  o.width = s.width;
  o.height = s.height;
  o.sampling = Sampling::voxel;
  o.order = order;
  o.composite.mode = CompositeMode::direct;
  o.classifier = classifier_preset("volpack");
  o.shade.enabled = true;
  // Eye space is viewing space; -L because VolPack's viewer vector points
  // into the scene (its H = norm(L + (0, 0, 1)), simdvol's norm(L + (0, 0, -1))).
  o.shade.light = {-Example::light[0], -Example::light[1], -Example::light[2]};
  o.shade.ka = Example::ambient;
  o.shade.kd = Example::diffuse;
  o.shade.ks = Example::specular;
  o.shade.shininess = Example::shininess;
  if (s.depth_cue) {
    const ViewGeometry g = make_view(vol, o.view, s.width, s.height, Sampling::voxel);
    const auto fit = fit_depth_cue(vol, g);
    o.shade.k1 = fit[0];
    o.shade.k2 = fit[1];
  } else {
    o.shade.k1 = 1.0;
    o.shade.k2 = 0.0;
  }
  validate(o);
  return o;
}

std::vector<std::string> unmatched() {
  return {
      "depth cueing: VolPack multiplies each voxel's whole colour (ambient included) by "
      "1.4 exp(-1.5 D), D = 0 at the window's front plane; simdvol cues only the diffuse and "
      "specular terms, by 1 / (k1 + k2 d): k1, k2 fitted by least squares over the volume's "
      "depth range (the 'matched' PSNR column turns cueing off in both)",
      "minimum voxel opacity: VolPack drops voxels below VP_MIN_VOXEL_OPACITY = 0.05; simdvol "
      "composites every voxel ('matched': 0 in VolPack)",
      "early ray termination: VolPack stops a ray at VP_MAX_RAY_OPACITY = 0.95; simdvol's "
      "direct compositing runs to the end ('matched': 1.0 in VolPack)",
      "shading table: VolPack quantises normals to 13 bits (7924 directions) and lights one "
      "side, max(N.L, 0) and max(N.H, 0) with N turned to its viewer vector (0, 0, +1) in eye "
      "space, which points into the scene (so simdvol gets the light -L, making |N.L| and "
      "|N.H| agree); simdvol lights float normals two-sided, |N.L| and |N.H|",
      "gradients: VolPack rounds |grad| to an integer 0..221 and zeroes gradient and normal on "
      "the volume's boundary voxels; simdvol keeps float magnitudes and clamps neighbours",
      "opacity: VolPack's classified volume holds 8-bit opacities and corrects them per view by "
      "a table for the sheared slice spacing; simdvol keeps float opacities, samples every "
      "voxel length along the ray",
      "resampling: shear-warp interpolates bilinearly within each voxel slice (the slices "
      "composite at the major axis' spacing), then warps the intermediate image bilinearly "
      "into 8-bit pixels; simdvol resamples in 3-D along rays (order 3 here: Aitken's cubic "
      "Lagrange interpolation) and "
      "scales bilinearly, in float",
  };
}

Image mirror_x(const Image& img) {
  Image out(img.width(), img.height());
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) out.at(x, y) = img.at(img.width() - 1 - x, y);
  return out;
}

Image mirror_y(const Image& img) {
  Image out(img.width(), img.height());
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) out.at(x, y) = img.at(x, img.height() - 1 - y);
  return out;
}

}  // namespace simdvol::volpack
