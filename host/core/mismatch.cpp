// Multi-pass shear rotation vs the minimum-mismatch mapping (see mismatch.hpp).
//
// Derivation of the 3-D route (thesis 5.3.4 says Schröder & Salem use "4
// shears in one coordinate and 1 shear in two coordinates"):
//   M = Rz(a) Ry(b) Rz(c) E (z-y-z Euler angles, half turns moved into the
//   exact flip E so that |a|, |b|, |c| <= 90 degrees). In the (x, y) plane
//   Rz(t) = [[cos, -sin], [sin, cos]] = X_y(-tan t/2) Y_x(sin t) X_y(-tan t/2)
//   (eq 5.4 read literally). In the (z, x) plane Ry(t) is the same rotation,
//   written with x as the outer coordinate: X_z(tan t/2) Z_x(-sin t)
//   X_z(tan t/2). In mapping order (rightmost factor first) that is
//     X_y Y_x X_y | X_z Z_x X_z | X_y Y_x X_y
//   and the two junctions move x twice in a row, so they merge into one pass
//   x += k_y y + k_z z ("a shear involving the other two coordinates"):
//     X_y, Y_x, X_yz, Z_x, X_zy, Y_x, X_y  = 7 passes (5 elementary + 2).
//   With c = 0 (a two-angle rotation Rz(a) Ry(b)) the first two passes vanish
//   and X_yz becomes X_z: X_z, Z_x, X_zy, Y_x, X_y = 5 passes, 4 elementary +
//   1 two-coordinate: exactly Schröder & Salem's count. A general 3-angle
//   rotation cannot be done that way: 4 one-parameter shears and 1
//   two-parameter shear give 6 parameters, and a least-squares search over all
//   1280 orderings of such 5-pass patterns (no two neighbours moving the same
//   coordinate) found none reproducing a generic rotation; we therefore use 7
//   passes for three angles and report the pass count.
#include "simdvol/mismatch.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "simdvol/error.hpp"
#include "simdvol_shared.h"

namespace simdvol {

namespace {

constexpr double kPi = std::numbers::pi;

double rad(double deg) {
  return deg * kPi / 180.0;
}

Mat3 identity3() {
  return Mat3{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
}

ShearPass pass(int axis, int src, double k) {
  ShearPass p;
  p.axis = axis;
  p.k[src] = k;
  return p;
}

// Paeth's three shears of [[c, -s], [s, c]] in the plane (outer, inner):
// outer += -tan(t/2) inner; inner += sin(t) outer; outer += -tan(t/2) inner.
// For Ry the plane is (z, x) with x as outer coordinate, written
// L(tan) U(-sin) L(tan) -- see the file comment.
void append_rz(std::vector<ShearPass>& v, double t) {
  const double tt = std::tan(t / 2), s = std::sin(t);
  v.push_back(pass(0, 1, -tt));
  v.push_back(pass(1, 0, s));
  v.push_back(pass(0, 1, -tt));
}
void append_ry(std::vector<ShearPass>& v, double t) {
  const double tt = std::tan(t / 2), s = std::sin(t);
  v.push_back(pass(0, 2, tt));
  v.push_back(pass(2, 0, -s));
  v.push_back(pass(0, 2, tt));
}

// Coefficients below 1e-13 (left over from angles that are 0 up to rounding in
// the Euler extraction) count as zero: they move no point of any grid we use.
bool is_zero(const ShearPass& p) {
  return std::fabs(p.k[0]) < 1e-13 && std::fabs(p.k[1]) < 1e-13 && std::fabs(p.k[2]) < 1e-13;
}

// Drops all-zero passes and merges neighbours that move the same coordinate.
std::vector<ShearPass> simplify(const std::vector<ShearPass>& in) {
  std::vector<ShearPass> out;
  for (const ShearPass& p : in) {
    if (is_zero(p)) continue;
    ShearPass q = p;
    for (double& k : q.k)
      if (std::fabs(k) < 1e-13) k = 0;
    if (!out.empty() && out.back().axis == q.axis) {
      for (int j = 0; j < 3; ++j) out.back().k[j] += q.k[j];
      if (is_zero(out.back())) out.pop_back();
    } else {
      out.push_back(q);
    }
  }
  return out;
}

// Mismatch accumulator for one method.
class Acc {
 public:
  Acc(std::string method, int dims, int64_t reserve) : dims_(dims) {
    s_.method = std::move(method);
    d_.reserve(static_cast<std::size_t>(reserve));
  }
  void add(const Vec3& err) {
    double sq = 0;
    for (int a = 0; a < dims_; ++a) {
      const double e = std::fabs(err[a]);
      sq += e * e;
      coord_sum_ += e;
      s_.coord_max = std::max(s_.coord_max, e);
      bump(s_.coord_hist, e);
    }
    const double d = std::sqrt(sq);
    sum_ += d;
    s_.max = std::max(s_.max, d);
    bump(s_.hist, d);
    d_.push_back(static_cast<float>(d));
  }
  MismatchStats finish() {
    const int64_t n = static_cast<int64_t>(d_.size());
    s_.samples = n;
    if (n > 0) {
      s_.mean = sum_ / static_cast<double>(n);
      s_.coord_mean = coord_sum_ / static_cast<double>(n * dims_);
      s_.p50 = quantile(0.50);
      s_.p90 = quantile(0.90);
      s_.p99 = quantile(0.99);
    }
    return s_;
  }

 private:
  void bump(std::vector<int64_t>& h, double v) {
    const auto i = static_cast<std::size_t>(std::floor(v / s_.bin_width));
    if (h.size() <= i) h.resize(i + 1, 0);
    ++h[i];
  }
  // Nearest-rank quantile.
  double quantile(double q) {
    const auto n = d_.size();
    std::size_t k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n)));
    k = std::clamp<std::size_t>(k, 1, n) - 1;
    std::nth_element(d_.begin(), d_.begin() + static_cast<std::ptrdiff_t>(k), d_.end());
    return d_[k];
  }
  int dims_;
  MismatchStats s_;
  std::vector<float> d_;
  double sum_ = 0, coord_sum_ = 0;
};

