// MetaImage volumes (.mha, .mhd) through MetaIO, the reader ITK, VTK,
// 3D Slicer and elastix use (ITK's copy: libITKMetaIO). MetaIO parses the
// header and reads the voxels; what it does not check is checked here:
// it reports a short data file, a failed decompression or a missing data
// file on std::cerr and reads on (its Read returns true with the voxels
// half filled), and it allocates whatever the header's sizes ask for. So
// the sizes are checked before anything is read, its messages are caught
// while it reads, and any message it writes while reading the voxels
// makes the file an error that quotes it.
#include <metaImage.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <mutex>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "file_checks.hpp"
#include "read_watch.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

/// Catches what MetaIO writes to std::cerr and std::cout while it lives
/// (MetaIO has no other way to report; some warnings go to std::cout),
/// one load at a time.
class MetaIOMessages {
 public:
  MetaIOMessages()
      : lock_(mutex()),
        old_err_(std::cerr.rdbuf(text_.rdbuf())),
        old_out_(std::cout.rdbuf(text_.rdbuf())) {}
  ~MetaIOMessages() {
    std::cout.rdbuf(old_out_);
    std::cerr.rdbuf(old_err_);
  }
  MetaIOMessages(const MetaIOMessages&) = delete;
  MetaIOMessages& operator=(const MetaIOMessages&) = delete;

  /// What was written since the last take, on one line ("" if nothing).
  std::string take() {
    std::string s = text_.str();
    text_.str(std::string());
    std::replace(s.begin(), s.end(), '\n', ' ');
    std::string one;
    for (char c : s)  // runs of blanks as one
      if (!(c == ' ' && (one.empty() || one.back() == ' '))) one += c;
    while (!one.empty() && one.back() == ' ') one.pop_back();
    if (one.size() > 300) one = one.substr(0, 300) + "...";
    return one;
  }

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  std::lock_guard<std::mutex> lock_;
  std::ostringstream text_;
  std::streambuf* old_err_;
  std::streambuf* old_out_;
};

/// The byte size of a scalar MetaIO element type; 0 for the types that
/// are not one number per element (strings, arrays, matrices, none).
std::size_t scalar_bytes(MET_ValueEnumType t) {
  switch (t) {
    case MET_ASCII_CHAR:
    case MET_CHAR:
    case MET_UCHAR:
    case MET_SHORT:
    case MET_USHORT:
    case MET_INT:
    case MET_UINT:
    case MET_LONG:
    case MET_ULONG:
    case MET_LONG_LONG:
    case MET_ULONG_LONG:
    case MET_FLOAT:
    case MET_DOUBLE:
      return MET_ValueTypeSize[t];
    default:
      return 0;
  }
}

template <typename T>
void copy_as_float(const unsigned char* src, std::size_t n, bool swap, float* out) {
  for (std::size_t i = 0; i < n; ++i)
    out[i] = static_cast<float>(load_scalar<T>(src + i * sizeof(T), swap));
}

/// `n` values of type `t` as stored (in the other byte order where `swap`).
void convert(MET_ValueEnumType t, const unsigned char* src, std::size_t n, bool swap, float* out) {
  switch (t) {
    case MET_ASCII_CHAR:
    case MET_CHAR:
      return copy_as_float<int8_t>(src, n, swap, out);
    case MET_UCHAR:
      return copy_as_float<uint8_t>(src, n, swap, out);
    case MET_SHORT:
      return copy_as_float<int16_t>(src, n, swap, out);
    case MET_USHORT:
      return copy_as_float<uint16_t>(src, n, swap, out);
    case MET_INT:
    case MET_LONG:
      return copy_as_float<int32_t>(src, n, swap, out);
    case MET_UINT:
    case MET_ULONG:
      return copy_as_float<uint32_t>(src, n, swap, out);
    case MET_LONG_LONG:
      return copy_as_float<int64_t>(src, n, swap, out);
    case MET_ULONG_LONG:
      return copy_as_float<uint64_t>(src, n, swap, out);
    case MET_FLOAT:
      return copy_as_float<float>(src, n, swap, out);
    case MET_DOUBLE:
      return copy_as_float<double>(src, n, swap, out);
    default:
      return;
  }
}

/// The VoxelType kept: u8, u16 and i16 as stored (int8 as i16, as for
/// NIfTI and NRRD), every wider type as f32.
VoxelType kept_type(MET_ValueEnumType t) {
  switch (t) {
    case MET_UCHAR:
      return VoxelType::u8;
    case MET_USHORT:
      return VoxelType::u16;
    case MET_ASCII_CHAR:
    case MET_CHAR:
    case MET_SHORT:
      return VoxelType::i16;
    default:
      return VoxelType::f32;
  }
}

