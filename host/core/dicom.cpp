// DICOM through GDCM: a series of single-frame slices (a directory, or any
// one slice of it) or one multi-frame file, as a 3-D volume.
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPhotometricInterpretation.h>
#include <gdcmPixelFormat.h>
#include <gdcmScanner.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmSplitMosaicFilter.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "child_read.hpp"
#include "file_checks.hpp"
#include "read_watch.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

const gdcm::Tag kSeriesUid(0x0020, 0x000e);
const gdcm::Tag kModality(0x0008, 0x0060);
const gdcm::Tag kSeriesDescription(0x0008, 0x103e);
const gdcm::Tag kNumberOfFrames(0x0028, 0x0008);
const gdcm::Tag kInstanceNumber(0x0020, 0x0013);
const gdcm::Tag kAcquisitionNumber(0x0020, 0x0012);
const gdcm::Tag kTemporalPosition(0x0020, 0x0100);
const gdcm::Tag kEchoNumbers(0x0018, 0x0086);
const gdcm::Tag kPosition(0x0020, 0x0032);     // Image Position (Patient)
const gdcm::Tag kOrientation(0x0020, 0x0037);  // Image Orientation (Patient)
const gdcm::Tag kRescaleIntercept(0x0028, 0x1052);
const gdcm::Tag kRescaleSlope(0x0028, 0x1053);
const gdcm::Tag kSharedGroups(0x5200, 0x9229);    // Shared Functional Groups Sequence
const gdcm::Tag kPerFrameGroups(0x5200, 0x9230);  // Per-frame Functional Groups Sequence
const gdcm::Tag kPlanePosition(0x0020, 0x9113);
const gdcm::Tag kPlaneOrientation(0x0020, 0x9116);
const gdcm::Tag kPixelMeasures(0x0028, 0x9110);
const gdcm::Tag kPixelSpacing(0x0028, 0x0030);  // rows' spacing (y), then columns' (x)
const gdcm::Tag kPixelValueTransformation(0x0028, 0x9145);
const gdcm::Tag kGridFrameOffsets(0x3004, 0x000c);  // an RT dose grid's frames
const gdcm::Tag kImageType(0x0008, 0x0008);
const gdcm::Tag kSpacingBetweenSlices(0x0018, 0x0088);
const gdcm::Tag kSliceThickness(0x0018, 0x0050);

/// One image file read by GDCM, its pixels not yet decoded.
struct Slice {
  fs::path file;
  std::unique_ptr<gdcm::ImageReader> reader = std::make_unique<gdcm::ImageReader>();
  unsigned frames = 1;
  unsigned nx = 0, ny = 0;  ///< a frame's size (a mosaic's tile)
  unsigned tiles = 0;       ///< a Siemens mosaic: tiles per row of its image; 0: none
  double mosaic_sign = 1;   ///< -1: its tiles run against the planes' normal
};

/// One 2-D image of the volume: a slice of a series, or a frame of a
/// multi-frame file, with where it lies and how its values scale.
struct Frame {
  std::size_t slice = 0;                        ///< its file, in the slices
  unsigned frame = 0;                           ///< its frame in that file
  std::optional<std::array<double, 3>> origin;  ///< Image Position (Patient)
  double position = 0.0;                        ///< the origin along the normal
  std::array<double, 6> cosines{1, 0, 0, 0, 1, 0};
  bool oriented = false;                ///< the file says how it lies (else GDCM's identity)
  std::array<double, 2> spacing{1, 1};  ///< between columns (x), between rows (y)
  double slope = 1.0, intercept = 0.0;
  /// Acquisition order among the frames at one position: a slice's Temporal
  /// Position Identifier, Echo Numbers, Acquisition Number and Instance
  /// Number (0 where missing); a frame's place in its file.
  std::array<double, 4> order{0, 0, 0, 0};
};

/// The normal of the plane of Image Orientation (Patient) `c`: rows x
/// columns.
std::array<double, 3> plane_normal(const std::array<double, 6>& c) {
  return {c[1] * c[5] - c[2] * c[4], c[2] * c[3] - c[0] * c[5], c[0] * c[4] - c[1] * c[3]};
}

double dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// The numbers of a DS or IS element of `ds` (split at backslashes);
/// empty where it is missing or any part is not a number.
std::vector<double> numbers(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return {};
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (!bv || bv->GetLength() == 0 || bv->GetLength() > 4096) return {};
  const std::string text(bv->GetPointer(), bv->GetLength());
  std::vector<double> out;
  for (std::size_t at = 0;;) {
    const std::size_t end = text.find('\\', at);
    std::string part = text.substr(at, end == std::string::npos ? std::string::npos : end - at);
    while (!part.empty() && (part.back() == ' ' || part.back() == '\0')) part.pop_back();
    const std::size_t lead = part.find_first_not_of(' ');
    part = lead == std::string::npos ? std::string() : part.substr(lead);
    char* stop = nullptr;
    const double v = std::strtod(part.c_str(), &stop);
    if (part.empty() || *stop != '\0' || !std::isfinite(v)) return {};
    out.push_back(v);
    if (end == std::string::npos) return out;
    at = end + 1;
  }
}

/// A sequence element of `ds`; null where it is missing or not a sequence.
gdcm::SmartPointer<gdcm::SequenceOfItems> sequence(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return nullptr;
  return ds.GetDataElement(tag).GetValueAsSQ();
}

/// The numbers of `tag` in the first item of the sequence `group` of `ds`
/// (a functional group's macro), where there are `count` of them.
std::vector<double> group_numbers(const gdcm::DataSet& ds, const gdcm::Tag& group,
                                  const gdcm::Tag& tag, std::size_t count) {
  const auto sq = sequence(ds, group);
  if (!sq || sq->GetNumberOfItems() < 1) return {};
  std::vector<double> v = numbers(sq->GetItem(1).GetNestedDataSet(), tag);
  return v.size() == count ? v : std::vector<double>{};
}

std::string format_mm(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", v);
  return b;
}

/// GDCM's warnings, caught for the loader's time (GDCM reports a file cut
/// inside its pixel data only as a warning, "Incomplete Pixel Data found,
/// use file at own risk", and fills the rest); its errors silenced: they
/// come back as return values. GDCM's streams and flags are global, as
/// teem's biff: the loaders are not thread-safe.
class GdcmWarnings {
 public:
  GdcmWarnings()
      : saved_(&gdcm::Trace::GetWarningStream()), was_on_(gdcm::Trace::GetWarningFlag()) {
    gdcm::Trace::SetWarningStream(caught_);
    gdcm::Trace::WarningOn();
    gdcm::Trace::ErrorOff();
    gdcm::Trace::DebugOff();
  }
  ~GdcmWarnings() {
    gdcm::Trace::SetWarningStream(*saved_);
    gdcm::Trace::SetWarning(was_on_);
  }
  GdcmWarnings(const GdcmWarnings&) = delete;
  GdcmWarnings& operator=(const GdcmWarnings&) = delete;
  /// Whether a warning since the last call contained `text`.
  bool said(const char* text) {
    const bool found = caught_.str().find(text) != std::string::npos;
    caught_.str({});
    return found;
  }

 private:
  std::ostringstream caught_;
  std::ostream* saved_;
  bool was_on_;
};

