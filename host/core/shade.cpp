// The shade stage, serial reference (thesis ch. 4.3, eq 4.1-4.3).
//
// Conventions (the OpenCL kernel implements exactly these formulas):
//
//  Gradient (eq 4.3's operator). For voxel (x, y, z) and axis a, with the
//  neighbour indices clamped into [0, n_a - 1]:
//      g_a = 0.5 * (f(i_a + 1) - f(i_a - 1)) * grad_scale[a]
//      grad_scale[a] = min(spacing) / spacing[a]
//  so g is d f / d(physical distance) in value units per smallest voxel
//  spacing. At an edge the clamp makes it a one-sided half difference
//  0.5 * (f(1) - f(0)); along an axis of length 1 it is 0. This is the same
//  scale as VolPack's gradient magnitudes (a u8 volume gives |g| <= 255 *
//  sqrt(3) / 2 = 220.8, VolPack's VP_GRAD_MAX = 221).
//
//  Light and view (eq 4.2). ShadeParams::light points from the scene
//  towards the light in viewing space (x right, y down the image, z into the
//  scene). The observer looks along +z, so V = (0, 0, -1) points towards
//  the observer. L = light / |light|; H = (V + L) / |V + L|, or H = V when
//  |V + L| < 1e-12 (light straight behind the volume: with the two-sided
//  |N.H| below, H = V and H = L are the same choice). ViewGeometry::rot maps
//  object (physical) coordinates to viewing coordinates and is orthonormal,
//  so L and H are taken to object space with its transpose:
//      light_obj = rot^T L,   halfway_obj = rot^T H.
//
//  Depth (eq 4.1's d(x)). Voxel (i0, i1, i2) covers [i, i + 1) along each
//  axis in index space; its centre is i + 0.5 and the volume's centre is
//  n / 2. In units of the smallest voxel spacing, with s_a = spacing[a] /
//  min(spacing), the centre's physical offset from the volume's centre is
//      p_a = (i_a + 0.5 - n_a / 2) * s_a
//  and its viewing depth is z = sum_a rot[2][a] * p_a, which lies within
//  [-R, R] for R = view.radius (half the diagonal). Then
//      d = (z + R) / (2 R)        (0 = nearest point of the bounding sphere,
//                                  1 = farthest)
//  which is affine in the index:
//      d = dot(depth_dir, i) + depth_offset
//      depth_dir[a]  = rot[2][a] * s_a / (2 R)
//      depth_offset  = 0.5 + sum_a rot[2][a] * s_a * (0.5 - n_a / 2) / (2 R)
//
//  Lighting (eq 4.1 with f = 1, V_lambda = 1, one colour channel: the
//  material colour multiplies later, in classify). Per voxel:
//      |g| = sqrt(g.g)
//      N   = g / |g|, or N = 0 when g.g < t (only ambient light), t =
//            surface_threshold(the value range's span): 1e-12 for a span
//            of 1 or more, (1e-6 span)^2 below (at least 1e-32)
//      cue = 1 / (k1 + k2 * d)
//      Id  = ka + cue * kd * |N.L|
//      Is  = cue * ks * |N.H|^n        (Is = 0 when N = 0, whatever n)
//  Lighting is two-sided: |N.L| and |N.H|, so the sign of N (which way the
//  gradient points across a surface) does not matter. With shading
//  disabled, Id = 1 and Is = 0 (|g| is still computed; classify needs it).
//  A non-finite g.g (a NaN or infinite neighbour, or two neighbours further
//  apart than the largest float, whose float difference overflows) counts
//  as g = 0: |g| = 0, N = 0. A finite g whose g.g overflows float (|g|
//  above about 1.8e19) is lit as any other: the kernels take its length
//  rescaled (shade.cl, sv_grad_len).
#include "simdvol/shade.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "number_text.hpp"
#include "simdvol/error.hpp"

