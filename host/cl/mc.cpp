// Monte Carlo compositing on the device (mc_cl.hpp).
#include "simdvol/mc_cl.hpp"

#include <limits>
#include <string>

#include "buffer_checks.hpp"
#include "simdvol/mc.hpp"

namespace simdvol {

namespace {

constexpr std::size_t kWgs = 64;

cl::NDRange range(int64_t n) {
  return cl::NDRange(round_up(static_cast<std::size_t>(std::max<int64_t>(n, 1)), kWgs));
}

Defines mc_defines(const CompositeParams& p, bool alloc, bool stats) {
  return {{"SHARED", p.streams == RandomStreams::shared ? "1" : "0"},
          {"EXACT", p.exact_opacity ? "1" : "0"},
          {"STRAT", p.stratified ? "1" : "0"},
          {"DROP", p.drop_transparent ? "1" : "0"},
          {"ALLOC", alloc ? "1" : "0"},
          {"STATS", stats ? "1" : "0"}};
}

// Float division must round as on the host for bitwise agreement.
const std::string kOptions = "-cl-fp32-correctly-rounded-divide-sqrt";

int log2_exact(int64_t p) {
  int b = 0;
  while ((int64_t(1) << b) < p) ++b;
  return b;
}

cl::Buffer int_buffer(Device& device, int64_t n, const std::string& what) {
  return device.buffer(CL_MEM_READ_WRITE,
                       static_cast<std::size_t>(std::max<int64_t>(n, 1)) * sizeof(cl_int), nullptr,
                       what);
}

void check_pixels(int width, int height) {
  if (width < 1 || height < 1 || int64_t(width) * height >= std::numeric_limits<cl_int>::max())
    throw ArgumentError("size", "viewing grid must be 1 .. 2^31 - 2 pixels");
}

// The kernels' defines need exact opacity for stratified picks (mc.cl's
// #error): refused as the reference refuses them (render.cpp, composite.cpp).
void check_params(const CompositeParams& p) {
  if (p.stratified && !p.exact_opacity)
    throw ArgumentError("--mc-stratified", "needs exact opacity (--exact-opacity)");
}

// Per-pixel lists of `npx` pixels over `segs`: the offsets and the items the
// walks index (enqueue_ray_lists makes the items one per segment).
void check_rays(const DeviceRayLists& rays, const LocalSegments& segs) {
  const int64_t npx = int64_t(rays.width) * rays.height;
  detail::check_buffer(rays.offset, npx + 1, sizeof(cl_int), "rays.offset",
                       "int offsets (width x height + 1)");
  detail::check_buffer(rays.items, segs.count, sizeof(cl_int), "rays.items",
                       "int items (one per segment)");
}

DeviceMcStats* prepare_stats(Device& device, DeviceMcStats* stats, int64_t n, cl::Buffer& dummy) {
  if (stats) {
    stats->count = n;
    stats->buffer =
        device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(n, 1)) * 16,
                      nullptr, "Monte Carlo statistics");
  } else {
    dummy = device.buffer(CL_MEM_READ_WRITE, 16, nullptr, "Monte Carlo statistics (unused)");
  }
  return stats;
}

}  // namespace

