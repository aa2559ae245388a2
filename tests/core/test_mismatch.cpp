// Multi-pass shear rotation vs minimum-mismatch mapping (thesis 5.3.4, 5.4, 5.7).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>
#include <vector>

#include "simdvol/error.hpp"
#include "simdvol/mismatch.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;

namespace {

constexpr double kPi = std::numbers::pi;

Mat3 rz(double deg) {
  const double t = deg * kPi / 180, c = std::cos(t), s = std::sin(t);
  return Mat3{{{c, -s, 0}, {s, c, 0}, {0, 0, 1}}};
}
Mat3 ry(double deg) {
  const double t = deg * kPi / 180, c = std::cos(t), s = std::sin(t);
  return Mat3{{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
}

double max_diff(const Mat3& a, const Mat3& b) {
  double d = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) d = std::max(d, std::fabs(a[i][j] - b[i][j]));
  return d;
}

// One pass with rounding, as route_rounded does it.
IVec3 apply_pass(const ShearPass& s, IVec3 q, int sign) {
  double off = 0;
  for (int j = 0; j < 3; ++j)
    if (j != s.axis) off += s.k[j] * static_cast<double>(q[j]);
  q[s.axis] += sign * static_cast<int64_t>(std::round(off));
  return q;
}

std::vector<IVec3> grid(int n, int dims) {
  std::vector<IVec3> g;
  const int nz = dims == 3 ? n : 1;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) g.push_back({x - n / 2, y - n / 2, dims == 3 ? z - n / 2 : 0});
  return g;
}

}  // namespace

TEST(Mismatch, Eq54ProductIsTheInverseRotation) {
  // Eq 5.4's shears multiply to [[c, -s], [s, c]] = T_theta^-1 (the transpose of
  // the thesis's T_theta); with the signs flipped they give T_theta itself.
  for (double t = -180; t <= 180; t += 7.5)
    for (double d : {0.0, 0.3}) {
      const double th = t + d;
      const ShearRoute r = paeth_2d(th);
      EXPECT_EQ(r.passes.size(), 3u);
      EXPECT_LT(max_diff(route_matrix(r), transpose(rotation(th, 0, 0))), 1e-12) << th;
      EXPECT_LT(max_diff(route_matrix(paeth_2d(-th)), rotation(th, 0, 0)), 1e-12) << th;
      // Unrounded pass-by-pass mapping equals the matrix.
      const Vec3 p{47, 181, 0};
      const Vec3 e = route_exact(r, p), m = multiply(route_matrix(r), p);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(e[a], m[a], 1e-9);
    }
  // Literal coefficients at 30 degrees: x by -tan 15, y by sin 30, x by -tan 15.
  const ShearRoute r = paeth_2d(30);
  EXPECT_EQ(r.passes[0].axis, 0);
  EXPECT_NEAR(r.passes[0].k[1], -std::tan(15 * kPi / 180), 1e-15);
  EXPECT_EQ(r.passes[1].axis, 1);
  EXPECT_NEAR(r.passes[1].k[0], 0.5, 1e-15);
  EXPECT_EQ(r.flip, (std::array<int, 3>{1, 1, 1}));
  EXPECT_EQ(paeth_2d(150).flip, (std::array<int, 3>{-1, -1, 1}));
}