/// Whether ElementDataFile says the voxels follow the header (MetaIO
/// takes these three spellings).
bool local_data(const std::string& name) {
  return name == "LOCAL" || name == "Local" || name == "local";
}

/// MetaIO's header parser trusts its input: a field name of 255
/// characters or more overflows its name buffer (a strcpy: found by
/// scripts/fuzz, glibc's fortify stopped the process), a value of 255 or
/// more the object's Comment, Name, ObjectType, ObjectSubType and
/// AcquisitionDate buffers, an NDims above 4 its SequenceID (4 floats) and
/// above 10 its arrays of 10, a line without a separator runs into the
/// next one, and a value past the 500 characters it reads of a line breaks
/// its parse. So the header's lines, up to and including ElementDataFile
/// (what follows are the voxels), are checked before MetaIO sees them:
/// "Field = value" (or "Field: value", as MetaIO also takes), the name
/// under 200 characters, those five values under 200 and any other under
/// 450 (a 4 x 4 TransformMatrix at ITK's 17 digits takes about 400),
/// without control characters, NDims a whole number. Returns where the
/// line after ElementDataFile starts (where voxels after the header begin,
/// as MetaIO reads them).
uint64_t check_header_lines(const fs::path& path) {
  constexpr std::size_t kMost = 1 << 20, kName = 200, kValue = 450;
  std::ifstream in(path, std::ios::binary);
  std::string text(kMost, '\0');
  in.read(text.data(), static_cast<std::streamsize>(kMost));
  text.resize(static_cast<std::size_t>(in.gcount()));
  const auto printable = [](const std::string& t, bool high_ok) {
    for (unsigned char c : t)
      if ((c < 0x20 && c != '\t') || c == 0x7f || (c >= 0x80 && !high_ok)) return false;
    return true;
  };
  const auto trim = [](std::string t) {
    const std::size_t a = t.find_first_not_of(" \t\r");
    if (a == std::string::npos) return std::string();
    return t.substr(a, t.find_last_not_of(" \t\r") + 1 - a);
  };
  std::size_t at = 0;
  for (int line = 1; at < text.size(); ++line) {
    const std::size_t end = std::min(text.find('\n', at), text.size());
    const std::string whole = text.substr(at, end - at);
    at = end + 1;
    if (trim(whole).empty()) continue;
    const std::string shown = "header line " + std::to_string(line) + " ('" +
                              (printable(whole, false) ? whole.substr(0, 60) : "binary") + "')";
    const std::size_t sep = whole.find_first_of("=:");
    if (sep == std::string::npos)
      throw FileError(path, "not a MetaImage header: " + shown + " is not 'Field = value'");
    const std::string key = trim(whole.substr(0, sep)), value = trim(whole.substr(sep + 1));
    const bool copied = key == "Comment" || key == "Name" || key == "ObjectType" ||
                        key == "ObjectSubType" || key == "AcquisitionDate";
    const std::size_t most = copied ? kName : kValue;
    if (key.empty() || key.size() > kName || value.size() > most)
      throw FileError(path, "not a MetaImage header MetaIO can read safely: " + shown +
                                (key.size() > kName ? " has a name longer than 200 characters"
                                                    : " has a value longer than " +
                                                          std::to_string(most) + " characters"));
    if (!printable(key, false) || !printable(value, true))
      throw FileError(path, "not a MetaImage header MetaIO can read safely: " + shown +
                                " holds control characters");
    if (key == "NDims") {
      if (value.empty() || value.size() > 3 ||
          value.find_first_not_of("0123456789") != std::string::npos)
        throw FileError(path, "NDims = " + value.substr(0, 20) + " is not a whole number");
      const int nd = std::stoi(value);
      if (nd == 2) throw FileError(path, "holds a 2-D image (NDims = 2), not a volume");
      if (nd != 3 && nd != 4)
        throw FileError(
            path, "NDims = " + value + ": a 3-D volume (or a 4-D series of them) is expected");
    }
    if (key == "HeaderSize") {
      // MetaIO keeps it in an int and takes -1 for "the voxels at the end of
      // the file": 2147483648 or more came back as -1 (the file's last
      // bytes read as the voxels), -2 as well.
      const bool digits = !value.empty() && value.size() <= 10 &&
                          value.find_first_not_of("0123456789") == std::string::npos;
      if (value != "-1" && (!digits || std::stoll(value) > 2147483647))
        throw FileError(path, "HeaderSize = " + value.substr(0, 20) +
                                  " is neither -1 (the voxels at the end of the file) nor a "
                                  "number of bytes from 0 to 2147483647");
    }
    if (key == "ElementDataFile") return std::min<uint64_t>(at, text.size());
  }
  throw FileError(path, std::string("not a MetaImage header: no ElementDataFile line") +
                            (text.size() == kMost ? " in its first MiB" : ""));
}

