// Volume loaders (raw, VolPack .den, NRRD through teem, NIfTI-1 through
// niftilib) and the NRRD writer. Every malformed input throws FileError
// naming the file and the problem; sizes are checked before large buffers
// are allocated, so a header that claims huge dims fails early.
#include "simdvol/io.hpp"

#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <unordered_set>
#include <vector>

#include "file_checks.hpp"
#include "read_watch.hpp"
#include "simdvol/error.hpp"
#include "temp_files.hpp"

extern "C" {
#include <nifti2_io.h>
#include <teem/biff.h>
#include <teem/nrrd.h>
}

namespace simdvol {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------- helpers

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

/// A directory named where a volume file is expected: FileError.
void refuse_directory(const fs::path& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw FileError(path, "is a directory, not a volume file");
}

}  // namespace

std::string errno_text(int e) {
  return std::generic_category().message(e);
}

// (declared in file_checks.hpp, shared with the other loaders)
uint64_t require_regular_file(const fs::path& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) {
    if (ec && ec != std::errc::no_such_file_or_directory)
      throw FileError(path, "cannot access file: " + ec.message());
    throw FileError(path, "file not found (no such file)");
  }
  refuse_non_regular_file(path, "a volume file");
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) throw FileError(path, "cannot read file size: " + ec.message());
  if (size == 0) throw FileError(path, "file is empty (0 bytes)");
  return static_cast<uint64_t>(size);
}

std::size_t checked_count(const fs::path& path, const std::array<int64_t, 3>& dims,
                          std::size_t bytes_per_voxel) {
  try {
    // The float copy we keep must fit as well as the file's own bytes.
    checked_voxel_count(dims, path.string(), sizeof(float));
    return checked_voxel_count(dims, path.string(), bytes_per_voxel);
  } catch (const ArgumentError& e) {
    const std::string msg = e.what();
    const std::string prefix = path.string() + ": ";
    throw FileError(path, msg.rfind(prefix, 0) == 0 ? msg.substr(prefix.size()) : msg);
  }
}

std::string dims_text(const std::array<int64_t, 3>& d) {
  return std::to_string(d[0]) + " x " + std::to_string(d[1]) + " x " + std::to_string(d[2]);
}

int64_t pick_volume(const fs::path& path, int64_t count, std::optional<int64_t> index,
                    const std::string& what, const char* holder) {
  if (count > 1 && !index)
    throw FileError(path, "holds " + std::to_string(count) + " 3-D volumes " + what +
                              ": give the index of one, 0.." + std::to_string(count - 1) +
                              " (simdvol: --volume-index)");
  if (index && (*index < 0 || *index >= count))
    throw FileError(path, "volume index " + std::to_string(*index) + " is outside 0.." +
                              std::to_string(count - 1) + " (the " + holder + " holds " +
                              std::to_string(count) + (count == 1 ? " volume)" : " volumes)"));
  return index ? *index : 0;
}

std::array<double, 3> sane_spacing(std::array<double, 3> s) {
  for (double& v : s) {
    v = std::fabs(v);
    if (!(v > 0.0) || !std::isfinite(v)) v = 1.0;
  }
  return s;
}