/// Reads `file` as an image (header and the pixels' bytes, not decoded).
void read_image(const fs::path& path, Slice& s, GdcmWarnings& warnings) {
  s.reader->SetFileName(s.file.c_str());
  warnings.said("");
  const std::string which =
      s.file == path ? std::string() : " (" + s.file.filename().string() + ")";
  if (!s.reader->Read())
    throw FileError(path,
                    "is not a DICOM image GDCM can read (not DICOM, truncated, or no pixel "
                    "data)" +
                        which);
  if (warnings.said("Incomplete Pixel Data"))
    throw FileError(path,
                    "truncated: its pixel data end before the length its header gives" + which);
}

/// The volume type for a pixel format, where no scale applies.
VoxelType voxel_type(const gdcm::PixelFormat& pf) {
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8:
      return VoxelType::u8;
    case gdcm::PixelFormat::INT8:
    case gdcm::PixelFormat::INT16:
      return VoxelType::i16;
    case gdcm::PixelFormat::UINT16:
      return VoxelType::u16;
    default:
      return VoxelType::f32;
  }
}

/// Calls `f` with a value of the C++ type GDCM decodes `pf` to; false
/// (and no call) for a type the loader does not take (1-bit, 12-bit
/// packed, ...).
template <typename F>
bool with_scalar_type(const gdcm::PixelFormat& pf, F&& f) {
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8:
      f(uint8_t{});
      return true;
    case gdcm::PixelFormat::INT8:
      f(int8_t{});
      return true;
    case gdcm::PixelFormat::UINT16:
      f(uint16_t{});
      return true;
    case gdcm::PixelFormat::INT16:
      f(int16_t{});
      return true;
    case gdcm::PixelFormat::UINT32:
      f(uint32_t{});
      return true;
    case gdcm::PixelFormat::INT32:
      f(int32_t{});
      return true;
    case gdcm::PixelFormat::FLOAT32:
      f(float{});
      return true;
    case gdcm::PixelFormat::FLOAT64:
      f(double{});
      return true;
    default:
      return false;
  }
}

/// Whether the loader takes the scalar type GDCM decodes `pf` to.
bool supported(const gdcm::PixelFormat& pf) {
  return with_scalar_type(pf, [](auto) {});
}

/// Appends `n` decoded pixels of `pf` from `buf` to `out`, times `slope`
/// plus `inter`.
void convert(const char* buf, const gdcm::PixelFormat& pf, std::size_t n, double slope,
             double inter, float* out) {
  with_scalar_type(pf, [&](auto tag) {
    using T = decltype(tag);
    for (std::size_t i = 0; i < n; ++i) {
      T v;
      std::memcpy(&v, buf + i * sizeof(T), sizeof(T));
      out[i] = static_cast<float>(static_cast<double>(v) * slope + inter);
    }
  });
}

/// Walks a DICOM file's element headers (tag, VR, length) without reading
/// their values, so that an element that claims more bytes than the file
/// holds is found before GDCM allocates them: GDCM's reader sizes a value
/// by its claimed length first (a 10 kB file claiming 2.7 GB cost 2.7 GB).
/// Sequences and items are walked into; encapsulated pixel data's fragments
/// are checked and skipped. A deflated data set is left to GDCM (its
/// lengths are of inflated bytes). Returns false where the bytes do not
/// parse as DICOM at all (so a directory's other files can be skipped).
class DicomWalker {
 public:
  DicomWalker(const fs::path& path, const fs::path& file, uint64_t size)
      : path_(path), file_(file), in_(file, std::ios::binary), size_(size) {}

  bool check() {
    if (!in_) throw FileError(path_, "cannot open " + file_.string());
    unsigned char b[132];
    uint64_t at = 0;
    if (size_ >= 132 && read(0, b, 132) && std::memcmp(b + 128, "DICM", 4) == 0) {
      at = 132;
      marked_ = true;
      // The file meta group (0002,xxxx): explicit VR, little-endian.
      std::string syntax;
      for (;;) {
        unsigned char h[12];
        if (at + 8 > size_ || !read(at, h, 8) || le16(h) != 0x0002) break;
        const uint64_t header = long_vr(h + 4) ? 12 : 8;
        if (at + header > size_) return cut_header(at);
        const uint64_t len = explicit_length(h, at);
        if (!fits(at, header, len, h)) return false;
        if (le16(h + 2) == 0x0010 && len < 256) {  // Transfer Syntax UID
          syntax.resize(len);
          if (!read(at + header, syntax.data(), len)) return true;
          while (!syntax.empty() && (syntax.back() == '\0' || syntax.back() == ' '))
            syntax.pop_back();
        }
        at += header + len;
      }
      // A file cut at the end of its meta group, or at one of its elements'
      // ends (GDCM's reader stops the process on it: an assert).
      if (at >= size_)
        return cut_header(at, "after its file meta information, before its data set");
      if (syntax == "1.2.840.10008.1.2.1.99") {  // deflated: GDCM's to check
        rows_ = pixels_ = true;
        return true;
      }
      // Some writers put an implicit-VR data set under an explicit transfer
      // syntax (highdicom 0.1.0 did); GDCM and pydicom read such a file by
      // what its first element looks like, and so does this walk.
      explicit_ = syntax != "1.2.840.10008.1.2" && vr_letters_at(at);
      big_ = syntax == "1.2.840.10008.1.2.2";
    } else {
      // No preamble (old ACR-NEMA style): little-endian, explicit VR where
      // the first element looks so.
      if (size_ < 8 || !read(0, b, 8)) return false;
      explicit_ = vr_letters_at(0);
    }
    const uint64_t stop = walk(at, size_, false, 0);
    if (stop == kNotDicom) return false;
    // The file ends inside an element's header (GDCM's reader stops the
    // process on one: an assert), unless what is left is zero padding.
    return stop >= size_ || zeros_from(stop) || cut_header(stop);
  }

  /// Whether the data set has Rows (0028,0010), an image's, and pixel data
  /// (7fe0,0010, or the float forms 0008 and 0009), after check().
  bool rows() const { return rows_; }
  bool pixels() const { return pixels_; }

 private:
  static constexpr uint64_t kNotDicom = ~uint64_t{0};
  static constexpr uint32_t kUndefined = 0xffffffffu;

  /// A file that ends inside an element's header at `at` (or with its meta
  /// group): an error where the file is marked DICOM, else not DICOM
  /// (false).
  bool cut_header(uint64_t at, const char* where = "inside the header of the element") const {
    if (!marked_) return false;
    throw FileError(
        path_, std::string("truncated: the file ends ") + where + " at byte " + std::to_string(at) +
                   (file_ == path_ ? std::string() : " (in " + file_.filename().string() + ")"));
  }
  /// Whether the bytes from `at` to the end are all zero.
  bool zeros_from(uint64_t at) {
    unsigned char b[8];
    const uint64_t n = size_ - at;
    if (n > sizeof b || !read(at, b, n)) return false;
    for (uint64_t k = 0; k < n; ++k)
      if (b[k] != 0) return false;
    return true;
  }