TEST(Mismatch, Route3dEqualsTheRotation) {
  int seven = 0;
  for (double th = -170; th <= 180; th += 37)
    for (double ph = -175; ph <= 180; ph += 41)
      for (double vp = -160; vp <= 180; vp += 53) {
        const Mat3 m = transpose(rotation(th, ph, vp));
        const ShearRoute r = shear_route_3d(m);
        EXPECT_LT(max_diff(route_matrix(r), m), 1e-12) << th << " " << ph << " " << vp;
        EXPECT_LE(r.passes.size(), 7u);
        for (std::size_t i = 0; i + 1 < r.passes.size(); ++i)
          EXPECT_NE(r.passes[i].axis, r.passes[i + 1].axis);  // merged
        for (const ShearPass& p : r.passes) {
          EXPECT_EQ(p.k[p.axis], 0.0);
          // Angles within +-90 degrees keep every coefficient within +-1.
          for (int j = 0; j < 3; ++j) EXPECT_LE(std::fabs(p.k[j]), 1.0 + 1e-12);
        }
        seven += r.passes.size() == 7;
      }
  EXPECT_GT(seven, 0);
  // Two-angle rotations: Schröder & Salem's 5 passes, 4 one-coordinate + 1 two-coordinate.
  for (double a : {-80.0, -30.0, 10.0, 45.0, 90.0})
    for (double b : {-90.0, -20.0, 15.0, 60.0}) {
      const Mat3 m = multiply(rz(a), ry(b));
      const ShearRoute direct = shear_route_zy(a, b);
      EXPECT_LT(max_diff(route_matrix(direct), m), 1e-12);
      ASSERT_EQ(direct.passes.size(), 5u);
      int one = 0, two = 0;
      for (const ShearPass& p : direct.passes) (p.sources() == 1 ? one : two) += 1;
      EXPECT_EQ(one, 4);
      EXPECT_EQ(two, 1);
      const ShearRoute general = shear_route_3d(m);
      EXPECT_LT(max_diff(route_matrix(general), m), 1e-12);
      EXPECT_EQ(general.passes.size(), 5u) << general.description;
    }
  EXPECT_THROW(shear_route_3d(Mat3{{{1, 0, 0}, {0, 1, 0}, {0, 0, -1}}}), ArgumentError);
  EXPECT_THROW(shear_route_3d(Mat3{{{2, 0, 0}, {0, 1, 0}, {0, 0, 1}}}), ArgumentError);
  EXPECT_THROW(shear_route_zy(100, 0), ArgumentError);
}

TEST(Mismatch, EveryRoundedPassIsABijection) {
  const ShearRoute r2 = paeth_2d(30);
  const ShearRoute r3 = shear_route_3d(transpose(rotation(30, 20, 10)));
  for (const auto& [route, dims, n] :
       {std::tuple{r2, 2, 181}, std::tuple{r3, 3, 31}, std::tuple{paeth_2d(73.3), 2, 101}}) {
    const std::vector<IVec3> g = grid(n, dims);
    std::set<IVec3> whole;
    for (const IVec3& p : g) whole.insert(route_rounded(route, p));
    EXPECT_EQ(whole.size(), g.size());  // injective on the grid
    for (const ShearPass& s : route.passes) {
      std::set<IVec3> out;
      for (const IVec3& p : g) {
        const IVec3 q = apply_pass(s, p, +1);
        out.insert(q);
        // The offset depends only on coordinates the pass leaves alone, so
        // subtracting it again recovers p: the pass is invertible on Z^3.
        EXPECT_EQ(apply_pass(s, q, -1), p);
      }
      EXPECT_EQ(out.size(), g.size());
    }
  }
}

TEST(Mismatch, MinimumMismatchBounds) {
  for (double th : {30.0, 12.5, 61.0}) {
    const MismatchReport r = mismatch_2d(th, 200, 150);
    EXPECT_EQ(r.floor.samples, 200 * 150);
    EXPECT_LT(r.floor.max, std::sqrt(2.0));
    EXPECT_LT(r.floor.coord_max, 1.0);
    EXPECT_LE(r.nearest.max, std::sqrt(2.0) / 2 + 1e-12);
    EXPECT_LE(r.nearest.coord_max, 0.5 + 1e-12);
  }
  for (ViewAngles v : {ViewAngles{30, 20, 10}, ViewAngles{-45, 75, 130}}) {
    const MismatchReport r = mismatch_3d(v, 40);
    EXPECT_EQ(r.floor.samples, 40 * 40 * 40);
    EXPECT_LT(r.floor.max, std::sqrt(3.0));
    EXPECT_LT(r.floor.coord_max, 1.0);
    EXPECT_LE(r.nearest.max, std::sqrt(3.0) / 2 + 1e-12);
    EXPECT_LE(r.nearest.coord_max, 0.5 + 1e-12);
  }
}

// A quarter turn maps grid points onto grid points: the floor mapping (as
// the matching takes it, in 32.32 fixed point) has no mismatch. Floored in
// double, cos 90 = 6e-17 put 3 at 2.9999999999999996 and 115 of 256
// points 1 off.
TEST(Mismatch, QuarterTurnsHaveNoFloorMismatch) {
  for (double th : {90.0, 180.0, 270.0, -90.0}) {
    const MismatchReport r = mismatch_2d(th, 16, 16);
    EXPECT_LT(r.floor.max, 1e-9) << th;
    EXPECT_LT(r.nearest.max, 1e-9) << th;
  }
  for (ViewAngles v : {ViewAngles{90, 0, 0}, ViewAngles{0, 90, 0}, ViewAngles{90, 180, -90}}) {
    const MismatchReport r = mismatch_3d(v, 8);
    EXPECT_LT(r.floor.max, 1e-9) << v.theta << "," << v.phi << "," << v.varphi;
  }
}