namespace {

/// Converts `n` voxels of `type` stored at `src` (byte order `swap`ped or not)
/// to floats at `dst`.
void convert_to_float(VoxelType type, const unsigned char* src, std::size_t n, bool swap,
                      float* dst) {
  switch (type) {
    case VoxelType::u8:
      for (std::size_t i = 0; i < n; ++i) dst[i] = static_cast<float>(src[i]);
      break;
    case VoxelType::u16:
      for (std::size_t i = 0; i < n; ++i)
        dst[i] = static_cast<float>(load_scalar<uint16_t>(src + 2 * i, swap));
      break;
    case VoxelType::i16:
      for (std::size_t i = 0; i < n; ++i)
        dst[i] = static_cast<float>(load_scalar<int16_t>(src + 2 * i, swap));
      break;
    case VoxelType::f32:
      for (std::size_t i = 0; i < n; ++i) dst[i] = load_scalar<float>(src + 4 * i, swap);
      break;
  }
}

/// Reads `n` voxels of `type` from `in` (already positioned) into `vol`.
void read_voxels(const fs::path& path, std::ifstream& in, VoxelType type, bool swap, Volume& vol) {
  const std::size_t bpv = voxel_bytes(type);
  const std::size_t n = vol.voxel_count();
  constexpr std::size_t chunk_voxels = std::size_t{1} << 20;
  std::vector<unsigned char> buf(std::min(n, chunk_voxels) * bpv);
  float* out = vol.data().data();
  for (std::size_t done = 0; done < n;) {
    const std::size_t m = std::min(chunk_voxels, n - done);
    in.read(reinterpret_cast<char*>(buf.data()), static_cast<std::streamsize>(m * bpv));
    if (static_cast<std::size_t>(in.gcount()) != m * bpv)
      throw FileError(path, "truncated data: read failed after " +
                                std::to_string(done * bpv + static_cast<std::size_t>(in.gcount())) +
                                " voxel bytes of " + std::to_string(n * bpv));
    convert_to_float(type, buf.data(), m, swap, out + done);
    done += m;
  }
}

// ---------------------------------------------------------------- teem RAII

std::string biff_message(const char* key) {
  char* err = biffGetDone(key);
  if (!err) return "unknown teem error";
  std::string s(err);
  std::free(err);
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  // biff stacks messages one per line; keep them readable on one line.
  for (char& c : s)
    if (c == '\n') c = ';';
  return s;
}

struct NrrdDeleter {
  void operator()(Nrrd* n) const { nrrdNuke(n); }
};
struct NioDeleter {
  void operator()(NrrdIoState* n) const { nrrdIoStateNix(n); }
};
using NrrdPtr = std::unique_ptr<Nrrd, NrrdDeleter>;
using NioPtr = std::unique_ptr<NrrdIoState, NioDeleter>;

struct NrrdShape {
  std::array<int64_t, 3> dims{};
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  std::array<unsigned int, 3> axes{0, 1, 2};  ///< which nrrd axes are x, y, z
  int volume_axis = -1;                       ///< the axis of a 4-D nrrd's volumes, else -1
  int64_t volumes = 1;                        ///< that axis's size: 3-D volumes in the file
  int64_t index = 0;                          ///< the volume read
};

double nrrd_axis_spacing(const Nrrd* n, unsigned int ax) {
  const NrrdAxisInfo& a = n->axis[ax];
  if (std::isfinite(a.spacing) && a.spacing != 0.0) return std::fabs(a.spacing);
  if (n->spaceDim > 0) {
    double s2 = 0.0;
    bool ok = true;
    for (unsigned int i = 0; i < n->spaceDim; ++i) {
      if (!std::isfinite(a.spaceDirection[i])) ok = false;
      s2 += a.spaceDirection[i] * a.spaceDirection[i];
    }
    if (ok && s2 > 0.0) return std::sqrt(s2);
  }
  return 1.0;
}

/// The orientation letters of the axes `axes` (x, y, z) of a nrrd in an
/// anatomical space (RAS, LAS, LPS, or one of them with time): the closest
/// axes of their space directions. Empty for another space or a direction
/// that is missing, 0 or not finite.
std::string nrrd_orientation(const Nrrd* n, const std::array<unsigned int, 3>& axes) {
  const char* world = nullptr;  // the letters of the space's +x, +y, +z
  switch (n->space) {
    case nrrdSpaceRightAnteriorSuperior:
    case nrrdSpaceRightAnteriorSuperiorTime:
      world = "RAS";
      break;
    case nrrdSpaceLeftAnteriorSuperior:
    case nrrdSpaceLeftAnteriorSuperiorTime:
      world = "LAS";
      break;
    case nrrdSpaceLeftPosteriorSuperior:
    case nrrdSpaceLeftPosteriorSuperiorTime:
      world = "LPS";
      break;
    default:
      return {};
  }
  if (n->spaceDim < 3) return {};
  std::array<std::array<double, 3>, 3> d{};
  for (int i = 0; i < 3; ++i)
    for (int c = 0; c < 3; ++c) d[i][c] = n->axis[axes[i]].spaceDirection[c];
  return closest_orientation(d, world);
}

/// Dims and spacing of a 3-D nrrd, or of the volume at `index` of a 4-D one.
/// A 4-D nrrd's volume axis: its one axis of a kind that is not spatial (a
/// list, a vector, ...: a diffusion series' gradients), else an axis of size
/// 1, else the last (slowest) axis, as NIfTI's fourth (a time series).
NrrdShape nrrd_shape(const fs::path& path, const Nrrd* n, std::optional<int64_t> index) {
  NrrdShape s;
  if (n->dim == 3) {
    // axes 0, 1, 2
  } else if (n->dim == 4) {
    int drop = -1, components = 0;
    for (unsigned int a = 0; a < 4; ++a) {
      const int kind = n->axis[a].kind;
      if (kind != nrrdKindUnknown && !nrrdKindIsDomain(kind)) {
        ++components;
        drop = static_cast<int>(a);
      }
    }
    if (components > 1)
      throw FileError(path, "4-D NRRD with " + std::to_string(components) +
                                " axes of a non-spatial kind: not a series of 3-D volumes");
    for (unsigned int a = 0; a < 4 && drop < 0; ++a)
      if (n->axis[a].size == 1) drop = static_cast<int>(a);
    if (drop < 0) drop = 3;
    s.volume_axis = drop;
    if (n->axis[drop].size > static_cast<size_t>(std::numeric_limits<int32_t>::max()))
      throw FileError(path, "axis size " + std::to_string(n->axis[drop].size) + " overflows");
    s.volumes = static_cast<int64_t>(n->axis[drop].size);
    unsigned int k = 0;
    for (unsigned int a = 0; a < 4; ++a)
      if (static_cast<int>(a) != drop) s.axes[k++] = a;
  } else {
    throw FileError(path, "dimension " + std::to_string(n->dim) +
                              " is not supported (a 3-D volume is expected)");
  }
  // An axis whose kind says it holds components (RGB-color, a vector, a
  // list, ...) rather than positions makes a colour or vector image, not a
  // scalar volume; axes of no kind (most files) or a domain kind are taken.
  for (int i = 0; i < 3; ++i) {
    const int kind = n->axis[s.axes[i]].kind;
    if (kind != nrrdKindUnknown && !nrrdKindIsDomain(kind))
      throw FileError(path, "axis " + std::to_string(s.axes[i]) + " (size " +
                                std::to_string(n->axis[s.axes[i]].size) + ") is of kind '" +
                                airEnumStr(nrrdKind, kind) +
                                "', not a spatial axis: the file holds a colour or vector "
                                "image, not a scalar volume");
  }
  for (int i = 0; i < 3; ++i) {
    const size_t sz = n->axis[s.axes[i]].size;
    if (sz > static_cast<size_t>(std::numeric_limits<int64_t>::max()))
      throw FileError(path, "axis size " + std::to_string(sz) + " overflows");
    s.dims[i] = static_cast<int64_t>(sz);
    s.spacing[i] = nrrd_axis_spacing(n, s.axes[i]);
  }
  s.spacing = sane_spacing(s.spacing);
  s.index = pick_volume(path, s.volumes, index,
                        "along axis " + std::to_string(s.volume_axis) + " (a 4-D image)");
  return s;
}

/// The VoxelType a nrrd type maps to (other integer and double types are
/// converted: int8 -> i16, wider types -> f32).
VoxelType nrrd_voxel_type(const fs::path& path, int type) {
  switch (type) {
    case nrrdTypeUChar:
      return VoxelType::u8;
    case nrrdTypeUShort:
      return VoxelType::u16;
    case nrrdTypeShort:
    case nrrdTypeChar:
      return VoxelType::i16;
    case nrrdTypeFloat:
    case nrrdTypeInt:
    case nrrdTypeUInt:
    case nrrdTypeLLong:
    case nrrdTypeULLong:
    case nrrdTypeDouble:
      return VoxelType::f32;
    default:
      break;
  }
  throw FileError(path, std::string("unsupported NRRD type '") + airEnumStr(nrrdType, type) +
                            "' (expected an integer or floating-point scalar type)");
}

template <typename T>
void nrrd_copy(const Nrrd* n, const NrrdShape& s, float* out) {
  // Strides of the nrrd axes; the volume read starts at index times its
  // axis's stride (0 for a 3-D nrrd).
  std::array<size_t, 4> stride{1, 1, 1, 1};
  for (unsigned int a = 1; a < n->dim; ++a) stride[a] = stride[a - 1] * n->axis[a - 1].size;
  const T* src = static_cast<const T*>(n->data) +
                 (s.volume_axis >= 0 ? static_cast<size_t>(s.index) * stride[s.volume_axis] : 0);
  const size_t sx = stride[s.axes[0]], sy = stride[s.axes[1]], sz = stride[s.axes[2]];
  size_t o = 0;
  for (int64_t z = 0; z < s.dims[2]; ++z)
    for (int64_t y = 0; y < s.dims[1]; ++y) {
      const T* row = src + static_cast<size_t>(z) * sz + static_cast<size_t>(y) * sy;
      for (int64_t x = 0; x < s.dims[0]; ++x) out[o++] = static_cast<float>(row[x * sx]);
    }
}

/// Checks a "data file: <format> <min> <max> <step> [<subdim>]" line before
/// teem parses it: teem 1.11 passes the format to sprintf after checking only
/// that its first conversion is %d (so "%d%s" reads a missing argument), and
/// counts the files with an int loop that never ends when max + step
/// overflows. Only %d (with at most two width digits) and %% are accepted, and
/// min, max and step must give 1 to 100000 files within +-2^30. Returns
/// whether the line is "LIST [<subdim>]" (the names on the lines after it).
bool nrrd_check_data_file_line(const fs::path& path, const std::string& value) {
  std::istringstream words(value);
  std::string format;
  words >> format;
  int conversions = 0;
  for (std::size_t i = 0; i < format.size(); ++i) {
    if (format[i] != '%') continue;
    if (i + 1 < format.size() && format[i + 1] == '%') {
      ++i;
      continue;
    }
    std::size_t j = i + 1, digits = 0;
    while (j < format.size() && std::isdigit(static_cast<unsigned char>(format[j]))) ++j, ++digits;
    if (j >= format.size() || format[j] != 'd' || digits > 2)
      throw FileError(path, "data file name '" + format +
                                "': a '%' must begin %d (width at most 2 digits) or %%");
    ++conversions;
    i = j;
  }
  if (conversions == 0) return format == "LIST";  // one file name, or LIST
  if (conversions > 1)
    throw FileError(path, "data file format '" + format + "' has more than one %d");
  long long mn = 0, mx = 0, step = 0;
  if (!(words >> mn >> mx >> step))
    throw FileError(path, "data file format '" + format + "' needs <min> <max> <step>");
  constexpr long long lim = 1LL << 30;
  const bool in_range = mn >= -lim && mn <= lim && mx >= -lim && mx <= lim && step != 0 &&
                        step >= -lim && step <= lim && (mx - mn) / step >= 0 &&
                        (mx - mn) / step < 100000;
  if (!in_range)
    throw FileError(path, "data file format '" + format + "': min " + std::to_string(mn) +
                              ", max " + std::to_string(mx) + ", step " + std::to_string(step) +
                              " do not give 1 to 100000 files");
  return false;
}

/// Reads the NRRD header lines (up to the first blank line, or after
/// "data file: LIST" to the end of the file; at most 1 MiB) and checks what
/// teem cannot be trusted with: the magic, so that teem never tries its
/// other formats (its text reader leaks on malformed input), a last header
/// line without a newline, a line with a NUL byte, and the data file line
/// (nrrd_check_data_file_line).
void nrrd_prescan_header(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path, "cannot open file: " + errno_text(errno));
  std::string text(std::size_t{1} << 20, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  const bool more = in && in.peek() != std::char_traits<char>::eof();  // past the 1 MiB read
  std::size_t pos = 0;
  auto next_line = [&](std::string& line) {
    if (pos >= text.size()) return false;
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    line.assign(text, pos, eol - pos);
    pos = eol + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  std::string line;
  next_line(line);
  // The whole first line, as teem compares it (NRRD0001 .. NRRD0005 today).
  if (line.size() != 8 || line.compare(0, 7, "NRRD000") != 0 || line[7] < '1' || line[7] > '9')
    throw FileError(path,
                    "not a NRRD file (the header does not begin with the magic line NRRD000x)");
  bool have_dimension = false;
  // After "data file: LIST" teem takes every later line of the file as a
  // data file name, past blank lines too: those lines are checked as well.
  bool list = false;
  int line_number = 1;
  while (true) {
    const std::size_t start = pos;
    if (!next_line(line)) break;
    ++line_number;
    // teem 1.11 over-reads its line buffer (a heap overflow found by the
    // fuzzer, in a biff message about a LIST of data files) when the file
    // ends inside a header line: a header must end with a newline.
    if (text.find('\n', start) == std::string::npos && text.size() < (std::size_t{1} << 20))
      throw FileError(path, "truncated header: the last header line has no newline");
    if (line.empty()) {
      if (list) continue;
      break;  // the end of the header
    }
    // teem 1.11 over-reads its line buffer (a heap overflow in a biff
    // message, found by the fuzzer) on a header line with a NUL byte, after
    // "data file: LIST". A header is text: no line of it holds a NUL.
    if (line.find('\0') != std::string::npos)
      throw FileError(path, "malformed header: line " + std::to_string(line_number) +
                                " holds a NUL byte (a NRRD header is text)");
    if (list || line[0] == '#') continue;  // a data file name, or a comment
    const std::size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    if (colon + 1 < line.size() && line[colon + 1] == '=') continue;  // key/value pair
    std::string key;
    for (std::size_t i = 0; i < colon; ++i)
      if (line[i] != ' ' && line[i] != '\t')
        key += static_cast<char>(std::tolower(static_cast<unsigned char>(line[i])));
    if (key == "dimension") have_dimension = true;
    // The per-axis fields need the dimension before them (the format says
    // so, and teem refuses them otherwise), and teem 1.11 leaks what it
    // parsed of a kinds or centers line when it refuses it (fuzzer finding):
    // refused here, by name.
    static const char* const kPerAxis[] = {"sizes",    "spacings", "thicknesses",    "axismins",
                                           "axismaxs", "centers",  "centerings",     "labels",
                                           "units",    "kinds",    "spacedirections"};
    if (!have_dimension)
      for (const char* field : kPerAxis)
        if (key == field)
          throw FileError(path, "malformed header: the per-axis field '" + line.substr(0, colon) +
                                    "' before 'dimension'");
    if (key == "datafile") {
      // teem 1.11 leaks its file-name array when it parses a data file line
      // before knowing the dimension (fuzzer finding); the format wants the
      // dimension first anyway.
      if (!have_dimension)
        throw FileError(path, "malformed header: 'data file' before 'dimension'");
      list = nrrd_check_data_file_line(path, line.substr(colon + 1));
    }
  }
  if (list && more) throw FileError(path, "a header whose LIST of data files runs past 1 MiB");
}

/// Names of the data files of a detached-header nrrd (after a header-only
/// read), resolved relative to the header's directory.
std::vector<fs::path> nrrd_data_files(const fs::path& path, const NrrdIoState* nio) {
  std::vector<fs::path> files;
  const fs::path dir = path.parent_path();
  auto resolve = [&](const std::string& name) {
    fs::path p(name);
    return p.is_absolute() ? p : dir / p;
  };
  if (nio->dataFNFormat) {
    const int step = nio->dataFNStep;
    if (step == 0) return files;
    // The format was checked by nrrd_check_data_file_line (one %d).
    for (int64_t i = nio->dataFNMin; step > 0 ? i <= nio->dataFNMax : i >= nio->dataFNMax;
         i += step) {
      char name[4096];
      std::snprintf(name, sizeof name, nio->dataFNFormat, static_cast<int>(i));
      files.push_back(resolve(name));
      if (files.size() > 100000) break;
    }
  } else if (nio->dataFNArr) {
    for (unsigned int i = 0; i < nio->dataFNArr->len; ++i)
      if (nio->dataFN[i] && std::string(nio->dataFN[i]) != "-")
        files.push_back(resolve(nio->dataFN[i]));
  }
  return files;
}

/// Offset of the first byte after the blank line that ends an attached NRRD
/// header, or nothing if it cannot be found in the first 16 MiB.
std::optional<uint64_t> nrrd_header_end(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::vector<char> buf(1 << 16);
  uint64_t pos = 0;
  char prev = 0;  // the last character seen, carriage returns aside
  while (pos < (uint64_t{16} << 20)) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const auto got = static_cast<std::size_t>(in.gcount());
    if (got == 0) break;
    for (std::size_t i = 0; i < got; ++i) {
      const char c = buf[i];
      if (c == '\r') continue;  // tolerate CRLF line endings
      if (c == '\n' && prev == '\n') return pos + i + 1;
      prev = c;
    }
    pos += got;
  }
  return std::nullopt;
}

/// Decodes the gzip data of a NRRD (`data`, from byte `offset`): gzip members
/// up to the end of the one that completes the `need` bytes the header asks
/// for, CRC checks included. Throws FileError (naming `path`) if the stream
/// is corrupt or ends early. teem
/// reports both too, but leaks its gzip state when it does (teem 1.11
/// _nrrdEncodingGzip_read returns without _nrrdGzClose), and says less.
void nrrd_gzip_precheck(const fs::path& path, const fs::path& data, uint64_t offset,
                        uint64_t need) {
  std::ifstream in(data, std::ios::binary);
  if (!in) throw FileError(path, "cannot open data file " + data.string());
  in.seekg(static_cast<std::streamoff>(offset));
  if (!in) throw FileError(path, "cannot seek to the gzip data");
  z_stream z{};
  if (inflateInit2(&z, 15 + 16) != Z_OK) throw FileError(path, "zlib: inflateInit2 failed");
  struct Ender {
    z_stream* z;
    ~Ender() { inflateEnd(z); }
  } ender{&z};
  std::vector<unsigned char> ibuf(1 << 16), obuf(1 << 16);
  uint64_t total = 0;
  bool ended = false;  // the last member's end was reached
  while (!(ended && total >= need)) {
    if (z.avail_in == 0) {
      in.read(reinterpret_cast<char*>(ibuf.data()), static_cast<std::streamsize>(ibuf.size()));
      const auto got = static_cast<uInt>(in.gcount());
      if (got == 0) break;
      z.next_in = ibuf.data();
      z.avail_in = got;
    }
    if (ended) {  // another gzip member follows (as gzip -c a b > c writes)
      if (inflateReset(&z) != Z_OK) throw FileError(path, "zlib: inflateReset failed");
      ended = false;
    }
    z.next_out = obuf.data();
    z.avail_out = static_cast<uInt>(obuf.size());
    const int r = inflate(&z, Z_NO_FLUSH);
    total += obuf.size() - z.avail_out;
    if (r == Z_STREAM_END) {
      ended = true;
    } else if (r != Z_OK && r != Z_BUF_ERROR) {
      throw FileError(path, std::string("corrupt gzip data: ") + (z.msg ? z.msg : "zlib error") +
                                " after " + std::to_string(total) + " decoded bytes");
    }
  }
  if (total < need)
    throw FileError(path, "truncated data: the gzip data decode to " + std::to_string(total) +
                              " bytes, but the header needs " + std::to_string(need));
}

/// One volume of a 4-D NRRD read from its data stream, the other volumes
/// skipped, not held: where the data are one stream (attached after the
/// header, or one detached file), raw or gzip, with no line skip (and no
/// byte skip for gzip, which teem applies after decoding). teem's nrrdLoad
/// reads every volume (a diffusion series of 65 volumes held whole for one).
struct NrrdVolumeStream {
  fs::path data;                      ///< the file holding the data
  uint64_t offset = 0;                ///< where they start in it (raw: byte skip included)
  bool gzip = false;                  ///< gzip members, else raw bytes
  bool swap = false;                  ///< elements stored in the other byte order
  int type = 0;                       ///< nrrdType of the elements
  std::size_t esize = 0;              ///< bytes per element
  std::array<std::size_t, 4> size{};  ///< the 4 axes' sizes, axis 0 fastest
};

/// Reads the data stream of a NRRD sequentially: `read` fills bytes (all of
/// them, or throws FileError naming `path`), `skip` passes over bytes. The
/// stream comes in 1 MiB of decoded bytes at a time, so that the runs of a
/// volume axis that is the fastest (one element between two skips) cost a
/// copy each, not a seek or an inflate call; a raw skip past the buffer is
/// a seek.
class NrrdDataReader {
 public:
  NrrdDataReader(const fs::path& path, const NrrdVolumeStream& st)
      : path_(path), gzip_(st.gzip), in_(st.data, std::ios::binary) {
    if (!in_) throw FileError(path_, "cannot open data file " + st.data.string());
    in_.seekg(static_cast<std::streamoff>(st.offset));
    if (!in_) throw FileError(path_, "cannot seek to the voxel data");
    if (gzip_ && inflateInit2(&z_, 15 + 16) != Z_OK)
      throw FileError(path_, "zlib: inflateInit2 failed");
  }
  ~NrrdDataReader() {
    if (gzip_) inflateEnd(&z_);
  }
  NrrdDataReader(const NrrdDataReader&) = delete;
  NrrdDataReader& operator=(const NrrdDataReader&) = delete;