  bool read(uint64_t at, void* buf, uint64_t n) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(at));
    in_.read(static_cast<char*>(buf), static_cast<std::streamsize>(n));
    return static_cast<uint64_t>(in_.gcount()) == n;
  }
  /// Whether the element at `at` has a VR's two letters where explicit VR
  /// puts them.
  bool vr_letters_at(uint64_t at) {
    unsigned char h[8];
    return at + 8 <= size_ && read(at, h, 8) && std::isupper(h[4]) && std::isupper(h[5]);
  }
  static uint16_t le16(const unsigned char* p) { return static_cast<uint16_t>(p[0] | p[1] << 8); }
  uint16_t u16(const unsigned char* p) const {
    return big_ ? static_cast<uint16_t>(p[0] << 8 | p[1]) : le16(p);
  }
  uint32_t u32(const unsigned char* p) const {
    return big_ ? (uint32_t{p[0]} << 24 | uint32_t{p[1]} << 16 | uint32_t{p[2]} << 8 | p[3])
                : (uint32_t{p[3]} << 24 | uint32_t{p[2]} << 16 | uint32_t{p[1]} << 8 | p[0]);
  }
  static bool long_vr(const unsigned char* vr) {
    static constexpr const char* kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                            "SV", "UC", "UN", "UR", "UT", "UV"};
    for (const char* v : kLong)
      if (vr[0] == v[0] && vr[1] == v[1]) return true;
    return false;
  }
  /// An explicit-VR element's length (its header read from `at`).
  uint64_t explicit_length(unsigned char* h, uint64_t at) {
    if (!long_vr(h + 4)) return u16(h + 6);
    if (!read(at + 8, h + 8, 4)) return 0;
    return u32(h + 8);
  }
  std::string tag_text(const unsigned char* h) const {
    char t[16];
    std::snprintf(t, sizeof t, "(%04x,%04x)", u16(h), u16(h + 2));
    return t;
  }
  /// Whether a value of `len` bytes after the header at `at` ends within
  /// the file; where it does not, a file marked DICOM (by its preamble) is
  /// an error, another is taken for something else (false).
  bool fits(uint64_t at, uint64_t header, uint64_t len, const unsigned char* h) const {
    if (len == kUndefined) return true;
    const uint64_t left = at + header <= size_ ? size_ - (at + header) : 0;
    if (len <= left) return true;
    if (!marked_) return false;
    throw FileError(
        path_, "truncated or corrupt: element " + tag_text(h) + " claims " + std::to_string(len) +
                   " bytes, but only " + std::to_string(left) + " follow it" +
                   (file_ == path_ ? std::string() : " (in " + file_.filename().string() + ")"));
  }

  /// Walks elements from `at` to `end`, or to a delimiter where
  /// `until_delimiter`; returns where it stopped (kNotDicom: not DICOM).
  uint64_t walk(uint64_t at, uint64_t end, bool until_delimiter, int depth) {
    if (depth > 64) throw FileError(path_, "corrupt: sequences nested more than 64 deep");
    while (at + 8 <= end) {
      unsigned char h[12];
      if (!read(at, h, 8)) return at;
      const uint16_t group = u16(h), element = u16(h + 2);
      if (group == 0xfffe) {
        const uint32_t len = u32(h + 4);
        if (element == 0xe0dd || element == 0xe00d) return at + 8;  // a delimiter
        if (element != 0xe000) return depth == 0 ? kNotDicom : at;
        if (!fits(at, 8, len, h)) return kNotDicom;  // an item
        if (len == kUndefined) {
          at = walk(at + 8, end, true, depth + 1);
          if (at == kNotDicom) return kNotDicom;
        } else {
          if (walk(at + 8, at + 8 + len, false, depth + 1) == kNotDicom) return kNotDicom;
          at += 8 + len;
        }
        continue;
      }
      if (depth == 0 && group == 0x0028 && element == 0x0010) rows_ = true;
      if (depth == 0 && group == 0x7fe0 &&
          (element == 0x0010 || element == 0x0008 || element == 0x0009))
        pixels_ = true;
      uint64_t header = 8, len = 0;
      bool sequence = false;
      if (explicit_) {
        if (!std::isupper(h[4]) || !std::isupper(h[5])) return depth == 0 ? kNotDicom : at;
        header = long_vr(h + 4) ? 12 : 8;
        if (at + header > size_) {
          cut_header(at);  // (throws where the file is marked DICOM)
          return kNotDicom;
        }
        len = explicit_length(h, at);
        sequence = h[4] == 'S' && h[5] == 'Q';
      } else {
        len = u32(h + 4);
      }
      if (!fits(at, header, len, h)) return kNotDicom;
      if (len == kUndefined) {
        // A sequence (or UN holding one), or encapsulated pixel data whose
        // items are fragments of bytes.
        const bool fragments = group == 0x7fe0 || (explicit_ && (h[4] == 'O'));
        at = fragments ? skip_fragments(at + header, end, h)
                       : walk(at + header, end, true, depth + 1);
        if (at == kNotDicom) return kNotDicom;
        continue;
      }
      if (!sequence && !explicit_ && len >= 8) {
        // Implicit VR: a defined-length value that begins with an item is a
        // sequence, as GDCM reads it.
        unsigned char v[4];
        if (read(at + header, v, 4) && u16(v) == 0xfffe && u16(v + 2) == 0xe000) sequence = true;
      }
      if (sequence && walk(at + header, at + header + len, false, depth + 1) == kNotDicom)
        return kNotDicom;
      at += header + len;
    }
    (void)until_delimiter;
    return at;
  }

  /// Encapsulated pixel data: items of bytes up to the sequence delimiter.
  uint64_t skip_fragments(uint64_t at, uint64_t end, const unsigned char* owner) {
    while (at + 8 <= end) {
      unsigned char h[8];
      if (!read(at, h, 8)) return at;
      if (u16(h) != 0xfffe) return at;
      if (u16(h + 2) == 0xe0dd) return at + 8;
      const uint32_t len = u32(h + 4);
      if (len == kUndefined) return at;  // (not a fragment: GDCM's to judge)
      if (!fits(at, 8, len, owner)) return kNotDicom;
      at += 8 + len;
    }
    return at;
  }

  const fs::path& path_;
  const fs::path& file_;
  std::ifstream in_;
  uint64_t size_;
  bool explicit_ = true;
  bool big_ = false;
  bool marked_ = false;  ///< "DICM" at byte 128
  bool rows_ = false, pixels_ = false;
};

/// DicomWalker::check on `file`: throws FileError for a claimed length
/// past the file's end, or for a file marked DICOM that ends inside an
/// element's header or with its meta group; false where the bytes are not
/// DICOM. `rows`, `pixels`: DicomWalker::rows() and pixels(), if given.
bool dicom_lengths_fit(const fs::path& path, const fs::path& file, bool* rows = nullptr,
                       bool* pixels = nullptr) {
  std::error_code ec;
  const uintmax_t size = fs::file_size(file, ec);
  if (ec) throw FileError(path, "cannot read the size of " + file.string() + ": " + ec.message());
  DicomWalker w(path, file, static_cast<uint64_t>(size));
  const bool ok = w.check();
  if (rows) *rows = w.rows();
  if (pixels) *pixels = w.pixels();
  return ok;
}

