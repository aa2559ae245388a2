// The references of the resample and local stages (local.hpp): sub-ray
// composites combined in depth order equal the serial renderer's pixels, the
// samples are resample_rgba's, footprints round-trip, and the X-Net read
// counts agree with an independent count through KdSplit's documented
// pe_of_cell. The matchings here are built by brute force (every sample's
// owner), independently of match_reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

#include "simdvol/error.hpp"
#include "simdvol/local.hpp"
#include "simdvol/render.hpp"
#include "simdvol/resample.hpp"

using namespace simdvol;

namespace {

// The greedy k-d split of pe_array.hpp (kd_split lives in simdvol_cl).
KdSplit split_of(const Dims3& dims, int bits) {
  KdSplit s;
  s.dims = dims;
  s.bits = bits;
  s.bit_axis.assign(static_cast<std::size_t>(bits), 0);
  for (int i = 0; i < bits; ++i) {
    int best = 0;
    int64_t best_extent = -1;
    for (int a = 0; a < 3; ++a) {
      const int64_t e = (dims[a] + (int64_t(1) << s.axis_bits[a]) - 1) >> s.axis_bits[a];
      if (e > best_extent) best = a, best_extent = e;
    }
    s.bit_axis[static_cast<std::size_t>(bits - 1 - i)] = best;
    ++s.axis_bits[best];
  }
  for (int a = 0; a < 3; ++a)
    s.cell[a] = (dims[a] + (int64_t(1) << s.axis_bits[a]) - 1) >> s.axis_bits[a];
  return s;
}

// pe_of_cell exactly as documented in pe_array.hpp (highest PE bit first).
int64_t pe_of_cell(const KdSplit& s, const Dims3& index) {
  std::array<int, 3> remaining = s.axis_bits;
  int64_t pe = 0;
  for (int b = s.bits - 1; b >= 0; --b) {
    const int a = s.bit_axis[static_cast<std::size_t>(b)];
    --remaining[a];
    pe |= ((index[a] >> remaining[a]) & 1) << b;
  }
  return pe;
}
int64_t owner(const KdSplit& s, const Dims3& v) {
  return pe_of_cell(s, {v[0] / s.cell[0], v[1] / s.cell[1], v[2] / s.cell[2]});
}

// Brute-force matching: every in-volume sample to the owner of floor(X).
Matching brute_matching(const ViewGeometry& view, const KdSplit& split) {
  const int64_t P = split.pes();
  std::vector<std::vector<sv_segment>> per(static_cast<std::size_t>(P));
  for (int j = 0; j < view.height(); ++j)
    for (int i = 0; i < view.width(); ++i) {
      const auto [k0, k1] = view.ray_range(i, j);
      int64_t cur = -1;
      for (int64_t k = k0; k < k1; ++k) {
        const Dims3 v{fixed_floor(view.fixed(0, i, j, k)), fixed_floor(view.fixed(1, i, j, k)),
                      fixed_floor(view.fixed(2, i, j, k))};
        const int64_t p = owner(split, v);
        if (p != cur) {
          per[static_cast<std::size_t>(p)].push_back(
              {i, j, static_cast<sv_i32>(k), static_cast<sv_i32>(k + 1)});
          cur = p;
        } else {
          ++per[static_cast<std::size_t>(p)].back().k1;
        }
      }
    }
  Matching m;
  m.seg_offset.push_back(0);
  for (int64_t p = 0; p < P; ++p) {
    auto& v = per[static_cast<std::size_t>(p)];
    std::sort(v.begin(), v.end(), [](const sv_segment& a, const sv_segment& b) {
      return a.j != b.j ? a.j < b.j : a.i < b.i;
    });
    sv_rect r{0, 0, 0, 0};
    int64_t load = 0;
    if (!v.empty()) {
      int i0 = v[0].i, i1 = v[0].i, j0 = v[0].j, j1 = v[0].j;
      for (const auto& s : v) {
        i0 = std::min(i0, s.i), i1 = std::max(i1, s.i), j0 = std::min(j0, s.j),
        j1 = std::max(j1, s.j);
        load += s.k1 - s.k0;
      }
      r = {i0, j0, i1 - i0 + 1, j1 - j0 + 1};
    }
    m.segments.insert(m.segments.end(), v.begin(), v.end());
    m.seg_offset.push_back(static_cast<int64_t>(m.segments.size()));
    m.rects.push_back(r);
    m.loads.push_back(load);
  }
  return m;
}

// Moves every boundary between consecutive segments of a ray to a random
// place between them (as balancing does, more freely); segments may become
// empty.
void perturb(Matching& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::map<std::pair<int, int>, std::vector<sv_segment*>> rays;
  for (auto& s : m.segments) rays[{s.j, s.i}].push_back(&s);
  for (auto& [key, segs] : rays) {
    std::sort(segs.begin(), segs.end(),
              [](const sv_segment* a, const sv_segment* b) { return a->k0 < b->k0; });
    for (std::size_t t = 0; t + 1 < segs.size(); ++t) {
      std::uniform_int_distribution<int> u(segs[t]->k0, segs[t + 1]->k1);
      const int b = u(rng);
      segs[t]->k1 = b;
      segs[t + 1]->k0 = b;
    }
  }
  std::fill(m.loads.begin(), m.loads.end(), 0);
  for (int64_t p = 0; p < m.pes(); ++p)
    for (int64_t n = m.seg_offset[p]; n < m.seg_offset[p + 1]; ++n)
      m.loads[p] += m.segments[n].k1 - m.segments[n].k0;
}

std::vector<Rgba> random_voxels(const Dims3& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Rgba> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  for (Rgba& x : v) {
    // Mostly thin material so that rays do not saturate.
    x.a = u(rng) * 0.2f;
    x.r = x.a * u(rng);
    x.g = x.a * u(rng);
    x.b = x.a * u(rng);
  }
  return v;
}

struct Case {
  ViewAngles angles;
  Sampling sampling;
};
const Case kCases[] = {{{0, 0, 0}, Sampling::voxel},
                       {{0, 30, 0}, Sampling::voxel},
                       {{45, 45, 0}, Sampling::pixel},
                       {{17.3, -61.2, 104.9}, Sampling::voxel}};

}  // namespace

