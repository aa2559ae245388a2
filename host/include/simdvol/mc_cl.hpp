// Monte Carlo compositing on the device (kernels/mc.cl); the references and
// the definitions (keying, exact opacity, allocation rule) are in mc.hpp and
// composite.hpp.
//
// Inputs: a matching's segments on the device (LocalSegments, local_cl.hpp)
// and the resample stage's samples in segment order (enqueue_resample).
//
// Whole ray. The generator is keyed by the absolute depth index k, so a walk
// stops at the first k of the whole ray with u(m, k) < alpha_k whichever PE
// holds it. On the device the pixel's owner (one work-item per pixel, as
// after the swap and display) walks the ray's segments in increasing k0,
// reading their samples: enqueue_ray_lists builds per-pixel lists of the
// non-empty segments (count, scan, fill, sort: unique result) and
// enqueue_mc_whole runs the walks. The samples travel to the pixel's owner
// (router traffic, one float4 per sample): whole-ray walks are sequential
// along the ray by definition. (A walk-mask scheme, where each PE reports the
// first stop of every walk in its segment and the owner keeps the front-most,
// moves n ints per segment instead; it is not done here.)
//
// Per sub-ray (ch. 7.4). enqueue_mc_local: one work-item per segment, its
// walks over its own samples, written into the PE's footprint (as
// enqueue_local); the footprints are then composited with over in depth order
// (the swap stage, or composite_footprints on the host). With allocation
// (ch. 7.5 (b)) enqueue_mc_allocation first computes each segment's exact
// opacity and, per ray, the walks of its segments (allocate_walks).
//
// Every enqueue_* validates first, enqueues without waiting and returns the
// kernels' events; buffers must outlive the queue's work. The validation
// takes the sizes of the caller's buffers on the host (check_segments,
// check_samples, check_footprints in local_cl.hpp; the ray lists' offsets
// and items, the image, the allocation's walks): ArgumentError naming the
// one too small for what the kernels index.
#pragma once

#include <cstdint>
#include <vector>

#include "simdvol/composite.hpp"
#include "simdvol/device.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// Per-pixel lists of the non-empty segments in increasing k0 (as RaySegments).
struct DeviceRayLists {
  int width = 0, height = 0;
  cl::Buffer offset;  ///< cl_int[width * height + 1]
  cl::Buffer items;   ///< cl_int[segment count] (the non-empty ones used)
  cl::Buffer counts;  ///< cl_int[width * height] scratch
  std::vector<StageEvent> events;
};
/// `view` must be the one the segments were matched in (its grid is the
/// image: width() x height()); segments outside it are ignored by the
/// kernels (never written out of bounds).
DeviceRayLists enqueue_ray_lists(Device& device, const LocalSegments& segs,
                                 const ViewGeometry& view);
/// Blocking read-back (for tests): offsets and items as RaySegments.
struct RaySegments;
RaySegments read_ray_lists(Device& device, const DeviceRayLists& rays);

/// Work counters per work-item on the device (int4: walks, draws, skipped,
/// fallback), summed on the host.
struct DeviceMcStats {
  cl::Buffer buffer;
  int64_t count = 0;
  McStats read(Device& device) const;
};

/// Whole-ray Monte Carlo into `image` (cl_float4[width * height], the
/// intermediate image, row-major). p.samples walks per ray; p.streams,
/// p.exact_opacity, p.drop_transparent honoured; p.stratified needs
/// p.exact_opacity (ArgumentError "--mc-stratified", as the reference). `stats`, if given, receives
/// the work counters.
cl::Event enqueue_mc_whole(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const cl::Buffer& samples, const DeviceRayLists& rays,
                           const CompositeParams& p, const cl::Buffer& image,
                           DeviceMcStats* stats = nullptr);

/// Walks per segment by opacity (cl_int[segments]) for a per-ray budget.
struct DeviceAllocation {
  cl::Buffer alpha;  ///< cl_float[segments]: exact opacity of each segment
  cl::Buffer walks;  ///< cl_int[segments]
  std::vector<StageEvent> events;
};
DeviceAllocation enqueue_mc_allocation(Device& device, const LocalSegments& segs,
                                       const cl::Buffer& sample_off, const cl::Buffer& samples,
                                       const DeviceRayLists& rays, int budget);

/// Per sub-ray Monte Carlo into the footprints: every segment's pixel
/// written (its estimate; 0 for an empty segment), the others only if
/// zeroed first (enqueue_zero_footprints, or enqueue_zero_uncovered for
/// the pixels without a segment). `alloc` (if given) supplies the walks per
/// segment, else p.samples each. `width` is the viewing grid's width (ray ids).
cl::Event enqueue_mc_local(Device& device, const LocalSegments& segs, const cl::Buffer& sample_off,
                           const cl::Buffer& samples, int width, const CompositeParams& p,
                           const DeviceAllocation* alloc, DeviceFootprints& fp,
                           DeviceMcStats* stats = nullptr);

}  // namespace simdvol