/// One series found in a directory: its images' files (in name order),
/// what each was when the scan first read it (where load_volume watches:
/// watch_file), and what it is, for a list of several.
struct SeriesFiles {
  std::vector<fs::path> files;
  std::vector<std::optional<FileIdentity>> identities;
  std::string modality, description;
  /// Has load_volume watch the files (read again if one changes).
  void watch() const {
    for (std::size_t i = 0; i < files.size(); ++i) watch_file(files[i], identities[i]);
  }
};

/// Trims the blanks and NULs DICOM pads its values with.
std::string trim_value(const char* v) {
  std::string s = v ? v : "";
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  return s;
}

/// Calls take(entry) for each entry of `dir` (below it, where `recursive`:
/// hidden directories left out, at most 16 deep) while more() holds, as
/// scan_series walks a series' directory; a listing error is left in `ec`.
template <class Take, class More>
void walk_series_dir(const fs::path& dir, bool recursive, std::error_code& ec, Take&& take,
                     More&& more) {
  if (recursive) {
    for (fs::recursive_directory_iterator
             it(dir, fs::directory_options::skip_permission_denied, ec),
         end;
         !ec && it != end && more(); it.increment(ec)) {
      std::error_code sec;
      if (it->is_directory(sec) &&
          (it.depth() >= 16 || it->path().filename().string().starts_with(".")))
        it.disable_recursion_pending();
      take(*it);
    }
  } else {
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end && more(); it.increment(ec))
      take(*it);
  }
}

/// The series a directory's images belong to, by Series Instance UID, with
/// their files; files GDCM does not read as DICOM, and DICOMDIR, are
/// skipped (and where not `strict`, those cut short). `recursive`: the
/// directories below it too (a CD's DICOM/PA0/ST0/SE0/... tree), hidden
/// ones left out, at most 16 deep and 100,000 files.
std::map<std::string, SeriesFiles> scan_series(const fs::path& path, const fs::path& dir,
                                               bool strict, bool recursive) {
  constexpr std::size_t kMaxFiles = 100000;
  std::vector<fs::path> files;
  std::map<fs::path, std::optional<FileIdentity>> identities;  // (watched only)
  const bool watching = watching_files();
  std::size_t seen = 0;
  std::error_code ec;
  auto take = [&](const fs::directory_entry& e) {
    std::error_code sec;
    if (!e.is_regular_file(sec)) return;
    const std::string name = e.path().filename().string();
    if (name == "DICOMDIR" || name.starts_with(".")) return;
    if (++seen > kMaxFiles)
      throw FileError(path, "holds more than " + std::to_string(kMaxFiles) +
                                " files in the directories below it; give the directory of "
                                "one series");
    // A file that is not DICOM is skipped. One whose lengths run past its
    // end, or that ends inside an element's header, is an error that names
    // it where the directory was asked for, and skipped beside a file asked
    // for (a slice of its series then shows as missing); so is one without
    // Rows or pixel data (cut at an element's end, or not an image: a
    // report), where the directory's series or GDCM's read of it names it.
    // A sibling cut so had stopped the file asked for from loading (GDCM's
    // reader stopped the process on some, an assert).
    bool rows = false, pixels = false;
    // (before the first read of it: a file replaced after it is a change)
    const std::optional<FileIdentity> identity =
        watching ? file_identity(e.path()) : std::optional<FileIdentity>();
    try {
      if (!dicom_lengths_fit(path, e.path(), &rows, &pixels)) return;
    } catch (const FileError&) {
      if (strict) throw;
      return;
    }
    if (!strict && !(rows && pixels)) return;
    files.push_back(e.path());
    if (watching) identities[e.path()] = identity;
  };
  walk_series_dir(dir, recursive, ec, take, [] { return true; });
  if (ec) throw FileError(path, "cannot list the directory " + dir.string() + ": " + ec.message());
  std::sort(files.begin(), files.end());
  gdcm::Scanner scanner;
  scanner.AddTag(kSeriesUid);
  scanner.AddTag(kModality);
  scanner.AddTag(kSeriesDescription);
  std::vector<std::string> names;
  for (const fs::path& f : files) names.push_back(f.string());
  if (!names.empty() && !scanner.Scan(names))
    throw FileError(path, "GDCM could not scan the directory " + dir.string());
  std::map<std::string, SeriesFiles> series;
  for (const fs::path& f : files) {
    if (!scanner.IsKey(f.c_str())) continue;
    SeriesFiles& s = series[trim_value(scanner.GetValue(f.c_str(), kSeriesUid))];
    if (s.files.empty()) {
      s.modality = trim_value(scanner.GetValue(f.c_str(), kModality));
      s.description = trim_value(scanner.GetValue(f.c_str(), kSeriesDescription));
    }
    s.files.push_back(f);
    const auto id = identities.find(f);
    s.identities.push_back(id != identities.end() ? id->second : std::nullopt);
  }
  return series;
}

/// A frame's name in messages: its file in a series, "frame N" (from 1)
/// of a multi-frame file (or mosaic), "frame N of FILE" in a series of them.
std::string frame_label(const std::vector<Slice>& slices, const Frame& f) {
  const Slice& s = slices[f.slice];
  if (s.frames == 1) return s.file.filename().string();
  return "frame " + std::to_string(f.frame + 1) +
         (slices.size() > 1 ? " of " + s.file.filename().string() : std::string());
}
std::string frame_name(const std::vector<Slice>& slices, const Frame& f) {
  return " (" + frame_label(slices, f) + ")";
}

/// The one frame of a slice of a series (slice `i`): GDCM's plane, origin
/// and scale; its numbers order it among slices at one position.
/// A slice without a position is refused where it is one of several.
Frame single_frame(const fs::path& path, const Slice& s, std::size_t i, bool in_series) {
  const gdcm::Image& im = s.reader->GetImage();
  const gdcm::DataSet& ds = s.reader->GetFile().GetDataSet();
  Frame f;
  f.slice = i;
  std::copy(im.GetDirectionCosines(), im.GetDirectionCosines() + 6, f.cosines.begin());
  f.oriented = ds.FindDataElement(kOrientation);
  if (ds.FindDataElement(kPosition))
    f.origin = {im.GetOrigin()[0], im.GetOrigin()[1], im.GetOrigin()[2]};
  else if (in_series)
    throw FileError(path,
                    "a slice of its series has no Image Position (Patient), so its place "
                    "in the volume is unknown (" +
                        s.file.filename().string() + ")");
  f.spacing = {im.GetSpacing(0), im.GetSpacing(1)};
  f.slope = im.GetSlope();
  f.intercept = im.GetIntercept();
  const gdcm::Tag keys[4] = {kTemporalPosition, kEchoNumbers, kAcquisitionNumber, kInstanceNumber};
  for (int k = 0; k < 4; ++k) {
    const std::vector<double> n = numbers(ds, keys[k]);
    f.order[k] = n.size() == 1 ? n[0] : 0.0;
  }
  return f;
}

