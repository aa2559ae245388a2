// The multi-pass shear rotation (thesis 5.3.4, Paeth / Schröder & Salem) as a
// baseline for the minimum-mismatch mapping mu*(p_H) = floor(T^-1 p_H)
// (thesis 5.4, eq 5.5), and operation counts per sample (thesis 5.7.2).
//
// Both routes map a viewing-space grid point p_H back to an object-space grid
// point: the exact (unrounded) position is T^-1 p_H, and the mismatch of a
// route at p_H is the distance between T^-1 p_H and the grid point it uses.
//
// Coordinates are integers relative to an integer centre (the rotation is
// about a grid point), so every pass maps integer points to integer points.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "simdvol/view.hpp"

namespace simdvol {

using IVec3 = std::array<int64_t, 3>;

/// One shear pass: coordinate `axis` moves by k . p (k[axis] == 0). With
/// rounding, the move is round_half_away(k . p), a translation along `axis`
/// that is constant for fixed other coordinates, hence a bijection on Z^3.
struct ShearPass {
  int axis = 0;
  Vec3 k{};
  /// How many other coordinates the offset depends on (1: elementary shear,
  /// 1M + 1A; 2: "shear involving the other two coordinates", 2M + 2A).
  int sources() const;
};

/// A shear route: p -> flip (exact sign change, no rounding) -> passes[0] ->
/// passes[1] -> ... (passes[0] is the rightmost factor of the matrix product).
struct ShearRoute {
  std::array<int, 3> flip{1, 1, 1};  ///< diagonal +-1 matrix E, det +1
  std::vector<ShearPass> passes;
  std::string description;  ///< how it was derived (angles, merges)
};

/// The exact matrix product P_last ... P_0 E of a route.
Mat3 route_matrix(const ShearRoute& r);

/// Maps an integer point through the route, rounding (half away from zero)
/// after every pass.
IVec3 route_rounded(const ShearRoute& r, const IVec3& p);

/// Same, without rounding: the route's matrix applied to p, pass by pass.
Vec3 route_exact(const ShearRoute& r, const Vec3& p);

/// Thesis eq 5.4 taken literally: shear x by -tan(theta/2), y by sin(theta),
/// x by -tan(theta/2). Its product is [[c, -s], [s, c]] = T_theta^-1 (the
/// transpose of the thesis's T_theta = [[c, s], [-s, c]]), i.e. exactly the
/// inverse mapping p_H -> G that the minimum-mismatch route uses. For
/// |theta| > 90 degrees a half turn is taken out first as an exact flip
/// (tan(theta/2) grows without bound near 180 degrees). Angle in degrees.
ShearRoute paeth_2d(double theta_deg);

/// A shear route for an arbitrary rotation M (det +1, orthogonal): M is split
/// as Rz(a) Ry(b) Rz(c) E (z-y-z Euler angles, all in [-90, 90] degrees after
/// taking half turns out into the exact flip E), each plane rotation as three
/// Paeth shears, and adjacent passes moving the same coordinate merged. That
/// gives 7 passes in general (5 elementary shears + 2 shears of x by y and z)
/// and 5 passes (4 elementary + 1 two-coordinate, Schröder & Salem's count)
/// when a or c is 0, i.e. for a two-angle rotation Rz(a) Ry(b) or Ry(b) Rz(c).
/// Passes whose coefficients are all zero are dropped. Throws ArgumentError if
/// M is not a rotation.
ShearRoute shear_route_3d(const Mat3& m);

/// The 5-pass decomposition of Rz(a) Ry(b) (angles in degrees, |a|, |b| <= 90):
/// x by z, z by x, x by (y, z), y by x, x by y. Exposed for the tests.
ShearRoute shear_route_zy(double a_deg, double b_deg);

/// Summary and histograms of mismatch distances for one route.
struct MismatchStats {
  std::string method;
  int64_t samples = 0;
  double mean = 0, max = 0, p50 = 0, p90 = 0, p99 = 0;  ///< Euclidean distance
  double coord_mean = 0, coord_max = 0;                 ///< |per-coordinate error| pooled over axes
  double bin_width = 0.05;
  std::vector<int64_t> hist;        ///< Euclidean distance, bin i = [i w, (i+1) w)
  std::vector<int64_t> coord_hist;  ///< |per-coordinate error|, same bins
};

struct MismatchReport {
  int dims = 2;
  std::string description;  ///< the route used
  int passes = 0;
  MismatchStats shear, floor, nearest;
};

/// 2-D: every point of an nx x ny viewing grid (centre (nx/2, ny/2), integer
/// division), mapped by eq 5.4's rounded shears, by floor(T^-1 p_H) (eq 5.5)
/// and by round(T^-1 p_H). Throws ArgumentError for sizes outside 1..16384.
MismatchReport mismatch_2d(double theta_deg, int nx, int ny);

/// 3-D: every point of an n^3 viewing grid (centre n/2), exact position
/// T^-1 p_H with T = rotation(view) (eq 5.2), shear route shear_route_3d(T^-1).
/// Throws ArgumentError for n outside 1..512.
MismatchReport mismatch_3d(ViewAngles view, int n);

/// The x, y error of the literal eq 5.4 route at the viewing point (x, y) for
/// angle theta: rounded point minus exact point T^-1 (x, y).
struct PointError {
  IVec3 rounded{};
  Vec3 exact{};
  double dx = 0, dy = 0, dist = 0;
};
PointError paeth_point_error(double theta_deg, int64_t x, int64_t y);
/// The forward reading: object point (x, y) sheared by the corrected
/// decomposition of T_theta itself (signs flipped), error in viewing space.
PointError paeth_forward_point_error(double theta_deg, int64_t x, int64_t y);

/// Operation tallies of a counting implementation (every multiplication,
/// addition/subtraction and rounding/floor actually executed).
struct OpCount {
  uint64_t mul = 0, add = 0, rnd = 0;
  uint64_t samples = 0;
  /// Per-sample counts; exact when every sample costs the same (the tests
  /// check that the totals are multiples of `samples`).
  double mul_per() const { return samples ? double(mul) / double(samples) : 0.0; }
  double add_per() const { return samples ? double(add) / double(samples) : 0.0; }
  double rnd_per() const { return samples ? double(rnd) / double(samples) : 0.0; }
};

enum class Interp { nearest, linear };

/// Minimum-mismatch resampling of an n^3 synthetic volume at the n^3 viewing
/// grid: per sample, T^-1 p_H (direct: 9M + 6A; incremental along x: 3A),
/// then nearest (3 roundings) or trilinear (3 floors, 3 fractions, 3 (1 - f),
/// 7 lerps of the form (1 - f) a + f b: 14M + 7A).
OpCount count_min_mismatch(const Mat3& tinv, int n, Interp interp, bool incremental);

/// Multi-pass shear resampling of an n^3 synthetic volume (n x n image when
/// dims == 2): every pass, for every sample, computes its offset (1M per
/// source, 1A per extra source), rounds it (1R), adds it to the position
/// (1A) and, for linear, takes the fraction (1A), 1 - f (1A) and one lerp
/// (2M + 1A). Flips cost nothing.
OpCount count_shear(const ShearRoute& r, int n, int dims, Interp interp);

/// The nearest-neighbour multi-pass resampling itself (used by the tests to
/// check that resampling pass by pass fetches exactly the object sample at
/// route_rounded(p_H)). Volume values are vol[(z * n + y) * n + x], centred
/// coordinates; samples whose chain leaves the grid read 0.
std::vector<double> shear_resample_nearest(const ShearRoute& r, const std::vector<double>& vol,
                                           int n);

}  // namespace simdvol
