// Reference Aitken/Neville resampling (thesis 5.6.3–5.6.4), orders 0–3.
//
// 1-D: the stencil of aitken_stencil() is combined with Neville's recurrence
// in insertion order (the header's form). The thesis prints the recurrence
// as the last line of eq 5.16 (its text calls it eq 5.17; the printed
// eq 5.17 is the error term) with a sign slip: f_{0..n-1} + (x - x0) /
// (xn - x0) (f_{0..n-1} - f_{1..n}), where the line above it gives
// f_{1..n} - f_{0..n-1} (test Aitken1D.WeightsAreTheLagrangeWeightsOfEq513).
// After point k is inserted the table column
//   q[i] = P_{i..k}, i = k, k-1, ..., 0
// is updated from the previous column (q[i] = P_{i..k-1}) as
//   q[k] = f[k]
//   q[i] = ((x - x_i) q[i+1] - (x - x_k) q[i]) / (x_k - x_i),   i = k-1 .. 0
// so q[0] = P_{0..k} is the order-k estimate. x - x_i is evaluated as
// (floor_x - x_i) + frac in float: the integer part is a small exact integer.
//
// 3-D (the order the OpenCL kernels follow): the (order+1)^3 neighbours are
// gathered with each index clamped into the volume (edge replicate); then
//   1. along x, for every (y, z) stencil pair,
//   2. along y, for every z stencil position, over the step-1 results,
//   3. along z, over the step-2 results.
// Each axis uses its own stencil from its own floor/fraction (fixed_floor and
// fixed_frac of view.hpp; fixed_frac may round up to exactly 1.0f for a
// fraction within 2^-25 of 1, which is still the right position, f + 1).
// The float expression above is evaluated as written (a true division, no
// reciprocal); an implementation wanting bitwise agreement must do the same
// without FMA contraction. Orders are template parameters so the loops unroll
// and the rows of one step vectorise (same per-row operations, same result).
#include "simdvol/resample.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "simdvol/error.hpp"
#include "simdvol/view.hpp"

namespace simdvol {
namespace {

void check_order(int order) {
  if (order < 0 || order > kMaxOrder)
    throw ArgumentError("order", "interpolation order " + std::to_string(order) +
                                     " is outside 0.." + std::to_string(kMaxOrder));
}

// Stencil positions into s[0..order]; no validation (callers check order).
inline void stencil(int64_t f, float t, int order, int64_t* s) {
  const bool low = t <= 0.5f;
  s[0] = low ? f : f + 1;
  if (order >= 1) s[1] = low ? f + 1 : f;
  if (order >= 2) s[2] = low ? f - 1 : f + 2;
  if (order >= 3) s[3] = low ? f + 2 : f - 1;
}

// Neville in insertion order (see the file comment) on R independent rows at
// once: q[i * R + r] holds f[i] of row r on entry and q[r] = P_{0..Order} of
// row r on exit. d[i] = x - x_i. Every row sees exactly the scalar sequence of
// operations, so the result does not depend on R (the loops over r are there
// for the vectoriser).
template <int Order, int R>
inline void neville_rows(float* q, const int64_t* xs, const float* d, float* levels) {
  if (levels) levels[0] = q[0];
  for (int k = 1; k <= Order; ++k) {
    for (int i = k - 1; i >= 0; --i) {
      const float denom = static_cast<float>(xs[k] - xs[i]);
      const float di = d[i], dk = d[k];
      for (int r = 0; r < R; ++r)
        q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) / denom;
    }
    if (levels) levels[k] = q[0];
  }
}

// One axis of a 3-D sample: stencil positions, clamped indices and x - x_i.
struct Axis {
  int64_t pos[kMaxOrder + 1];
  int64_t idx[kMaxOrder + 1];
  float d[kMaxOrder + 1];
};

template <int Order>
inline void make_axis(int64_t fixed, int64_t n, Axis& a) {
  const int64_t f = fixed_floor(fixed);
  const float t = fixed_frac(fixed);
  stencil(f, t, Order, a.pos);
  for (int i = 0; i <= Order; ++i) {
    a.idx[i] = std::clamp<int64_t>(a.pos[i], 0, n - 1);
    a.d[i] = static_cast<float>(f - a.pos[i]) + t;
  }
}

// Combines a gathered block v[a * M * M + c * M + b] (a: x stencil index,
// b: y, c: z; M = Order + 1), destroying it: x first (for every (y, z) pair),
// then y (for every z), then z.
template <int Order>
inline float combine(float* v, const Axis& ax, const Axis& ay, const Axis& az) {
  constexpr int M = Order + 1;
  neville_rows<Order, M * M>(v, ax.pos, ax.d, nullptr);  // v[c * M + b] = along x
  float w[M * M];                                        // w[b * M + c]
  for (int c = 0; c < M; ++c)
    for (int b = 0; b < M; ++b) w[b * M + c] = v[c * M + b];
  neville_rows<Order, M>(w, ay.pos, ay.d, nullptr);  // w[c] = along y
  neville_rows<Order, 1>(w, az.pos, az.d, nullptr);  // w[0] = along z
  return w[0];
}

template <int Order>
float resample_scalar_t(const Volume& vol, const std::array<int64_t, 3>& fp) {
  constexpr int M = Order + 1;
  Axis ax, ay, az;
  make_axis<Order>(fp[0], vol.nx(), ax);
  make_axis<Order>(fp[1], vol.ny(), ay);
  make_axis<Order>(fp[2], vol.nz(), az);
  const float* data = vol.data().data();
  const int64_t nx = vol.nx(), nxy = vol.nx() * vol.ny();
  float v[M * M * M];
  for (int c = 0; c < M; ++c)
    for (int b = 0; b < M; ++b) {
      const float* row = data + az.idx[c] * nxy + ay.idx[b] * nx;
      for (int a = 0; a < M; ++a) v[a * M * M + c * M + b] = row[ax.idx[a]];
    }
  return combine<Order>(v, ax, ay, az);
}

template <int Order>
Rgba resample_rgba_t(const std::vector<Rgba>& voxels, const std::array<int64_t, 3>& dims,
                     const std::array<int64_t, 3>& fp) {
  constexpr int M = Order + 1;
  Axis ax, ay, az;
  make_axis<Order>(fp[0], dims[0], ax);
  make_axis<Order>(fp[1], dims[1], ay);
  make_axis<Order>(fp[2], dims[2], az);
  const int64_t nx = dims[0], nxy = dims[0] * dims[1];
  float r[M * M * M], g[M * M * M], b[M * M * M], al[M * M * M];
  for (int c = 0; c < M; ++c)
    for (int j = 0; j < M; ++j) {
      const Rgba* row = voxels.data() + az.idx[c] * nxy + ay.idx[j] * nx;
      for (int a = 0; a < M; ++a) {
        const Rgba& p = row[ax.idx[a]];
        const int n = a * M * M + c * M + j;
        r[n] = p.r;
        g[n] = p.g;
        b[n] = p.b;
        al[n] = p.a;
      }
    }
  return Rgba{combine<Order>(r, ax, ay, az), combine<Order>(g, ax, ay, az),
              combine<Order>(b, ax, ay, az), combine<Order>(al, ax, ay, az)};
}

int64_t to_fixed(double x, const char* name) {
  const double scaled = x * 4294967296.0;
  // Keep the floor within int32 so that stencil arithmetic cannot overflow.
  if (!std::isfinite(x) || std::fabs(x) >= 2147483648.0)
    throw ArgumentError(name, "coordinate is not finite or out of range");
  return static_cast<int64_t>(std::llround(scaled));
}

}  // namespace