/// Inflates `length` bytes of zlib or gzip data (as MetaIO takes either)
/// that start `start` bytes into `file`, drops the first `skip` bytes of
/// what comes out and keeps the next out.size(). MetaIO's own inflation
/// loops for ever on some corrupt streams (found by scripts/fuzz: a
/// timeout in MET_PerformUncompression), so compressed voxels are read
/// here; only what is needed is kept, a 4-D file's earlier volumes
/// streamed past.
void inflate_part(const fs::path& path, const fs::path& file, uint64_t start, uint64_t length,
                  uint64_t skip, std::vector<unsigned char>& out) {
  std::ifstream in(file, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(start));
  if (!in)
    throw FileError(path, "cannot read " + file.string() + " at byte " + std::to_string(start));
  z_stream z{};
  if (inflateInit2(&z, 15 + 32) != Z_OK) throw std::bad_alloc();
  struct End {
    z_stream* z;
    ~End() { inflateEnd(z); }
  } end{&z};
  std::vector<unsigned char> chunk(1 << 20), dropped(1 << 16);
  uint64_t left = length, kept = 0;
  int err = Z_OK;
  while (kept < out.size()) {
    if (z.avail_in == 0) {
      if (left == 0) break;
      in.read(reinterpret_cast<char*>(chunk.data()),
              static_cast<std::streamsize>(std::min<uint64_t>(left, chunk.size())));
      const auto got = static_cast<uint64_t>(in.gcount());
      if (got == 0) break;
      left -= got;
      z.next_in = chunk.data();
      z.avail_in = static_cast<uInt>(got);
    }
    const bool dropping = skip > 0;
    unsigned char* to = dropping ? dropped.data() : out.data() + kept;
    const uint64_t room = dropping ? std::min<uint64_t>(skip, dropped.size()) : out.size() - kept;
    z.next_out = to;
    z.avail_out = static_cast<uInt>(std::min<uint64_t>(room, 1u << 30));
    const uInt before = z.avail_out, fed = z.avail_in;
    err = inflate(&z, Z_NO_FLUSH);
    const uint64_t made = before - z.avail_out;
    if (dropping)
      skip -= made;
    else
      kept += made;
    if (err == Z_STREAM_END) break;
    if (err == Z_MEM_ERROR) throw std::bad_alloc();
    if (err != Z_OK && err != Z_BUF_ERROR)
      throw FileError(path,
                      "its compressed voxels in " + file.string() + " are corrupt (zlib: " +
                          (err == Z_NEED_DICT ? std::string("a stream that needs a dictionary")
                           : z.msg            ? std::string(z.msg)
                                              : "error " + std::to_string(err)) +
                          ")");
    if (made == 0 && fed > 0 && z.avail_in == fed) break;  // (no progress: zlib says it cannot be)
    if (err == Z_BUF_ERROR && z.avail_in == 0 && left == 0) break;
  }
  if (kept < out.size())
    throw FileError(path, "its compressed voxels in " + file.string() + " inflate to " +
                              std::to_string(kept) + " of the " + std::to_string(out.size()) +
                              " bytes the header promises (truncated?)");
}

/// MetaIO's MetaImage, with the one field it keeps to itself.
class Meta : public MetaImage {
 public:
  /// CompressedDataSize of the header (0 where it does not say).
  std::streamoff compressed_bytes() const { return m_CompressedDataSize; }
};

}  // namespace

