// The PE array model (PE grid spec, mesh, k-d split, cell layout, halo cost)
// and the layout/gather kernels against the serial reference, bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <random>
#include <set>

#include "simdvol/layout.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {
namespace {

#define SIMDVOL_REQUIRE_OPENCL()                          \
  do {                                                    \
    try {                                                 \
      list_devices();                                     \
    } catch (const NoDeviceError& e) {                    \
      GTEST_SKIP() << "no OpenCL platform: " << e.what(); \
    }                                                     \
  } while (0)

// ---------------------------------------------------------------- PE grid

TEST(PeGrid, ParsesCountsAndGrids) {
  PeGrid d;
  EXPECT_EQ(d.width, 128);
  EXPECT_EQ(d.height, 64);
  EXPECT_EQ(d.bits(), 13);
  auto g = parse_pe_grid("8192");
  EXPECT_EQ(g.width, 128);
  EXPECT_EQ(g.height, 64);
  g = parse_pe_grid("128x64");
  EXPECT_EQ(g.width, 128);
  EXPECT_EQ(g.height, 64);
  g = parse_pe_grid("64X128");
  EXPECT_EQ(g.width, 64);
  EXPECT_EQ(g.height, 128);
  g = parse_pe_grid("1");
  EXPECT_EQ(g.width, 1);
  EXPECT_EQ(g.height, 1);
  g = parse_pe_grid("2");
  EXPECT_EQ(g.width, 2);
  EXPECT_EQ(g.height, 1);
  g = parse_pe_grid("1024");
  EXPECT_EQ(g.width, 32);
  EXPECT_EQ(g.height, 32);
  g = parse_pe_grid("16384");
  EXPECT_EQ(g.width, 128);
  EXPECT_EQ(g.height, 128);
  g = parse_pe_grid("256x1");
  EXPECT_EQ(g.count(), 256);
  for (const char* bad : {"", "0", "100", "-4", "12a", "x", "3x5", "0x8", "8x", "x8", "1x3",
                          "2097152", "4096x4096"}) {
    try {
      parse_pe_grid(bad, "--pes");
      ADD_FAILURE() << "accepted \"" << bad << "\"";
    } catch (const ArgumentError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("--pes: ", 0), 0u) << e.what();
    }
  }
}

TEST(PeGrid, MeshCoordinatesAndChebyshevDistance) {
  PeGrid g{128, 64};
  EXPECT_EQ(mesh_coord(g, 0).x, 0);
  EXPECT_EQ(mesh_coord(g, 129).x, 1);
  EXPECT_EQ(mesh_coord(g, 129).y, 1);
  EXPECT_EQ(mesh_coord(g, 8191).x, 127);
  EXPECT_EQ(mesh_coord(g, 8191).y, 63);
  EXPECT_EQ(mesh_distance(g, 0, 129), 1);          // diagonal X-Net link
  EXPECT_EQ(mesh_distance(g, 0, 3 + 2 * 128), 3);  // max(3, 2)
  EXPECT_EQ(mesh_distance(g, 8191, 0), 127);
  EXPECT_EQ(mesh_distance(g, 5, 5), 0);
}

// ---------------------------------------------------------------- k-d split

