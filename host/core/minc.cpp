// MINC volumes (.mnc: MINC1 on netCDF, MINC2 on HDF5), the McConnell Brain
// Imaging Centre's format (BrainWeb, the ICBM and MNI templates, CIVET),
// through libminc's C++ reader (minc_1_reader, which reads both). HDF5
// and netCDF are not safe on hostile files, so the file is read in a child
// process (read_in_child), as DICOM is; SIMDVOL_MINC_IN_PROCESS=1 reads in
// this process (the fuzz target).
#include <minc_1_rw.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <new>
#include <optional>
#include <string>
#include <vector>

#include "child_read.hpp"
#include "file_checks.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

/// Whether the file starts as netCDF (MINC1) or HDF5 (MINC2) files start
/// (HDF5's signature may follow a user block of 512, 1024, 2048 ... bytes).
bool minc_signature(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  char b[8] = {};
  if (!in.read(b, 8)) return false;
  if (std::memcmp(b, "CDF", 3) == 0 && (b[3] == 1 || b[3] == 2)) return true;
  static const char hdf5[8] = {'\x89', 'H', 'D', 'F', '\r', '\n', '\x1a', '\n'};
  for (std::streamoff at = 0; at <= (1 << 20); at = at == 0 ? 512 : at * 2) {
    in.clear();
    in.seekg(at);
    if (!in.read(b, 8)) return false;
    if (std::memcmp(b, hdf5, 8) == 0) return true;
  }
  return false;
}

/// How far a classic netCDF file's (MINC1's) variables reach, from its
/// header (CDF-1 or CDF-2: magic, record count, dimensions, attributes,
/// variables with their sizes and offsets): netCDF reads what lies past a
/// file's end as zeros without an error (found by hand: a MINC1 file cut at
/// a third loaded its second frame), so the file must be this long.
/// nullopt where the header cannot be walked (libminc then says why).
std::optional<uint64_t> netcdf_extent(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> h(1 << 22);
  in.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
  h.resize(static_cast<std::size_t>(in.gcount()));
  std::size_t at = 0;
  bool ok = true;
  const auto u32 = [&]() -> uint64_t {
    if (at + 4 > h.size()) {
      ok = false;
      return 0;
    }
    const uint64_t v = (uint64_t{h[at]} << 24) | (uint64_t{h[at + 1]} << 16) |
                       (uint64_t{h[at + 2]} << 8) | h[at + 3];
    at += 4;
    return v;
  };
  const auto skip = [&](uint64_t bytes) {
    if (bytes > h.size() - std::min(at, h.size()))
      ok = false;
    else
      at += static_cast<std::size_t>(bytes);
  };
  const auto pad4 = [](uint64_t n) { return (n + 3) / 4 * 4; };
  const auto type_bytes = [](uint64_t t) -> uint64_t {
    return t == 1 || t == 2 ? 1 : t == 3 ? 2 : t == 4 || t == 5 ? 4 : t == 6 ? 8 : 0;
  };
  if (h.size() < 8 || h[0] != 'C' || h[1] != 'D' || h[2] != 'F' || (h[3] != 1 && h[3] != 2))
    return std::nullopt;
  const bool wide = h[3] == 2;
  at = 4;
  const uint64_t records = u32();
  const auto skip_atts = [&]() {
    const uint64_t tag = u32(), count = u32();
    if (tag != 0 && tag != 0x0C) ok = false;
    for (uint64_t i = 0; ok && i < count; ++i) {
      skip(pad4(u32()));  // name
      const uint64_t bytes = type_bytes(u32());
      if (bytes == 0) ok = false;
      const uint64_t n = u32();
      if (n > (uint64_t{1} << 32)) ok = false;
      if (ok) skip(pad4(n * bytes));
    }
  };
  std::vector<uint64_t> dim_len;
  const uint64_t dim_tag = u32(), dims = u32();
  if ((dim_tag != 0 && dim_tag != 0x0A) || dims > 1024) ok = false;
  for (uint64_t i = 0; ok && i < dims; ++i) {
    skip(pad4(u32()));
    dim_len.push_back(u32());
  }
  skip_atts();
  const uint64_t var_tag = u32(), vars = u32();
  if ((var_tag != 0 && var_tag != 0x0B) || vars > 65536) ok = false;
  struct Var {
    bool record;
    uint64_t vsize, begin;
  };
  std::vector<Var> list;
  uint64_t record_bytes = 0;
  for (uint64_t i = 0; ok && i < vars; ++i) {
    skip(pad4(u32()));
    const uint64_t nd = u32();
    if (nd > 1024) ok = false;
    bool record = false;
    for (uint64_t d = 0; ok && d < nd; ++d) {
      const uint64_t id = u32();
      if (id >= dim_len.size())
        ok = false;
      else if (d == 0 && dim_len[id] == 0)
        record = true;
    }
    skip_atts();
    u32();  // type
    const uint64_t vsize = u32();
    const uint64_t begin = wide ? (u32() << 32 | u32()) : u32();
    list.push_back({record, vsize, begin});
    if (record) record_bytes += vsize;
  }
  if (!ok) {
    // A header that cannot be walked within the whole file is corrupt:
    // netCDF would allocate what its counts say (gigabytes, found by
    // scripts/fuzz) before it gave up. (Past the window: libminc decides.)
    if (h.size() < (1u << 22))
      throw FileError(path,
                      "its netCDF header is corrupt (a count, a type or a dimension in it "
                      "makes no sense within the file's " +
                          std::to_string(h.size()) + " bytes)");
    return std::nullopt;
  }
  uint64_t extent = 0;
  for (const Var& v : list)
    extent = std::max(extent, v.record ? (records == 0 || records == 0xffffffffu
                                              ? v.begin
                                              : v.begin + (records - 1) * record_bytes + v.vsize)
                                       : v.begin + v.vsize);
  return extent;
}