namespace simdvol {
namespace {

double dot3(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// rot^T v (rot orthonormal, so this is rot^-1 v).
Vec3 transpose_times(const Mat3& rot, const Vec3& v) {
  Vec3 r{};
  for (int a = 0; a < 3; ++a) r[a] = rot[0][a] * v[0] + rot[1][a] * v[1] + rot[2][a] * v[2];
  return r;
}

bool finite3(const Vec3& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

void validate(const ShadeParams& p) {
  using detail::number_text;
  const auto need_finite = [](double v, const char* option) {
    if (!std::isfinite(v))
      throw ArgumentError(option, "must be finite (got " + std::to_string(v) + ")");
  };
  for (double v : {p.ka, p.kd, p.ks, p.shininess}) need_finite(v, "--phong");
  for (double v : {p.k1, p.k2}) need_finite(v, "--depth-cue");
  if (!finite3(p.light)) throw ArgumentError("--light", "must be finite");
  // hypot: |light| without overflow or underflow (1e200 and 1e-200 are
  // directions too; their squares are not doubles).
  if (!(std::hypot(p.light[0], p.light[1], p.light[2]) > 0.0))
    throw ArgumentError("--light", "must be a non-zero direction");
  if (p.ka < 0 || p.kd < 0 || p.ks < 0)
    throw ArgumentError("--phong", "ka, kd and ks must be >= 0");
  if (p.shininess < 0) throw ArgumentError("--phong", "the exponent n must be >= 0");
  // The cue's denominator k1 + k2 d must stay positive for every d in [0, 1].
  if (p.k1 <= 0 || p.k1 + p.k2 <= 0)
    throw ArgumentError("--depth-cue",
                        "k1 + k2 * d must be > 0 for d in [0, 1] (k1 = " + std::to_string(p.k1) +
                            ", k2 = " + std::to_string(p.k2) + ")");
  // The device lights in float: each coefficient a float, and the light a
  // voxel can get, ka + max(kd, ks) / min(k1, k1 + k2), far from float's
  // largest (a k1 of 1e-40 made the cue infinite there, and inf * 0 a NaN,
  // where the reference's double gave 0: images 42-52 dB apart).
  constexpr double kMaxLight = 1e30;
  for (const double v : {p.ka, p.kd, p.ks, p.shininess})
    if (v > kMaxLight)
      throw ArgumentError("--phong", "coefficients and the exponent must be at most 1e30 (got " +
                                         number_text(v) + ")");
  for (const double v : {p.k1, p.k2})
    if (std::fabs(v) > kMaxLight)
      throw ArgumentError("--depth-cue",
                          "k1 and k2 must lie in -1e30 .. 1e30 (got " + number_text(v) + ")");
  const double light = p.ka + std::max(p.kd, p.ks) / std::min(p.k1, p.k1 + p.k2);
  if (!(light <= kMaxLight))
    throw ArgumentError("--phong and --depth-cue",
                        "a voxel's light could reach ka + max(kd, ks) / min(k1, k1 + k2) = " +
                            number_text(light) + ", beyond 1e30 (float arithmetic overflows)");
}

namespace {

// gradient() without its checks: shade() walks the volume's own voxels.
Vec3 gradient_at(const Volume& vol, int64_t x, int64_t y, int64_t z, const Vec3& grad_scale) {
  const std::array<int64_t, 3> i{x, y, z};
  Vec3 g{};
  for (int a = 0; a < 3; ++a) {
    std::array<int64_t, 3> lo = i, hi = i;
    lo[a] = std::max<int64_t>(i[a] - 1, 0);
    hi[a] = std::min<int64_t>(i[a] + 1, vol.dims()[a] - 1);
    const float fh = vol.at(hi[0], hi[1], hi[2]), fl = vol.at(lo[0], lo[1], lo[2]);
    // Neighbours further apart than the largest float: the kernels' float
    // difference is infinite there, so this one is too (no surface).
    const float fd = fh - fl;
    const double diff = std::isfinite(fd) ? static_cast<double>(fh) - static_cast<double>(fl)
                                          : static_cast<double>(fd);
    g[a] = 0.5 * diff * grad_scale[a];
  }
  return g;
}

}  // namespace

Vec3 gradient(const Volume& vol, int64_t x, int64_t y, int64_t z, const Vec3& grad_scale) {
  vol.check_voxel_count();
  const std::array<int64_t, 3> i{x, y, z};
  for (int a = 0; a < 3; ++a)
    if (i[a] < 0 || i[a] >= vol.dims()[a])
      // (a voxel outside was read from outside the volume's data)
      throw ArgumentError("xyz"[a] + std::string(), "voxel " + std::to_string(i[a]) +
                                                        " lies outside the volume's 0 .. " +
                                                        std::to_string(vol.dims()[a] - 1));
  return gradient_at(vol, x, y, z, grad_scale);
}

ShadeFrame make_shade_frame(const Volume& vol, const ViewGeometry& view, const ShadeParams& p) {
  validate(p);  // before the range's pass over the voxels
  vol.check_voxel_count();
  return make_shade_frame(vol, view, p, vol.range());
}

ShadeFrame make_shade_frame(const Volume& vol, const ViewGeometry& view, const ShadeParams& p,
                            const ValueRange& range) {
  validate(p);
  vol.check_voxel_count();
  if (!(view.radius > 0) || !std::isfinite(view.radius))
    throw ArgumentError("view.radius",
                        "must be positive (got " + std::to_string(view.radius) + ")");
  for (const auto& row : view.rot)
    if (!std::isfinite(row[0]) || !std::isfinite(row[1]) || !std::isfinite(row[2]))
      throw ArgumentError("view.rot", "must be finite");

  ShadeFrame f;
  // |g_a| <= (max - min) / 2, so |g|^2 <= 0.75 (max - min)^2: below
  // FLT_MAX = 3.4e38 for spans under 2.1e19 (1e19 leaves a margin).
  const double span = static_cast<double>(range.max) - static_cast<double>(range.min);
  f.grad_over = span >= 1e19;
  f.surface_g2 = surface_threshold(span);
  const double min_sp = std::min({vol.spacing()[0], vol.spacing()[1], vol.spacing()[2]});
  Vec3 s{};  // spacing in units of the smallest spacing
  for (int a = 0; a < 3; ++a) {
    s[a] = vol.spacing()[a] / min_sp;
    f.grad_scale[a] = min_sp / vol.spacing()[a];
  }

  // L and H in viewing space (eq 4.2), V = (0, 0, -1) towards the observer.
  const double ln = std::hypot(p.light[0], p.light[1], p.light[2]);
  const Vec3 L{p.light[0] / ln, p.light[1] / ln, p.light[2] / ln};
  const Vec3 V{0.0, 0.0, -1.0};
  const Vec3 vl{V[0] + L[0], V[1] + L[1], V[2] + L[2]};
  const double hn = std::sqrt(dot3(vl, vl));
  const Vec3 H = hn < 1e-12 ? V : Vec3{vl[0] / hn, vl[1] / hn, vl[2] / hn};
  f.light_obj = transpose_times(view.rot, L);
  f.halfway_obj = transpose_times(view.rot, H);

  // d = (z + R) / (2 R), z = sum_a rot[2][a] * (i_a + 0.5 - n_a / 2) * s_a.
  const double two_r = 2.0 * view.radius;
  f.depth_offset = 0.5;
  for (int a = 0; a < 3; ++a) {
    const double w = view.rot[2][a] * s[a] / two_r;
    f.depth_dir[a] = w;
    f.depth_offset += w * (0.5 - 0.5 * static_cast<double>(vol.dims()[a]));
  }
  return f;
}

double surface_threshold(double span) {
  const double s = !(span < 1.0) ? 1.0 : std::max(span, 1e-10);  // NaN: 1
  return 1e-12 * s * s;
}

float specular_floor(double shininess) {
  if (!(shininess > 0.0)) return 0.0f;
  const double t = std::exp2(-100.0 / shininess);
  return std::max(static_cast<float>(t), std::numeric_limits<float>::min());
}

std::vector<ShadeSample> shade(const Volume& vol, const ViewGeometry& view, const ShadeParams& p) {
  const ShadeFrame f = make_shade_frame(vol, view, p);
  const double spec_floor = specular_floor(p.shininess);
  std::vector<ShadeSample> out(vol.voxel_count());
  for (int64_t z = 0; z < vol.nz(); ++z)
    for (int64_t y = 0; y < vol.ny(); ++y)
      for (int64_t x = 0; x < vol.nx(); ++x) {
        const Vec3 g = gradient_at(vol, x, y, z, f.grad_scale);
        double g2 = dot3(g, g);
        if (!std::isfinite(g2)) g2 = 0.0;  // a NaN/inf neighbour: no surface
        const double mag = std::sqrt(g2);
        ShadeSample& s = out[vol.index(x, y, z)];
        s.gradient = static_cast<float>(mag);
        if (!p.enabled) {
          s.diffuse = 1.0f;
          s.specular = 0.0f;
          continue;
        }
        const double d = f.depth_dir[0] * static_cast<double>(x) +
                         f.depth_dir[1] * static_cast<double>(y) +
                         f.depth_dir[2] * static_cast<double>(z) + f.depth_offset;
        const double cue = 1.0 / (p.k1 + p.k2 * d);
        if (g2 < f.surface_g2) {  // no surface: N = 0, ambient only
          s.diffuse = static_cast<float>(p.ka);
          s.specular = 0.0f;
          continue;
        }
        const double nl = std::fabs(dot3(g, f.light_obj)) / mag;
        const double nh = std::fabs(dot3(g, f.halfway_obj)) / mag;
        s.diffuse = static_cast<float>(p.ka + cue * p.kd * nl);
        const double power = nh < spec_floor ? 0.0 : std::pow(nh, p.shininess);
        s.specular = static_cast<float>(cue * p.ks * power);
      }
  return out;
}

}  // namespace simdvol