  void read(unsigned char* dst, uint64_t n) {
    while (n > 0) {
      if (pos_ == len_) refill();
      const std::size_t k = static_cast<std::size_t>(std::min<uint64_t>(n, len_ - pos_));
      std::memcpy(dst, buf_.data() + pos_, k);
      dst += k;
      pos_ += k;
      n -= k;
    }
  }

  void skip(uint64_t n) {
    const std::size_t k = static_cast<std::size_t>(std::min<uint64_t>(n, len_ - pos_));
    pos_ += k;
    n -= k;
    if (n > buf_.size() && !gzip_) {
      in_.seekg(static_cast<std::streamoff>(n), std::ios::cur);
      if (!in_) short_data();
      done_ += n;
      return;
    }
    while (n > 0) {
      refill();
      const std::size_t j = static_cast<std::size_t>(std::min<uint64_t>(n, len_));
      pos_ = j;
      n -= j;
    }
  }

 private:
  [[noreturn]] void short_data() const {
    throw FileError(path_, "truncated data: the voxel data end after " + std::to_string(done_) +
                               " bytes, before the volume asked for");
  }

  /// The next bytes of the stream into buf_ (at least one, or FileError).
  void refill() {
    pos_ = len_ = 0;
    if (!gzip_) {
      in_.read(reinterpret_cast<char*>(buf_.data()), static_cast<std::streamsize>(buf_.size()));
      len_ = static_cast<std::size_t>(in_.gcount());
      if (len_ == 0) short_data();
      done_ += len_;
      return;
    }
    while (len_ == 0) {
      if (z_.avail_in == 0) {
        in_.read(reinterpret_cast<char*>(ibuf_.data()), static_cast<std::streamsize>(ibuf_.size()));
        const auto got = static_cast<uInt>(in_.gcount());
        if (got == 0) short_data();
        z_.next_in = ibuf_.data();
        z_.avail_in = got;
      }
      if (ended_) {  // another gzip member follows
        if (inflateReset(&z_) != Z_OK) throw FileError(path_, "zlib: inflateReset failed");
        ended_ = false;
      }
      z_.next_out = buf_.data();
      z_.avail_out = static_cast<uInt>(buf_.size());
      const int r = inflate(&z_, Z_NO_FLUSH);
      len_ = buf_.size() - z_.avail_out;
      done_ += len_;
      if (r == Z_STREAM_END)
        ended_ = true;
      else if (r != Z_OK && r != Z_BUF_ERROR)
        throw FileError(path_, std::string("corrupt gzip data: ") +
                                   (z_.msg ? z_.msg : "zlib error") + " after " +
                                   std::to_string(done_) + " decoded bytes");
    }
  }