Rgba clamp_sample(const Rgba& s, int order) {
  if (order < 2) return s;
  const float a = std::fmin(std::fmax(s.a, 0.0f), 1.0f);
  auto c = [a](float v) { return std::fmin(std::fmax(v, 0.0f), a); };
  return Rgba{c(s.r), c(s.g), c(s.b), a};
}

std::array<int64_t, 4> aitken_stencil(int64_t floor_x, float frac, int order) {
  check_order(order);
  std::array<int64_t, 4> s{};
  stencil(floor_x, frac, order, s.data());
  return s;
}

float aitken(const float* f, const int64_t* xs, int order, int64_t floor_x, float frac,
             float* levels) {
  check_order(order);
  float d[kMaxOrder + 1];
  float q[kMaxOrder + 1];
  for (int i = 0; i <= order; ++i) {
    d[i] = static_cast<float>(floor_x - xs[i]) + frac;
    q[i] = f[i];
  }
  switch (order) {
    case 0:
      neville_rows<0, 1>(q, xs, d, levels);
      break;
    case 1:
      neville_rows<1, 1>(q, xs, d, levels);
      break;
    case 2:
      neville_rows<2, 1>(q, xs, d, levels);
      break;
    default:
      neville_rows<3, 1>(q, xs, d, levels);
      break;
  }
  return q[0];
}

float aitken_1d(const std::vector<float>& values, double x, int order) {
  check_order(order);
  if (values.empty()) throw ArgumentError("values", "no samples to interpolate");
  if (!std::isfinite(x) || std::fabs(x) >= 2147483648.0)
    throw ArgumentError("x", "coordinate is not finite or out of range");
  const double fl = std::floor(x);
  const auto f = static_cast<int64_t>(fl);
  const auto t = static_cast<float>(x - fl);
  int64_t xs[kMaxOrder + 1];
  float v[kMaxOrder + 1];
  stencil(f, t, order, xs);
  const auto last = static_cast<int64_t>(values.size()) - 1;
  for (int i = 0; i <= order; ++i)
    v[i] = values[static_cast<std::size_t>(std::clamp<int64_t>(xs[i], 0, last))];
  return aitken(v, xs, order, f, t);
}

float resample_scalar(const Volume& vol, const std::array<int64_t, 3>& fixed_pos, int order) {
  vol.check_voxel_count();  // (a data() resized apart from its dims was read past its end)
  if (vol.voxel_count() == 0) throw ArgumentError("volume", "volume is empty");
  switch (order) {
    case 0:
      return resample_scalar_t<0>(vol, fixed_pos);
    case 1:
      return resample_scalar_t<1>(vol, fixed_pos);
    case 2:
      return resample_scalar_t<2>(vol, fixed_pos);
    case 3:
      return resample_scalar_t<3>(vol, fixed_pos);
    default:
      check_order(order);
  }
  return 0.0f;  // unreachable: check_order throws
}

Rgba resample_rgba(const std::vector<Rgba>& voxels, const std::array<int64_t, 3>& dims,
                   const std::array<int64_t, 3>& fixed_pos, int order) {
  check_order(order);
  if (voxels.size() != checked_voxel_count(dims, "dims", sizeof(Rgba)))
    throw ArgumentError("voxels", "RGBA voxel count does not match the dimensions");
  switch (order) {
    case 0:
      return resample_rgba_t<0>(voxels, dims, fixed_pos);
    case 1:
      return resample_rgba_t<1>(voxels, dims, fixed_pos);
    case 2:
      return resample_rgba_t<2>(voxels, dims, fixed_pos);
    default:
      return resample_rgba_t<3>(voxels, dims, fixed_pos);
  }
}

float resample_scalar_at(const Volume& vol, double x, double y, double z, int order) {
  return resample_scalar(vol, {to_fixed(x, "x"), to_fixed(y, "y"), to_fixed(z, "z")}, order);
}

}  // namespace simdvol