TEST(KdSplit, GreedyHalvingOfTheLargestExtent) {
  // 256^3 over 8192: x, y, z, x, y, z, ... with x getting the 13th split.
  KdSplit s = kd_split({256, 256, 256}, 8192);
  EXPECT_EQ(s.bits, 13);
  EXPECT_EQ(s.axis_bits, (std::array<int, 3>{5, 4, 4}));
  EXPECT_EQ(s.cell, (Dims3{8, 16, 16}));
  EXPECT_EQ(s.bit_axis[12], 0);  // the first, coarsest split is along x
  EXPECT_EQ(s.bit_axis[11], 1);
  EXPECT_EQ(s.bit_axis[10], 2);
  EXPECT_EQ(s.bit_axis[0], 0);
  // 93x57x31 over 8: 93 -> x (47), 57 -> y (29), 47 -> x (24).
  s = kd_split({93, 57, 31}, 8);
  EXPECT_EQ(s.bit_axis, (std::vector<int>{0, 1, 0}));
  EXPECT_EQ(s.cell, (Dims3{24, 29, 31}));
  // Ties go to x, then y, then z.
  s = kd_split({4, 4, 4}, 4);
  EXPECT_EQ(s.bit_axis, (std::vector<int>{1, 0}));
  s = kd_split({3, 4, 4}, 2);
  EXPECT_EQ(s.bit_axis, (std::vector<int>{1}));
  // Dims smaller than the split count: cells of extent 1 and cells wholly
  // outside the volume.
  s = kd_split({5, 3, 2}, 64);
  EXPECT_EQ(s.cell, (Dims3{1, 1, 1}));
  EXPECT_EQ(s.splits()[0] * s.splits()[1] * s.splits()[2], 64);
  s = kd_split({7, 7, 7}, 1);
  EXPECT_EQ(s.cell, (Dims3{7, 7, 7}));
  EXPECT_TRUE(s.bit_axis.empty());
  EXPECT_THROW(kd_split({0, 5, 5}, 8), ArgumentError);
  EXPECT_THROW(kd_split({5, 5, 5}, 12), ArgumentError);
}

TEST(KdSplit, CellIndexIsABijectionAndCellsTileTheVolume) {
  for (Dims3 dims : {Dims3{93, 57, 31}, Dims3{5, 3, 2}, Dims3{17, 1, 9}}) {
    for (int64_t pes = 1; pes <= 4096; pes *= 4) {
      KdSplit s = kd_split(dims, pes);
      std::set<Dims3> seen;
      for (int64_t p = 0; p < pes; ++p) {
        Dims3 idx = s.cell_index(p);
        for (int a = 0; a < 3; ++a) ASSERT_LT(idx[a], s.splits()[a]);
        ASSERT_EQ(s.pe_of_cell(idx), p);
        seen.insert(idx);
      }
      ASSERT_EQ(static_cast<int64_t>(seen.size()), pes);
      // Every voxel's owner holds it in its cell.
      for (int64_t z = 0; z < dims[2]; ++z)
        for (int64_t y = 0; y < dims[1]; ++y)
          for (int64_t x = 0; x < dims[0]; ++x) {
            Dims3 o = s.cell_origin(s.owner({x, y, z}));
            Dims3 v{x, y, z};
            for (int a = 0; a < 3; ++a) {
              ASSERT_GE(v[a], o[a]);
              ASSERT_LT(v[a], o[a] + s.cell[a]);
            }
          }
    }
  }
}

// kd_region against the explicit union of the member cells.
TEST(KdSplit, RegionIsTheUnionOfMergedCells) {
  for (Dims3 dims : {Dims3{93, 57, 31}, Dims3{5, 3, 2}}) {
    for (int64_t pes : {1, 2, 8, 64, 256}) {
      KdSplit s = kd_split(dims, pes);
      for (int64_t p = 0; p < pes; ++p)
        for (int level = 0; level <= s.bits; ++level) {
          Box u{{INT64_MAX, INT64_MAX, INT64_MAX}, {INT64_MIN, INT64_MIN, INT64_MIN}};
          const int64_t members = int64_t(1) << level;
          const int64_t first = (p >> level) << level;
          for (int64_t q = first; q < first + members; ++q) {
            Dims3 o = s.cell_origin(q);
            for (int a = 0; a < 3; ++a) {
              u.lo[a] = std::min(u.lo[a], o[a]);
              u.hi[a] = std::max(u.hi[a], o[a] + s.cell[a]);
            }
          }
          // The member cells fill the bounding box exactly (no gaps): volumes agree.
          int64_t box_volume = 1, cell_volume = s.cell[0] * s.cell[1] * s.cell[2];
          for (int a = 0; a < 3; ++a) box_volume *= u.hi[a] - u.lo[a];
          ASSERT_EQ(box_volume, members * cell_volume);
          ASSERT_EQ(kd_region(s, p, level), u) << "p " << p << " level " << level;
        }
    }
  }
}

