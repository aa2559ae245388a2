// Analytic test volumes: the 3-D Shepp–Logan head phantom in Hounsfield
// units and the Marschner–Lobb signal.
#include "simdvol/phantom.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <new>
#include <numbers>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "simdvol/error.hpp"

namespace simdvol {

double phantom_subsample(int64_t i, int64_t n, int m, int s) {
  const double h = n <= 1 ? 2.0 : 2.0 / static_cast<double>(n - 1);
  return phantom_coord(i, n) + h * ((static_cast<double>(m) + 0.5) / static_cast<double>(s) - 0.5);
}
namespace {

// One ellipsoid of the phantom: centre, semi-axes, rotation about z (degrees,
// counter-clockwise) and the value it adds, in HU, to every point inside it.
struct Ellipsoid {
  double cx, cy, cz;
  double a, b, c;
  double angle_deg;
  double add_hu;
};

// Geometry: the ten ellipsoids of the 3-D Shepp–Logan head phantom of Kak &
// Slaney, "Principles of Computerized Tomographic Imaging" (1988), table on
// p. 102, with the published errata applied (slaney.org/pct/pct-errata.html).
// Their original additive densities (relative to water) are
//   a 2.00, b -0.98, c -0.02, d -0.02, e 0.02, f 0.02, g 0.01, h 0.01,
//   i 0.02, j -0.02.
//
// Intensities: a linear rescaling of those densities cannot give the wanted
// CT-like contrast (brain 1.02 and ventricles 1.00 would be 20 HU apart), so
// each ellipsoid gets its own additive HU value instead. The background is air,
// -1000 HU, and the sums give
//   outside the head            -1000                 (air)
//   a \ b, the skull            -1000 + 2000 = 1000   (bone)
//   b, the brain                 1000 -  960 =   40   (soft tissue)
//   c, d, the ventricles           40 -  140 = -100   (fat)
//   e, f, i (density +0.02)        40 +   30 =   70   (e and f overlap: 100)
//   g, h    (density +0.01)        40 +   20 =   60
//   j       (density -0.02)        40 -   40 =    0   (water)
// i.e. the small features keep the sign and order of Kak & Slaney's contrasts.
// Where ventricle c reaches into e the sum is -70. The angle rotates an
// ellipsoid counter-clockwise about the z axis through its centre (x towards
// y); the head's long axis is y. Values are integers, so no rounding is lost.
// The volume keeps the default spacing 1 (the grid is isotropic).
constexpr double kAirHu = -1000.0;
constexpr std::array<Ellipsoid, 10> kEllipsoids{{
    // centre                  semi-axes                 angle  add HU
    {0.0, 0.0, 0.0, 0.69, 0.92, 0.90, 0.0, 2000.0},        // a skull outer
    {0.0, 0.0, 0.0, 0.6624, 0.874, 0.88, 0.0, -960.0},     // b brain
    {-0.22, 0.0, -0.25, 0.41, 0.16, 0.21, 108.0, -140.0},  // c ventricle
    {0.22, 0.0, -0.25, 0.31, 0.11, 0.22, 72.0, -140.0},    // d ventricle
    {0.0, 0.35, -0.25, 0.21, 0.25, 0.50, 0.0, 30.0},       // e
    {0.0, 0.1, -0.25, 0.046, 0.046, 0.046, 0.0, 30.0},     // f
    {-0.08, -0.65, -0.25, 0.046, 0.023, 0.02, 0.0, 20.0},  // g
    {0.06, -0.65, -0.25, 0.046, 0.023, 0.02, 90.0, 20.0},  // h
    {0.06, -0.105, 0.625, 0.056, 0.04, 0.10, 90.0, 30.0},  // i
    {0.0, 0.1, 0.625, 0.056, 0.056, 0.10, 0.0, -40.0},     // j
}};

// Rotation terms, precomputed once so the grid and the analytic function use
// the very same numbers (and so agree exactly).
struct Prepared {
  Ellipsoid e;
  double cos_t, sin_t;
  double half_x, half_y;  // half extents of the rotated ellipse in x and y
};

const std::array<Prepared, 10>& prepared() {
  static const std::array<Prepared, 10> p = [] {
    std::array<Prepared, 10> out{};
    for (std::size_t k = 0; k < kEllipsoids.size(); ++k) {
      const Ellipsoid& e = kEllipsoids[k];
      const double t = e.angle_deg * std::numbers::pi / 180.0;
      const double c = std::cos(t), s = std::sin(t);
      out[k] = {e, c, s, std::hypot(e.a * c, e.b * s), std::hypot(e.a * s, e.b * c)};
    }
    return out;
  }();
  return p;
}

// Whether (x, y, z) is inside (or on) the ellipsoid: the point is rotated by
// -angle about the ellipsoid's centre into its own axes.
inline bool inside(const Prepared& p, double x, double y, double z) {
  const double dx = x - p.e.cx, dy = y - p.e.cy, dz = z - p.e.cz;
  const double u = p.cos_t * dx + p.sin_t * dy;
  const double v = -p.sin_t * dx + p.cos_t * dy;
  const double qu = u / p.e.a, qv = v / p.e.b, qw = dz / p.e.c;
  return qu * qu + qv * qv + qw * qw <= 1.0;
}

// Grid indices [lo, hi] whose coordinates may lie in [centre - half, centre +
// half]; one index of margin on each side (the exact test decides).
void index_range(double centre, double half, int n, int& lo, int& hi) {
  if (n <= 1) {
    lo = 0;
    hi = n - 1;
    return;
  }
  const double scale = 0.5 * (n - 1);
  const double f_lo = std::floor((centre - half + 1.0) * scale) - 1.0;
  const double f_hi = std::ceil((centre + half + 1.0) * scale) + 1.0;
  lo = static_cast<int>(std::clamp(f_lo, 0.0, static_cast<double>(n - 1)));
  hi = static_cast<int>(std::clamp(f_hi, 0.0, static_cast<double>(n - 1)));
}

// Runs fn(k0, k1) over slabs [k0, k1) of the z planes 0 .. n - 1, one per
// thread (up to the hardware's threads, and only for volumes of at least
// 64^3 voxels: the threads' start costs more below). Each voxel belongs to
// one slab and sees the same operations in the same order as in one pass,
// so the volume is the same bit for bit. A thread that cannot be started
// leaves its slab to the calling thread.
template <class Fn>
void for_each_slab(int n, Fn fn) {
  const int threads =
      n < 64 ? 1 : static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 16u));
  const auto bound = [&](int t) { return static_cast<int>(int64_t(n) * t / threads); };
  std::vector<std::thread> pool;
  int started = 1;  // slabs 1 .. started - 1 run on their own threads
  try {
    pool.reserve(static_cast<std::size_t>(threads - 1));
    for (; started < threads; ++started) pool.emplace_back(fn, bound(started), bound(started + 1));
  } catch (const std::system_error&) {  // no more threads: the rest run here
  } catch (const std::bad_alloc&) {
  }
  fn(0, bound(1));
  for (int t = started; t < threads; ++t) fn(bound(t), bound(t + 1));
  for (std::thread& th : pool) th.join();
}