Volume load_minc_here(const fs::path& path, uint64_t file_bytes, std::optional<int64_t> index,
                      int64_t* volumes) {
  try {
    minc::minc_1_reader r;
    r.open(path.c_str(), false, false, false);
    const int nd = r.dim_no();
    if (nd != 3 && nd != 4)
      throw FileError(path, std::to_string(nd) +
                                " dimensions: a 3-D volume (or a 4-D series of them) is expected");
    for (int i = 0; i < nd; ++i)
      if (r.dim(i).dim == minc::dim_info::DIM_VEC)
        throw FileError(path, "its dimension '" + r.dim(i).name +
                                  "' holds vector components (a colour or vector image), not a "
                                  "scalar volume");
    if (nd == 4 && r.dim(0).dim != minc::dim_info::DIM_TIME)
      throw FileError(path, "4 dimensions, the slowest '" + r.dim(0).name +
                                "', not time: a series of 3-D volumes is expected");
    // The file's order kept: its fastest dimension is x, as other loaders
    // keep theirs (`--orient` turns the axes).
    std::array<int64_t, 3> dims{};
    std::array<double, 3> spacing{};
    std::array<std::array<double, 3>, 3> dirs{};
    bool placed = true;
    for (int a = 0; a < 3; ++a) {
      const minc::dim_info& d = r.dim(nd - 1 - a);
      if (d.dim == minc::dim_info::DIM_TIME)
        throw FileError(path,
                        "its time dimension is not the slowest: a series of 3-D volumes "
                        "is expected");
      dims[a] = static_cast<int64_t>(d.length);
      if (dims[a] <= 0)
        throw FileError(path,
                        "its dimension '" + d.name + "' has length " + std::to_string(dims[a]));
      spacing[a] = std::fabs(d.step);
      const double sign = d.step < 0 ? -1.0 : 1.0;
      std::array<double, 3> c{};
      if (d.have_dir_cos) {
        for (int j = 0; j < 3; ++j) c[j] = d.dir_cos[j];
      } else if (d.dim >= minc::dim_info::DIM_X && d.dim <= minc::dim_info::DIM_Z) {
        c[d.dim - minc::dim_info::DIM_X] = 1.0;  // (xspace, yspace, zspace: the world's axes)
      } else {
        placed = false;
      }
      for (int j = 0; j < 3; ++j) dirs[a][j] = sign * c[j];
    }
    const int64_t frames = nd == 4 ? static_cast<int64_t>(r.dim(0).length) : 1;
    if (frames <= 0) throw FileError(path, "its time dimension has length 0");
    const std::size_t n = checked_count(path, dims, sizeof(float));
    // What the file can hold, before the volume is allocated: a MINC1
    // voxel takes a byte at least, a MINC2 one (HDF5, perhaps deflated)
    // what deflate could pack it into.
    const uint64_t all = static_cast<uint64_t>(frames) * n;
    if (all / static_cast<uint64_t>(frames) != n ||
        (r.is_minc2() ? !deflate_could_hold(file_bytes, all) : all > file_bytes))
      throw FileError(path, "its dimensions (" + std::to_string(frames) + " x " + dims_text(dims) +
                                " voxels) cannot fit in its " + std::to_string(file_bytes) +
                                " bytes (corrupt header?)");
    if (volumes) *volumes = frames;
    const int64_t frame = pick_volume(path, frames, index, "(time points: a 4-D image)");

    Volume vol(dims, VoxelType::f32, sane_spacing(spacing));
    // Real values (libminc applies the slices' image-min and image-max),
    // slice by slice in file order; the frames before the one asked for
    // are read and let go.
    r.setup_read_float();
    const auto slice = static_cast<std::size_t>(r.slice_len());
    if (slice == 0 || n % slice != 0)
      throw FileError(
          path, "libminc's slices (" + std::to_string(slice) + " values) do not divide the volume");
    std::vector<float> scratch(slice);
    float* out = vol.data().data();
    const std::size_t first = static_cast<std::size_t>(frame) * n;
    std::size_t at = 0;
    r.begin();
    do {
      const bool keep = at >= first && at < first + n;
      r.read(keep ? out + (at - first) : scratch.data());
      at += slice;
    } while (at < first + n && r.next_slice());
    if (at < first + n)
      throw FileError(path, "libminc read " + std::to_string(at) + " of its values, not " +
                                std::to_string(first + n));
    if (placed) vol.set_orientation(closest_orientation(dirs, "RAS"));
    return vol;
  } catch (const minc::generic_error& e) {
    throw FileError(path, std::string("libminc could not read it: ") + (e.msg() ? e.msg() : "?"));
  }
}

}  // namespace

Volume load_minc(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                 int64_t* volumes) {
  if (volumes) *volumes = 1;
  const uint64_t bytes = require_regular_file(path);
  if (!minc_signature(path))
    throw FileError(path,
                    "not a MINC file (it starts as neither netCDF, MINC1's, nor HDF5, "
                    "MINC2's)");
  if (const auto reach = netcdf_extent(path); reach && *reach > bytes)
    throw FileError(path, "holds " + std::to_string(bytes) + " bytes, but its variables reach " +
                              std::to_string(*reach) + " (truncated?)");
  if (const char* e = std::getenv("SIMDVOL_MINC_IN_PROCESS"); e && std::string(e) == "1")
    return load_minc_here(path, bytes, volume_index, volumes);
  return read_in_child(
      path, "libminc",
      [&](int64_t* count) { return load_minc_here(path, bytes, volume_index, count); }, volumes,
      [bytes] {
        return ReadSize{bytes, 1};
      });
}

}  // namespace simdvol