  fs::path path_;
  bool gzip_;
  std::ifstream in_;
  z_stream z_{};
  bool ended_ = false;
  uint64_t done_ = 0;  ///< bytes of the stream taken in (decoded bytes for gzip)
  std::vector<unsigned char> buf_ = std::vector<unsigned char>(std::size_t{1} << 20);
  std::size_t pos_ = 0, len_ = 0;  ///< buf_[pos_, len_) not yet read or skipped
  std::vector<unsigned char> ibuf_ = std::vector<unsigned char>(std::size_t{1} << 16);
};

/// The elements of volume `index` along axis `vaxis` of the stream `st`, in
/// nrrd order with that axis left out (axis 0 fastest), in the host's byte
/// order. Along the volume axis the data are runs of stride(vaxis) elements,
/// one run per volume, repeated for every index of the axes above it.
std::vector<unsigned char> nrrd_read_volume(const fs::path& path, const NrrdVolumeStream& st,
                                            int vaxis, int64_t index) {
  std::size_t run = st.esize;  // bytes of one volume's run
  for (int a = 0; a < vaxis; ++a) run *= st.size[static_cast<std::size_t>(a)];
  std::size_t outer = 1;
  for (int a = vaxis + 1; a < 4; ++a) outer *= st.size[static_cast<std::size_t>(a)];
  const auto vols = static_cast<uint64_t>(st.size[static_cast<std::size_t>(vaxis)]);
  const auto k = static_cast<uint64_t>(index);
  std::vector<unsigned char> out(run * outer);
  NrrdDataReader reader(path, st);
  for (std::size_t o = 0; o < outer; ++o) {
    reader.skip(k * run);
    reader.read(out.data() + o * run, run);
    if (o + 1 < outer) reader.skip((vols - 1 - k) * run);
  }
  if (st.swap && st.esize > 1)
    for (std::size_t i = 0; i < out.size(); i += st.esize)
      std::reverse(out.begin() + static_cast<std::ptrdiff_t>(i),
                   out.begin() + static_cast<std::ptrdiff_t>(i + st.esize));
  return out;
}

// ---------------------------------------------------------------- NIfTI

/// The three headers of the NIfTI family, as niftilib reads them.
enum class NiftiKind { analyze, nifti1, nifti2 };

struct NiftiHeaderInfo {
  NiftiKind kind = NiftiKind::nifti1;
  bool pair = false;  ///< the header and the voxels in two files (.hdr and .img)
  fs::path data;      ///< the file of the voxels (the header's own for a single file)
  std::array<int64_t, 3> dims{};
  int64_t volumes = 1;  ///< dim[4] * ... * dim[7]: 3-D volumes one after another
  int datatype = 0;
  int bitpix = 0;
  uint64_t vox_offset = 0;  ///< the voxels' first byte in `data`
  /// An Analyze 7.5 header's bytes 112 and 116 (funused1, funused2), which
  /// SPM writes as its scale factor and offset (niftilib ignores them).
  double analyze_slope = 0.0, analyze_inter = 0.0;
};

/// niftilib's nifti_type code of a header, as its reader sets it: that
/// reader gives a NIfTI-2 file the NIfTI-1 codes (3.0.1), so the code says
/// Analyze, single file or pair.
int nifti_type_code(const NiftiHeaderInfo& info) {
  if (info.kind == NiftiKind::analyze) return NIFTI_FTYPE_ANALYZE;
  return info.pair ? NIFTI_FTYPE_NIFTI1_2 : NIFTI_FTYPE_NIFTI1_1;
}

/// Whether `name` (lower case) is one half of a .hdr/.img pair.
bool pair_name(const std::string& name) {
  return has_suffix(name, {".hdr", ".hdr.gz", ".img", ".img.gz"});
}

/// The header of a pair named by its .img (or .img.gz); the path itself otherwise.
fs::path nifti_header_path(const fs::path& path) {
  const std::string name = lower(path.filename().string());
  if (!has_suffix(name, {".img", ".img.gz"})) return path;
  // (niftilib may offer a single file of the same name, x.nii for x.img:
  // not this image's header.)
  std::unique_ptr<char, decltype(&std::free)> hdr(nifti_findhdrname(path.c_str()), &std::free);
  const std::string found = hdr ? lower(fs::path(hdr.get()).filename().string()) : std::string();
  if (!hdr || !has_suffix(found, {".hdr", ".hdr.gz"}))
    throw FileError(path, "the header of this .img (the .hdr beside it, or .hdr.gz) is missing");
  return fs::path(hdr.get());
}

/// Counts the bytes of `data` (plain or gzip), up to `need`; throws if it
/// holds fewer. Errors name `path`, the file asked for.
void nifti_count_bytes(const fs::path& path, const fs::path& data, uint64_t need,
                       const std::string& what) {
  const uint64_t file_size = require_regular_file(data);
  gzFile gz = gzopen(data.c_str(), "rb");
  if (!gz) throw FileError(path, "cannot open " + data.string() + ": " + errno_text(errno));
  struct GzCloser {
    gzFile g;
    ~GzCloser() { gzclose(g); }
  } closer{gz};
  const std::string in = data == path ? std::string() : " (in " + data.string() + ")";
  if (gzdirect(gz) != 0) {
    if (file_size < need)
      throw FileError(path, "truncated data" + in + ": file has " + std::to_string(file_size) +
                                " bytes, " + what + " needs " + std::to_string(need));
    return;
  }
  // (reject absurd claims before decompressing)
  if (!deflate_could_hold(file_size, need))
    throw FileError(path, "truncated data" + in + ": " + std::to_string(file_size) +
                              " compressed bytes cannot hold the " + std::to_string(need) +
                              " bytes the " + what + " needs");
  uint64_t total = 0;
  std::vector<unsigned char> buf(1 << 16);
  while (total < need) {
    const int r = gzread(gz, buf.data(), static_cast<unsigned>(buf.size()));
    if (r < 0) {
      int zerr = 0;
      const char* msg = gzerror(gz, &zerr);
      throw FileError(path, "corrupt compressed data" + in + ": " + (msg ? msg : "?"));
    }
    if (r == 0) break;
    total += static_cast<uint64_t>(r);
  }
  if (total < need)
    throw FileError(path, "truncated data" + in + ": decompresses to " + std::to_string(total) +
                              " bytes, " + what + " needs " + std::to_string(need));
}

/// Reads a NIfTI-1, NIfTI-2 or Analyze 7.5 header (plain or gzip) from
/// `header` and counts the voxel file's bytes, so that a truncated or
/// corrupt file is found before niftilib allocates or reads anything. A
/// file of several 3-D volumes needs `index` (which one; the file must hold
/// the volumes up to it). Errors name `path`, the file asked for.
NiftiHeaderInfo nifti_precheck(const fs::path& path, const fs::path& header,
                               std::optional<int64_t> index) {
  watch_file(header);  // (load_volume: read again if a half of the pair changes)
  if (header != path) require_regular_file(header);  // (load_nifti checked `path`)
  const bool pair_named = pair_name(lower(header.filename().string()));
  const std::string in = header == path ? std::string() : " (in " + header.string() + ")";
  unsigned char h[540];
  int got = 0;
  {
    gzFile gz = gzopen(header.c_str(), "rb");
    if (!gz) throw FileError(path, "cannot open file: " + errno_text(errno));
    struct GzCloser {
      gzFile g;
      ~GzCloser() { gzclose(g); }
    } closer{gz};
    got = gzread(gz, h, sizeof h);
    if (got < 0) {
      int zerr = 0;
      const char* msg = gzerror(gz, &zerr);
      throw FileError(path, "corrupt compressed data in header" + in + ": " + (msg ? msg : "?"));
    }
  }
  if (got < 4)
    throw FileError(path, "truncated header" + in + " (" + std::to_string(got) + " bytes)");
  const int32_t sizeof_hdr_le = load_scalar<int32_t>(h, std::endian::native == std::endian::big);
  const int32_t sizeof_hdr_be = load_scalar<int32_t>(h, std::endian::native == std::endian::little);
  bool file_be;  // byte order of the file
  int32_t sizeof_hdr;
  if (sizeof_hdr_le == 348 || sizeof_hdr_le == 540) {
    file_be = false;
    sizeof_hdr = sizeof_hdr_le;
  } else if (sizeof_hdr_be == 348 || sizeof_hdr_be == 540) {
    file_be = true;
    sizeof_hdr = sizeof_hdr_be;
  } else {
    throw FileError(path, "not a NIfTI or Analyze file (garbage header" + in + ": sizeof_hdr is " +
                              std::to_string(sizeof_hdr_le) + ", expected 348 or 540)");
  }
  if (got < sizeof_hdr)
    throw FileError(
        path, std::string(sizeof_hdr == 540 ? "truncated NIfTI-2 header" : "truncated header") +
                  in + " (" + std::to_string(got) + " of " + std::to_string(sizeof_hdr) +
                  " bytes)");
  const bool swap = file_be != (std::endian::native == std::endian::big);
  auto i16 = [&](int off) { return load_scalar<int16_t>(h + off, swap); };
  auto f32 = [&](int off) { return load_scalar<float>(h + off, swap); };
  auto i64 = [&](int off) { return load_scalar<int64_t>(h + off, swap); };

  NiftiHeaderInfo info;
  const char* single_name = ".nii";
  if (sizeof_hdr == 348) {
    if (std::memcmp(h + 344, "n+1", 4) == 0) {
      info.kind = NiftiKind::nifti1;
    } else if (std::memcmp(h + 344, "ni1", 4) == 0) {
      info.kind = NiftiKind::nifti1;
      info.pair = true;
    } else if (pair_named) {
      info.kind = NiftiKind::analyze;  // Analyze 7.5: no magic
      info.pair = true;
    } else {
      throw FileError(path, "not a single-file NIfTI-1 (bad magic; expected n+1)");
    }
  } else {
    // (The magic's last 4 bytes, "\r\n\032\n", are left unchecked, as
    // niftilib does: its own writer leaves them 0.)
    info.kind = NiftiKind::nifti2;
    if (std::memcmp(h + 4, "n+2", 4) == 0)
      info.pair = false;
    else if (std::memcmp(h + 4, "ni2", 4) == 0)
      info.pair = true;
    else
      throw FileError(path, "not a NIfTI-2 file (bad magic" + in + "; expected n+2 or ni2)");
    single_name = ".nii (NIfTI-2)";
  }
  if (info.pair != pair_named)
    throw FileError(path, info.pair ? "holds the header of a .hdr/.img pair (magic ni1 or ni2), "
                                      "but is not named .hdr"
                                    : std::string("holds a single-file NIfTI (magic n+1 or n+2), "
                                                  "but is named as half of a .hdr/.img pair; "
                                                  "expected ") +
                                          single_name);

  // dim[0..7], datatype, bitpix, vox_offset: at their places in each header.
  const bool v2 = info.kind == NiftiKind::nifti2;
  auto dim = [&](int i) { return v2 ? i64(16 + 8 * i) : static_cast<int64_t>(i16(40 + 2 * i)); };
  const int64_t ndim = dim(0);
  if (ndim < 1 || ndim > 7)
    throw FileError(path,
                    "garbage header" + in + ": dim[0] is " + std::to_string(ndim) + " (1..7)");
  int64_t d[8];
  for (int i = 0; i < 8; ++i) d[i] = i <= ndim ? dim(i) : 1;
  for (int i = 1; i <= ndim; ++i)
    if (d[i] <= 0)
      throw FileError(path, "non-positive dimension" + in + ": dim[" + std::to_string(i) + "] is " +
                                std::to_string(d[i]));
  int64_t nvol = 1;
  for (int i = 4; i <= ndim; ++i) {
    if (nvol > std::numeric_limits<int64_t>::max() / d[i])
      throw FileError(path, "dims overflow" + in + ": dim[4..7] multiply past 2^63");
    nvol *= d[i];
  }
  pick_volume(path, nvol, index, "(a 4-D image)");

  info.volumes = nvol;
  info.dims = {d[1], ndim >= 2 ? d[2] : 1, ndim >= 3 ? d[3] : 1};
  info.datatype = v2 ? i16(12) : i16(70);
  info.bitpix = v2 ? i16(14) : i16(72);
  int want_bits = 0;
  switch (info.datatype) {
    case DT_UINT8:
    case DT_INT8:
      want_bits = 8;
      break;
    case DT_INT16:
    case DT_UINT16:
      want_bits = 16;
      break;
    case DT_INT32:
    case DT_UINT32:
    case DT_FLOAT32:
      want_bits = 32;
      break;
    case DT_FLOAT64:
    case DT_INT64:
    case DT_UINT64:
      want_bits = 64;
      break;
    default:
      throw FileError(path, "unsupported NIfTI datatype " + std::to_string(info.datatype) +
                                " (expected a scalar integer or float type)");
  }
  if (info.bitpix != want_bits)
    throw FileError(path, "garbage header" + in + ": bitpix " + std::to_string(info.bitpix) +
                              " does not match datatype " + std::to_string(info.datatype));
  // A single file's voxels follow its header; a pair's start where the
  // header says in the .img (0, as a rule).
  const double least = info.pair ? 0.0 : static_cast<double>(sizeof_hdr);
  const double vox = v2 ? static_cast<double>(i64(168)) : static_cast<double>(f32(108));
  if (!std::isfinite(vox) || vox < least || vox > 1e15)
    throw FileError(path, "garbage header" + in + ": vox_offset " + std::to_string(vox));
  info.vox_offset = static_cast<uint64_t>(vox);
  if (info.kind == NiftiKind::analyze) {
    info.analyze_slope = f32(112);
    info.analyze_inter = f32(116);
  }

  const std::size_t n = checked_count(path, info.dims, static_cast<std::size_t>(want_bits / 8));
  const uint64_t volume_bytes = static_cast<uint64_t>(n) * static_cast<uint64_t>(want_bits / 8);
  // The bytes up to the end of the volume read (all of them for one volume).
  const uint64_t through = static_cast<uint64_t>(index ? *index : 0) + 1;
  if (volume_bytes > (std::numeric_limits<uint64_t>::max() - info.vox_offset) / through)
    throw FileError(path, "dims " + dims_text(info.dims) + " overflow the file size");
  const uint64_t need = info.vox_offset + volume_bytes * through;

  info.data = header;
  if (info.pair) {
    std::unique_ptr<char, decltype(&std::free)> img(
        nifti_findimgname(header.c_str(), info.kind == NiftiKind::nifti2 ? NIFTI_FTYPE_NIFTI2_2
                                                                         : nifti_type_code(info)),
        &std::free);
    const std::string found = img ? lower(fs::path(img.get()).filename().string()) : std::string();
    if (!img || !has_suffix(found, {".img", ".img.gz"}))
      throw FileError(path, "the voxels' file of the pair (the .img beside " +
                                header.filename().string() + ", or .img.gz) is missing");
    info.data = fs::path(img.get());
  }
  watch_file(info.data);
  nifti_count_bytes(path, info.data, need, "header (dims " + dims_text(info.dims) + ")");
  return info;
}

template <typename T>
void nifti_copy(const void* data, std::size_t n, float* out, double slope, double inter,
                bool scaled) {
  const T* src = static_cast<const T*>(data);
  if (scaled)
    for (std::size_t i = 0; i < n; ++i)
      out[i] = static_cast<float>(static_cast<double>(src[i]) * slope + inter);
  else
    for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<float>(src[i]);
}

/// The orientation letters of a NIfTI image's axes: from its sform where
/// sform_code > 0, else its qform where qform_code > 0 (niftilib's
/// nifti_dmat44_to_orientation: the closest axes of an oblique matrix);
/// empty for Analyze, for neither, or for a matrix niftilib cannot read.
std::string nifti_orientation(const nifti_image* nim, const NiftiHeaderInfo& info) {
  if (info.kind == NiftiKind::analyze) return {};
  const nifti_dmat44* m = nim->sform_code > 0   ? &nim->sto_xyz
                          : nim->qform_code > 0 ? &nim->qto_xyz
                                                : nullptr;
  if (!m) return {};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(m->m[r][c])) return {};
  int code[3] = {0, 0, 0};
  nifti_dmat44_to_orientation(*m, &code[0], &code[1], &code[2]);
  std::string letters;
  for (int c : code) {
    switch (c) {
      case NIFTI_L2R:
        letters += 'R';
        break;
      case NIFTI_R2L:
        letters += 'L';
        break;
      case NIFTI_P2A:
        letters += 'A';
        break;
      case NIFTI_A2P:
        letters += 'P';
        break;
      case NIFTI_I2S:
        letters += 'S';
        break;
      case NIFTI_S2I:
        letters += 'I';
        break;
      default:
        return {};
    }
  }
  return valid_orientation(letters) ? letters : std::string();
}