// The voxel index ranges [x0, x1] x [y0, y1] x [z0, z1] of ellipsoid p's
// bounding box on the n^3 grid, z cut to the slab [kb, ke) (empty when
// z0 > z1).
struct IndexBox {
  int x0, x1, y0, y1, z0, z1;
};
IndexBox index_box(const Prepared& p, int n, int kb, int ke) {
  IndexBox b{};
  index_range(p.e.cx, p.half_x, n, b.x0, b.x1);
  index_range(p.e.cy, p.half_y, n, b.y0, b.y1);
  index_range(p.e.cz, p.e.c, n, b.z0, b.z1);
  b.z0 = std::max(b.z0, kb);
  b.z1 = std::min(b.z1, ke - 1);
  return b;
}

void check_n(int n, const char* what) {
  if (n < 1) throw ArgumentError(what, "grid size must be positive, got " + std::to_string(n));
  checked_voxel_count({n, n, n}, what);
}

}  // namespace

float shepp_logan_hu(double x, double y, double z) {
  double hu = kAirHu;
  for (const Prepared& p : prepared())
    if (inside(p, x, y, z)) hu += p.e.add_hu;
  return static_cast<float>(std::round(hu));
}

namespace {

// supersample = 1: the indicator of each ellipsoid at the voxel centres.
void add_centre_samples(Volume& vol, int n) {
  std::vector<float>& d = vol.data();
  std::fill(d.begin(), d.end(), static_cast<float>(kAirHu));

  std::vector<double> coord(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) coord[i] = phantom_coord(i, n);

  // Each ellipsoid adds its value over its bounding box only. All values are
  // integers far below 2^24, so float accumulation is exact.
  for_each_slab(n, [&](int kb, int ke) {
    for (const Prepared& p : prepared()) {
      const auto [x0, x1, y0, y1, z0, z1] = index_box(p, n, kb, ke);
      const float add = static_cast<float>(p.e.add_hu);
      for (int k = z0; k <= z1; ++k)
        for (int j = y0; j <= y1; ++j)
          for (int i = x0; i <= x1; ++i)
            if (inside(p, coord[i], coord[j], coord[k])) d[vol.index(i, j, k)] += add;
    }
  });
}

// supersample = s > 1: each voxel first accumulates the exact integer
//   sum over ellipsoids of add_hu * (sub-samples inside it)
// on top of kAirHu * s^3 (|sum| <= 1100 * 16^3 < 2^24, so float holds it
// exactly), and is divided by s^3 and rounded at the end.
//
// Which voxels need sub-samples: the ellipsoid's normalised radius
// r = |(u / a, v / b, w / c)| changes by at most |d| / min(a, b, c) when the
// point moves by d (a rotation, then scalings by at most 1 / min(a, b, c)).
// Every sub-sample lies within the half-diagonal delta = sqrt(3) h / 2 of the
// voxel's centre, so with t = delta / min(a, b, c) (plus a rounding margin) a
// voxel whose centre has r > 1 + t has no sub-sample inside, one with
// r < 1 - t has all of them inside, and only the shell in between is counted.
void add_sub_samples(Volume& vol, int n, int s) {
  const int s3 = s * s * s;
  std::vector<float>& d = vol.data();
  std::fill(d.begin(), d.end(), static_cast<float>(kAirHu * s3));

  std::vector<double> coord(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) coord[i] = phantom_coord(i, n);
  std::vector<double> sub(static_cast<std::size_t>(n) * s);  // sub[i * s + m]
  for (int i = 0; i < n; ++i)
    for (int m = 0; m < s; ++m)
      sub[static_cast<std::size_t>(i) * s + m] = phantom_subsample(i, n, m, s);

  const double h = n <= 1 ? 2.0 : 2.0 / (n - 1);
  const double delta = 0.5 * std::sqrt(3.0) * h;

  for_each_slab(n, [&](int kb, int ke) {
    for (const Prepared& p : prepared()) {
      const auto [x0, x1, y0, y1, z0, z1] = index_box(p, n, kb, ke);
      const double t = delta / std::min({p.e.a, p.e.b, p.e.c}) * (1.0 + 1e-9) + 1e-9;
      const double all_in = t < 1.0 ? (1.0 - t) * (1.0 - t) : -1.0;  // r^2 below: all inside
      const double all_out = (1.0 + t) * (1.0 + t);                  // r^2 above: none inside
      const float add = static_cast<float>(p.e.add_hu);
      const float add_all = static_cast<float>(p.e.add_hu * s3);
      const double ia = 1.0 / p.e.a, ib = 1.0 / p.e.b, ic = 1.0 / p.e.c;
      for (int k = z0; k <= z1; ++k) {
        const double qw = (coord[k] - p.e.cz) * ic;
        for (int j = y0; j <= y1; ++j) {
          const double dy = coord[j] - p.e.cy;
          for (int i = x0; i <= x1; ++i) {
            const double dx = coord[i] - p.e.cx;
            const double qu = (p.cos_t * dx + p.sin_t * dy) * ia;
            const double qv = (-p.sin_t * dx + p.cos_t * dy) * ib;
            const double r2 = qu * qu + qv * qv + qw * qw;
            if (r2 > all_out) continue;
            float& v = d[vol.index(i, j, k)];
            if (r2 < all_in) {
              v += add_all;
              continue;
            }
            int count = 0;
            for (int mz = 0; mz < s; ++mz) {
              const double z = sub[static_cast<std::size_t>(k) * s + mz];
              for (int my = 0; my < s; ++my) {
                const double y = sub[static_cast<std::size_t>(j) * s + my];
                for (int mx = 0; mx < s; ++mx)
                  count += inside(p, sub[static_cast<std::size_t>(i) * s + mx], y, z);
              }
            }
            v += add * static_cast<float>(count);
          }
        }
      }
    }
    const std::size_t plane = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
    for (std::size_t e = plane * static_cast<std::size_t>(kb);
         e < plane * static_cast<std::size_t>(ke); ++e)
      d[e] = static_cast<float>(std::round(static_cast<double>(d[e]) / s3));
  });
}

}  // namespace