TEST(Mismatch, ShearRouteIsWorseAtThirtyDegrees) {
  // 2-D, 256^2 grid. Measured: shear mean 0.4968, max 1.0915, |coord| max
  // 1.0622; floor mean 0.7635, max 1.4092 (0.7647 and 1.4106 floored in double, before the
  // matching's fixed point); nearest mean 0.3828, max 0.7035.
  const MismatchReport r = mismatch_2d(30, 256, 256);
  EXPECT_NEAR(r.shear.mean, 0.497, 0.01);
  EXPECT_NEAR(r.shear.max, 1.09, 0.03);
  EXPECT_GT(r.shear.max, 1.5 * r.nearest.max);
  EXPECT_GT(r.shear.mean, 1.25 * r.nearest.mean);
  // Non-proximal points: the shear route is off by more than one grid step in
  // a coordinate somewhere; floor(T^-1 p_H) never is.
  EXPECT_GT(r.shear.coord_max, 1.03);
  EXPECT_LT(r.floor.coord_max, 1.0);
  // The minimum-mismatch statistics are those of a uniform offset in a unit
  // square: mean distance to a corner 0.7652, to the centre 0.3826.
  EXPECT_NEAR(r.floor.mean, 0.7652, 0.005);
  EXPECT_NEAR(r.nearest.mean, 0.3826, 0.005);
  EXPECT_GT(r.floor.p90, r.floor.p50);
  EXPECT_GE(r.floor.p99, r.floor.p90);

  // 3-D, T(30, 20, 10), 64^3 grid, 7 passes. Measured: shear mean 0.7263, max
  // 1.9394, |coord| max 1.8409; floor mean 0.9606, max 1.7187; nearest mean
  // 0.4803, max 0.8531.
  const MismatchReport q = mismatch_3d({30, 20, 10}, 64);
  EXPECT_EQ(q.passes, 7);
  EXPECT_NEAR(q.shear.mean, 0.726, 0.015);
  EXPECT_NEAR(q.shear.max, 1.94, 0.05);
  EXPECT_GT(q.shear.max, q.floor.max);
  EXPECT_GT(q.shear.max, 2 * q.nearest.max);
  EXPECT_GT(q.shear.coord_max, 1.5);
  EXPECT_NEAR(q.floor.mean, 0.9606, 0.005);
  EXPECT_NEAR(q.nearest.mean, 0.4803, 0.005);
  // Histograms hold every sample.
  int64_t total = 0;
  for (int64_t c : q.shear.hist) total += c;
  EXPECT_EQ(total, q.shear.samples);
  total = 0;
  for (int64_t c : q.shear.coord_hist) total += c;
  EXPECT_EQ(total, 3 * q.shear.samples);
}

TEST(Mismatch, ThesisPoint47And181) {
  // Eq 5.4 as printed, read as p_H -> G: (47, 181) -> x = 47 - 48 = -1,
  // y = 181 + round(-0.5) (a tie: 180 or 181 by the tie rule and by how sin 30
  // rounds in double), x = -1 - 48 = -49 either way; exact x = 47 cos 30 - 181 / 2.
  const PointError e = paeth_point_error(30, 47, 181);
  EXPECT_EQ(e.rounded[0], -49);
  EXPECT_TRUE(e.rounded[1] == 180 || e.rounded[1] == 181) << e.rounded[1];
  EXPECT_NEAR(e.exact[0], 47 * std::sqrt(3.0) / 2 - 90.5, 1e-9);
  EXPECT_NEAR(e.dx, 0.796806, 1e-6);  // the thesis says 1.04
  // Forward reading: object (47, 181) by T_theta's own shears -> (131, 134) vs
  // (131.2032, 133.2506).
  const PointError f = paeth_forward_point_error(30, 47, 181);
  EXPECT_EQ(f.rounded[0], 131);
  EXPECT_NEAR(f.dx, -0.203194, 1e-6);
}