// Binary swap stage k pairs p with p ^ 2^k: after merging the lower bits, the
// two regions are adjacent slabs split by a plane normal to bit k's axis, and
// the PE with bit k = 0 has the lower side.
TEST(KdSplit, SwapPartnersHoldAdjacentSlabs) {
  for (Dims3 dims : {Dims3{256, 256, 256}, Dims3{93, 57, 31}, Dims3{5, 3, 2}}) {
    for (int64_t pes : {2, 64, 8192}) {
      KdSplit s = kd_split(dims, pes);
      for (int64_t p = 0; p < pes; ++p)
        for (int k = 0; k < s.bits; ++k) {
          const int64_t q = p ^ (int64_t(1) << k);
          const int axis = s.bit_axis[k];
          Box a = kd_region(s, p, k), b = kd_region(s, q, k);
          for (int d = 0; d < 3; ++d) {
            if (d == axis) continue;
            ASSERT_EQ(a.lo[d], b.lo[d]);
            ASSERT_EQ(a.hi[d], b.hi[d]);
          }
          const bool low = ((p >> k) & 1) == 0;
          const Box& lower = low ? a : b;
          const Box& upper = low ? b : a;
          ASSERT_EQ(lower.hi[axis], upper.lo[axis]) << "p " << p << " k " << k;
          ASSERT_EQ(lower.hi[axis] - lower.lo[axis], upper.hi[axis] - upper.lo[axis]);
          // Together they are the region of the next stage.
          Box merged = kd_region(s, p, k + 1);
          ASSERT_EQ(merged.lo[axis], lower.lo[axis]);
          ASSERT_EQ(merged.hi[axis], upper.hi[axis]);
        }
    }
  }
}

// ---------------------------------------------------------------- layout

TEST(CellLayout, GeometryAndIndexing) {
  CellLayout L = make_cell_layout({256, 256, 256}, 8192, 1);
  EXPECT_EQ(L.block, (Dims3{10, 18, 18}));
  EXPECT_EQ(L.cell_stride, 3248);  // 3240 rounded up to 16
  EXPECT_EQ(L.elements(), 8192 * 3248);
  EXPECT_EQ(L.index(0, -1, -1, -1), 0);
  EXPECT_EQ(L.index(1, -1, -1, -1), 3248);
  EXPECT_EQ(L.index(2, 0, 0, 0), 2 * 3248 + (1 * 18 + 1) * 10 + 1);
  EXPECT_EQ(L.index(0, 8, 16, 16), 3239);
  for (int h = 0; h <= 2; ++h)
    for (int64_t pes = 1; pes <= 8192; pes *= 2) {
      CellLayout M = make_cell_layout({93, 57, 31}, pes, h);
      EXPECT_EQ(M.cell_stride % 16, 0);
      EXPECT_GE(M.cell_stride, M.block[0] * M.block[1] * M.block[2]);
      EXPECT_LT(M.cell_stride, M.block[0] * M.block[1] * M.block[2] + 16);
    }
  EXPECT_THROW(make_cell_layout({8, 8, 8}, 8, -1), ArgumentError);
  EXPECT_THROW(make_cell_layout({8, 8, 8}, 8, 9), ArgumentError);
  EXPECT_THROW(make_cell_layout({8, 8, 8}, 6, 1), ArgumentError);
}

