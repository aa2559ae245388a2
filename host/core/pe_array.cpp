// The PE array model: k-d split, cell layout, halo cost (see pe_array.hpp).
#include "simdvol/pe_array.hpp"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <limits>
#include <map>

#include "simdvol/error.hpp"

namespace simdvol {

namespace {

bool is_pow2(int64_t n) {
  return n > 0 && (n & (n - 1)) == 0;
}

int log2_exact(int64_t n) {
  // (Up to 62: 1 << 63 overflows, and n past 2^62 looped for ever.)
  int b = 0;
  while (b < 63 && (int64_t(1) << b) < n) ++b;
  return b;
}

void check_pes(int64_t pes, const std::string& argument) {
  if (!is_pow2(pes) || pes > kMaxPes)
    throw ArgumentError(argument, "PE count " + std::to_string(pes) +
                                      " is not a power of two between 1 and " +
                                      std::to_string(kMaxPes));
}

int64_t ceil_div(int64_t a, int64_t b) {
  return a <= 0 ? a / b : (a - 1) / b + 1;  // (a + b - 1 overflowed near INT64_MAX)
}

bool parse_int(std::string_view s, int64_t& out) {
  // Plain decimal: "0512" is refused, as the CLI's whole numbers are.
  if (s.empty() || (s.size() > 1 && s.front() == '0')) return false;
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

}  // namespace

int PeGrid::bits() const {
  return log2_exact(count());
}

PeGrid pe_grid(int64_t count, const std::string& argument) {
  check_pes(count, argument);
  int n = log2_exact(count);
  return PeGrid{int64_t(1) << ((n + 1) / 2), int64_t(1) << (n / 2)};
}

PeGrid parse_pe_grid(std::string_view spec, const std::string& argument) {
  std::string bad = "\"";  // built with append: GCC 12 warns falsely on "..." + string
  bad.append(spec);
  bad.append(
      "\" is not a PE count N or a grid WxH (e.g. 8192 or 128x64) with a "
      "power-of-two number of PEs");
  auto x = spec.find_first_of("xX");
  if (x == std::string_view::npos) {
    int64_t n = 0;
    if (!parse_int(spec, n)) throw ArgumentError(argument, bad);
    return pe_grid(n, argument);
  }
  int64_t w = 0, h = 0;
  if (!parse_int(spec.substr(0, x), w) || !parse_int(spec.substr(x + 1), h) || w < 1 || h < 1 ||
      w > kMaxPes || h > kMaxPes)
    throw ArgumentError(argument, bad);
  check_pes(w * h, argument);
  return PeGrid{w, h};
}

MeshCoord mesh_coord(const PeGrid& grid, int64_t pe) {
  return {pe % grid.width, pe / grid.width};
}

int64_t mesh_distance(const PeGrid& grid, int64_t a, int64_t b) {
  MeshCoord p = mesh_coord(grid, a), q = mesh_coord(grid, b);
  return std::max(std::abs(p.x - q.x), std::abs(p.y - q.y));
}

Dims3 KdSplit::splits() const {
  return {int64_t(1) << axis_bits[0], int64_t(1) << axis_bits[1], int64_t(1) << axis_bits[2]};
}

Dims3 KdSplit::cell_index(int64_t pe) const {
  Dims3 idx{0, 0, 0};
  for (int b = bits - 1; b >= 0; --b) {
    int a = bit_axis[b];
    idx[a] = idx[a] * 2 + ((pe >> b) & 1);
  }
  return idx;
}

int64_t KdSplit::pe_of_cell(const Dims3& index) const {
  std::array<int, 3> remaining = axis_bits;
  int64_t pe = 0;
  for (int b = bits - 1; b >= 0; --b) {
    int a = bit_axis[b];
    --remaining[a];
    pe |= ((index[a] >> remaining[a]) & 1) << b;
  }
  return pe;
}

Dims3 KdSplit::cell_origin(int64_t pe) const {
  Dims3 idx = cell_index(pe);
  return {idx[0] * cell[0], idx[1] * cell[1], idx[2] * cell[2]};
}

int64_t KdSplit::owner(const Dims3& v) const {
  return pe_of_cell({v[0] / cell[0], v[1] / cell[1], v[2] / cell[2]});
}

KdSplit kd_split(const Dims3& dims, int64_t pes) {
  for (int a = 0; a < 3; ++a)
    if (dims[a] < 1)
      throw ArgumentError("dims", "dimension " + std::to_string(a) + " is " +
                                      std::to_string(dims[a]) + ", not positive");
  check_pes(pes, "PEs");
  KdSplit s;
  s.dims = dims;
  s.bits = log2_exact(pes);
  s.bit_axis.assign(s.bits, 0);
  for (int i = 0; i < s.bits; ++i) {  // i = 0 is the first (coarsest) split: bit N-1
    int best = 0;
    int64_t best_extent = -1;
    for (int a = 0; a < 3; ++a) {
      int64_t e = ceil_div(dims[a], int64_t(1) << s.axis_bits[a]);
      if (e > best_extent) best = a, best_extent = e;  // strict: ties keep the lower axis
    }
    s.bit_axis[s.bits - 1 - i] = best;
    ++s.axis_bits[best];
  }
  for (int a = 0; a < 3; ++a) s.cell[a] = ceil_div(dims[a], int64_t(1) << s.axis_bits[a]);
  return s;
}

Box kd_region(const KdSplit& split, int64_t pe, int level) {
  std::array<int, 3> low_bits{0, 0, 0};
  for (int b = 0; b < level && b < split.bits; ++b) ++low_bits[split.bit_axis[b]];
  Dims3 idx = split.cell_index(pe);
  Box box;
  for (int a = 0; a < 3; ++a) {
    int64_t first = (idx[a] >> low_bits[a]) << low_bits[a];
    box.lo[a] = first * split.cell[a];
    box.hi[a] = box.lo[a] + (int64_t(1) << low_bits[a]) * split.cell[a];
  }
  return box;
}

int64_t CellLayout::index(int64_t pe, int64_t lx, int64_t ly, int64_t lz) const {
  return pe * cell_stride + ((lz + halo) * block[1] + (ly + halo)) * block[0] + (lx + halo);
}

Dims3 CellLayout::source(int64_t pe, int64_t lx, int64_t ly, int64_t lz) const {
  Dims3 o = split.cell_origin(pe);
  Dims3 l{lx, ly, lz};
  Dims3 s;
  for (int a = 0; a < 3; ++a) s[a] = std::clamp(o[a] + l[a], int64_t(0), dims()[a] - 1);
  return s;
}

CellLayout make_cell_layout(const Dims3& dims, int64_t pes, int halo) {
  if (halo < 0 || halo > 8)
    throw ArgumentError("halo", "halo width " + std::to_string(halo) + " is not in 0..8");
  CellLayout L;
  L.split = kd_split(dims, pes);
  L.halo = halo;
  for (int a = 0; a < 3; ++a) L.block[a] = L.split.cell[a] + 2 * halo;
  // Guard the products against overflow: each factor is at most 2^31-ish for
  // sane volumes, but check rather than assume.
  const int64_t limit = std::numeric_limits<int64_t>::max() / 64;
  int64_t block = 1;
  for (int a = 0; a < 3; ++a) {
    if (L.block[a] > limit / block) throw ArgumentError("dims", "cell block size overflows");
    block *= L.block[a];
  }
  L.cell_stride = (block + 15) / 16 * 16;
  if (L.cell_stride > limit / pes) throw ArgumentError("dims", "cell buffer size overflows");
  return L;
}

std::vector<float> layout_reference(const std::vector<float>& volume, const CellLayout& L) {
  const Dims3& n = L.dims();
  if (volume.size() != static_cast<std::size_t>(n[0] * n[1] * n[2]))
    throw ArgumentError("volume", "size does not match the layout's dims");
  std::vector<float> cells(static_cast<std::size_t>(L.elements()), 0.0f);
  const int64_t h = L.halo;
  for (int64_t pe = 0; pe < L.pes(); ++pe) {
    Dims3 o = L.split.cell_origin(pe);
    for (int64_t lz = -h; lz < L.cell()[2] + h; ++lz)
      for (int64_t ly = -h; ly < L.cell()[1] + h; ++ly)
        for (int64_t lx = -h; lx < L.cell()[0] + h; ++lx) {
          int64_t x = std::clamp(o[0] + lx, int64_t(0), n[0] - 1);
          int64_t y = std::clamp(o[1] + ly, int64_t(0), n[1] - 1);
          int64_t z = std::clamp(o[2] + lz, int64_t(0), n[2] - 1);
          cells[L.index(pe, lx, ly, lz)] = volume[(z * n[1] + y) * n[0] + x];
        }
  }
  return cells;
}

std::vector<float> gather_reference(const std::vector<float>& cells, const CellLayout& L) {
  if (cells.size() != static_cast<std::size_t>(L.elements()))
    throw ArgumentError("cells", "size does not match the layout");
  const Dims3& n = L.dims();
  std::vector<float> volume(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  for (int64_t z = 0; z < n[2]; ++z)
    for (int64_t y = 0; y < n[1]; ++y)
      for (int64_t x = 0; x < n[0]; ++x) {
        int64_t pe = L.split.owner({x, y, z});
        Dims3 o = L.split.cell_origin(pe);
        volume[(z * n[1] + y) * n[0] + x] = cells[L.index(pe, x - o[0], y - o[1], z - o[2])];
      }
  return volume;
}

std::vector<HaloTransfer> halo_transfers(const CellLayout& L, const PeGrid& grid, int64_t pe,
                                         std::size_t voxel_bytes) {
  if (grid.count() != L.pes())
    throw ArgumentError("PE grid", std::to_string(grid.count()) + " PEs, but the layout has " +
                                       std::to_string(L.pes()));
  // Along each axis, the padded positions [-h, c + h) map (after clamping) to
  // runs of equal source cell index.
  std::array<std::vector<std::pair<int64_t, int64_t>>, 3> runs;  // (cell index, count)
  Dims3 o = L.split.cell_origin(pe);
  for (int a = 0; a < 3; ++a) {
    for (int64_t l = -L.halo; l < L.cell()[a] + L.halo; ++l) {
      int64_t s = std::clamp(o[a] + l, int64_t(0), L.dims()[a] - 1);
      int64_t idx = s / L.cell()[a];
      if (!runs[a].empty() && runs[a].back().first == idx)
        ++runs[a].back().second;
      else
        runs[a].push_back({idx, 1});
    }
  }
  std::map<int64_t, int64_t> from;
  for (auto [iz, nz] : runs[2])
    for (auto [iy, ny] : runs[1])
      for (auto [ix, nx] : runs[0]) {
        int64_t src = L.split.pe_of_cell({ix, iy, iz});
        if (src != pe) from[src] += nx * ny * nz;
      }
  std::vector<HaloTransfer> out;
  for (auto [src, voxels] : from)
    out.push_back(
        {src, mesh_distance(grid, pe, src), voxels, voxels * static_cast<int64_t>(voxel_bytes)});
  return out;
}

HaloCost halo_cost(const CellLayout& L, const PeGrid& grid, std::size_t voxel_bytes) {
  HaloCost c;
  for (int64_t pe = 0; pe < L.pes(); ++pe) {
    auto t = halo_transfers(L, grid, pe, voxel_bytes);
    int64_t pe_bytes = 0;
    for (const auto& x : t) {
      c.voxels += x.voxels;
      c.bytes += x.bytes;
      c.byte_hops += x.bytes * x.distance;
      c.max_distance = std::max(c.max_distance, x.distance);
      pe_bytes += x.bytes;
    }
    c.transfers += static_cast<int64_t>(t.size());
    c.max_pe_bytes = std::max(c.max_pe_bytes, pe_bytes);
    c.max_pe_transfers = std::max(c.max_pe_transfers, static_cast<int64_t>(t.size()));
  }
  return c;
}

}  // namespace simdvol