Volume load_metaimage(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                      int64_t* volumes) {
  if (volumes) *volumes = 1;
  const uint64_t header_file_bytes = require_regular_file(path);
  const uint64_t header_end = check_header_lines(path);
  MetaIOMessages said;
  Meta meta;
  try {
    if (!meta.Read(path.c_str(), false)) {
      const std::string why = said.take();
      throw FileError(path, "not a MetaImage header MetaIO can read" +
                                (why.empty() ? std::string() : " (MetaIO: " + why + ")"));
    }
  } catch (const std::bad_alloc&) {
    throw FileError(path, "MetaIO ran out of memory reading its header (corrupt header?)");
  }
  said.take();  // warnings of a header that was read: the checks below speak

  const int ndims = meta.NDims();
  if (ndims == 2) throw FileError(path, "holds a 2-D image (NDims = 2), not a volume");
  if (ndims != 3 && ndims != 4)
    throw FileError(path, "NDims = " + std::to_string(ndims) +
                              ": a 3-D volume (or a 4-D series of them) is expected");
  if (meta.ElementNumberOfChannels() != 1)
    throw FileError(path,
                    "ElementNumberOfChannels = " + std::to_string(meta.ElementNumberOfChannels()) +
                        ": a colour or vector image, not a scalar volume");
  const MET_ValueEnumType etype = meta.ElementType();
  const std::size_t ebytes = scalar_bytes(etype);
  if (ebytes == 0) {
    const bool known = etype >= 0 && etype < static_cast<int>(MET_NUM_VALUE_TYPES);
    throw FileError(path, std::string("ElementType ") +
                              (known ? MET_ValueTypeName[etype] : "unknown") +
                              " is not a scalar type (MET_UCHAR, MET_SHORT, MET_FLOAT, ...)");
  }
  std::array<int64_t, 3> dims{};
  for (int i = 0; i < ndims; ++i)
    if (meta.DimSize(i) <= 0)
      throw FileError(path, "DimSize " + std::to_string(i) + " is " +
                                std::to_string(meta.DimSize(i)) + " (must be positive)");
  for (int i = 0; i < 3; ++i) dims[i] = meta.DimSize(i);
  const int64_t count = ndims == 4 ? meta.DimSize(3) : 1;
  const std::size_t n = checked_count(path, dims, ebytes);
  const std::size_t bytes = n * ebytes;
  if (static_cast<uint64_t>(count) > std::numeric_limits<uint64_t>::max() / bytes)
    throw FileError(path, "its " + std::to_string(count) + " volumes of " + dims_text(dims) +
                              " overflow a byte count");
  const uint64_t all_bytes = static_cast<uint64_t>(count) * bytes;
  // Where the voxels are. MetaIO also reads a LIST of slice files and a
  // printf pattern of them ("slice%03d.raw 1 40 1"), but with hazards a
  // header can reach: the pattern is its format string, a step of 0
  // divides by zero (SIGFPE, found by scripts/fuzz), a negative one never
  // ends, and an empty line in a LIST is written before its start. Those
  // two forms are refused; ITK, Slicer and elastix write neither unless
  // asked to.
  const std::string data_name = meta.ElementDataFileName();
  if (data_name.rfind("LIST", 0) == 0)
    throw FileError(path, "ElementDataFile = " + data_name.substr(0, 40) +
                              ": a list of slice files, which simdvol does not read (the voxels "
                              "must follow the header or lie in one file)");
  if (data_name.find('%') != std::string::npos)
    throw FileError(path, "ElementDataFile = " + data_name.substr(0, 80) +
                              ": a pattern of slice files, which simdvol does not read (the "
                              "voxels must follow the header or lie in one file)");
  if (data_name.empty()) throw FileError(path, "its ElementDataFile is empty");
  if (volumes) *volumes = count;
  const int64_t index = pick_volume(path, count, volume_index, "(a 4-D image)");

  // The data file's size bounds what may be read from it (MetaIO would
  // allocate a compressed size or read past a short file without a word).
  // (MetaIO inflates only binary voxels: compressed ASCII is read as ASCII)
  bool compressed = meta.CompressedData() && meta.BinaryData();
  fs::path data_path = path;
  if (!local_data(data_name)) {
    const fs::path named_path = fs::path(data_name).is_absolute()
                                    ? fs::path(data_name)
                                    : path.parent_path() / fs::path(data_name);
    const std::string named = "its voxels' file " + named_path.string() + " (ElementDataFile)";
    std::error_code ec;
    data_path = named_path;
    fs::file_status st = fs::status(data_path, ec);
    // (MetaIO then looks for the name with .gz or .Z added: compressed)
    for (const char* suffix : {".gz", ".Z"}) {
      if (fs::exists(st)) break;
      data_path = named_path;
      data_path += suffix;
      st = fs::status(data_path, ec);
      compressed = true;
    }
    watch_file(data_path);  // (load_volume: read again if it changes)
    if (!fs::exists(st)) throw FileError(path, named + " is missing");
    if (fs::is_directory(st)) throw FileError(path, named + " is a directory");
    // (a FIFO would block the read, a device such as /dev/zero fill memory)
    if (!fs::is_regular_file(st)) throw FileError(path, named + " is not a regular file");
  }
  std::error_code ec;
  const uint64_t data_file_bytes =
      data_path == path ? header_file_bytes : static_cast<uint64_t>(fs::file_size(data_path, ec));
  if (ec)
    throw FileError(path, "cannot read the size of " + data_path.string() + ": " + ec.message());
  // What the data file holds for the voxels: past HeaderSize in a file of
  // its own (the header's own bytes are in the count for LOCAL voxels).
  const uint64_t skip = !local_data(data_name) && meta.HeaderSize() > 0
                            ? static_cast<uint64_t>(meta.HeaderSize())
                            : 0;
  const uint64_t held = data_file_bytes > skip ? data_file_bytes - skip : 0;
  if (compressed && meta.compressed_bytes() > 0 &&
      static_cast<uint64_t>(meta.compressed_bytes()) > held)
    throw FileError(path, "its CompressedDataSize " + std::to_string(meta.compressed_bytes()) +
                              " is more than the " + std::to_string(held) + " bytes of " +
                              data_path.string());
  // (compressed voxels: what deflate could pack them into; an ASCII voxel,
  // BinaryData = False, takes a character at least)
  const uint64_t need = meta.BinaryData() || compressed ? all_bytes : all_bytes / ebytes;
  if (compressed ? !deflate_could_hold(held, need) : need > held) {
    if (compressed)
      throw FileError(path, "its " + std::to_string(held) + " compressed bytes in " +
                                data_path.string() + " cannot hold the " +
                                std::to_string(all_bytes) +
                                " bytes of voxel data the header promises (zlib packs at most "
                                "1032 bytes into one; corrupt header?)");
    if (!local_data(data_name) && meta.BinaryData())
      throw FileError(path, data_path.string() + " holds " + std::to_string(held) + " of the " +
                                std::to_string(all_bytes) +
                                " bytes of voxel data the header promises (truncated?)");
    throw FileError(path, data_path.string() + " (" + std::to_string(held) +
                              " bytes) cannot hold the " + std::to_string(count * n) +
                              " voxels the header promises (truncated?)");
  }

  // The voxels. Compressed ones are inflated here (above); raw binary ones
  // of a 4-D file read by MetaIO's ReadROI, only the volume asked for;
  // others (one volume, or ASCII, on which ReadROI fails) by MetaIO whole.
  const bool local = local_data(data_name);
  const bool roi = count > 1 && meta.BinaryData() && !compressed;
  const bool whole = !compressed && !roi;
  std::vector<unsigned char> stored(whole ? static_cast<std::size_t>(all_bytes) : bytes);
  if (compressed) {
    const uint64_t start = local ? header_end : skip;
    const uint64_t length = meta.compressed_bytes() > 0
                                ? static_cast<uint64_t>(meta.compressed_bytes())
                                : (data_file_bytes > start ? data_file_bytes - start : 0);
    inflate_part(path, data_path, start, length, static_cast<uint64_t>(index) * bytes, stored);
  } else {
    bool ok = false;
    try {
      MetaImage reader;
      if (roi) {
        int lo[4] = {0, 0, 0, static_cast<int>(index)};
        int hi[4] = {static_cast<int>(dims[0] - 1), static_cast<int>(dims[1] - 1),
                     static_cast<int>(dims[2] - 1), static_cast<int>(index)};
        ok = reader.ReadROI(lo, hi, path.c_str(), true, stored.data(), 1);
      } else {
        ok = reader.Read(path.c_str(), true, stored.data());
      }
    } catch (const std::bad_alloc&) {
      throw FileError(path, "MetaIO ran out of memory reading its voxels (corrupt header?)");
    }
    const std::string why = said.take();
    if (!ok || !why.empty())
      throw FileError(
          path, "its voxel data could not be read" +
                    (why.empty() ? std::string(" (MetaIO gave up)") : " (MetaIO: " + why + ")"));
  }

  const std::array<double, 3> spacing =
      sane_spacing({meta.ElementSpacing()[0], meta.ElementSpacing()[1], meta.ElementSpacing()[2]});
  Volume vol(dims, kept_type(etype), spacing);
  const std::size_t first = whole ? static_cast<std::size_t>(index) * bytes : 0;
  // (in the file's byte order, as MetaIO's ElementByteOrderFix would turn it)
  const bool swap = meta.BinaryDataByteOrderMSB() != (std::endian::native == std::endian::big);
  convert(etype, stored.data() + first, n, swap, vol.data().data());
  // MetaImage's space is ITK's, LPS; row i of TransformMatrix is the
  // direction of index axis i (as ITK's MetaImageIO reads it).
  const double* m = meta.TransformMatrix();
  std::array<std::array<double, 3>, 3> dirs{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dirs[i][j] = m[i * ndims + j];
  vol.set_orientation(closest_orientation(dirs, "LPS"));
  if (data_path != path) vol.add_companion_file(data_path);
  return vol;
}

}  // namespace simdvol