TEST(CellLayout, AllocationCheckRefusesOversizedBuffers) {
  EXPECT_NO_THROW(check_allocation(1000, 1000, "volume"));
  try {
    check_allocation(1001, 1000, "volume");
    FAIL() << "expected ArgumentError";
  } catch (const ArgumentError& e) {
    std::string m = e.what();
    EXPECT_EQ(m.rfind("volume: ", 0), 0u) << m;
    EXPECT_NE(m.find("1001"), std::string::npos) << m;
    EXPECT_NE(m.find("CL_DEVICE_MAX_MEM_ALLOC_SIZE"), std::string::npos) << m;
    // No advice that the caller did not give: a buffer of another kind
    // (an image) must not be told to use a smaller volume.
    EXPECT_EQ(m.find("smaller"), std::string::npos) << m;
    EXPECT_EQ(m.back(), ')') << m;
  }
  try {
    check_allocation(1001, 1000, "output image", "use a smaller --size");
    FAIL() << "expected ArgumentError";
  } catch (const ArgumentError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("output image: ", 0), 0u) << m;
    const std::string tail = "(CL_DEVICE_MAX_MEM_ALLOC_SIZE): use a smaller --size";
    ASSERT_GE(m.size(), tail.size()) << m;
    EXPECT_EQ(m.substr(m.size() - tail.size()), tail) << m;
  }
  EXPECT_THROW(check_allocation(0, 1000, "volume"), ArgumentError);
  // A 2048^3 layout with 8192 PEs: 32 GiB of floats, more than a fake 4 GiB limit.
  CellLayout L = make_cell_layout({2048, 2048, 2048}, 8192, 1);
  EXPECT_THROW(check_allocation(L.bytes(), uint64_t(4) << 30, "volume"), ArgumentError);
}

// Values with distinct bit patterns (denormals and negative zero included) so
// that any misplaced or converted copy shows.
std::vector<float> bit_pattern_volume(const Dims3& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<float> v(static_cast<std::size_t>(d[0] * d[1] * d[2]));
  for (auto& x : v) {
    uint32_t bits;
    do bits = static_cast<uint32_t>(rng());
    while (((bits >> 23) & 0xff) == 0xff);  // no inf / NaN
    std::memcpy(&x, &bits, sizeof x);
  }
  if (v.size() > 2) {
    v[0] = -0.0f;
    uint32_t denormal = 0x00000123u;
    std::memcpy(&v[1], &denormal, sizeof denormal);
  }
  return v;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

std::size_t first_difference(const std::vector<float>& a, const std::vector<float>& b) {
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0) return i;
  return std::min(a.size(), b.size());
}

TEST(CellLayout, ReferenceHaloHoldsClampedNeighbours) {
  Volume vol({93, 57, 31}, VoxelType::f32);
  for (std::size_t i = 0; i < vol.voxel_count(); ++i) vol.data()[i] = static_cast<float>(i);
  for (int h : {1, 2}) {
    CellLayout L = make_cell_layout(vol.dims(), 64, h);
    auto cells = layout_reference(vol.data(), L);
    for (int64_t pe : {int64_t(0), int64_t(1), int64_t(27), int64_t(63)}) {
      Dims3 o = L.split.cell_origin(pe);
      for (int64_t lz = -h; lz < L.cell()[2] + h; ++lz)
        for (int64_t ly = -h; ly < L.cell()[1] + h; ++ly)
          for (int64_t lx = -h; lx < L.cell()[0] + h; ++lx)
            ASSERT_EQ(cells[L.index(pe, lx, ly, lz)],
                      vol.at_clamped(o[0] + lx, o[1] + ly, o[2] + lz))
                << "pe " << pe << " at " << lx << "," << ly << "," << lz;
    }
    EXPECT_TRUE(same_bits(gather_reference(cells, L), vol.data()));
  }
}

class LayoutDevice : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    try {
      device_ = new Device();
    } catch (const NoDeviceError&) {
      device_ = nullptr;
    }
  }
  static void TearDownTestSuite() {
    delete device_;
    device_ = nullptr;
  }
  void SetUp() override {
    if (!device_) GTEST_SKIP() << "no OpenCL platform";
  }
  static Device* device_;
};
Device* LayoutDevice::device_ = nullptr;