TEST(Mismatch, OperationCountsMatchTheFormulas) {
  const int n = 12;
  const uint64_t s3 = n * n * n;
  const Mat3 tinv = transpose(rotation(30, 20, 10));
  auto expect = [](const OpCount& c, uint64_t samples, uint64_t m, uint64_t a, uint64_t r) {
    EXPECT_EQ(c.samples, samples);
    EXPECT_EQ(c.mul, m * samples);
    EXPECT_EQ(c.add, a * samples);
    EXPECT_EQ(c.rnd, r * samples);
  };
  // Minimum mismatch, direct T^-1 p (9M + 6A), nearest (3R) / trilinear
  // (3R + 3A fractions + 3A (1 - f) + 7 lerps of 2M + 1A).
  expect(count_min_mismatch(tinv, n, Interp::nearest, false), s3, 9, 6, 3);
  expect(count_min_mismatch(tinv, n, Interp::linear, false), s3, 23, 19, 3);
  // Incremental: one direct start, then 3A per sample.
  OpCount c = count_min_mismatch(tinv, n, Interp::nearest, true);
  EXPECT_EQ(c.mul, 9u);
  EXPECT_EQ(c.add, 6 + 3 * (s3 - 1));
  EXPECT_EQ(c.rnd, 3 * s3);
  c = count_min_mismatch(tinv, n, Interp::linear, true);
  EXPECT_EQ(c.mul, 9 + 14 * s3);
  EXPECT_EQ(c.add, 6 + 3 * (s3 - 1) + 13 * s3);
  EXPECT_EQ(c.rnd, 3 * s3);

  // Shear passes: per pass s M + s A + 1R (nearest; s = sources), plus 2M + 3A
  // for linear (fraction, 1 - f, lerp).
  expect(count_shear(paeth_2d(30), 64, 2, Interp::nearest), 64 * 64, 3, 3, 3);
  expect(count_shear(paeth_2d(30), 64, 2, Interp::linear), 64 * 64, 9, 12, 3);
  expect(count_shear(shear_route_zy(30, 20), n, 3, Interp::nearest), s3, 6, 6, 5);
  expect(count_shear(shear_route_zy(30, 20), n, 3, Interp::linear), s3, 16, 21, 5);
  const ShearRoute r7 = shear_route_3d(tinv);
  ASSERT_EQ(r7.passes.size(), 7u);
  expect(count_shear(r7, n, 3, Interp::nearest), s3, 9, 9, 7);
  expect(count_shear(r7, n, 3, Interp::linear), s3, 23, 30, 7);

  EXPECT_THROW(count_shear(r7, 16, 2, Interp::nearest), ArgumentError);
  EXPECT_THROW(count_min_mismatch(tinv, 1, Interp::nearest, false), ArgumentError);
}

TEST(Mismatch, NearestMultiPassResamplingFetchesTheRoutePoint) {
  // Resampling pass by pass (leftmost factor first) reads, for every viewing
  // sample, exactly the object sample at route_rounded(p_H).
  const int n = 24, h = n / 2;
  std::vector<double> vol(static_cast<std::size_t>(n) * n * n);
  for (std::size_t i = 0; i < vol.size(); ++i) vol[i] = static_cast<double>(i) + 1;
  for (const ShearRoute& r :
       {shear_route_3d(transpose(rotation(30, 20, 10))), shear_route_zy(-40, 25),
        shear_route_3d(transpose(rotation(170, -100, 20)))}) {
    const std::vector<double> out = shear_resample_nearest(r, vol, n);
    int checked = 0;
    for (const IVec3& p : grid(n, 3)) {
      // Follow the chain; skip samples whose chain leaves the grid (they read 0).
      IVec3 q{p[0] * r.flip[0], p[1] * r.flip[1], p[2] * r.flip[2]};
      auto inside = [&](const IVec3& v) {
        for (int a = 0; a < 3; ++a)
          if (v[a] < -h || v[a] >= n - h) return false;
        return true;
      };
      bool ok = inside(q);
      for (const ShearPass& s : r.passes) {
        q = apply_pass(s, q, +1);
        ok = ok && inside(q);
      }
      ASSERT_EQ(q, route_rounded(r, p));
      if (!ok) continue;
      const auto at = [&](const IVec3& v) {
        return static_cast<std::size_t>(((v[2] + h) * n + (v[1] + h)) * n + (v[0] + h));
      };
      EXPECT_EQ(out[at(p)], vol[at(q)]);
      ++checked;
    }
    EXPECT_GT(checked, n * n * n / 8);
  }
}
