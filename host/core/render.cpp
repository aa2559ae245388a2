#include "simdvol/render.hpp"

#include <chrono>
#include <cmath>

#include "simdvol/error.hpp"
#include "simdvol/local.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/resample.hpp"

namespace simdvol {

namespace {
using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The classified, lit voxels of a frame (both references' first stages).
std::vector<Rgba> shade_and_classify(const Volume& vol, const ViewGeometry& view,
                                     const RenderOptions& opt, RenderTimes* times) {
  auto t0 = Clock::now();
  const std::vector<ShadeSample> shading = shade(vol, view, opt.shade);
  if (times) times->shade_ms = ms_since(t0);
  t0 = Clock::now();
  // Opacities are defined per unit of the smallest voxel spacing; a different
  // sampling step corrects them (alpha' = 1 - (1 - alpha)^step).
  std::vector<Rgba> voxels = classify(vol, shading, opt.classifier, view.step);
  if (times) times->classify_ms = ms_since(t0);
  return voxels;
}
}  // namespace

void validate(const RenderOptions& opt) {
  if (opt.width <= 0 || opt.height <= 0 || opt.width > 16384 || opt.height > 16384)
    throw ArgumentError("--size", std::to_string(opt.width) + "x" + std::to_string(opt.height) +
                                      " is outside 1x1 .. 16384x16384");
  if (opt.order < 0 || opt.order > kMaxOrder)
    throw ArgumentError("--order", std::to_string(opt.order) + " is outside 0..3");
  const auto& c = opt.composite;
  if (c.mode == CompositeMode::mc && (c.samples <= 0 || c.samples > 1 << 20))
    throw ArgumentError("--samples", std::to_string(c.samples) + " is outside 1..1048576");
  if (c.mode == CompositeMode::adaptive && !(c.threshold > 0.0f && c.threshold <= 1.0f))
    throw ArgumentError("--threshold", "must lie in (0, 1]");
  if (c.stratified && c.mode == CompositeMode::mc && !c.exact_opacity)
    throw ArgumentError("--mc-stratified", "needs exact opacity (--exact-opacity)");
  for (double a : {opt.view.theta, opt.view.phi, opt.view.varphi})
    if (!std::isfinite(a)) throw ArgumentError("--view", "angles must be finite");
  validate(opt.shade);
}

Image warp_to_output(const Image& im, const ViewGeometry& view) {
  Image out(view.out_width, view.out_height);
  const int w = im.width(), h = im.height();
  auto px = [&](int64_t x, int64_t y) -> Rgba {
    if (x < 0 || y < 0 || x >= w || y >= h) return {};
    return im.at(static_cast<int>(x), static_cast<int>(y));
  };
  for (int y = 0; y < out.height(); ++y) {
    for (int x = 0; x < out.width(); ++x) {
      const auto [fx, fy] = view.output_to_intermediate(x, y);
      const double x0 = std::floor(fx), y0 = std::floor(fy);
      const float tx = static_cast<float>(fx - x0), ty = static_cast<float>(fy - y0);
      const auto ix = static_cast<int64_t>(x0), iy = static_cast<int64_t>(y0);
      const Rgba a = px(ix, iy), b = px(ix + 1, iy), c = px(ix, iy + 1), d = px(ix + 1, iy + 1);
      auto lerp2 = [&](float pa, float pb, float pc, float pd) {
        const float top = pa + tx * (pb - pa);
        const float bot = pc + tx * (pd - pc);
        return top + ty * (bot - top);
      };
      out.at(x, y) = {lerp2(a.r, b.r, c.r, d.r), lerp2(a.g, b.g, c.g, d.g),
                      lerp2(a.b, b.b, c.b, d.b), lerp2(a.a, b.a, c.a, d.a)};
    }
  }
  return out;
}

Image render_classified(const std::vector<Rgba>& voxels, const Volume& vol,
                        const ViewGeometry& view, const RenderOptions& opt, RenderTimes* times,
                        Image* intermediate) {
  validate(opt);
  vol.check_voxel_count();
  if (voxels.size() != vol.voxel_count())
    throw ArgumentError("voxels", "classified voxel count does not match the volume");
  // (A view of another volume rendered, its positions clamped.)
  for (int a = 0; a < 3; ++a)
    if (view.grid.dims[a] != vol.dims()[a])
      throw ArgumentError("view", "was made for a volume of other dimensions");
  auto t0 = Clock::now();
  Image im(view.width(), view.height());
  std::vector<Rgba> samples;
  samples.reserve(static_cast<std::size_t>(view.depth()));
  const bool adaptive = opt.composite.mode == CompositeMode::adaptive;
  for (int j = 0; j < view.height(); ++j) {
    for (int i = 0; i < view.width(); ++i) {
      // Matching: the samples of ray (i, j) whose floor(T^-1 p) lies in the
      // volume form one depth range [k0, k1).
      const auto [k0, k1] = view.ray_range(i, j);
      samples.clear();
      float acc = 0;  // accumulated alpha, only to stop resampling early (adaptive)
      for (int64_t k = k0; k < k1; ++k) {
        const std::array<int64_t, 3> pos{view.fixed(0, i, j, k), view.fixed(1, i, j, k),
                                         view.fixed(2, i, j, k)};
        const Rgba s = clamp_sample(resample_rgba(voxels, vol.dims(), pos, opt.order), opt.order);
        samples.push_back(s);
        if (adaptive) {
          acc += (1.0f - acc) * s.a;
          if (acc >= opt.composite.threshold) break;
        }
      }
      const uint32_t ray_id =
          static_cast<uint32_t>(j) * static_cast<uint32_t>(view.width()) + static_cast<uint32_t>(i);
      im.at(i, j) = composite(RaySamples{samples, k0}, ray_id, opt.composite);
    }
  }
  if (times) times->resample_composite_ms = ms_since(t0);
  if (view.sampling == Sampling::pixel) {
    if (intermediate) *intermediate = im;
    return im;
  }
  t0 = Clock::now();
  Image out = warp_to_output(im, view);
  if (times) times->warp_ms = ms_since(t0);
  if (intermediate) *intermediate = std::move(im);
  return out;
}

Image render_reference(const Volume& vol, const RenderOptions& opt, RenderTimes* times,
                       Image* intermediate) {
  validate(opt);
  const ViewGeometry view =
      make_view(vol, opt.view, opt.width, opt.height, opt.sampling, opt.framing);
  return render_classified(shade_and_classify(vol, view, opt, times), vol, view, opt, times,
                           intermediate);
}

Image render_subray_reference(const Volume& vol, const RenderOptions& opt, int64_t pes,
                              int balance_sweeps, bool allocate, RenderTimes* times) {
  validate(opt);
  if (opt.composite.mode != CompositeMode::mc)
    throw ArgumentError("--mc-scope",
                        "per sub-ray estimates are Monte Carlo: needs --composite mc");
  if (balance_sweeps < 0 || balance_sweeps > kMaxBalanceSweeps)
    throw ArgumentError("--balance-sweeps", std::to_string(balance_sweeps) + " is outside 0.." +
                                                std::to_string(kMaxBalanceSweeps));
  const ViewGeometry view =
      make_view(vol, opt.view, opt.width, opt.height, opt.sampling, opt.framing);
  pe_grid(pes, "--pe");  // a power of two in 1..kMaxPes, or ArgumentError naming --pe
  const KdSplit split = kd_split(vol.dims(), pes);
  const std::vector<Rgba> voxels = shade_and_classify(vol, view, opt, times);
  auto t0 = Clock::now();
  Matching m = match_reference(view, split);
  if (balance_sweeps > 0) m = balance_reference(m, view, split, balance_sweeps);
  const std::vector<Rgba> samples = resample_reference(m, voxels, vol.dims(), view, opt.order);
  const RaySegments rays = ray_segments(m, view.width(), view.height());
  std::vector<int32_t> walks;
  if (allocate) walks = allocation_reference(m, samples, rays, opt.composite.samples);
  Image im = composite_segments(m, mc_sub_reference(m, samples, rays, opt.composite, walks),
                                view.width(), view.height());
  if (times) times->resample_composite_ms = ms_since(t0);
  if (view.sampling == Sampling::pixel) return im;
  t0 = Clock::now();
  Image out = warp_to_output(im, view);
  if (times) times->warp_ms = ms_since(t0);
  return out;
}

}  // namespace simdvol