Vec3 minus(const Vec3& a, const Vec3& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
Vec3 to_vec(const IVec3& p) {
  return {static_cast<double>(p[0]), static_cast<double>(p[1]), static_cast<double>(p[2])};
}

// Runs the three methods over a list of centred grid points.
template <class Points>
MismatchReport run(int dims, const Mat3& tinv, const ShearRoute& route, int64_t count,
                   Points&& for_each_point) {
  MismatchReport rep;
  rep.dims = dims;
  rep.description = route.description;
  rep.passes = static_cast<int>(route.passes.size());
  Acc shear("shear", dims, count), fl("min-mismatch floor", dims, count),
      nr("min-mismatch nearest", dims, count);
  // The floor as the matching takes it: of T^-1 p with T^-1 in the view's
  // 32.32 fixed point (SV_FRAC_BITS; exact here in double: 33 significant
  // bits times a small integer). Of the double product, a turn of exactly
  // 90 degrees (cos 6e-17) floored 3 to 2 and reported mismatches of 1 that
  // the matching does not make.
  Mat3 fixed{};
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b)
      fixed[a][b] = std::ldexp(
          static_cast<double>(std::llround(std::ldexp(tinv[a][b], SV_FRAC_BITS))), -SV_FRAC_BITS);
  for_each_point([&](const IVec3& p) {
    const Vec3 x = multiply(tinv, to_vec(p));
    const Vec3 xf = multiply(fixed, to_vec(p));
    shear.add(minus(to_vec(route_rounded(route, p)), x));
    fl.add(minus({std::floor(xf[0]), std::floor(xf[1]), std::floor(xf[2])}, x));
    nr.add(minus({std::round(x[0]), std::round(x[1]), std::round(x[2])}, x));
  });
  rep.shear = shear.finish();
  rep.floor = fl.finish();
  rep.nearest = nr.finish();
  return rep;
}

// ---- counting implementation ------------------------------------------------

thread_local OpCount* g_ops = nullptr;