// ---------------------------------------------------------------- writing

template <typename T>
void store_integer(const fs::path& path, const std::vector<float>& src, unsigned char* dst) {
  constexpr double lo = static_cast<double>(std::numeric_limits<T>::min());
  constexpr double hi = static_cast<double>(std::numeric_limits<T>::max());
  for (std::size_t i = 0; i < src.size(); ++i) {
    const float v = src[i];
    if (std::isnan(v))
      throw FileError(
          path, "voxel " + std::to_string(i) + " is NaN and cannot be stored as an integer type");
    const double r = std::clamp(std::nearbyint(static_cast<double>(v)), lo, hi);
    const T t = static_cast<T>(r);
    std::memcpy(dst + i * sizeof(T), &t, sizeof(T));
  }
}

std::string format_double(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

}  // namespace

// ================================================================ loaders

Volume load_raw(const std::filesystem::path& path, const RawLayout& layout) {
  const uint64_t file_size = require_regular_file(path);
  const std::size_t bpv = voxel_bytes(layout.type);
  if (bpv == 0)
    throw FileError(path, "unknown voxel type " + std::to_string(static_cast<int>(layout.type)) +
                              " in the raw layout");
  const std::size_t n = checked_count(path, layout.dims, bpv);
  const uint64_t data_bytes = static_cast<uint64_t>(n) * bpv;
  if (data_bytes > std::numeric_limits<uint64_t>::max() - layout.header_bytes)
    throw FileError(path,
                    "header bytes plus dims " + dims_text(layout.dims) + " overflow the file size");
  const uint64_t need = layout.header_bytes + data_bytes;
  if (file_size < need)
    throw FileError(path, "truncated data: file has " + std::to_string(file_size) + " bytes, but " +
                              std::to_string(layout.header_bytes) + " header bytes + " +
                              dims_text(layout.dims) + " " + std::string(to_string(layout.type)) +
                              " voxels need " + std::to_string(need));
  if (file_size > need)
    throw FileError(path,
                    "file size disagrees with the layout: file has " + std::to_string(file_size) +
                        " bytes, but " + std::to_string(layout.header_bytes) + " header bytes + " +
                        dims_text(layout.dims) + " " + std::string(to_string(layout.type)) +
                        " voxels need " + std::to_string(need) + " (file is larger than expected)");
  std::array<double, 3> spacing = layout.spacing;
  for (int a = 0; a < 3; ++a)
    if (!(spacing[a] > 0.0) || !std::isfinite(spacing[a]))
      throw FileError(path, "voxel spacing " + std::to_string(spacing[a]) + " along axis " +
                                std::to_string(a) + " must be positive and finite");

  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path, "cannot open file: " + errno_text(errno));
  in.seekg(static_cast<std::streamoff>(layout.header_bytes));
  if (!in) throw FileError(path, "cannot seek past the header");
  Volume vol(layout.dims, layout.type, spacing);
  const bool file_big = layout.endian == Endian::big;
  const bool swap = file_big != (std::endian::native == std::endian::big);
  read_voxels(path, in, layout.type, swap, vol);
  return vol;
}