/// The frames of a multi-frame file, in the file's order. An enhanced
/// image (Enhanced CT, MR, PET: Per-frame Functional Groups) gives each
/// frame's position, plane and scale in its functional groups (a frame's
/// own, else the shared ones); an RT dose grid places its frames by its
/// Grid Frame Offset Vector along the normal; other multi-frame files
/// (GDCM's spacing, no positions) keep their frames as stored.
std::vector<Frame> multi_frame(const fs::path& path, const Slice& s) {
  const gdcm::Image& im = s.reader->GetImage();
  const gdcm::DataSet& ds = s.reader->GetFile().GetDataSet();
  const unsigned n = s.frames;
  Frame base = single_frame(path, s, 0, false);  // the file's plane, spacing and scale
  base.origin.reset();                           // (the first frame's, not every frame's)
  std::vector<Frame> frames(n, base);
  for (unsigned k = 0; k < n; ++k) frames[k].frame = k, frames[k].order = {0, 0, 0, double(k)};

  if (const auto per = sequence(ds, kPerFrameGroups)) {
    if (per->GetNumberOfItems() != n)
      throw FileError(path, "its Per-frame Functional Groups Sequence holds " +
                                std::to_string(per->GetNumberOfItems()) + " items for its " +
                                std::to_string(n) + " frames");
    const auto shared_sq = sequence(ds, kSharedGroups);
    const gdcm::DataSet* shared = shared_sq && shared_sq->GetNumberOfItems() >= 1
                                      ? &shared_sq->GetItem(1).GetNestedDataSet()
                                      : nullptr;
    // A frame's own value, else the shared one (and for the scale, else
    // the top level's, else none).
    auto value = [&](const gdcm::DataSet& own, const gdcm::Tag& group, const gdcm::Tag& tag,
                     std::size_t count) {
      std::vector<double> v = group_numbers(own, group, tag, count);
      if (v.empty() && shared) v = group_numbers(*shared, group, tag, count);
      return v;
    };
    const std::vector<double> top_slope = numbers(ds, kRescaleSlope),
                              top_intercept = numbers(ds, kRescaleIntercept);
    for (unsigned k = 0; k < n; ++k) {
      Frame& f = frames[k];
      const gdcm::DataSet& own = per->GetItem(k + 1).GetNestedDataSet();
      const std::vector<double> pos = value(own, kPlanePosition, kPosition, 3);
      if (pos.empty())
        throw FileError(path, "frame " + std::to_string(k + 1) +
                                  " has no Image Position (Patient) in its functional groups, "
                                  "so its place in the volume is unknown");
      f.origin = {pos[0], pos[1], pos[2]};
      const std::vector<double> rows_columns = value(own, kPixelMeasures, kPixelSpacing, 2);
      if (!rows_columns.empty()) f.spacing = {rows_columns[1], rows_columns[0]};
      const std::vector<double> cos = value(own, kPlaneOrientation, kOrientation, 6);
      if (!cos.empty()) {
        std::copy(cos.begin(), cos.end(), f.cosines.begin());
        f.oriented = true;
      }
      const std::vector<double> slope = value(own, kPixelValueTransformation, kRescaleSlope, 1),
                                inter = value(own, kPixelValueTransformation, kRescaleIntercept, 1);
      f.slope = !slope.empty() ? slope[0] : top_slope.size() == 1 ? top_slope[0] : 1.0;
      f.intercept = !inter.empty() ? inter[0] : top_intercept.size() == 1 ? top_intercept[0] : 0.0;
    }
    return frames;
  }

  const std::vector<double> offsets = numbers(ds, kGridFrameOffsets);
  if (offsets.size() == n && ds.FindDataElement(kPosition)) {
    // Offsets along the normal from the first frame (relative where the
    // first is 0; absolute, as older files write them, otherwise).
    const std::array<double, 3> normal = plane_normal(base.cosines);
    for (unsigned k = 0; k < n; ++k) {
      std::array<double, 3> o;
      for (int a = 0; a < 3; ++a) o[a] = im.GetOrigin()[a] + (offsets[k] - offsets[0]) * normal[a];
      frames[k].origin = o;
    }
  }
  return frames;
}

/// Resamples an nx x ny slice in place at (i - dx, j - dy), bilinearly;
/// where that falls outside the slice, the slice's smallest value.
void shift_slice(float* s, std::size_t nx, std::size_t ny, double dx, double dy) {
  if (dx == 0.0 && dy == 0.0) return;
  const std::vector<float> src(s, s + nx * ny);
  float fill = std::numeric_limits<float>::infinity();
  for (float v : src) fill = std::fmin(fill, v);
  for (std::size_t j = 0; j < ny; ++j)
    for (std::size_t i = 0; i < nx; ++i) {
      const double x = static_cast<double>(i) - dx, y = static_cast<double>(j) - dy;
      float& to = s[j * nx + i];
      if (!(x >= 0.0 && y >= 0.0 && x <= static_cast<double>(nx - 1) &&
            y <= static_cast<double>(ny - 1))) {
        to = fill;
        continue;
      }
      const auto x0 = static_cast<std::size_t>(x), y0 = static_cast<std::size_t>(y);
      const std::size_t x1 = std::min(x0 + 1, nx - 1), y1 = std::min(y0 + 1, ny - 1);
      const double fx = x - static_cast<double>(x0), fy = y - static_cast<double>(y0);
      const double top = (1 - fx) * src[y0 * nx + x0] + fx * src[y0 * nx + x1];
      const double bottom = (1 - fx) * src[y1 * nx + x0] + fx * src[y1 * nx + x1];
      to = static_cast<float>((1 - fy) * top + fy * bottom);
    }
}

/// Whether `ds` is a Siemens mosaic: one image whose tiles, left to right
/// and top to bottom, are the slices of a volume (ImageType has MOSAIC).
bool is_mosaic(const gdcm::DataSet& ds) {
  if (!ds.FindDataElement(kImageType)) return false;
  const gdcm::ByteValue* bv = ds.GetDataElement(kImageType).GetByteValue();
  return bv && std::string(bv->GetPointer(), bv->GetLength()).find("MOSAIC") != std::string::npos;
}

/// A slice's frame size, and for a Siemens mosaic its tiles: how many
/// images it holds and their size (Number Of Images In Mosaic in the CSA
/// header, else the Acquisition Matrix), and whether the tiles run along
/// the planes' normal (rows x columns) or against it (the CSA header's
/// Slice Normal Vector; along it where there is none), through GDCM's
/// SplitMosaicFilter.
void find_tiles(const fs::path& path, Slice& s) {
  const gdcm::Image& im = s.reader->GetImage();
  s.nx = im.GetDimension(0);
  s.ny = im.GetDimension(1);
  s.frames = im.GetNumberOfDimensions() > 2 ? im.GetDimension(2) : 1;
  if (s.frames != 1 || !is_mosaic(s.reader->GetFile().GetDataSet())) return;
  const std::string which = " (" + s.file.filename().string() + ")";
  gdcm::SplitMosaicFilter filter;
  filter.SetImage(im);
  filter.SetFile(s.reader->GetFile());
  unsigned dims[3] = {0, 0, 0};
  if (!filter.ComputeMOSAICDimensions(dims) || dims[0] == 0 || dims[1] == 0 || dims[2] == 0)
    throw FileError(path,
                    "is a Siemens mosaic (ImageType MOSAIC) whose number of images or their "
                    "size GDCM cannot find (no Number Of Images In Mosaic in its CSA header?)" +
                        which);
  const auto tiles = static_cast<unsigned>(std::ceil(std::sqrt(static_cast<double>(dims[2]))));
  if (uint64_t{tiles} * dims[0] > s.nx || uint64_t{tiles} * dims[1] > s.ny)
    throw FileError(path, "is a Siemens mosaic of " + std::to_string(dims[2]) + " images of " +
                              std::to_string(dims[0]) + " x " + std::to_string(dims[1]) +
                              ", which do not fit in its " + std::to_string(s.nx) + " x " +
                              std::to_string(s.ny) + " pixels" + which);
  double normal[3] = {0, 0, 0};
  bool inverted = false;
  s.mosaic_sign = filter.ComputeMOSAICSliceNormal(normal, inverted) && inverted ? -1.0 : 1.0;
  s.frames = dims[2];
  s.nx = dims[0];
  s.ny = dims[1];
  s.tiles = tiles;
}

