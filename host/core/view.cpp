#include "simdvol/view.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <string>

#include "simdvol/error.hpp"

namespace simdvol {

Mat3 multiply(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

Vec3 multiply(const Mat3& a, const Vec3& v) {
  Vec3 r{};
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) r[i] += a[i][k] * v[k];
  return r;
}

Mat3 transpose(const Mat3& a) {
  Mat3 t{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) t[i][j] = a[j][i];
  return t;
}

double determinant(const Mat3& a) {
  return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
         a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
         a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
}

Mat3 rotation(double theta_deg, double phi_deg, double varphi_deg) {
  const double d = std::numbers::pi / 180.0;
  const double ct = std::cos(theta_deg * d), st = std::sin(theta_deg * d);
  const double cp = std::cos(phi_deg * d), sp = std::sin(phi_deg * d);
  const double cv = std::cos(varphi_deg * d), sv = std::sin(varphi_deg * d);
  // Eq 5.2, factor by factor: T = A(varphi) B(phi) C(theta).
  const Mat3 a{{{0, 0, 1}, {-sv, cv, 0}, {cv, sv, 0}}};
  const Mat3 b{{{sp, 0, cp}, {0, 1, 0}, {cp, 0, -sp}}};
  const Mat3 c{{{ct, st, 0}, {-st, ct, 0}, {0, 0, 1}}};
  return multiply(a, multiply(b, c));
}

namespace {

int64_t to_fixed(double x) {
  return std::llround(std::ldexp(x, SV_FRAC_BITS));
}

// floor(a / b) and ceil(a / b) for b > 0, exact in 128-bit integers.
__int128 floor_div(__int128 a, __int128 b) {
  __int128 q = a / b;
  if ((a % b != 0) && (a < 0)) --q;
  return q;
}
__int128 ceil_div(__int128 a, __int128 b) {
  return -floor_div(-a, b);
}

}  // namespace

bool ViewGeometry::inside(int64_t i, int64_t j, int64_t k) const {
  for (int a = 0; a < 3; ++a) {
    const int64_t f = fixed_floor(fixed(a, i, j, k));
    if (f < 0 || f >= grid.dims[a]) return false;
  }
  return true;
}

std::array<int64_t, 2> ViewGeometry::ray_range(int64_t i, int64_t j) const {
  // Sample k is inside along axis a iff 0 <= base + k * d < n * 2^F.
  __int128 lo = 0, hi = grid.grid[2];  // [lo, hi)
  for (int a = 0; a < 3; ++a) {
    const __int128 base = fixed(a, i, j, 0);
    const __int128 d = grid.step[a][2];
    const __int128 top = static_cast<__int128>(grid.dims[a]) << SV_FRAC_BITS;
    if (d == 0) {
      if (base < 0 || base >= top) return {0, 0};
    } else if (d > 0) {
      // k >= ceil(-base / d) and k < ceil((top - base) / d)
      lo = std::max(lo, ceil_div(-base, d));
      hi = std::min(hi, ceil_div(top - base, d));
    } else {
      // base + k d < top  <=>  k > (top - base) / d  <=> k >= floor((base - top) / -d) + 1
      // base + k d >= 0   <=>  k <= base / -d          <=> k <  floor(base / -d) + 1
      lo = std::max(lo, floor_div(base - top, -d) + 1);
      hi = std::min(hi, floor_div(base, -d) + 1);
    }
  }
  if (lo >= hi) return {0, 0};
  return {static_cast<int64_t>(lo), static_cast<int64_t>(hi)};
}

std::array<double, 2> ViewGeometry::output_to_intermediate(int x, int y) const {
  if (sampling == Sampling::pixel) return {double(x), double(y)};
  // Output pixel centres in viewing units (the framing's span covers
  // min(out_width, out_height) pixels), then intermediate pixel coordinates.
  const double scale = std::min(out_width, out_height) / span;  // pixels per unit
  const double u = (x + 0.5 - 0.5 * out_width) / scale;
  const double v = (y + 0.5 - 0.5 * out_height) / scale;
  return {u / step + 0.5 * width() - 0.5, v / step + 0.5 * height() - 0.5};
}

Mat3 inverse_viewing_map(const ViewGeometry& view, Vec3& origin) {
  Mat3 m{};
  for (int a = 0; a < 3; ++a) {
    origin[a] = std::ldexp(static_cast<double>(view.grid.origin[a]), -SV_FRAC_BITS);
    for (int b = 0; b < 3; ++b)
      m[a][b] = std::ldexp(static_cast<double>(view.grid.step[a][b]), -SV_FRAC_BITS);
  }
  const double det = determinant(m);
  if (!(std::abs(det) > 0.0)) throw ArgumentError("view", "singular viewing map");
  Mat3 inv{};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      const int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
      inv[r][c] = (m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]) / det;
    }
  return inv;
}