Volume load_den(const std::filesystem::path& path) {
  // VolPack 1.0b3 examples/denfile.c (read_den/write_den): a 62-byte header
  // written in the writer's native byte order:
  //   int16 map_version (1; 0x0100 when byte-swapped, which gives the order)
  //   int16 orig_min[3], orig_max[3], orig_len[3],
  //         extr_min[3], extr_max[3], extr_len[3],
  //         map_min[3],  map_max[3],  map_len[3]   (map_len at byte 50)
  //   int16 map_warps                               (byte 56)
  //   int32 map_length = product of map_len         (byte 58)
  // then map_length 8-bit voxels, x fastest.
  constexpr std::size_t header = 62;
  const uint64_t file_size = require_regular_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path, "cannot open file: " + errno_text(errno));
  unsigned char h[header];
  in.read(reinterpret_cast<char*>(h), header);
  const auto got = static_cast<std::size_t>(in.gcount());
  if (got < 2) throw FileError(path, "truncated header (" + std::to_string(got) + " bytes)");
  bool file_be;
  if (h[0] == 1 && h[1] == 0)
    file_be = false;
  else if (h[0] == 0 && h[1] == 1)
    file_be = true;
  else
    throw FileError(path, "not a VolPack .den file (garbage header: bad version/magic " +
                              std::to_string(h[0]) + " " + std::to_string(h[1]) + ")");
  if (got < header)
    throw FileError(path, "truncated header (" + std::to_string(got) + " of 62 bytes)");
  const bool swap = file_be != (std::endian::native == std::endian::big);
  const std::array<int64_t, 3> dims{load_scalar<int16_t>(h + 50, swap),
                                    load_scalar<int16_t>(h + 52, swap),
                                    load_scalar<int16_t>(h + 54, swap)};
  const std::size_t n = checked_count(path, dims, 1);
  const int32_t map_length = load_scalar<int32_t>(h + 58, swap);
  if (map_length < 0 || static_cast<uint64_t>(map_length) != n)
    throw FileError(path, "inconsistent header: map_length " + std::to_string(map_length) +
                              " is not the product of the dims " + dims_text(dims));
  const uint64_t need = header + static_cast<uint64_t>(n);
  if (file_size < need)
    throw FileError(path, "truncated data: file has " + std::to_string(file_size) +
                              " bytes, header (dims " + dims_text(dims) + ") needs " +
                              std::to_string(need));
  if (file_size > need)
    throw FileError(path, "file size disagrees with the header: file has " +
                              std::to_string(file_size) + " bytes, dims " + dims_text(dims) +
                              " need " + std::to_string(need) + " (trailing bytes)");
  Volume vol(dims, VoxelType::u8);
  read_voxels(path, in, VoxelType::u8, false, vol);
  return vol;
}

Volume load_nrrd(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                 int64_t* volumes) {
  const uint64_t file_size = require_regular_file(path);
  const std::string name = path.string();
  nrrd_prescan_header(path);

  // Pass 1: the header only, to validate the shape and the data size
  // before teem allocates anything.
  NrrdShape shape;
  VoxelType vtype;
  std::optional<NrrdVolumeStream> stream;  // one volume of a 4-D file, read alone
  std::vector<fs::path> data_files;        // a detached header's (Volume::companion_files)
  {
    NrrdPtr hdr(nrrdNew());
    NioPtr nio(nrrdIoStateNew());
    if (!hdr || !nio) throw FileError(path, "out of memory");
    nio->skipData = 1;
    if (nrrdLoad(hdr.get(), name.c_str(), nio.get()))
      throw FileError(path, "cannot read NRRD header: " + biff_message(NRRD));
    if (nio->format != nrrdFormatNRRD)
      throw FileError(path,
                      std::string("not a NRRD file (teem read it as ") + nio->format->name + ")");
    shape = nrrd_shape(path, hdr.get(), volume_index);
    vtype = nrrd_voxel_type(path, hdr->type);
    const std::size_t esize = nrrdElementSize(hdr.get());
    // Every volume of a 4-D nrrd: teem reads them all.
    const std::size_t n = checked_count(path, shape.dims, esize * shape.volumes) *
                          static_cast<std::size_t>(shape.volumes);
    const uint64_t need = static_cast<uint64_t>(n) * esize;

    uint64_t available = 0;
    const std::vector<fs::path> files = nrrd_data_files(path, nio.get());
    data_files = files;
    for (const fs::path& f : files) watch_file(f);  // (load_volume: read again if one changes)
    if (files.empty()) {
      // attached: the data follow the header in this file
      const std::optional<uint64_t> off = nrrd_header_end(path);
      available = off && *off <= file_size ? file_size - *off : file_size;
    } else {
      for (const fs::path& f : files) {
        std::error_code ec;
        const uintmax_t s = fs::file_size(f, ec);
        if (ec) throw FileError(path, "data file " + f.string() + ": " + ec.message());
        available += static_cast<uint64_t>(s);
      }
    }
    const NrrdEncoding* enc = nio->encoding;
    const std::string ename = enc ? enc->name : "?";
    bool enough = true;
    if (ename == "raw")
      enough = need <= available;
    else if (ename == "gzip")
      enough = deflate_could_hold(available, need);
    else if (ename == "ascii" || ename == "text" || ename == "txt")
      enough = n <= available / 2 + 1;
    else if (ename == "hex")
      enough = need <= available / 2 + 1;
    // bzip2 can compress without useful bound; teem's own read reports shortness.
    if (!enough)
      throw FileError(path, "truncated data: " + std::to_string(available) + " bytes of " + ename +
                                " data cannot hold the " + std::to_string(need) +
                                " bytes the header (dims " + dims_text(shape.dims) + ") needs");
    // Gzip data in one file with no skips: decode them once first, so that
    // corrupt or short streams fail here (teem leaks when it finds them).
    if (ename == "gzip" && files.size() <= 1 && nio->lineSkip == 0 && nio->byteSkip == 0 &&
        !nio->dataFSkip) {
      if (files.empty()) {
        const std::optional<uint64_t> off = nrrd_header_end(path);
        if (off) nrrd_gzip_precheck(path, path, *off, need);
      } else {
        nrrd_gzip_precheck(path, files[0], 0, need);
      }
    }
    // Raw data in one file with no skips must match the header exactly
    // (teem itself only notices data that are too short).
    if (ename == "raw" && files.size() <= 1 && nio->lineSkip == 0 && nio->byteSkip == 0 &&
        !nio->dataFSkip) {
      uint64_t data_bytes = available;
      bool known = true;
      if (files.empty()) {
        const std::optional<uint64_t> off = nrrd_header_end(path);
        if (off)
          data_bytes = file_size - *off;
        else
          known = false;
      }
      if (known && data_bytes != need)
        throw FileError(path, std::string(data_bytes < need ? "truncated data"
                                                            : "data size disagrees "
                                                              "with the header") +
                                  ": " + std::to_string(data_bytes) +
                                  " bytes of raw data, but dims " + dims_text(shape.dims) + " of " +
                                  airEnumStr(nrrdType, hdr->type) + " need " +
                                  std::to_string(need));
    }
    // A volume of a 4-D file whose data are one raw or gzip stream: read
    // alone (nrrd_read_volume), not all of them through teem.
    const bool byte_order_known =
        esize == 1 || nio->endian == airEndianLittle || nio->endian == airEndianBig;
    if (shape.volumes > 1 && hdr->dim == 4 && files.size() <= 1 && nio->lineSkip == 0 &&
        !nio->dataFSkip && byte_order_known &&
        ((ename == "raw" && nio->byteSkip >= 0) || (ename == "gzip" && nio->byteSkip == 0))) {
      const std::optional<uint64_t> start =
          files.empty() ? nrrd_header_end(path) : std::optional<uint64_t>(0);
      if (start) {
        NrrdVolumeStream st;
        st.data = files.empty() ? path : files[0];
        st.gzip = ename == "gzip";
        st.offset = *start + (st.gzip ? 0 : static_cast<uint64_t>(nio->byteSkip));
        st.swap =
            esize > 1 && (nio->endian == airEndianBig) != (std::endian::native == std::endian::big);
        st.type = hdr->type;
        st.esize = esize;
        for (unsigned int a = 0; a < 4; ++a) st.size[a] = hdr->axis[a].size;
        stream = st;
      }
    }
  }

  // Pass 2: the data (teem reads them all), or the header again and the
  // one volume's data from the stream.
  NrrdPtr nrrd(nrrdNew());
  NioPtr nio(nrrdIoStateNew());
  if (!nrrd || !nio) throw FileError(path, "out of memory");
  if (stream) nio->skipData = 1;
  if (nrrdLoad(nrrd.get(), name.c_str(), nio.get()))
    throw FileError(path, "cannot read NRRD data: " + biff_message(NRRD));
  if (!stream && !nrrd->data) throw FileError(path, "NRRD has no data");
  const NrrdShape s = nrrd_shape(path, nrrd.get(), volume_index);
  if (s.dims != shape.dims || s.volumes != shape.volumes || s.volume_axis != shape.volume_axis)
    throw FileError(path, "NRRD changed while being read");
  if (volumes) *volumes = s.volumes;

  // What nrrd_copy reads: the whole nrrd and its shape, or the one volume
  // wrapped as a 3-D nrrd (its axes numbered without the volume axis).
  const Nrrd* src = nrrd.get();
  NrrdShape cs = s;
  std::vector<unsigned char> one;
  struct NixDeleter {
    void operator()(Nrrd* n) const { nrrdNix(n); }  // the struct only: `one` holds the data
  };
  std::unique_ptr<Nrrd, NixDeleter> wrapped;
  if (stream) {
    one = nrrd_read_volume(path, *stream, s.volume_axis, s.index);
    std::size_t sizes[3];
    unsigned int j = 0;
    for (unsigned int a = 0; a < 4; ++a)
      if (static_cast<int>(a) != s.volume_axis) sizes[j++] = stream->size[a];
    wrapped.reset(nrrdNew());
    if (!wrapped || nrrdWrap_nva(wrapped.get(), one.data(), stream->type, 3, sizes))
      throw FileError(path, "out of memory");
    for (unsigned int& a : cs.axes)
      if (static_cast<int>(a) > s.volume_axis) --a;
    cs.volume_axis = -1;
    cs.index = 0;
    src = wrapped.get();
  }

  Volume vol(s.dims, vtype, s.spacing);
  float* out = vol.data().data();
  switch (src->type) {
    case nrrdTypeChar:
      nrrd_copy<signed char>(src, cs, out);
      break;
    case nrrdTypeUChar:
      nrrd_copy<unsigned char>(src, cs, out);
      break;
    case nrrdTypeShort:
      nrrd_copy<int16_t>(src, cs, out);
      break;
    case nrrdTypeUShort:
      nrrd_copy<uint16_t>(src, cs, out);
      break;
    case nrrdTypeInt:
      nrrd_copy<int32_t>(src, cs, out);
      break;
    case nrrdTypeUInt:
      nrrd_copy<uint32_t>(src, cs, out);
      break;
    case nrrdTypeLLong:
      nrrd_copy<long long>(src, cs, out);
      break;
    case nrrdTypeULLong:
      nrrd_copy<unsigned long long>(src, cs, out);
      break;
    case nrrdTypeFloat:
      nrrd_copy<float>(src, cs, out);
      break;
    case nrrdTypeDouble:
      nrrd_copy<double>(src, cs, out);
      break;
    default:
      throw FileError(path, "unsupported NRRD type");
  }
  vol.set_orientation(nrrd_orientation(nrrd.get(), s.axes));
  for (const fs::path& f : data_files) vol.add_companion_file(f);
  return vol;
}