/// The slices of a Siemens mosaic (slice `i` of its series), placed as
/// nibabel and SPM place them: tile t at the file's Image Position
/// (Patient) plus t times the slices' spacing (Spacing Between Slices,
/// else Slice Thickness) along the way the tiles run. (The position is the
/// whole mosaic's corner, not the tile's: a shift in the plane, the same
/// for every tile and every file of a series, which the order along the
/// normal does not see.) Plane, scale and acquisition order are the file's.
std::vector<Frame> mosaic_frames(const fs::path& path, const Slice& s, std::size_t i) {
  const Frame base = single_frame(path, s, i, false);
  const gdcm::DataSet& ds = s.reader->GetFile().GetDataSet();
  const std::string which = " (" + s.file.filename().string() + ")";
  if (!base.origin)
    throw FileError(path,
                    "is a Siemens mosaic without Image Position (Patient), so its slices "
                    "cannot be placed" +
                        which);
  std::vector<double> dz = numbers(ds, kSpacingBetweenSlices);
  if (dz.size() != 1 || !(dz[0] > 0)) dz = numbers(ds, kSliceThickness);
  if (dz.size() != 1 || !(dz[0] > 0))
    throw FileError(path,
                    "is a Siemens mosaic without Spacing Between Slices or Slice Thickness, so "
                    "its slices cannot be placed" +
                        which);
  const std::array<double, 3> normal = plane_normal(base.cosines);
  std::vector<Frame> frames(s.frames, base);
  for (unsigned t = 0; t < s.frames; ++t) {
    frames[t].frame = t;
    std::array<double, 3> o;
    for (int a = 0; a < 3; ++a) o[a] = (*base.origin)[a] + s.mosaic_sign * t * dz[0] * normal[a];
    frames[t].origin = o;
  }
  return frames;
}