// A double whose arithmetic is tallied in *g_ops.
struct Counted {
  double v = 0;
};
Counted operator*(Counted a, Counted b) {
  ++g_ops->mul;
  return {a.v * b.v};
}
Counted operator+(Counted a, Counted b) {
  ++g_ops->add;
  return {a.v + b.v};
}
Counted operator-(Counted a, Counted b) {
  ++g_ops->add;
  return {a.v - b.v};
}
int64_t cfloor(Counted a) {
  ++g_ops->rnd;
  return static_cast<int64_t>(std::floor(a.v));
}
int64_t cround(Counted a) {
  ++g_ops->rnd;
  return static_cast<int64_t>(std::round(a.v));
}
int64_t iadd(int64_t a, int64_t b) {  // an address update that the thesis counts
  ++g_ops->add;
  return a + b;
}

struct OpScope {
  explicit OpScope(OpCount& c) { g_ops = &c; }
  ~OpScope() { g_ops = nullptr; }
  OpScope(const OpScope&) = delete;
  OpScope& operator=(const OpScope&) = delete;
};

double synthetic(int64_t x, int64_t y, int64_t z) {
  return std::sin(0.31 * static_cast<double>(x)) + std::cos(0.17 * static_cast<double>(y)) +
         0.01 * static_cast<double>(z * z);
}

void check_count_size(int n, int dims) {
  if (dims != 2 && dims != 3) throw ArgumentError("dims", "expected 2 or 3");
  if (n < 2 || n > (dims == 2 ? 4096 : 256))
    throw ArgumentError(
        "n", std::to_string(n) + " is outside 2.." + std::to_string(dims == 2 ? 4096 : 256));
}

}  // namespace

int ShearPass::sources() const {
  int s = 0;
  for (int j = 0; j < 3; ++j)
    if (j != axis && k[j] != 0) ++s;
  return s;
}

Mat3 route_matrix(const ShearRoute& r) {
  Mat3 m = identity3();
  for (int a = 0; a < 3; ++a) m[a][a] = r.flip[a];
  for (const ShearPass& p : r.passes) {
    Mat3 s = identity3();
    for (int j = 0; j < 3; ++j)
      if (j != p.axis) s[p.axis][j] = p.k[j];
    m = multiply(s, m);
  }
  return m;
}

IVec3 route_rounded(const ShearRoute& r, const IVec3& p) {
  IVec3 q{p[0] * r.flip[0], p[1] * r.flip[1], p[2] * r.flip[2]};
  for (const ShearPass& s : r.passes) {
    double off = 0;
    for (int j = 0; j < 3; ++j)
      if (j != s.axis) off += s.k[j] * static_cast<double>(q[j]);
    q[s.axis] += static_cast<int64_t>(std::round(off));
  }
  return q;
}

Vec3 route_exact(const ShearRoute& r, const Vec3& p) {
  Vec3 q{p[0] * r.flip[0], p[1] * r.flip[1], p[2] * r.flip[2]};
  for (const ShearPass& s : r.passes) {
    double off = 0;
    for (int j = 0; j < 3; ++j)
      if (j != s.axis) off += s.k[j] * q[j];
    q[s.axis] += off;
  }
  return q;
}

ShearRoute paeth_2d(double theta_deg) {
  if (!std::isfinite(theta_deg)) throw ArgumentError("theta", "must be finite");
  double t = std::remainder(theta_deg, 360.0);  // [-180, 180]
  ShearRoute r;
  std::ostringstream d;
  d << "eq 5.4: x by -tan(t/2), y by sin(t), x by -tan(t/2), t = " << t << " deg";
  if (std::fabs(t) > 90.0) {
    t -= std::copysign(180.0, t);
    r.flip = {-1, -1, 1};
    d << " (half turn as an exact flip, shears for " << t << " deg)";
  }
  append_rz(r.passes, rad(t));
  r.description = d.str();
  return r;
}

ShearRoute shear_route_zy(double a_deg, double b_deg) {
  if (!(std::fabs(a_deg) <= 90.0) || !(std::fabs(b_deg) <= 90.0))
    throw ArgumentError("angles", "expected |a|, |b| <= 90 degrees");
  const double a = rad(a_deg), b = rad(b_deg);
  ShearRoute r;
  r.passes.push_back(pass(0, 2, std::tan(b / 2)));
  r.passes.push_back(pass(2, 0, -std::sin(b)));
  ShearPass x = pass(0, 2, std::tan(b / 2));
  x.k[1] = -std::tan(a / 2);
  r.passes.push_back(x);
  r.passes.push_back(pass(1, 0, std::sin(a)));
  r.passes.push_back(pass(0, 1, -std::tan(a / 2)));
  std::ostringstream d;
  d << "Rz(" << a_deg << ") Ry(" << b_deg << "): 5 passes (x|z, z|x, x|yz, y|x, x|y)";
  r.description = d.str();
  return r;
}