TEST(LocalReference, SubRaysCompositeToTheSerialRenderer) {
  const Dims3 dims{21, 17, 13};
  const Volume vol(dims, VoxelType::f32);
  const std::vector<Rgba> voxels = random_voxels(dims, 5);
  int checked = 0;
  for (const Case& c : kCases) {
    const ViewGeometry view = make_view(vol, c.angles, 40, 36, c.sampling);
    for (int order = 0; order <= 3; ++order) {
      RenderOptions opt;
      opt.width = 40, opt.height = 36, opt.sampling = c.sampling, opt.view = c.angles;
      opt.order = order;
      Image ref;
      render_classified(voxels, vol, view, opt, nullptr, &ref);
      for (int bits : {0, 3, 6, 8}) {
        const KdSplit split = split_of(dims, bits);
        for (int perturbed = 0; perturbed < 2; ++perturbed) {
          Matching m = brute_matching(view, split);
          if (perturbed) perturb(m, 11u * bits + order);
          const std::vector<Rgba> sub = local_reference(m, voxels, dims, view, order);
          const Image im = composite_segments(m, sub, view.width(), view.height());
          ASSERT_EQ(im.width(), ref.width());
          EXPECT_LE(max_abs_diff(im, ref), 1e-5f)
              << "order " << order << " bits " << bits << " perturbed " << perturbed;
          // Footprints hold the same composites.
          const Footprints f = footprints_reference(m, sub);
          EXPECT_EQ(f.rect_offset.back(), rect_offsets(m).back());
          const Image im2 = composite_footprints(m, f, view.width(), view.height());
          EXPECT_EQ(max_abs_diff(im, im2), 0.0f);
          ++checked;
        }
      }
    }
  }
  EXPECT_EQ(checked, 4 * 4 * 4 * 2);
}

TEST(LocalReference, SamplesAreResampleRgbaInSegmentOrder) {
  const Dims3 dims{15, 11, 9};
  const Volume vol(dims, VoxelType::f32);
  const std::vector<Rgba> voxels = random_voxels(dims, 9);
  const ViewGeometry view = make_view(vol, {20, 35, 10}, 24, 24, Sampling::voxel);
  Matching m = brute_matching(view, split_of(dims, 5));
  perturb(m, 3);
  for (int order = 0; order <= 3; ++order) {
    const std::vector<Rgba> s = resample_reference(m, voxels, dims, view, order);
    const std::vector<int64_t> off = sample_offsets(m);
    ASSERT_EQ(static_cast<int64_t>(s.size()), off.back());
    int64_t total = 0;
    for (int64_t l : m.loads) total += l;
    EXPECT_EQ(off.back(), total);
    for (std::size_t n = 0; n < m.segments.size(); ++n) {
      const sv_segment& g = m.segments[n];
      for (int k = g.k0; k < g.k1; ++k) {
        // (clamped to valid opacities at orders >= 2 before compositing)
        const Rgba e =
            clamp_sample(resample_rgba(voxels, dims,
                                       {view.fixed(0, g.i, g.j, k), view.fixed(1, g.i, g.j, k),
                                        view.fixed(2, g.i, g.j, k)},
                                       order),
                         order);
        const Rgba& a = s[static_cast<std::size_t>(off[n] + (k - g.k0))];
        ASSERT_EQ(a.r, e.r);
        ASSERT_EQ(a.g, e.g);
        ASSERT_EQ(a.b, e.b);
        ASSERT_EQ(a.a, e.a);
      }
    }
  }
}