ViewGeometry make_view(const Volume& vol, ViewAngles angles, int out_width, int out_height,
                       Sampling sampling, Framing framing) {
  vol.check_voxel_count();
  return make_view(vol.dims(), vol.spacing(), angles, out_width, out_height, sampling, framing);
}

ViewGeometry make_view(const std::array<int64_t, 3>& dims, const std::array<double, 3>& sp,
                       ViewAngles angles, int out_width, int out_height, Sampling sampling,
                       Framing framing) {
  if (out_width <= 0 || out_height <= 0)
    throw ArgumentError("--size", "image size " + std::to_string(out_width) + "x" +
                                      std::to_string(out_height) + " must be positive");
  for (int a = 0; a < 3; ++a) {
    if (dims[a] <= 0) throw ArgumentError("volume", "the volume is empty");
    if (!(sp[a] > 0.0) || !std::isfinite(sp[a]))
      throw ArgumentError("volume", "voxel spacing must be positive and finite");
  }
  for (double a : {angles.theta, angles.phi, angles.varphi})
    if (!std::isfinite(a)) throw ArgumentError("--view", "angles must be finite");
  if (dims[0] > (int64_t{1} << 24) || dims[1] > (int64_t{1} << 24) || dims[2] > (int64_t{1} << 24))
    throw ArgumentError("volume", "a dimension exceeds 2^24 voxels");

  ViewGeometry g;
  g.sampling = sampling;
  g.out_width = out_width;
  g.out_height = out_height;
  g.rot = rotation(angles.theta, angles.phi, angles.varphi);

  const double smin = std::min({sp[0], sp[1], sp[2]});
  Vec3 extent{};
  double diag2 = 0;
  for (int a = 0; a < 3; ++a) {
    // (the ratio first: dims * spacing overflowed to inf for a spacing near
    // DBL_MAX, refused as too anisotropic though every spacing was alike)
    extent[a] = static_cast<double>(dims[a]) * (sp[a] / smin);
    diag2 += extent[a] * extent[a];
    g.longest = std::max(g.longest, extent[a]);
  }
  const auto spacing_text = [&] {
    std::ostringstream o;
    o << sp[0] << "," << sp[1] << "," << sp[2];
    return o.str();
  };
  if (!std::isfinite(diag2))
    throw ArgumentError("volume", "voxel spacing " + spacing_text() +
                                      ": its largest over its smallest is too large to render");
  g.radius = 0.5 * std::sqrt(diag2);
  g.span = framing == Framing::diagonal ? 2.0 * g.radius : g.longest;

  double wd = out_width, hd = out_height;
  if (sampling == Sampling::pixel) {
    g.step = g.span / std::min(out_width, out_height);
  } else {
    g.step = 1.0;
    const double scale = std::min(out_width, out_height) / g.span;
    wd = std::ceil(out_width / scale) + 2;
    hd = std::ceil(out_height / scale) + 2;
    // A ray more than the radius from the centre holds no sample (the
    // volume lies in its sphere), so an image far wider or taller than the
    // framed span (4096x64, 1x512) need not store its empty columns or rows:
    // both sides are cut alike to ceil(diagonal) + 3 pixels, or + 4 where
    // that keeps the count's parity, so the rays stay where they were
    // (pixel centres from -(n - 1) / 2 to (n - 1) / 2 >= radius + 1) and the
    // warp reads the cut pixels as the zeros they were. A 1x512 image of a
    // 97x301x33 volume took a 303 x 154,114 pixel image (747 MB) before.
    const double cut = std::ceil(2.0 * g.radius) + 3;
    const auto cut_to = [cut](double n) {
      if (!(n > cut)) return n;
      return std::fmod(n - cut, 2.0) == 0.0 ? cut : cut + 1;
    };
    wd = cut_to(wd);
    hd = cut_to(hd);
  }
  const double dd = std::max(1.0, std::ceil(2.0 * g.radius / g.step));
  // Voxel sampling steps at the smallest spacing: a strongly anisotropic
  // volume (a spacing of 1e7 beside 1) would need an intermediate image and
  // a depth far beyond memory. Bounds: 2^28 pixels (16384^2, as the largest
  // output) and 2^24 samples per ray (as the largest volume dimension).
  constexpr double kMaxPixels = double(int64_t{1} << 28), kMaxDepth = double(int64_t{1} << 24);
  if (!(wd * hd <= kMaxPixels) || !(dd <= kMaxDepth)) {
    std::ostringstream o;
    o << dims[0] << "x" << dims[1] << "x" << dims[2] << " voxels of spacing " << spacing_text()
      << " need a viewing grid of " << wd << " x " << hd << " x " << dd
      << " samples (at most 2^28 pixels and 2^24 samples per ray)"
      << (sampling == Sampling::voxel ? ": use --sampling pixel" : "");
    throw ArgumentError("volume", o.str());
  }
  const int wi = static_cast<int>(wd), hi = static_cast<int>(hd), depth = static_cast<int>(dd);

  // Viewing position of sample (i, j, k): step * (i + 1/2 - W/2, j + 1/2 - H/2,
  // k + 1/2 - D/2); object index position X_a = (T^T p)_a * smin / s_a + n_a / 2.
  const Mat3 tt = transpose(g.rot);
  const Vec3 c0{0.5 - 0.5 * wi, 0.5 - 0.5 * hi, 0.5 - 0.5 * depth};
  // Every position of the grid in 64-bit fixed point, with room to spare:
  // pixel sampling of a volume far thinner along one axis than along
  // another stepped 1e21 voxels a sample (llround out of range, then
  // overflowing sums in ViewGeometry::fixed).
  const double grid_n[3] = {static_cast<double>(wi), static_cast<double>(hi),
                            static_cast<double>(depth)};
  for (int a = 0; a < 3; ++a) {
    const double f = g.step * (smin / sp[a]);
    double reach = 0.5 * static_cast<double>(dims[a]);
    for (int b = 0; b < 3; ++b) reach += std::fabs(tt[a][b] * f) * (std::fabs(c0[b]) + grid_n[b]);
    if (!(std::ldexp(reach, SV_FRAC_BITS) < 0x1p61))
      throw ArgumentError("volume", "voxel spacing " + spacing_text() +
                                        ": its largest over its smallest is too large to render "
                                        "at this image size");
  }
  for (int a = 0; a < 3; ++a) {
    const double f = g.step * (smin / sp[a]);
    double o = 0.5 * static_cast<double>(dims[a]);
    for (int b = 0; b < 3; ++b) {
      g.grid.step[a][b] = to_fixed(tt[a][b] * f);
      o += tt[a][b] * f * c0[b];
    }
    g.grid.step[a][3] = 0;
    g.grid.origin[a] = to_fixed(o);
    g.grid.dims[a] = static_cast<sv_i32>(dims[a]);
  }
  g.grid.origin[3] = 0;
  g.grid.dims[3] = 0;
  g.grid.grid[0] = wi;
  g.grid.grid[1] = hi;
  g.grid.grid[2] = depth;
  g.grid.grid[3] = 0;
  g.view_dir_obj = multiply(tt, Vec3{0, 0, 1});
  return g;
}

}  // namespace simdvol