// Every P = 1 .. 8192 and halo 1, 2: the kernel's buffer equals the
// reference bit for bit, and gather restores the volume bit for bit.
TEST_F(LayoutDevice, RoundTripIsExactForEveryPeCount) {
  const Dims3 dims{93, 57, 31};
  const auto vol = bit_pattern_volume(dims, 1);
  for (int h : {1, 2}) {
    for (int64_t pes = 1; pes <= 8192; pes *= 2) {
      SCOPED_TRACE("P " + std::to_string(pes) + " halo " + std::to_string(h));
      PeArray array(*device_, pe_grid(pes));
      CellBuffer cells = array.layout(vol.data(), dims, h);
      auto got = cells.read(*device_);
      auto want = layout_reference(vol, cells.layout());
      ASSERT_TRUE(same_bits(got, want)) << "first difference at " << first_difference(got, want);
      auto back = array.gather(cells);
      ASSERT_TRUE(same_bits(back, vol)) << "first difference at " << first_difference(back, vol);
    }
  }
}

// The per-element variants of both kernels give the same bits.
TEST_F(LayoutDevice, VoxelVariantsAgree) {
  const Dims3 dims{93, 57, 31};
  const auto vol = bit_pattern_volume(dims, 2);
  for (int64_t pes : {1, 8, 512, 8192}) {
    SCOPED_TRACE("P " + std::to_string(pes));
    PeArray array(*device_, pe_grid(pes));
    CellBuffer cells = array.layout(vol.data(), dims, 2, LayoutKernel::voxel);
    ASSERT_TRUE(same_bits(cells.read(*device_), layout_reference(vol, cells.layout())));
    ASSERT_TRUE(same_bits(array.gather(cells, LayoutKernel::voxel), vol));
  }
}

// Dims smaller than the split count: cells of extent 1, many pad cells.
TEST_F(LayoutDevice, TinyVolumeWithMorePesThanVoxels) {
  for (Dims3 dims : {Dims3{5, 3, 2}, Dims3{1, 1, 1}, Dims3{1, 7, 1}}) {
    const auto vol = bit_pattern_volume(dims, 3);
    for (int64_t pes : {64, 8192}) {
      for (int h : {1, 2}) {
        PeArray array(*device_, pe_grid(pes));
        CellBuffer cells = array.layout(vol.data(), dims, h);
        EXPECT_EQ(cells.layout().cell(), (Dims3{1, 1, 1}));
        ASSERT_TRUE(same_bits(cells.read(*device_), layout_reference(vol, cells.layout())));
        ASSERT_TRUE(same_bits(array.gather(cells), vol));
      }
    }
  }
}

// The device buffer's halo equals Volume::at_clamped directly (independent
// of layout_reference).
TEST_F(LayoutDevice, HaloEqualsClampedVolume) {
  Volume vol({93, 57, 31}, VoxelType::f32);
  for (std::size_t i = 0; i < vol.voxel_count(); ++i) vol.data()[i] = static_cast<float>(i) * 0.5f;
  PeArray array(*device_, PeGrid{128, 64});
  for (int h : {1, 2}) {
    CellBuffer cells = array.layout(vol, h);
    const CellLayout& L = cells.layout();
    auto got = cells.read(*device_);
    for (int64_t pe : {int64_t(0), int64_t(1), int64_t(4095), int64_t(4096), int64_t(8191)}) {
      Dims3 o = L.split.cell_origin(pe);
      for (int64_t lz = -h; lz < L.cell()[2] + h; ++lz)
        for (int64_t ly = -h; ly < L.cell()[1] + h; ++ly)
          for (int64_t lx = -h; lx < L.cell()[0] + h; ++lx)
            ASSERT_EQ(got[L.index(pe, lx, ly, lz)], vol.at_clamped(o[0] + lx, o[1] + ly, o[2] + lz))
                << "pe " << pe << " at " << lx << "," << ly << "," << lz;
      // The alignment tail is zero.
      for (int64_t i = L.block[0] * L.block[1] * L.block[2]; i < L.cell_stride; ++i)
        ASSERT_EQ(got[pe * L.cell_stride + i], 0.0f);
    }
  }
}

