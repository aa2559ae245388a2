// Serial references of Monte Carlo compositing on the PE array (mc.hpp).
#include "simdvol/mc.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "simdvol/error.hpp"
#include "simdvol/local.hpp"

namespace simdvol {

namespace {

void check_samples(const Matching& m, const std::vector<Rgba>& samples,
                   const std::vector<int64_t>& off) {
  if (static_cast<int64_t>(samples.size()) != off.back())
    throw ArgumentError("samples", "count does not match the matching's segments");
  (void)m;
}

void check_rays(const Matching& m, const RaySegments& rays) {
  if (rays.width < 1 || rays.height < 1 ||
      rays.offset.size() != static_cast<std::size_t>(rays.width) * rays.height + 1)
    throw ArgumentError("rays", "do not match the image size");
  for (int64_t s : rays.items)
    if (s < 0 || s >= static_cast<int64_t>(m.segments.size()))
      throw ArgumentError("rays", "segment index out of range");
}

}  // namespace

RaySegments ray_segments(const Matching& m, int width, int height) {
  if (width < 1 || height < 1) throw ArgumentError("size", "image must not be empty");
  RaySegments r;
  r.width = width;
  r.height = height;
  const std::size_t npx = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  r.offset.assign(npx + 1, 0);
  for (const sv_segment& s : m.segments) {
    if (s.k1 <= s.k0) continue;
    if (s.i < 0 || s.j < 0 || s.i >= width || s.j >= height)
      throw ArgumentError("matching", "segment outside the image");
    ++r.offset[static_cast<std::size_t>(s.j) * width + s.i + 1];
  }
  for (std::size_t q = 0; q < npx; ++q) r.offset[q + 1] += r.offset[q];
  r.items.resize(static_cast<std::size_t>(r.offset[npx]));
  std::vector<int64_t> fill(r.offset.begin(), r.offset.end() - 1);
  for (std::size_t n = 0; n < m.segments.size(); ++n) {
    const sv_segment& s = m.segments[n];
    if (s.k1 <= s.k0) continue;
    r.items[static_cast<std::size_t>(fill[static_cast<std::size_t>(s.j) * width + s.i]++)] =
        static_cast<int64_t>(n);
  }
  for (std::size_t q = 0; q < npx; ++q)
    std::sort(r.items.begin() + r.offset[q], r.items.begin() + r.offset[q + 1],
              [&](int64_t a, int64_t b) {
                return m.segments[static_cast<std::size_t>(a)].k0 <
                       m.segments[static_cast<std::size_t>(b)].k0;
              });
  return r;
}

int32_t allocation_weight(float alpha) {
  return alpha > 0.0f ? static_cast<int32_t>(std::ceil(std::min(alpha, 1.0f) * 256.0f)) : 0;
}

std::vector<int32_t> allocate_walks(std::span<const float> alphas, int budget) {
  if (budget < 0) throw ArgumentError("budget", "must not be negative");
  // Opacities (an infinite or huge one gave negative walk counts, a NaN an
  // undefined conversion); a composited opacity may round a hair past 1,
  // and one of 0 or below is transparent.
  for (std::size_t s = 0; s < alphas.size(); ++s)
    if (!(alphas[s] <= 1.0f + 1e-5f) || std::isnan(alphas[s]) || std::isinf(alphas[s]))
      throw ArgumentError("alphas", "opacity " + std::to_string(alphas[s]) + " of sub-ray " +
                                        std::to_string(s) + " is not a number of at most 1");
  const std::size_t S = alphas.size();
  std::vector<int32_t> n(S, 0);
  // Integer weights (allocation_weight): exact sums, floors and remainders,
  // the same on the device. The floats' q_s = r alpha_s / A made a last-bit
  // difference between the device's opacities and the serial reference's a
  // different allocation wherever sub-rays tie (a piecewise-constant
  // phantom has many), 0.3 apart in a pixel's alpha.
  int c = 0;
  int64_t W = 0;
  for (float a : alphas)
    if (a > 0.0f) {
      ++c;
      W += allocation_weight(a);
    }
  if (c == 0) return n;
  for (std::size_t s = 0; s < S; ++s) n[s] = alphas[s] > 0.0f ? 1 : 0;
  if (budget <= c) return n;
  const int64_t r = budget - c;
  std::vector<int64_t> f(S, 0), rem(S, -1);
  int64_t sum_f = 0;
  for (std::size_t s = 0; s < S; ++s) {
    if (!(alphas[s] > 0.0f)) continue;
    const int64_t rw = r * allocation_weight(alphas[s]);
    f[s] = rw / W;
    rem[s] = rw % W;
    sum_f += f[s];
  }
  const int64_t L = r - sum_f;  // 0 <= L < c
  for (std::size_t s = 0; s < S; ++s) {
    if (!(alphas[s] > 0.0f)) continue;
    int64_t rank = 0;  // sub-rays ahead of s: larger remainder, or equal and in front
    for (std::size_t t = 0; t < S; ++t)
      if (alphas[t] > 0.0f && (rem[t] > rem[s] || (rem[t] == rem[s] && t < s))) ++rank;
    n[s] = static_cast<int32_t>(1 + f[s] + (rank < L ? 1 : 0));
  }
  return n;
}

std::vector<float> segment_alphas(const Matching& m, const std::vector<Rgba>& samples) {
  const std::vector<int64_t> off = sample_offsets(m);
  check_samples(m, samples, off);
  std::vector<float> a(m.segments.size(), 0.0f);
  for (std::size_t s = 0; s < m.segments.size(); ++s) {
    float acc = 0.0f;
    for (int64_t q = off[s]; q < off[s + 1]; ++q)
      acc = acc + (1.0f - acc) * samples[static_cast<std::size_t>(q)].a;
    a[s] = acc;
  }
  return a;
}

std::vector<int32_t> allocation_reference(const Matching& m, const std::vector<Rgba>& samples,
                                          const RaySegments& rays, int budget) {
  check_rays(m, rays);
  const std::vector<float> alpha = segment_alphas(m, samples);
  std::vector<int32_t> walks(m.segments.size(), 0);
  std::vector<float> a;
  for (std::size_t q = 0; q + 1 < rays.offset.size(); ++q) {
    a.clear();
    for (int64_t t = rays.offset[q]; t < rays.offset[q + 1]; ++t)
      a.push_back(alpha[static_cast<std::size_t>(rays.items[static_cast<std::size_t>(t)])]);
    const std::vector<int32_t> n = allocate_walks(a, budget);
    for (int64_t t = rays.offset[q]; t < rays.offset[q + 1]; ++t)
      walks[static_cast<std::size_t>(rays.items[static_cast<std::size_t>(t)])] =
          n[static_cast<std::size_t>(t - rays.offset[q])];
  }
  return walks;
}

Image mc_whole_reference(const Matching& m, const std::vector<Rgba>& samples,
                         const RaySegments& rays, const CompositeParams& p, McStats* stats) {
  check_rays(m, rays);
  if (p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  const std::vector<int64_t> off = sample_offsets(m);
  check_samples(m, samples, off);
  Image im(rays.width, rays.height);
  std::vector<Rgba> ray;
  for (int j = 0; j < rays.height; ++j)
    for (int i = 0; i < rays.width; ++i) {
      const std::size_t q = static_cast<std::size_t>(j) * rays.width + i;
      ray.clear();
      int64_t first = 0;
      for (int64_t t = rays.offset[q]; t < rays.offset[q + 1]; ++t) {
        const auto s = static_cast<std::size_t>(rays.items[static_cast<std::size_t>(t)]);
        if (t == rays.offset[q]) first = m.segments[s].k0;
        if (!ray.empty() && m.segments[s].k0 != first + static_cast<int64_t>(ray.size()))
          throw ArgumentError("matching", "the segments of a ray leave a gap");
        ray.insert(ray.end(), samples.begin() + off[s], samples.begin() + off[s + 1]);
      }
      im.at(i, j) = composite_mc_walks(RaySamples{ray, first}, mc_ray_id(i, j, rays.width),
                                       p.samples, p, stats);
    }
  return im;
}

std::vector<Rgba> mc_sub_reference(const Matching& m, const std::vector<Rgba>& samples,
                                   const RaySegments& rays, const CompositeParams& p,
                                   const std::vector<int32_t>& walks, McStats* stats) {
  check_rays(m, rays);
  const std::vector<int64_t> off = sample_offsets(m);
  check_samples(m, samples, off);
  if (!walks.empty() && walks.size() != m.segments.size())
    throw ArgumentError("walks", "one per segment expected");
  if (walks.empty() && p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  std::vector<Rgba> out(m.segments.size());
  for (std::size_t s = 0; s < m.segments.size(); ++s) {
    const sv_segment& g = m.segments[s];
    if (g.k1 <= g.k0) continue;  // empty: 0 (no walk is started)
    const int n = walks.empty() ? p.samples : walks[s];
    const std::span<const Rgba> v(samples.data() + off[s],
                                  static_cast<std::size_t>(off[s + 1] - off[s]));
    out[s] = composite_mc_walks(RaySamples{v, g.k0}, mc_ray_id(g.i, g.j, rays.width), n, p, stats);
  }
  return out;
}

}  // namespace simdvol