DeviceRayLists enqueue_ray_lists(Device& device, const LocalSegments& segs,
                                 const ViewGeometry& view) {
  check_bounds_unpacked(segs, "enqueue_ray_lists");
  check_segments(segs, false);
  const int width = view.width(), height = view.height();
  check_pixels(width, height);
  DeviceRayLists r;
  r.width = width;
  r.height = height;
  const int npx = width * height;
  r.counts = int_buffer(device, npx, "ray counts");
  r.offset = int_buffer(device, npx + 1, "ray offsets");
  r.items = int_buffer(device, segs.count, "ray items");
  cl_check(device.queue().enqueueFillBuffer(r.counts, cl_int(0), 0,
                                            static_cast<std::size_t>(npx) * sizeof(cl_int)),
           "clEnqueueFillBuffer(ray counts)");
  const cl_int nseg = static_cast<cl_int>(segs.count);
  cl::Kernel kc = device.kernel("mc", "simdvol_mc_ray_count", {}, kOptions);
  set_args(kc, "simdvol_mc_ray_count", segs.segments, nseg, cl_int(width), cl_int(height),
           r.counts);
  r.events.push_back({"ray count", device.run(kc, "simdvol_mc_ray_count", range(nseg),
                                              cl::NDRange(kWgs), LocalSize::at_most)});
  cl::Kernel ks = device.kernel("mc", "simdvol_mc_ray_scan", {}, kOptions);
  set_args(ks, "simdvol_mc_ray_scan", r.counts, cl_int(npx), r.offset);
  r.events.push_back(
      {"ray scan", device.run(ks, "simdvol_mc_ray_scan", cl::NDRange(1), cl::NDRange(1))});
  cl::Kernel kf = device.kernel("mc", "simdvol_mc_ray_fill", {}, kOptions);
  set_args(kf, "simdvol_mc_ray_fill", segs.segments, nseg, cl_int(width), cl_int(height), r.offset,
           r.counts, r.items);
  r.events.push_back({"ray fill", device.run(kf, "simdvol_mc_ray_fill", range(nseg),
                                             cl::NDRange(kWgs), LocalSize::at_most)});
  cl::Kernel kt = device.kernel("mc", "simdvol_mc_ray_sort", {}, kOptions);
  set_args(kt, "simdvol_mc_ray_sort", segs.segments, cl_int(npx), r.offset, r.items);
  r.events.push_back({"ray sort", device.run(kt, "simdvol_mc_ray_sort", range(npx),
                                             cl::NDRange(kWgs), LocalSize::at_most)});
  return r;
}

RaySegments read_ray_lists(Device& device, const DeviceRayLists& rays) {
  const std::size_t npx = static_cast<std::size_t>(rays.width) * rays.height;
  std::vector<cl_int> off(npx + 1);
  cl_check(device.queue().enqueueReadBuffer(rays.offset, CL_TRUE, 0, off.size() * sizeof(cl_int),
                                            off.data()),
           "clEnqueueReadBuffer(ray offsets)");
  std::vector<cl_int> items(static_cast<std::size_t>(off.back()));
  if (!items.empty())
    cl_check(device.queue().enqueueReadBuffer(rays.items, CL_TRUE, 0, items.size() * sizeof(cl_int),
                                              items.data()),
             "clEnqueueReadBuffer(ray items)");
  RaySegments r;
  r.width = rays.width;
  r.height = rays.height;
  r.offset.assign(off.begin(), off.end());
  r.items.assign(items.begin(), items.end());
  return r;
}

McStats DeviceMcStats::read(Device& device) const {
  std::vector<cl_int4> v(static_cast<std::size_t>(count));
  if (!v.empty())
    cl_check(
        device.queue().enqueueReadBuffer(buffer, CL_TRUE, 0, v.size() * sizeof(cl_int4), v.data()),
        "clEnqueueReadBuffer(Monte Carlo statistics)");
  McStats s;
  for (const cl_int4& x : v) {
    s.walks += x.s[0];
    s.draws += x.s[1];
    s.skipped += x.s[2];
    s.fallbacks += x.s[3];
  }
  return s;
}