Volume load_dicom_files(const fs::path& path, std::optional<int64_t> index, int64_t* volumes) {
  GdcmWarnings warnings;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw FileError(path, "file not found (no such file or directory)");
  // A DICOMDIR (a CD's index) stands for the tree of files beside it.
  const bool dicomdir = path.filename() == "DICOMDIR" && fs::is_regular_file(st);
  const bool is_dir = fs::is_directory(st) || dicomdir;
  if (!is_dir) refuse_non_regular_file(path, "a DICOM file");

  // The files of the volume: one multi-frame file, or a series' slices.
  std::vector<fs::path> files;
  if (is_dir) {
    const fs::path dir =
        dicomdir ? (path.has_parent_path() ? path.parent_path() : fs::path(".")) : path;
    const auto series = scan_series(path, dir, true, true);
    if (series.empty())
      throw FileError(path, std::string("holds no DICOM image") +
                                (dicomdir ? " beside it" : " (nor do the directories below it)"));
    if (series.size() > 1) {
      std::string list;
      for (const auto& [uid, s] : series) {
        list += "\n  " + (uid.empty() ? std::string("(no Series Instance UID)") : uid) + ": ";
        if (!s.modality.empty()) list += s.modality + ", ";
        if (!s.description.empty()) list += "'" + s.description + "', ";
        list += std::to_string(s.files.size()) + " image(s), e.g. " +
                s.files.front().lexically_relative(dir).string();
      }
      throw FileError(path, "holds " + std::to_string(series.size()) +
                                " DICOM series; give one file of the series to load:" + list);
    }
    files = series.begin()->second.files;
    series.begin()->second.watch();
  } else {
    gdcm::Scanner scanner;
    scanner.AddTag(kSeriesUid);
    scanner.AddTag(kNumberOfFrames);
    if (!dicom_lengths_fit(path, path) || !scanner.Scan({path.string()}) ||
        !scanner.IsKey(path.c_str()))
      throw FileError(path, "is not a DICOM file GDCM can read");
    const char* frames = scanner.GetValue(path.c_str(), kNumberOfFrames);
    const char* uid = scanner.GetValue(path.c_str(), kSeriesUid);
    if ((frames && std::atol(frames) > 1) || !uid) {
      files = {path};  // a multi-frame volume, or a file with no series to look for
    } else {
      // The slices of its series beside it.
      const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
      const auto series = scan_series(path, dir, false, false);
      const auto it = series.find(trim_value(uid));
      files = it != series.end() ? it->second.files : std::vector<fs::path>{path};
      if (it != series.end()) it->second.watch();
    }
  }

  std::vector<Slice> slices(files.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    slices[i].file = files[i];
    read_image(path, slices[i], warnings);
    find_tiles(path, slices[i]);
  }
  const gdcm::Image& first = slices.front().reader->GetImage();
  const gdcm::PixelFormat pf = first.GetPixelFormat();
  if (pf.GetSamplesPerPixel() != 1)
    throw FileError(path, "holds " + std::to_string(pf.GetSamplesPerPixel()) +
                              " samples per pixel (colour); only grey-scale images are volumes");
  if (!supported(pf))
    throw FileError(path, std::string("pixel format ") + pf.GetScalarTypeAsString() +
                              " is not supported (8, 16 or 32-bit integers, or floats)");
  const unsigned int nx = slices.front().nx, ny = slices.front().ny;
  const unsigned int nframes = slices.front().frames;
  const bool mosaics = slices.front().tiles > 0;
  if (slices.size() > 1 && nframes > 1 && !mosaics)
    throw FileError(path, "its series mixes multi-frame files (" +
                              slices.front().file.filename().string() + " holds " +
                              std::to_string(nframes) + " frames); give one of them");
  for (Slice& s : slices) {
    const gdcm::Image& im = s.reader->GetImage();
    const std::string which = " (" + s.file.filename().string() + ")";
    if (im.GetDimension(0) != first.GetDimension(0) || im.GetDimension(1) != first.GetDimension(1))
      throw FileError(path, "its slices differ in size: " + std::to_string(first.GetDimension(0)) +
                                " x " + std::to_string(first.GetDimension(1)) + " and " +
                                std::to_string(im.GetDimension(0)) + " x " +
                                std::to_string(im.GetDimension(1)) + which);
    if ((s.tiles > 0) != mosaics || s.nx != nx || s.ny != ny || s.frames != nframes)
      throw FileError(path, "its images differ in how many slices they hold (Siemens mosaics " +
                                std::string(mosaics ? "and" : "among") + " other images)" + which);
    if (!(im.GetPixelFormat() == pf))
      throw FileError(path, "its slices differ in pixel format" + which);
  }

  // The frames: a series' slices, or a multi-frame file's frames, each with
  // its plane, position and scale.
  std::vector<Frame> frames;
  if (mosaics)
    for (std::size_t i = 0; i < slices.size(); ++i) {
      const std::vector<Frame> tiles = mosaic_frames(path, slices[i], i);
      frames.insert(frames.end(), tiles.begin(), tiles.end());
    }
  else if (nframes > 1)
    frames = multi_frame(path, slices.front());
  else
    for (std::size_t i = 0; i < slices.size(); ++i)
      frames.push_back(single_frame(path, slices[i], i, slices.size() > 1));
  const std::array<double, 6> cos = frames.front().cosines;
  for (const Frame& f : frames)
    for (int k = 0; k < 6; ++k)
      if (!(std::fabs(f.cosines[k] - cos[k]) <= 1e-4))
        throw FileError(path,
                        "its slices lie in different planes (Image Orientation (Patient) "
                        "differs" +
                            frame_name(slices, f) + "): not one volume");
  const std::array<double, 2> pixel = frames.front().spacing;
  for (const Frame& f : frames)
    for (int a = 0; a < 2; ++a)
      if (!(std::fabs(f.spacing[a] - pixel[a]) <= 1e-4 * std::fabs(pixel[a])))
        throw FileError(path, "its slices differ in Pixel Spacing: " + format_mm(pixel[0]) + " x " +
                                  format_mm(pixel[1]) + " mm and " + format_mm(f.spacing[0]) +
                                  " x " + format_mm(f.spacing[1]) + " mm" + frame_name(slices, f) +
                                  ": not one volume");
  const std::array<double, 3> row{cos[0], cos[1], cos[2]}, col{cos[3], cos[4], cos[5]};
  const std::array<double, 3> normal = plane_normal(cos);
  const bool placed = std::all_of(frames.begin(), frames.end(),
                                  [](const Frame& f) { return f.origin.has_value(); });
  for (Frame& f : frames) {
    if (f.origin && !(std::isfinite((*f.origin)[0]) && std::isfinite((*f.origin)[1]) &&
                      std::isfinite((*f.origin)[2])))
      throw FileError(
          path, "the Image Position (Patient) of " + frame_label(slices, f) + " is not a number");
    if (f.origin) f.position = dot(*f.origin, normal);
  }

  // The frames of the volume asked for, in order along the normal: where
  // several lie at each position (time points, echoes, acquisitions), the
  // index-th of each in acquisition order.
  std::array<double, 3> spacing{pixel[0], pixel[1], first.GetSpacing(2)};
  std::vector<const Frame*> chosen;
  int64_t nvol = 1;
  if (!placed || frames.size() == 1) {
    // A multi-frame file that gives no frame positions: its frames as
    // stored, its z spacing GDCM's.
    for (const Frame& f : frames) chosen.push_back(&f);
    // One slice: its thickness along z, as a mosaic's (GDCM gives 1 where
    // the file has no Spacing Between Slices, and `info` printed that 1
    // for a CT slice 5 mm thick).
    if (frames.size() == 1 && slices.size() == 1) {
      const gdcm::DataSet& ds = slices.front().reader->GetFile().GetDataSet();
      std::vector<double> dz = numbers(ds, kSpacingBetweenSlices);
      if (dz.size() != 1 || !(dz[0] > 0) || !std::isfinite(dz[0]))
        dz = numbers(ds, kSliceThickness);
      if (dz.size() == 1 && dz[0] > 0 && std::isfinite(dz[0])) spacing[2] = dz[0];
    }
  } else {
    std::vector<const Frame*> order;
    for (const Frame& f : frames) order.push_back(&f);
    std::stable_sort(order.begin(), order.end(), [](const Frame* a, const Frame* b) {
      return a->position != b->position ? a->position < b->position : a->order < b->order;
    });
    const double span = order.back()->position - order.front()->position;
    const double tol = 1e-3 * std::max(1.0, span / static_cast<double>(order.size() - 1));
    std::vector<std::vector<const Frame*>> at;  // the frames at each position
    for (const Frame* f : order) {
      if (at.empty() || f->position - at.back().front()->position > tol) at.emplace_back();
      at.back().push_back(f);
    }
    nvol = static_cast<int64_t>(at.front().size());
    for (const auto& here : at)
      if (static_cast<int64_t>(here.size()) != nvol) {
        const auto& fewer = here.size() < at.front().size() ? here : at.front();
        const auto& more = here.size() < at.front().size() ? at.front() : here;
        auto names = [&](const std::vector<const Frame*>& fs) {
          std::string n;
          for (std::size_t i = 0; i < fs.size() && i < 4; ++i)
            n += (i ? ", " : "") + frame_label(slices, *fs[i]);
          return n + (fs.size() > 4 ? ", ..." : "");
        };
        throw FileError(path,
                        "its slices do not make whole volumes: " + std::to_string(more.size()) +
                            " lie at " + format_mm(more.front()->position) + " mm (" + names(more) +
                            ") but " + std::to_string(fewer.size()) + " at " +
                            format_mm(fewer.front()->position) + " mm (" + names(fewer) +
                            "): a slice missing, or slices of several acquisitions in one series?");
      }
    const int64_t v =
        pick_volume(path, nvol, index,
                    "(" + std::to_string(nvol) + " slices at each of " + std::to_string(at.size()) +
                        " positions: time points, echoes or acquisitions)",
                    "series");
    for (const auto& here : at) chosen.push_back(here[static_cast<std::size_t>(v)]);
    if (chosen.size() > 1) {
      const double mean = (chosen.back()->position - chosen.front()->position) /
                          static_cast<double>(chosen.size() - 1);
      for (std::size_t i = 1; i < chosen.size(); ++i) {
        const double gap = chosen[i]->position - chosen[i - 1]->position;
        if (std::fabs(gap - mean) > 0.01 * mean + 1e-3)
          throw FileError(path, "its slices are not evenly spaced: " + format_mm(gap) +
                                    " mm between " + frame_label(slices, *chosen[i - 1]) + " and " +
                                    frame_label(slices, *chosen[i]) + ", " + format_mm(mean) +
                                    " mm on average (a slice missing?)");
      }
      spacing[2] = mean;
    }
  }
  if (volumes) *volumes = nvol;
  if (index && (!placed || frames.size() == 1) && *index != 0)
    throw FileError(path, "volume index " + std::to_string(*index) +
                              " is outside 0..0 (the series holds 1 volume)");
  for (double& s : spacing)
    if (!(s > 0.0) || !std::isfinite(s)) s = 1.0;

  // A slice whose origin lies off the line through the first one's along
  // the normal (a CT gantry tilt shears the slices, each shifted in its
  // plane by the tilt's tangent times its depth): the shift in pixels, by
  // which the slice is resampled so that the volume's grid is orthogonal,
  // as dcm2niix corrects a tilt. Below a twentieth of a pixel it is left
  // alone (positions written to a few decimals).
  std::vector<std::array<double, 2>> shift(chosen.size(), {0.0, 0.0});
  bool sheared = false;
  if (placed && chosen.size() > 1) {
    const std::array<double, 3>& o0 = *chosen.front()->origin;
    for (std::size_t k = 0; k < chosen.size(); ++k) {
      const std::array<double, 3>& o = *chosen[k]->origin;
      const std::array<double, 3> d{o[0] - o0[0], o[1] - o0[1], o[2] - o0[2]};
      const double u = dot(d, row), v = dot(d, col);
      shift[k] = {u / spacing[0], v / spacing[1]};
      if (!(std::fabs(shift[k][0]) < nx && std::fabs(shift[k][1]) < ny))
        throw FileError(path, "its slices lie beside each other, not one behind another: " +
                                  frame_label(slices, *chosen[k]) + " is " + format_mm(u) + " x " +
                                  format_mm(v) + " mm off the line through " +
                                  frame_label(slices, *chosen.front()) +
                                  " along the normal, more than the image's size");
      sheared = sheared || std::fabs(shift[k][0]) > 0.05 || std::fabs(shift[k][1]) > 0.05;
    }
  }
  std::string shear_note;
  if (sheared) {
    // The tilt from the last slice: its offset in the plane against its
    // distance along the normal.
    const double du = shift.back()[0] * spacing[0], dv = shift.back()[1] * spacing[1];
    const double depth = chosen.back()->position - chosen.front()->position;
    shear_note = "its " + std::to_string(chosen.size()) +
                 " slices were resampled in their plane to undo a gantry tilt of " +
                 format_mm(std::atan2(std::hypot(du, dv), depth) * 180.0 / M_PI) +
                 " degrees (the last lies " + format_mm(std::hypot(du, dv)) +
                 " mm off the first one's line along the normal)";
  }

  // Rescale Slope and Intercept, per frame (they may differ from slice to
  // slice); a volume any frame of which is scaled loads as f32.
  bool scaled = false;
  for (const Frame* f : chosen) {
    if (!std::isfinite(f->slope) || !std::isfinite(f->intercept) || f->slope == 0.0)
      throw FileError(path, "Rescale Slope " + format_mm(f->slope) + " / Intercept " +
                                format_mm(f->intercept) + " of " + frame_label(slices, *f) +
                                " are not usable");
    scaled = scaled || f->slope != 1.0 || f->intercept != 0.0;
  }
  const std::array<int64_t, 3> dims{nx, ny, static_cast<int64_t>(chosen.size())};
  Volume vol(dims, scaled || sheared ? VoxelType::f32 : voxel_type(pf), spacing);
  const std::size_t per_frame = static_cast<std::size_t>(nx) * ny;
  const std::size_t frame_bytes = per_frame * pf.GetPixelSize();
  std::vector<char> buf;
  std::size_t decoded = slices.size();  // the slice whose pixels `buf` holds
  float* out = vol.data().data();
  for (std::size_t k = 0; k < chosen.size(); ++k) {
    const Frame* f = chosen[k];
    if (f->slice != decoded) {
      const Slice& s = slices[f->slice];
      const gdcm::Image& im = s.reader->GetImage();
      const unsigned long len = im.GetBufferLength();
      if (len < uint64_t{im.GetDimension(0)} * im.GetDimension(1) * (s.tiles ? 1 : s.frames) *
                    pf.GetPixelSize())
        throw FileError(
            path, "holds fewer pixels than its header says (" + s.file.filename().string() + ")");
      buf.resize(len);
      if (!im.GetBuffer(buf.data()))
        throw FileError(path, "GDCM could not decode the pixels of " + s.file.filename().string() +
                                  " (corrupt, or a compression it cannot read)");
      decoded = f->slice;
    }
    const Slice& s = slices[f->slice];
    if (s.tiles > 0) {
      // Tile t of a mosaic: row t / tiles, column t % tiles of nx x ny tiles.
      const std::size_t row = f->frame / s.tiles, col = f->frame % s.tiles;
      const std::size_t stride = static_cast<std::size_t>(s.reader->GetImage().GetDimension(0));
      for (std::size_t y = 0; y < ny; ++y)
        convert(buf.data() + ((row * ny + y) * stride + col * nx) * pf.GetPixelSize(), pf, nx,
                f->slope, f->intercept, out + y * nx);
    } else {
      convert(buf.data() + f->frame * frame_bytes, pf, per_frame, f->slope, f->intercept, out);
    }
    if (sheared) shift_slice(out, nx, ny, shift[k][0], shift[k][1]);
    out += per_frame;
  }

  // Where the axes point: rows, columns and the frames' order along the
  // normal, in DICOM's LPS space; none where a file does not say how its
  // images lie (GDCM gives rows along x and columns along y where the file
  // says nothing) or a multi-frame file does not place its frames.
  const bool said =
      std::all_of(frames.begin(), frames.end(), [](const Frame& f) { return f.oriented; });
  if (said && (placed || frames.size() == 1))
    vol.set_orientation(closest_orientation({row, col, normal}, "LPS"));
  if (!shear_note.empty()) vol.add_note(shear_note);
  // A series' other slices, so that no output is written over one
  // (check_not_an_input: a slice without DICOM's preamble, under any name,
  // was not told as DICOM by its contents).
  for (const fs::path& f : files)
    if (f.lexically_normal() != path.lexically_normal()) vol.add_companion_file(f);
  return vol;
}