Volume shepp_logan(int n, int supersample) {
  check_n(n, "shepp_logan size");
  if (supersample < 1 || supersample > 16)
    throw ArgumentError("shepp_logan supersample",
                        "must be in 1..16, got " + std::to_string(supersample));
  Volume vol({n, n, n}, VoxelType::i16);
  if (supersample == 1)
    add_centre_samples(vol, n);
  else
    add_sub_samples(vol, n, supersample);
  return vol;
}

double marschner_lobb_value(double x, double y, double z) {
  constexpr double fm = 6.0, alpha = 0.25;
  constexpr double pi = std::numbers::pi;
  const double r = std::sqrt(x * x + y * y);
  const double rho_r = std::cos(2.0 * pi * fm * std::cos(pi * r / 2.0));
  return (1.0 - std::sin(pi * z / 2.0) + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha));
}

Volume marschner_lobb(int n) {
  check_n(n, "marschner_lobb size");
  Volume vol({n, n, n}, VoxelType::f32);
  std::vector<float>& d = vol.data();
  for_each_slab(n, [&](int kb, int ke) {
    for (int k = kb; k < ke; ++k) {
      const double z = phantom_coord(k, n);
      for (int j = 0; j < n; ++j) {
        const double y = phantom_coord(j, n);
        for (int i = 0; i < n; ++i)
          d[vol.index(i, j, k)] =
              static_cast<float>(marschner_lobb_value(phantom_coord(i, n), y, z));
      }
    }
  });
  return vol;
}

}  // namespace simdvol
