// Serial references of the resample and local stages (local.hpp).
#include "simdvol/local.hpp"

#include <algorithm>
#include <string>

#include "over_inline.hpp"
#include "simdvol/composite.hpp"
#include "simdvol/error.hpp"
#include "simdvol/resample.hpp"

namespace simdvol {

namespace {

// (A view of another volume resampled its positions clamped.)
void check_view(const ViewGeometry& view, const Dims3& dims) {
  for (int a = 0; a < 3; ++a)
    if (view.grid.dims[a] != dims[a])
      throw ArgumentError("view", "was made for a volume of other dimensions");
}

void check_voxels(const std::vector<Rgba>& voxels, const Dims3& dims, int order) {
  if (order < 0 || order > kMaxOrder)
    throw ArgumentError("order", "interpolation order " + std::to_string(order) +
                                     " is outside 0.." + std::to_string(kMaxOrder));
  if (dims[0] < 1 || dims[1] < 1 || dims[2] < 1 ||
      static_cast<int64_t>(voxels.size()) != dims[0] * dims[1] * dims[2])
    throw ArgumentError("voxels", "count does not match the dimensions");
}

// Fixed-point position of sample k of segment s.
inline std::array<int64_t, 3> position(const ViewGeometry& view, const sv_segment& s, int64_t k) {
  return {view.fixed(0, s.i, s.j, k), view.fixed(1, s.i, s.j, k), view.fixed(2, s.i, s.j, k)};
}

}  // namespace

std::vector<int64_t> sample_offsets(const Matching& m) {
  std::vector<int64_t> off(m.segments.size() + 1, 0);
  for (std::size_t s = 0; s < m.segments.size(); ++s)
    off[s + 1] = off[s] + std::max<int64_t>(0, m.segments[s].k1 - m.segments[s].k0);
  return off;
}

std::vector<Rgba> resample_reference(const Matching& m, const std::vector<Rgba>& voxels,
                                     const Dims3& dims, const ViewGeometry& view, int order) {
  check_voxels(voxels, dims, order);
  check_view(view, dims);
  check_matching(m, view);
  const std::vector<int64_t> off = sample_offsets(m);
  std::vector<Rgba> out(static_cast<std::size_t>(off.back()));
  std::size_t n = 0;
  for (const sv_segment& s : m.segments)
    for (int64_t k = s.k0; k < s.k1; ++k)
      out[n++] = clamp_sample(resample_rgba(voxels, dims, position(view, s, k), order), order);
  return out;
}

std::vector<Rgba> local_reference(const Matching& m, const std::vector<Rgba>& voxels,
                                  const Dims3& dims, const ViewGeometry& view, int order) {
  check_voxels(voxels, dims, order);
  check_view(view, dims);
  check_matching(m, view);
  std::vector<Rgba> out(m.segments.size());
  std::vector<Rgba> samples;
  for (std::size_t n = 0; n < m.segments.size(); ++n) {
    const sv_segment& s = m.segments[n];
    samples.clear();
    for (int64_t k = s.k0; k < s.k1; ++k)
      samples.push_back(
          clamp_sample(resample_rgba(voxels, dims, position(view, s, k), order), order));
    out[n] = composite_direct(RaySamples{samples, s.k0});
  }
  return out;
}

std::vector<int64_t> rect_offsets(const Matching& m) {
  std::vector<int64_t> off(m.rects.size() + 1, 0);
  for (std::size_t p = 0; p < m.rects.size(); ++p)
    off[p + 1] = off[p] + static_cast<int64_t>(m.rects[p].w) * m.rects[p].h;
  return off;
}

Footprints footprints_reference(const Matching& m, const std::vector<Rgba>& composites) {
  check_matching(m);
  if (composites.size() != m.segments.size())
    throw ArgumentError("composites", "one per segment expected");
  Footprints f;
  f.rect_offset = rect_offsets(m);
  f.pixels.assign(static_cast<std::size_t>(f.rect_offset.back()), Rgba{});
  for (int64_t p = 0; p < m.pes(); ++p) {
    const sv_rect& r = m.rects[static_cast<std::size_t>(p)];
    for (int64_t n = m.seg_offset[static_cast<std::size_t>(p)];
         n < m.seg_offset[static_cast<std::size_t>(p + 1)]; ++n) {
      const sv_segment& s = m.segments[static_cast<std::size_t>(n)];
      if (s.i < r.i0 || s.j < r.j0 || s.i >= r.i0 + r.w || s.j >= r.j0 + r.h)
        throw ArgumentError("matching", "segment outside the footprint of PE " + std::to_string(p));
      f.pixels[static_cast<std::size_t>(f.rect_offset[static_cast<std::size_t>(p)] +
                                        int64_t(s.j - r.j0) * r.w + (s.i - r.i0))] =
          composites[static_cast<std::size_t>(n)];
    }
  }
  return f;
}

Image composite_segments(const Matching& m, const std::vector<Rgba>& composites, int width,
                         int height) {
  check_matching(m);
  if (composites.size() != m.segments.size())
    throw ArgumentError("composites", "one per segment expected");
  Image im(width, height);
  const std::size_t npx = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  // Counting sort of the non-empty segments by pixel, then by k0 per pixel.
  std::vector<int64_t> start(npx + 1, 0);
  for (const sv_segment& s : m.segments) {
    if (s.k1 <= s.k0) continue;
    if (s.i < 0 || s.j < 0 || s.i >= width || s.j >= height)
      throw ArgumentError("matching", "segment outside the image");
    ++start[static_cast<std::size_t>(s.j) * width + s.i + 1];
  }
  for (std::size_t q = 0; q < npx; ++q) start[q + 1] += start[q];
  std::vector<std::pair<int32_t, int64_t>> order(static_cast<std::size_t>(start[npx]));
  {
    std::vector<int64_t> fill(start.begin(), start.end() - 1);
    for (std::size_t n = 0; n < m.segments.size(); ++n) {
      const sv_segment& s = m.segments[n];
      if (s.k1 <= s.k0) continue;
      order[static_cast<std::size_t>(fill[static_cast<std::size_t>(s.j) * width + s.i]++)] = {
          s.k0, static_cast<int64_t>(n)};
    }
  }
  for (std::size_t q = 0; q < npx; ++q) {
    auto b = order.begin() + start[q], e = order.begin() + start[q + 1];
    std::sort(b, e);
    Rgba acc{};
    for (auto it = b; it != e; ++it)
      acc = detail::over_inline(acc, composites[static_cast<std::size_t>(it->second)]);
    im.pixels()[q] = acc;
  }
  return im;
}

Image composite_footprints(const Matching& m, const Footprints& f, int width, int height) {
  check_matching(m);
  if (f.rect_offset.size() != m.rects.size() + 1 ||
      static_cast<int64_t>(f.pixels.size()) != f.rect_offset.back())
    throw ArgumentError("footprints", "do not match the matching's rectangles");
  std::vector<Rgba> comp(m.segments.size());
  for (int64_t p = 0; p < m.pes(); ++p) {
    const sv_rect& r = m.rects[static_cast<std::size_t>(p)];
    for (int64_t n = m.seg_offset[static_cast<std::size_t>(p)];
         n < m.seg_offset[static_cast<std::size_t>(p + 1)]; ++n) {
      const sv_segment& s = m.segments[static_cast<std::size_t>(n)];
      if (s.i < r.i0 || s.j < r.j0 || s.i >= r.i0 + r.w || s.j >= r.j0 + r.h)
        throw ArgumentError("matching", "segment outside the footprint of PE " + std::to_string(p));
      comp[static_cast<std::size_t>(n)] = f.pixels[static_cast<std::size_t>(
          f.rect_offset[static_cast<std::size_t>(p)] + int64_t(s.j - r.j0) * r.w + (s.i - r.i0))];
    }
  }
  return composite_segments(m, comp, width, height);
}

OwnerTables owner_tables(const KdSplit& split) {
  if (static_cast<int>(split.bit_axis.size()) != split.bits)
    throw ArgumentError("split", "bit_axis does not have one entry per PE bit");
  OwnerTables t;
  for (int a = 0; a < 3; ++a) {
    if (split.cell[a] < 1 || split.dims[a] < 1)
      throw ArgumentError("split", "cell extent and dims must be positive");
    // PE bits of axis a, from the lowest PE bit: the lowest is the finest split
    // and carries the lowest bit of the cell index (KdSplit::pe_of_cell).
    std::vector<int> pe_bits;
    for (int b = 0; b < split.bits; ++b)
      if (split.bit_axis[static_cast<std::size_t>(b)] == a) pe_bits.push_back(b);
    t.bits[a].resize(static_cast<std::size_t>(split.dims[a]));
    t.local[a].resize(static_cast<std::size_t>(split.dims[a]));
    for (int64_t g = 0; g < split.dims[a]; ++g) {
      const int64_t index = g / split.cell[a];
      int64_t pe = 0;
      for (std::size_t r = 0; r < pe_bits.size(); ++r) pe |= ((index >> r) & 1) << pe_bits[r];
      t.bits[a][static_cast<std::size_t>(g)] = pe;
      t.local[a][static_cast<std::size_t>(g)] = g - index * split.cell[a];
    }
  }
  return t;
}

int64_t XnetReads::total_reads() const {
  int64_t s = 0;
  for (int64_t r : reads) s += r;
  return s;
}
int64_t XnetReads::total_voxels() const {
  int64_t s = 0;
  for (int64_t r : voxels) s += r;
  return s;
}
int64_t XnetReads::max_voxels() const {
  int64_t s = 0;
  for (int64_t r : voxels) s = std::max(s, r);
  return s;
}

XnetReads xnet_reads(const Matching& m, const KdSplit& split, const ViewGeometry& view, int order) {
  check_matching(m, view);
  if (order < 0 || order > kMaxOrder)
    throw ArgumentError("order", "interpolation order " + std::to_string(order) +
                                     " is outside 0.." + std::to_string(kMaxOrder));
  if (split.pes() != m.pes()) throw ArgumentError("split", "PE count differs from the matching's");
  const OwnerTables t = owner_tables(split);
  const Dims3& n = split.dims;
  XnetReads x;
  x.reads.assign(static_cast<std::size_t>(m.pes()), 0);
  x.voxels.assign(static_cast<std::size_t>(m.pes()), 0);
  std::vector<int64_t> remote;
  const int M = order + 1;
  for (int64_t p = 0; p < m.pes(); ++p) {
    remote.clear();
    int64_t reads = 0;
    for (int64_t q = m.seg_offset[static_cast<std::size_t>(p)];
         q < m.seg_offset[static_cast<std::size_t>(p + 1)]; ++q) {
      const sv_segment& s = m.segments[static_cast<std::size_t>(q)];
      for (int64_t k = s.k0; k < s.k1; ++k) {
        int64_t idx[3][kMaxOrder + 1];
        for (int a = 0; a < 3; ++a) {
          const int64_t fx = view.fixed(a, s.i, s.j, k);
          const auto st = aitken_stencil(fixed_floor(fx), fixed_frac(fx), order);
          for (int e = 0; e < M; ++e) idx[a][e] = std::clamp<int64_t>(st[e], 0, n[a] - 1);
        }
        for (int c = 0; c < M; ++c)
          for (int b = 0; b < M; ++b)
            for (int a = 0; a < M; ++a) {
              const auto gx = static_cast<std::size_t>(idx[0][a]);
              const auto gy = static_cast<std::size_t>(idx[1][b]);
              const auto gz = static_cast<std::size_t>(idx[2][c]);
              if ((t.bits[0][gx] | t.bits[1][gy] | t.bits[2][gz]) == p) continue;
              ++reads;
              remote.push_back((idx[2][c] * n[1] + idx[1][b]) * n[0] + idx[0][a]);
            }
      }
    }
    std::sort(remote.begin(), remote.end());
    x.reads[static_cast<std::size_t>(p)] = reads;
    x.voxels[static_cast<std::size_t>(p)] =
        std::unique(remote.begin(), remote.end()) - remote.begin();
  }
  return x;
}

}  // namespace simdvol