Volume load_nifti(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                  int64_t* volumes) {
  require_regular_file(path);
  const fs::path header = nifti_header_path(path);
  const NiftiHeaderInfo info = nifti_precheck(path, header, volume_index);
  const int64_t index = volume_index ? *volume_index : 0;
  if (volumes) *volumes = info.volumes;

  nifti_set_debug_level(0);  // niftilib reports on stderr otherwise
  struct NimDeleter {
    void operator()(nifti_image* p) const { nifti_image_free(p); }
  };
  // The header first; the voxels after the checks below.
  std::unique_ptr<nifti_image, NimDeleter> nim(nifti_image_read(header.c_str(), 0));
  if (!nim) throw FileError(path, "niftilib could not read the file (corrupt or truncated)");
  const int type_read = nim->nifti_type == NIFTI_FTYPE_NIFTI2_1   ? NIFTI_FTYPE_NIFTI1_1
                        : nim->nifti_type == NIFTI_FTYPE_NIFTI2_2 ? NIFTI_FTYPE_NIFTI1_2
                                                                  : nim->nifti_type;
  if (type_read != nifti_type_code(info))
    throw FileError(path, "niftilib reads the header as file type " +
                              std::to_string(nim->nifti_type) + ", not " +
                              std::to_string(nifti_type_code(info)));
  const std::array<int64_t, 3> dims{nim->nx, nim->ny, nim->nz};
  if (dims != info.dims)
    throw FileError(path, "niftilib dims " + dims_text(dims) + " disagree with the header " +
                              dims_text(info.dims));
  if (nim->iname_offset < 0 || static_cast<uint64_t>(nim->iname_offset) != info.vox_offset)
    throw FileError(path, "niftilib's voxel offset " + std::to_string(nim->iname_offset) +
                              " disagrees with the header's " + std::to_string(info.vox_offset));
  const std::size_t n = checked_count(path, dims, static_cast<std::size_t>(nim->nbyper));
  if (nim->nvox <= 0 ||
      static_cast<uint64_t>(nim->nvox) / n != static_cast<uint64_t>(info.volumes) ||
      static_cast<uint64_t>(nim->nvox) % n != 0)
    throw FileError(path, "voxel count disagrees with the dims");
  // niftilib's reader (nifti_read_buffer) replaces every NaN and Inf of a
  // float volume by 0 as it reads, without a word: a background masked
  // with NaN would become voxels of value 0, which a classification may
  // make opaque. Float voxels are read as the file stores them instead
  // (znzlib, plain and gzip alike, from the image's offset in the voxels'
  // file, swapped as niftilib swaps them); NaN voxels then render
  // transparent (docs/HARDENING.md). So is the one volume asked for of a
  // 4-D file, of any type (niftilib would read them all). Other types
  // through niftilib.
  std::vector<unsigned char> stored;
  const void* d = nullptr;
  if (nim->datatype == DT_FLOAT32 || nim->datatype == DT_FLOAT64 || info.volumes > 1) {
    const std::size_t bytes = n * static_cast<std::size_t>(nim->nbyper);
    stored.resize(bytes);
    znzFile fp = znzopen(info.data.c_str(), "rb", nifti_is_gzfile(info.data.c_str()));
    if (znz_isnull(fp)) throw FileError(path, "could not be opened for its voxels");
    // (the pre-check bounded the offset: below the file's size, or its
    // decompressed size, which it counted)
    const auto offset =
        static_cast<long>(info.vox_offset) + static_cast<long>(index) * static_cast<long>(bytes);
    const bool at = znzseek(fp, offset, SEEK_SET) >= 0;
    const std::size_t got = at ? znzread(stored.data(), 1, bytes, fp) : 0;
    znzclose(fp);
    if (got > bytes)  // (znzread of a .gz passes gzread's -1 on as a size_t)
      throw FileError(path, "its voxel data could not be read (corrupt compressed data?)");
    if (got != bytes)
      throw FileError(path, "holds " + std::to_string(got) + " of the " + std::to_string(bytes) +
                                " bytes of voxel data its header promises (truncated?)");
    if (nim->byteorder != nifti_short_order() && nim->nbyper > 1)
      nifti_swap_Nbytes(static_cast<int64_t>(n), nim->nbyper, stored.data());
    d = stored.data();
  } else {
    if (nifti_image_load(nim.get()) != 0 || !nim->data)
      throw FileError(path, "niftilib read no voxel data (truncated?)");
    d = nim->data;
  }

  // An Analyze header's scale is SPM's (bytes 112 and 116), which niftilib
  // does not read; NIfTI's is scl_slope and scl_inter.
  const bool analyze = info.kind == NiftiKind::analyze;
  const double slope = analyze ? info.analyze_slope : nim->scl_slope;
  const double inter = analyze ? info.analyze_inter : nim->scl_inter;
  const bool scaled = std::isfinite(slope) && slope != 0.0 &&
                      (slope != 1.0 || (std::isfinite(inter) && inter != 0.0));
  const double inter_used = std::isfinite(inter) ? inter : 0.0;

  VoxelType vtype = VoxelType::f32;
  if (!scaled) switch (nim->datatype) {
      case DT_UINT8:
        vtype = VoxelType::u8;
        break;
      case DT_UINT16:
        vtype = VoxelType::u16;
        break;
      case DT_INT16:
      case DT_INT8:
        vtype = VoxelType::i16;
        break;
      default:
        vtype = VoxelType::f32;
        break;
    }
  const std::array<double, 3> spacing = sane_spacing(
      {static_cast<double>(nim->dx), static_cast<double>(nim->dy), static_cast<double>(nim->dz)});
  Volume vol(dims, vtype, spacing);
  float* out = vol.data().data();
  switch (nim->datatype) {
    case DT_UINT8:
      nifti_copy<uint8_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_INT8:
      nifti_copy<int8_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_INT16:
      nifti_copy<int16_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_UINT16:
      nifti_copy<uint16_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_INT32:
      nifti_copy<int32_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_UINT32:
      nifti_copy<uint32_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_INT64:
      nifti_copy<int64_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_UINT64:
      nifti_copy<uint64_t>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_FLOAT32:
      nifti_copy<float>(d, n, out, slope, inter_used, scaled);
      break;
    case DT_FLOAT64:
      nifti_copy<double>(d, n, out, slope, inter_used, scaled);
      break;
    default:
      throw FileError(path, "unsupported NIfTI datatype " + std::to_string(nim->datatype));
  }
  vol.set_orientation(nifti_orientation(nim.get(), info));
  // A pair: both halves, whichever was named (.hdr or .img, plain or .gz).
  for (const fs::path& f : {header, info.data})
    if (f != path) vol.add_companion_file(f);
  return vol;
}

VolumeFileKind volume_file_kind(const std::filesystem::path& path) {
  const std::string name = lower(path.filename().string());
  if (has_suffix(name, {".nii", ".nii.gz", ".hdr", ".hdr.gz", ".img", ".img.gz"}))
    return VolumeFileKind::nifti;
  if (has_suffix(name, {".nrrd", ".nhdr"})) return VolumeFileKind::nrrd;
  if (has_suffix(name, {".mha", ".mhd"})) return VolumeFileKind::metaimage;
  if (has_suffix(name, {".mgh", ".mgz", ".mgh.gz"})) return VolumeFileKind::mgh;
  if (has_suffix(name, {".mnc"})) return VolumeFileKind::minc;
  if (has_suffix(name, {".den"})) return VolumeFileKind::den;
  if (has_suffix(name, {".raw"})) return VolumeFileKind::raw;
  if (has_suffix(name, {".dcm", ".dicom", ".ima"}) || name == "dicomdir")
    return VolumeFileKind::dicom;
  std::error_code ec;
  if (fs::is_directory(path, ec)) return VolumeFileKind::dicom;
  if (fs::is_regular_file(path, ec)) {
    std::ifstream in(path, std::ios::binary);
    char b[132] = {};
    if (in.read(b, sizeof b) && std::memcmp(b + 128, "DICM", 4) == 0) return VolumeFileKind::dicom;
  }
  return VolumeFileKind::unknown;
}