/// load_dicom_files, GDCM's exceptions made FileErrors.
Volume load_dicom_here(const fs::path& path, std::optional<int64_t> index, int64_t* volumes) {
  try {
    return load_dicom_files(path, index, volumes);
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {  // GDCM's own exceptions (malformed data)
    throw FileError(path, std::string("GDCM could not read it: ") + e.what());
  }
}

/// The files a read of `path` may meet, for read_in_child's time limit:
/// those below a directory (or a DICOMDIR's), as scan_series walks them
/// (hidden directories left out, 16 deep, 100,000 files at most); a file's own
/// and those beside it (its series' slices).
ReadSize dicom_read_size(const fs::path& path) {
  std::error_code ec;
  const bool is_dir = fs::is_directory(path, ec);
  const bool tree = is_dir || path.filename() == "DICOMDIR";
  const fs::path where = is_dir                   ? path
                         : path.has_parent_path() ? path.parent_path()
                                                  : fs::path(".");
  ReadSize size;
  const auto add = [&](const fs::directory_entry& e) {
    std::error_code sec;
    if (!e.is_regular_file(sec)) return;
    ++size.files;
    const uintmax_t n = e.file_size(sec);
    if (!sec) size.bytes += n;
  };
  walk_series_dir(where, tree, ec, add, [&] { return size.files < 100000; });
  return size;
}

}  // namespace

Volume load_dicom(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                  int64_t* volumes) {
  // GDCM (and the codecs under it) stop the process with assert() or worse
  // on some files, valid ones among them (Debian's GDCM 3.0.21 aborts in
  // GetSpacingValue on an RT dose grid of one frame): the files are read in
  // a child process (read_in_child), so that such a file is an error, not
  // the end of the program. SIMDVOL_DICOM_IN_PROCESS=1 reads in this
  // process (the fuzz target).
  if (const char* e = std::getenv("SIMDVOL_DICOM_IN_PROCESS"); e && std::string(e) == "1")
    return load_dicom_here(path, volume_index, volumes);
  return read_in_child(
      path, "GDCM", [&](int64_t* count) { return load_dicom_here(path, volume_index, count); },
      volumes, [&] { return dicom_read_size(path); });
}

}  // namespace simdvol