TEST(LocalReference, OwnerTablesMatchPeOfCell) {
  for (const Dims3 dims : {Dims3{93, 57, 31}, Dims3{256, 256, 256}, Dims3{5, 3, 1}})
    for (int bits : {0, 1, 4, 7, 13}) {
      const KdSplit s = split_of(dims, bits);
      const OwnerTables t = owner_tables(s);
      for (int64_t z = 0; z < dims[2]; z += 3)
        for (int64_t y = 0; y < dims[1]; y += 2)
          for (int64_t x = 0; x < dims[0]; ++x) {
            const Dims3 v{x, y, z};
            ASSERT_EQ(t.bits[0][x] | t.bits[1][y] | t.bits[2][z], owner(s, v));
            for (int a = 0; a < 3; ++a) ASSERT_EQ(t.local[a][v[a]], v[a] % s.cell[a]);
          }
    }
}

TEST(LocalReference, XnetReadsAgreeWithAnIndependentCount) {
  const Dims3 dims{19, 14, 11};
  const Volume vol(dims, VoxelType::f32);
  const ViewGeometry view = make_view(vol, {10, 40, 25}, 30, 30, Sampling::voxel);
  const KdSplit split = split_of(dims, 6);
  for (int perturbed = 0; perturbed < 2; ++perturbed) {
    Matching m = brute_matching(view, split);
    if (perturbed) perturb(m, 77);
    for (int order = 0; order <= 3; ++order) {
      const XnetReads x = xnet_reads(m, split, view, order);
      ASSERT_EQ(x.reads.size(), 64u);
      int64_t all_reads = 0;
      for (int64_t p = 0; p < m.pes(); ++p) {
        int64_t reads = 0;
        std::set<std::array<int64_t, 3>> distinct;
        for (int64_t n = m.seg_offset[p]; n < m.seg_offset[p + 1]; ++n) {
          const sv_segment& g = m.segments[n];
          for (int k = g.k0; k < g.k1; ++k) {
            std::array<std::array<int64_t, 4>, 3> st;
            for (int a = 0; a < 3; ++a) {
              const int64_t f = view.fixed(a, g.i, g.j, k);
              st[a] = aitken_stencil(fixed_floor(f), fixed_frac(f), order);
              for (int e = 0; e <= order; ++e)
                st[a][e] = std::clamp<int64_t>(st[a][e], 0, dims[a] - 1);
            }
            for (int c = 0; c <= order; ++c)
              for (int b = 0; b <= order; ++b)
                for (int a = 0; a <= order; ++a) {
                  const Dims3 v{st[0][a], st[1][b], st[2][c]};
                  if (owner(split, v) != p) {
                    ++reads;
                    distinct.insert(v);
                  }
                }
          }
        }
        EXPECT_EQ(x.reads[p], reads) << "PE " << p;
        EXPECT_EQ(x.voxels[p], static_cast<int64_t>(distinct.size())) << "PE " << p;
        all_reads += reads;
        EXPECT_LE(x.reads[p], m.loads[p] * (order + 1) * (order + 1) * (order + 1));
      }
      EXPECT_EQ(x.total_reads(), all_reads);
      // Higher orders reach further: linear and above read across cell faces.
      if (order >= 1) {
        EXPECT_GT(all_reads, 0);
      }
    }
  }
  // One PE: nothing is remote.
  const KdSplit one = split_of(dims, 0);
  const XnetReads x1 = xnet_reads(brute_matching(view, one), one, view, 3);
  EXPECT_EQ(x1.total_reads(), 0);
}

TEST(LocalReference, RejectsBadArguments) {
  const Dims3 dims{8, 8, 8};
  const Volume vol(dims, VoxelType::f32);
  const ViewGeometry view = make_view(vol, {}, 8, 8, Sampling::voxel);
  const KdSplit split = split_of(dims, 2);
  Matching m = brute_matching(view, split);
  const std::vector<Rgba> voxels = random_voxels(dims, 1);
  EXPECT_THROW(local_reference(m, voxels, dims, view, 4), ArgumentError);
  EXPECT_THROW(local_reference(m, voxels, {8, 8, 7}, view, 1), ArgumentError);
  Matching bad = m;
  bad.segments[0].k1 = view.depth() + 1;
  EXPECT_THROW(resample_reference(bad, voxels, dims, view, 1), ArgumentError);
  bad = m;
  bad.seg_offset[1] = bad.seg_offset[2] + 1;
  EXPECT_THROW(local_reference(bad, voxels, dims, view, 1), ArgumentError);
  EXPECT_THROW(footprints_reference(m, {}), ArgumentError);
  EXPECT_THROW(xnet_reads(m, split_of(dims, 3), view, 1), ArgumentError);
  // A view made for another volume resampled its positions clamped.
  const ViewGeometry other =
      make_view(Volume({8, 8, 16}, VoxelType::f32), {}, 8, 8, Sampling::voxel);
  const Matching mo = brute_matching(other, split_of({8, 8, 16}, 2));
  EXPECT_THROW(resample_reference(mo, voxels, dims, other, 1), ArgumentError);
  EXPECT_THROW(local_reference(mo, voxels, dims, other, 1), ArgumentError);
}