ShearRoute shear_route_3d(const Mat3& m) {
  const Mat3 mmt = multiply(m, transpose(m));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (!std::isfinite(m[i][j]) || std::fabs(mmt[i][j] - (i == j ? 1.0 : 0.0)) > 1e-9)
        throw ArgumentError("rotation", "matrix is not orthogonal");
  if (determinant(m) < 0) throw ArgumentError("rotation", "determinant is -1 (a reflection)");

  // z-y-z Euler angles: M = Rz(a) Ry(b) Rz(c).
  double a = 0, b = std::acos(std::clamp(m[2][2], -1.0, 1.0)), c = 0;
  const double sb = std::sin(b);
  if (sb > 1e-12) {
    a = std::atan2(m[1][2], m[0][2]);
    c = std::atan2(m[2][1], -m[2][0]);
  } else if (m[2][2] > 0) {
    b = 0;
    a = std::atan2(m[1][0], m[0][0]);
  } else {
    b = kPi;
    a = std::atan2(-m[1][0], -m[0][0]);
  }
  // Take half turns out as exact flips E (M = Rz(a) Ry(b) Rz(c) E):
  //   Ry(b) = Ry(b -+ pi) Ry(pi), Ry(pi) Rz(c) = Rz(-c) Ry(pi), Ry(pi) = diag(-1, 1, -1);
  //   Rz(t) = Rz(t -+ pi) Rz(pi), Rz(pi) Ry(b) = Ry(-b) Rz(pi), Rz(pi) = diag(-1, -1, 1).
  std::array<int, 3> e{1, 1, 1};
  auto times = [&e](std::array<int, 3> d) {
    for (int i = 0; i < 3; ++i) e[i] *= d[i];
  };
  if (std::fabs(b) > kPi / 2) {
    b -= std::copysign(kPi, b);
    c = -c;
    times({-1, 1, -1});
  }
  if (std::fabs(a) > kPi / 2) {
    a -= std::copysign(kPi, a);
    b = -b;
    times({-1, -1, 1});
  }
  if (std::fabs(c) > kPi / 2) {
    c -= std::copysign(kPi, c);
    times({-1, -1, 1});
  }
  std::vector<ShearPass> raw;
  append_rz(raw, c);
  append_ry(raw, b);
  append_rz(raw, a);
  ShearRoute r;
  r.flip = e;
  r.passes = simplify(raw);
  int two = 0;
  for (const ShearPass& p : r.passes) two += p.sources() == 2;
  std::ostringstream d;
  d << "Rz(" << a * 180 / kPi << ") Ry(" << b * 180 / kPi << ") Rz(" << c * 180 / kPi << ") flip("
    << e[0] << "," << e[1] << "," << e[2] << "): " << r.passes.size() << " passes ("
    << r.passes.size() - two << " one-coordinate, " << two << " two-coordinate)";
  r.description = d.str();
  return r;
}

MismatchReport mismatch_2d(double theta_deg, int nx, int ny) {
  if (nx < 1 || ny < 1 || nx > 4096 || ny > 4096)
    throw ArgumentError("size", "2-D grid must be 1..4096 on each side");
  const ShearRoute route = paeth_2d(theta_deg);
  const Mat3 tinv = transpose(rotation(theta_deg, 0, 0));
  return run(2, tinv, route, int64_t{nx} * ny, [&](auto&& f) {
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) f(IVec3{i - nx / 2, j - ny / 2, 0});
  });
}

MismatchReport mismatch_3d(ViewAngles view, int n) {
  if (n < 1 || n > 256) throw ArgumentError("size", "3-D grid must be 1..256 on each side");
  const Mat3 tinv = transpose(rotation(view.theta, view.phi, view.varphi));
  const ShearRoute route = shear_route_3d(tinv);
  return run(3, tinv, route, int64_t{n} * n * n, [&](auto&& f) {
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) f(IVec3{x - n / 2, y - n / 2, z - n / 2});
  });
}