namespace {

Volume load_volume_once(const std::filesystem::path& path, const std::optional<RawLayout>& raw,
                        std::optional<int64_t> volume_index, int64_t* volumes) {
  if (volumes) *volumes = 1;
  const VolumeFileKind kind = volume_file_kind(path);
  // A directory is a DICOM series, unless its name says another format.
  if (kind != VolumeFileKind::dicom) refuse_directory(path);
  if (kind == VolumeFileKind::nifti) return load_nifti(path, volume_index, volumes);
  if (kind == VolumeFileKind::nrrd) return load_nrrd(path, volume_index, volumes);
  if (kind == VolumeFileKind::dicom) return load_dicom(path, volume_index, volumes);
  if (kind == VolumeFileKind::metaimage) return load_metaimage(path, volume_index, volumes);
  if (kind == VolumeFileKind::mgh) return load_mgh(path, volume_index, volumes);
  if (kind == VolumeFileKind::minc) return load_minc(path, volume_index, volumes);
  if (volume_index)
    throw FileError(path, std::string("a volume index applies only to NIfTI, NRRD, MetaImage, MGH, "
                                      "MINC and DICOM (") +
                              std::string(kSeriesFileNames) + ")");
  if (kind == VolumeFileKind::den) return load_den(path);
  if (kind == VolumeFileKind::raw) {
    if (!raw)
      throw FileError(path, "a .raw file needs its layout (dims, type, endianness) to be given");
    return load_raw(path, *raw);
  }
  // A name that cannot be looked up is told as such, not as its ending
  // (a missing file, or a loop of symbolic links, was "unknown volume file
  // extension ''").
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st))
    throw FileError(path, ec && ec != std::errc::no_such_file_or_directory
                              ? ec.message()
                              : std::string("no such file"));
  throw FileError(path, "unknown volume file extension '" + path.extension().string() +
                            "' (expected " + std::string(kVolumeFileNames) + ")");
}

}  // namespace

std::optional<FileIdentity> file_identity(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  if (S_ISDIR(st.st_mode)) return FileIdentity{st.st_dev, st.st_ino, 0, {}, {}};
  return FileIdentity{st.st_dev, st.st_ino, st.st_size, st.st_mtim, st.st_ctim};
}

namespace {

/// The files one load_volume's read has met (watch_file), on its thread.
struct ReadWatch {
  std::vector<WatchedFile> files;
  std::unordered_set<std::string> names;
};
thread_local ReadWatch* t_read_watch = nullptr;

/// Makes `w` this thread's watch while it lives (the one before after).
class WatchScope {
 public:
  explicit WatchScope(ReadWatch& w) : before_(t_read_watch) { t_read_watch = &w; }
  ~WatchScope() { t_read_watch = before_; }
  WatchScope(const WatchScope&) = delete;
  WatchScope& operator=(const WatchScope&) = delete;

 private:
  ReadWatch* before_;
};

/// The first of `w`'s files that is not what it was when the read met it.
const WatchedFile* changed_file(const ReadWatch& w) {
  for (const WatchedFile& f : w.files)
    if (file_identity(f.path) != f.identity) return &f;
  return nullptr;
}

}  // namespace

bool watching_files() {
  return t_read_watch != nullptr;
}

void watch_file(const std::filesystem::path& file, const std::optional<FileIdentity>& identity) {
  if (!t_read_watch || !t_read_watch->names.insert(file.string()).second) return;
  t_read_watch->files.push_back({file, identity});
}

void watch_file(const std::filesystem::path& file) {
  if (t_read_watch && !t_read_watch->names.contains(file.string()))
    watch_file(file, file_identity(file));
}

std::vector<WatchedFile> watched_files() {
  return t_read_watch ? t_read_watch->files : std::vector<WatchedFile>{};
}

// The loaders open the file by its name several times (its size, a header
// pass, the data; teem, niftilib and GDCM each by name): a file another
// program replaces meanwhile, as every careful writer does (a temporary
// file renamed over it: simdvol's own), was read half from the old file
// and half from the new, and refused as "truncated data" (the old size
// against the new header) where neither file is. And they read other files
// beside it (a detached header's data files, a pair's other half, a DICOM
// series' slices, one after another), which a writer replacing them mixed
// into a volume the files never held together. So the path is looked up
// before the read, and every other file the read met (watch_file) when it
// first met it, and all of them again after: where one names another file
// (or the same file changed) the volume is read again, up to three times.
// (One stat a file each time: a series of 300 slices is 600 more.)
Volume load_volume(const std::filesystem::path& path, const std::optional<RawLayout>& raw,
                   std::optional<int64_t> volume_index, int64_t* volumes) {
  constexpr int kReads = 3;
  for (int read = 1;; ++read) {
    ReadWatch watch;
    const WatchedFile* changed = nullptr;
    {
      const WatchScope scope(watch);
      watch_file(path);
      try {
        Volume vol = load_volume_once(path, raw, volume_index, volumes);
        changed = changed_file(watch);
        if (!changed) return vol;
      } catch (const FileError&) {
        changed = changed_file(watch);
        if (!changed) throw;  // the files' own fault
      }
    }
    if (read < kReads) {
      // A file renamed over the path is replaced at once: read it again at
      // once. A writer of several files (a series' slices) takes a while:
      // the next read waits for it, 10 ms, then 100 ms.
      if (changed->path != path)
        std::this_thread::sleep_for(std::chrono::milliseconds(read == 1 ? 10 : 100));
      continue;
    }
    throw FileError(
        path, (changed->path == path ? std::string() : "its file " + changed->path.string() + " ") +
                  "changed while being read, " + std::to_string(kReads) +
                  " times running (is another program writing it?)");
  }
}

void refuse_non_regular_file(const fs::path& path, const char* noun) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (fs::is_directory(st)) throw FileError(path, std::string("is a directory, not ") + noun);
  if (fs::exists(st) && !fs::is_regular_file(st)) throw FileError(path, "is not a regular file");
}

fs::path write_target(const fs::path& path) {
  fs::path p = path;
  for (int links = 0; links < 40; ++links) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) return p;
    const fs::path to = fs::read_symlink(p, ec);
    if (ec)
      throw FileError(path, "cannot read the symbolic link " + p.string() + ": " + ec.message());
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  throw FileError(path, "too many levels of symbolic links");
}

bool write_fully(int fd, const void* p, std::size_t n) {
  const char* c = static_cast<const char*>(p);
  while (n > 0) {
    const ssize_t w = ::write(fd, c, std::min<std::size_t>(n, std::size_t{1} << 30));
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    c += w;
    n -= static_cast<std::size_t>(w);
  }
  return true;
}

bool read_fully(int fd, void* p, std::size_t n) {
  char* c = static_cast<char*>(p);
  while (n > 0) {
    const ssize_t r = ::read(fd, c, std::min<std::size_t>(n, std::size_t{1} << 30));
    if (r < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    if (r == 0) return false;
    c += r;
    n -= static_cast<std::size_t>(r);
  }
  return true;
}

bool has_suffix(std::string_view name, std::initializer_list<std::string_view> suffixes) {
  for (std::string_view s : suffixes)
    if (name.size() > s.size() && name.ends_with(s)) return true;
  return false;
}

// ================================================================ writer

void write_file_atomically(const fs::path& path, std::initializer_list<std::string_view> parts) {
  // Beside the file replaced (path, or its symbolic link's target: so the
  // rename is atomic and keeps the link).
  TempFile tmp(write_target(path), path);
  bool ok = true;
  for (std::string_view part : parts) ok = ok && write_fully(tmp.fd(), part.data(), part.size());
  if (!ok) {
    const int e = errno;
    tmp.fail("write failed: " + errno_text(e));
  }
  tmp.commit();
}

void save_nrrd(const Volume& vol, const std::filesystem::path& path) {
  if (vol.voxel_count() == 0) throw FileError(path, "cannot save an empty volume");
  const VoxelType t = vol.type();
  const std::size_t bpv = voxel_bytes(t);
  const std::size_t n = checked_count(path, vol.dims(), bpv);
  if (n != vol.voxel_count()) throw FileError(path, "volume data disagree with its dims");

  std::vector<unsigned char> bytes(n * bpv);
  switch (t) {
    case VoxelType::u8:
      store_integer<uint8_t>(path, vol.data(), bytes.data());
      break;
    case VoxelType::u16:
      store_integer<uint16_t>(path, vol.data(), bytes.data());
      break;
    case VoxelType::i16:
      store_integer<int16_t>(path, vol.data(), bytes.data());
      break;
    case VoxelType::f32:
      std::memcpy(bytes.data(), vol.data().data(), n * sizeof(float));
      break;
  }

  const char* type_name = t == VoxelType::u8    ? "uint8"
                          : t == VoxelType::u16 ? "uint16"
                          : t == VoxelType::i16 ? "int16"
                                                : "float";
  std::string header = "NRRD0004\n";
  header += "# Complete NRRD file format specification at:\n";
  header += "# http://teem.sourceforge.net/nrrd/format.html\n";
  header += std::string("type: ") + type_name + "\n";
  header += "dimension: 3\n";
  header += "sizes: " + std::to_string(vol.nx()) + " " + std::to_string(vol.ny()) + " " +
            std::to_string(vol.nz()) + "\n";
  if (vol.orientation().empty()) {
    header += "spacings: " + format_double(vol.spacing()[0]) + " " +
              format_double(vol.spacing()[1]) + " " + format_double(vol.spacing()[2]) + "\n";
  } else {
    // Where the axes point: each axis's direction in RAS space, its length
    // the spacing (teem takes no spacings beside space directions).
    header += "space: right-anterior-superior\nspace directions:";
    for (int a = 0; a < 3; ++a) {
      const char c = vol.orientation()[static_cast<std::size_t>(a)];
      const int axis = c == 'R' || c == 'L' ? 0 : c == 'A' || c == 'P' ? 1 : 2;
      const double len = (c == 'R' || c == 'A' || c == 'S') ? vol.spacing()[a] : -vol.spacing()[a];
      std::string dir = " (";
      for (int k = 0; k < 3; ++k) {
        if (k > 0) dir += ',';
        dir += format_double(k == axis ? len : 0.0);
      }
      header += dir;
      header += ')';
    }
    header += "\n";
  }
  if (bpv > 1)
    header += std::string("endian: ") +
              (std::endian::native == std::endian::little ? "little" : "big") + "\n";
  header += "encoding: raw\n\n";

  write_file_atomically(
      path, {header, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size())});
}

}  // namespace simdvol