cl::Event enqueue_mc_whole(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const cl::Buffer& samples, const DeviceRayLists& rays,
                           const CompositeParams& p, const cl::Buffer& image,
                           DeviceMcStats* stats) {
  check_bounds_unpacked(segs, "enqueue_mc_whole");
  if (p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  check_params(p);
  check_pixels(rays.width, rays.height);
  const int npx = rays.width * rays.height;
  check_segments(segs, false);
  check_samples(segs, sample_off, samples);
  check_rays(rays, segs);
  detail::check_buffer(image, npx, sizeof(cl_float4), "image", "float4 pixels (width x height)");
  cl::Buffer dummy;
  prepare_stats(device, stats, npx, dummy);
  const std::string name = "simdvol_mc_whole";
  cl::Kernel k = device.kernel("mc", name, mc_defines(p, false, stats != nullptr), kOptions);
  set_args(k, name, segs.segments, sample_off, samples, rays.offset, rays.items, cl_int(rays.width),
           cl_int(npx), cl_int(p.samples), cl_ulong(p.seed), image, stats ? stats->buffer : dummy);
  return device.run(k, name, range(npx), cl::NDRange(kWgs), LocalSize::at_most);
}

DeviceAllocation enqueue_mc_allocation(Device& device, const LocalSegments& segs,
                                       const cl::Buffer& sample_off, const cl::Buffer& samples,
                                       const DeviceRayLists& rays, int budget) {
  check_bounds_unpacked(segs, "enqueue_mc_allocation");
  if (budget < 0) throw ArgumentError("budget", "must not be negative");
  check_pixels(rays.width, rays.height);
  check_segments(segs, false);
  check_samples(segs, sample_off, samples);
  check_rays(rays, segs);
  DeviceAllocation a;
  a.alpha = device.buffer(CL_MEM_READ_WRITE,
                          static_cast<std::size_t>(std::max<int64_t>(segs.count, 1)) * 4, nullptr,
                          "segment opacities");
  a.walks = int_buffer(device, segs.count, "walks per segment");
  cl::Kernel ka = device.kernel("mc", "simdvol_mc_alpha", {}, kOptions);
  set_args(ka, "simdvol_mc_alpha", segs.segments, cl_int(segs.count), sample_off, samples, a.alpha,
           a.walks);
  a.events.push_back({"alpha", device.run(ka, "simdvol_mc_alpha", range(segs.count),
                                          cl::NDRange(kWgs), LocalSize::at_most)});
  const int npx = rays.width * rays.height;
  cl::Kernel kb = device.kernel("mc", "simdvol_mc_allocate", {}, kOptions);
  set_args(kb, "simdvol_mc_allocate", rays.offset, rays.items, cl_int(npx), a.alpha, cl_int(budget),
           a.walks);
  a.events.push_back({"allocate", device.run(kb, "simdvol_mc_allocate", range(npx),
                                             cl::NDRange(kWgs), LocalSize::at_most)});
  return a;
}

cl::Event enqueue_mc_local(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const cl::Buffer& samples, int width, const CompositeParams& p,
                           const DeviceAllocation* alloc, DeviceFootprints& fp,
                           DeviceMcStats* stats) {
  check_bounds_unpacked(segs, "enqueue_mc_local");
  if (!alloc && p.samples <= 0) throw ArgumentError("--samples", "must be positive");
  if (width < 1) throw ArgumentError("width", "must be positive");
  check_params(p);
  check_segments(segs);
  check_samples(segs, sample_off, samples);
  check_footprints(fp, segs.pes);
  if (alloc)
    detail::check_buffer(alloc->walks, segs.count, sizeof(cl_int), "alloc.walks",
                         "int walks (one per segment)");
  cl::Buffer dummy;
  prepare_stats(device, stats, segs.count, dummy);
  const std::string name = "simdvol_mc_local";
  cl::Kernel k =
      device.kernel("mc", name, mc_defines(p, alloc != nullptr, stats != nullptr), kOptions);
  cl::Buffer no_alloc;
  if (!alloc) no_alloc = int_buffer(device, 1, "walks (unused)");
  set_args(k, name, segs.segments, cl_int(segs.count), segs.seg_offset,
           cl_int(log2_exact(segs.pes)), sample_off, samples, cl_int(width), cl_int(p.samples),
           alloc ? alloc->walks : no_alloc, cl_ulong(p.seed), segs.rects, fp.offsets, fp.pixels,
           stats ? stats->buffer : dummy);
  return device.run(k, name, range(segs.count), cl::NDRange(kWgs), LocalSize::at_most);
}

}  // namespace simdvol