TEST_F(LayoutDevice, RefusesVolumesBeyondTheMaxAllocation) {
  PeArray array(*device_, PeGrid{128, 64});
  // 4096^3 floats is 256 GiB: beyond any max allocation of this machine.
  try {
    array.cell_layout({4096, 4096, 4096}, 1);
    FAIL() << "expected ArgumentError";
  } catch (const ArgumentError& e) {
    EXPECT_NE(std::string(e.what()).find("largest allocation"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("use a smaller volume or fewer PEs"), std::string::npos)
        << e.what();
  }
  // Mismatched PE counts are refused before anything is enqueued.
  PeArray other(*device_, pe_grid(8));
  const auto vol = bit_pattern_volume({9, 9, 9}, 4);
  CellBuffer cells = other.layout(vol.data(), {9, 9, 9}, 1);
  EXPECT_THROW(array.gather(cells), ArgumentError);
}

// ---------------------------------------------------------------- halo cost

TEST(HaloCost, InteriorCellOf256CubedHas26Neighbours) {
  CellLayout L = make_cell_layout({256, 256, 256}, 8192, 1);
  PeGrid g{128, 64};
  // A PE whose cell is away from every face of the volume.
  const int64_t pe = L.split.pe_of_cell({10, 7, 7});
  auto t = halo_transfers(L, g, pe);
  EXPECT_EQ(t.size(), 26u);
  int64_t voxels = 0;
  for (const auto& x : t) {
    voxels += x.voxels;
    EXPECT_EQ(x.bytes, 4 * x.voxels);
    EXPECT_EQ(x.distance, mesh_distance(g, pe, x.from_pe));
  }
  EXPECT_EQ(voxels, 10 * 18 * 18 - 8 * 16 * 16);
  // One PE: nothing to fetch.
  CellLayout one = make_cell_layout({256, 256, 256}, 1, 2);
  HaloCost c1 = halo_cost(one, pe_grid(1));
  EXPECT_EQ(c1.transfers, 0);
  EXPECT_EQ(c1.bytes, 0);
  EXPECT_THROW(halo_transfers(L, pe_grid(64), 0), ArgumentError);
}

// halo_cost against a brute force over every padded position.
TEST(HaloCost, MatchesBruteForce) {
  for (Dims3 dims : {Dims3{17, 9, 5}, Dims3{5, 3, 2}, Dims3{64, 64, 64}}) {
    for (int64_t pes : {2, 16, 64}) {
      for (int h : {1, 2}) {
        CellLayout L = make_cell_layout(dims, pes, h);
        PeGrid g = pe_grid(pes);
        HaloCost want;
        for (int64_t pe = 0; pe < pes; ++pe) {
          std::map<int64_t, int64_t> from;
          for (int64_t lz = -h; lz < L.cell()[2] + h; ++lz)
            for (int64_t ly = -h; ly < L.cell()[1] + h; ++ly)
              for (int64_t lx = -h; lx < L.cell()[0] + h; ++lx) {
                int64_t src = L.split.owner(L.source(pe, lx, ly, lz));
                if (src != pe) ++from[src];
              }
          int64_t pe_bytes = 0;
          for (auto [src, n] : from) {
            want.voxels += n;
            want.bytes += 4 * n;
            pe_bytes += 4 * n;
            want.byte_hops += 4 * n * mesh_distance(g, pe, src);
            want.max_distance = std::max(want.max_distance, mesh_distance(g, pe, src));
          }
          want.transfers += static_cast<int64_t>(from.size());
          want.max_pe_bytes = std::max(want.max_pe_bytes, pe_bytes);
          want.max_pe_transfers =
              std::max(want.max_pe_transfers, static_cast<int64_t>(from.size()));
        }
        HaloCost got = halo_cost(L, g);
        EXPECT_EQ(got.transfers, want.transfers);
        EXPECT_EQ(got.voxels, want.voxels);
        EXPECT_EQ(got.bytes, want.bytes);
        EXPECT_EQ(got.max_pe_bytes, want.max_pe_bytes);
        EXPECT_EQ(got.max_pe_transfers, want.max_pe_transfers);
        EXPECT_EQ(got.max_distance, want.max_distance);
        EXPECT_EQ(got.byte_hops, want.byte_hops);
        EXPECT_GT(got.transfers, 0);
      }
    }
  }
}

}  // namespace
}  // namespace simdvol