PointError paeth_point_error(double theta_deg, int64_t x, int64_t y) {
  PointError e;
  const ShearRoute r = paeth_2d(theta_deg);
  e.rounded = route_rounded(r, {x, y, 0});
  e.exact = multiply(transpose(rotation(theta_deg, 0, 0)), to_vec({x, y, 0}));
  e.dx = static_cast<double>(e.rounded[0]) - e.exact[0];
  e.dy = static_cast<double>(e.rounded[1]) - e.exact[1];
  e.dist = std::hypot(e.dx, e.dy);
  return e;
}

PointError paeth_forward_point_error(double theta_deg, int64_t x, int64_t y) {
  PointError e;
  const ShearRoute r = paeth_2d(-theta_deg);  // product Rz(-theta) = T_theta
  e.rounded = route_rounded(r, {x, y, 0});
  e.exact = multiply(rotation(theta_deg, 0, 0), to_vec({x, y, 0}));
  e.dx = static_cast<double>(e.rounded[0]) - e.exact[0];
  e.dy = static_cast<double>(e.rounded[1]) - e.exact[1];
  e.dist = std::hypot(e.dx, e.dy);
  return e;
}

OpCount count_min_mismatch(const Mat3& tinv, int n, Interp interp, bool incremental) {
  check_count_size(n, 3);
  const auto idx = [n](int64_t x, int64_t y, int64_t z) {
    return static_cast<std::size_t>((z * n + y) * n + x);
  };
  std::vector<double> vol(static_cast<std::size_t>(n) * n * n);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) vol[idx(x, y, z)] = synthetic(x, y, z);
  const auto fetch = [&](int64_t x, int64_t y, int64_t z) {
    x += n / 2;
    y += n / 2;
    z += n / 2;
    if (x < 0 || y < 0 || z < 0 || x >= n || y >= n || z >= n) return Counted{0};
    return Counted{vol[idx(x, y, z)]};
  };
  Counted m[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m[i][j] = {tinv[i][j]};

  OpCount ops;
  OpScope scope(ops);
  double checksum = 0;
  Counted p[3], row[3], plane[3];
  const int h = n / 2;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Counted q[3] = {{double(x - h)}, {double(y - h)}, {double(z - h)}};
        if (!incremental || (x == 0 && y == 0 && z == 0)) {
          for (int i = 0; i < 3; ++i) p[i] = m[i][0] * q[0] + m[i][1] * q[1] + m[i][2] * q[2];
          if (incremental)
            for (int i = 0; i < 3; ++i) row[i] = plane[i] = p[i];
        } else if (x == 0 && y == 0) {
          for (int i = 0; i < 3; ++i) p[i] = row[i] = plane[i] = plane[i] + m[i][2];
        } else if (x == 0) {
          for (int i = 0; i < 3; ++i) p[i] = row[i] = row[i] + m[i][1];
        } else {
          for (int i = 0; i < 3; ++i) p[i] = p[i] + m[i][0];
        }
        Counted v;
        if (interp == Interp::nearest) {
          v = fetch(cround(p[0]), cround(p[1]), cround(p[2]));
        } else {
          int64_t f0[3];
          Counted f[3], g[3];
          for (int a = 0; a < 3; ++a) {
            f0[a] = cfloor(p[a]);
            f[a] = p[a] - Counted{double(f0[a])};
            g[a] = Counted{1} - f[a];
          }
          Counted c[4];
          for (int k = 0; k < 4; ++k) {  // along x: (1 - f) a + f b
            const int64_t yy = f0[1] + (k & 1), zz = f0[2] + (k >> 1);
            c[k] = g[0] * fetch(f0[0], yy, zz) + f[0] * fetch(f0[0] + 1, yy, zz);
          }
          const Counted e0 = g[1] * c[0] + f[1] * c[1], e1 = g[1] * c[2] + f[1] * c[3];
          v = g[2] * e0 + f[2] * e1;
        }
        checksum += v.v;
      }
  ops.samples = static_cast<uint64_t>(n) * n * n;
  (void)checksum;
  return ops;
}

