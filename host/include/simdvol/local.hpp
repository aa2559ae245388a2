// Resampling and local (sub-ray) compositing on the PE array (thesis ch. 5.6,
// 7.3): serial references of the `resample` and `local` stages and of the
// footprints the local stage writes. The device stages are in local_cl.hpp.
//
// Input: a Matching (match.hpp; after balancing, segments may be empty or
// reach past their PE's cell) and the classified premultiplied voxels, flat
// (x fastest). Every sample (i, j, k) of every segment is resampled exactly
// as resample_rgba (resample.hpp) does at view.fixed(a, i, j, k), then taken
// through clamp_sample (orders 2 and 3 clamped to valid opacities): the
// result does not depend on which PE resamples it. On the PE array, a stencil voxel
// at global g (clamped into the volume) is read from the cell of the PE that
// owns it; when that is not the resampling PE it is an X-Net read
// (xnet_reads counts them).
//
// Sample order: segment order (PE p's segments at seg_offset[p] ..
// seg_offset[p+1], each segment's samples k0 .. k1-1); sample_offsets() gives
// the CSR offsets (prefix sum of k1 - k0 over segments).
//
// Footprints: PE p's rectangle rects[p] = {i0, j0, w, h} holds one (C', a)
// per pixel; pixel (i, j) is element rect_offset[p] + (j - j0) * w + (i - i0);
// rect_offset is the prefix sum of w * h; pixels without a segment are 0.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "simdvol/image.hpp"
#include "simdvol/match.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/view.hpp"

namespace simdvol {

/// Prefix sum of the segments' lengths (segments.size() + 1 entries).
std::vector<int64_t> sample_offsets(const Matching& m);

/// Every sample of every segment in segment order (see the file comment),
/// as clamp_sample(resample_rgba(...)) of `voxels` (dims `dims`, x fastest). Throws
/// ArgumentError for a bad order, a voxel count that does not match, or a
/// segment outside the viewing grid.
std::vector<Rgba> resample_reference(const Matching& m, const std::vector<Rgba>& voxels,
                                     const Dims3& dims, const ViewGeometry& view, int order);

/// One composite per segment: its samples front to back with over (an empty
/// segment gives 0). Same arguments as resample_reference.
std::vector<Rgba> local_reference(const Matching& m, const std::vector<Rgba>& voxels,
                                  const Dims3& dims, const ViewGeometry& view, int order);

/// The footprints of the per-segment composites (see the file comment).
struct Footprints {
  std::vector<int64_t> rect_offset;  ///< P + 1 entries
  std::vector<Rgba> pixels;          ///< rect_offset[P] entries
};
/// rect_offset of m's rectangles (prefix sum of w * h).
std::vector<int64_t> rect_offsets(const Matching& m);
/// Scatters per-segment composites into the footprints. Throws
/// ArgumentError if a segment lies outside its PE's rectangle.
Footprints footprints_reference(const Matching& m, const std::vector<Rgba>& composites);

/// The intermediate image from per-segment composites: per pixel, the
/// non-empty segments of its ray in increasing k0, combined with over
/// (pixels without a segment are 0). width x height is the viewing grid.
Image composite_segments(const Matching& m, const std::vector<Rgba>& composites, int width,
                         int height);
/// Same, reading each segment's composite from the footprints.
Image composite_footprints(const Matching& m, const Footprints& f, int width, int height);

/// Owner of a voxel under a k-d split, separable per axis: the PE bits that
/// coordinate g of axis a contributes (owner = x[gx] | y[gy] | z[gz], as
/// KdSplit::owner). Also used to build the device's address tables.
struct OwnerTables {
  std::array<std::vector<int64_t>, 3> bits;   ///< per axis, dims[a] entries
  std::array<std::vector<int64_t>, 3> local;  ///< per axis: g - cell origin along a
};
OwnerTables owner_tables(const KdSplit& split);

/// X-Net reads of the resampling stage per PE: the stencil voxels (after
/// clamping) of the PE's samples whose owner is another PE.
struct XnetReads {
  std::vector<int64_t> reads;   ///< per PE: stencil reads from another PE's cell
  std::vector<int64_t> voxels;  ///< per PE: distinct remote voxels (what a halo exchange moves)
  int64_t total_reads() const;
  int64_t total_voxels() const;
  int64_t max_voxels() const;  ///< the SIMD step cost: the busiest PE
};
/// Counts for matching `m` of `view` under `split` (same PE count).
XnetReads xnet_reads(const Matching& m, const KdSplit& split, const ViewGeometry& view, int order);

}  // namespace simdvol