std::vector<double> shear_resample_nearest(const ShearRoute& r, const std::vector<double>& vol,
                                           int n) {
  check_count_size(n, 3);
  const std::size_t total = static_cast<std::size_t>(n) * n * n;
  if (vol.size() != total) throw ArgumentError("vol", "size is not n^3");
  const int h = n / 2;
  std::vector<double> cur = vol, next(total);
  const auto idx = [n](int64_t x, int64_t y, int64_t z) {
    return static_cast<std::size_t>((z * n + y) * n + x);
  };
  // Time order: the leftmost factor first (I_1(q) = I_0(P_last q), ...).
  for (auto it = r.passes.rbegin(); it != r.passes.rend(); ++it) {
    const ShearPass& s = *it;
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          int64_t q[3] = {x - h, y - h, z - h};
          double off = 0;
          for (int j = 0; j < 3; ++j)
            if (j != s.axis) off += s.k[j] * static_cast<double>(q[j]);
          q[s.axis] += static_cast<int64_t>(std::round(off));
          const int64_t a = q[0] + h, b = q[1] + h, c = q[2] + h;
          const bool in = a >= 0 && b >= 0 && c >= 0 && a < n && b < n && c < n;
          next[idx(x, y, z)] = in ? cur[idx(a, b, c)] : 0.0;
        }
    std::swap(cur, next);
  }
  // Finally the flip: V(p) = I(E p).
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const int64_t a = (x - h) * r.flip[0] + h, b = (y - h) * r.flip[1] + h,
                      c = (z - h) * r.flip[2] + h;
        const bool in = a >= 0 && b >= 0 && c >= 0 && a < n && b < n && c < n;
        next[idx(x, y, z)] = in ? cur[idx(a, b, c)] : 0.0;
      }
  return next;
}

OpCount count_shear(const ShearRoute& r, int n, int dims, Interp interp) {
  check_count_size(n, dims);
  if (dims == 2)
    for (const ShearPass& s : r.passes)
      if (s.axis == 2 || s.k[2] != 0) throw ArgumentError("route", "is not a 2-D route");
  const int64_t nz = dims == 3 ? n : 1;
  const std::size_t total = static_cast<std::size_t>(n) * n * static_cast<std::size_t>(nz);
  const int h = n / 2, hz = dims == 3 ? n / 2 : 0;
  const auto idx = [n](int64_t x, int64_t y, int64_t z) {
    return static_cast<std::size_t>((z * n + y) * n + x);
  };
  std::vector<Counted> cur(total), next(total);
  for (int64_t z = 0; z < nz; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) cur[idx(x, y, z)] = {synthetic(x, y, z)};
  const auto fetch = [&](const int64_t q[3]) {
    const int64_t a = q[0] + h, b = q[1] + h, c = q[2] + hz;
    if (a < 0 || b < 0 || c < 0 || a >= n || b >= n || c >= nz) return Counted{0};
    return cur[idx(a, b, c)];
  };

  OpCount ops;
  OpScope scope(ops);
  for (auto it = r.passes.rbegin(); it != r.passes.rend(); ++it) {
    const ShearPass& s = *it;
    for (int64_t z = 0; z < nz; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          int64_t q[3] = {x - h, y - h, z - hz};
          Counted off{0};
          bool first = true;
          for (int j = 0; j < 3; ++j) {
            if (j == s.axis || s.k[j] == 0) continue;
            const Counted term = Counted{s.k[j]} * Counted{double(q[j])};
            off = first ? term : off + term;
            first = false;
          }
          Counted v;
          if (interp == Interp::nearest) {
            q[s.axis] = iadd(q[s.axis], cround(off));
            v = fetch(q);
          } else {
            const int64_t fl = cfloor(off);
            const Counted f = off - Counted{double(fl)};
            const Counted g = Counted{1} - f;
            q[s.axis] = iadd(q[s.axis], fl);
            const Counted v0 = fetch(q);
            ++q[s.axis];  // the neighbour's address, not counted (as in the thesis)
            v = g * v0 + f * fetch(q);
          }
          next[idx(x, y, z)] = v;
        }
    std::swap(cur, next);
  }
  ops.samples = total;
  return ops;
}

}  // namespace simdvol
