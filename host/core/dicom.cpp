// DICOM through GDCM: a series of single-frame slices (a directory, or any
// one slice of it) or one multi-frame file, as a 3-D volume.
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPhotometricInterpretation.h>
#include <gdcmPixelFormat.h>
#include <gdcmScanner.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

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
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "file_checks.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

const gdcm::Tag kSeriesUid(0x0020, 0x000e);
const gdcm::Tag kNumberOfFrames(0x0028, 0x0008);

/// One image file read by GDCM, its pixels not yet decoded.
struct Slice {
  fs::path file;
  std::unique_ptr<gdcm::ImageReader> reader = std::make_unique<gdcm::ImageReader>();
  double position = 0.0;  ///< Image Position (Patient) along the slices' normal
};

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
void convert(const std::vector<char>& buf, const gdcm::PixelFormat& pf, std::size_t n, double slope,
             double inter, float* out) {
  with_scalar_type(pf, [&](auto tag) {
    using T = decltype(tag);
    for (std::size_t i = 0; i < n; ++i) {
      T v;
      std::memcpy(&v, buf.data() + i * sizeof(T), sizeof(T));
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
        const uint64_t len = explicit_length(h, at);
        const uint64_t header = long_vr(h + 4) ? 12 : 8;
        if (!fits(at, header, len, h)) return false;
        if (le16(h + 2) == 0x0010 && len < 256) {  // Transfer Syntax UID
          syntax.resize(len);
          if (!read(at + header, syntax.data(), len)) return true;
          while (!syntax.empty() && (syntax.back() == '\0' || syntax.back() == ' '))
            syntax.pop_back();
        }
        at += header + len;
      }
      if (syntax == "1.2.840.10008.1.2.1.99") return true;  // deflated: GDCM's to check
      explicit_ = syntax != "1.2.840.10008.1.2";
      big_ = syntax == "1.2.840.10008.1.2.2";
    } else {
      // No preamble (old ACR-NEMA style): explicit VR if a VR's letters stand
      // where they would, else implicit; little-endian.
      if (size_ < 8 || !read(0, b, 8)) return false;
      explicit_ = std::isupper(b[4]) && std::isupper(b[5]);
    }
    return walk(at, size_, false, 0) != kNotDicom;
  }

 private:
  static constexpr uint64_t kNotDicom = ~uint64_t{0};
  static constexpr uint32_t kUndefined = 0xffffffffu;

  bool read(uint64_t at, void* buf, uint64_t n) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(at));
    in_.read(static_cast<char*>(buf), static_cast<std::streamsize>(n));
    return static_cast<uint64_t>(in_.gcount()) == n;
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
      uint64_t header = 8, len = 0;
      bool sequence = false;
      if (explicit_) {
        if (!std::isupper(h[4]) || !std::isupper(h[5])) return depth == 0 ? kNotDicom : at;
        header = long_vr(h + 4) ? 12 : 8;
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
};

/// DicomWalker::check on `file`: throws FileError for a claimed length
/// past the file's end; false where the bytes are not DICOM.
bool dicom_lengths_fit(const fs::path& path, const fs::path& file) {
  std::error_code ec;
  const uintmax_t size = fs::file_size(file, ec);
  if (ec) throw FileError(path, "cannot read the size of " + file.string() + ": " + ec.message());
  DicomWalker w(path, file, static_cast<uint64_t>(size));
  return w.check();
}

/// The series a directory's images belong to, by Series Instance UID, with
/// their files (in name order); files GDCM does not read as DICOM, and
/// DICOMDIR, are skipped (and where not `strict`, those cut short).
std::map<std::string, std::vector<fs::path>> scan_series(const fs::path& path, const fs::path& dir,
                                                         bool strict) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code sec;
    if (!it->is_regular_file(sec)) continue;
    const std::string name = it->path().filename().string();
    if (name == "DICOMDIR" || name.starts_with(".")) continue;
    // A file that is not DICOM is skipped; one whose lengths run past its
    // end is an error that names it where the directory was asked for, and
    // skipped beside a file asked for (a slice of its series then shows as
    // missing).
    try {
      if (!dicom_lengths_fit(path, it->path())) continue;
    } catch (const FileError&) {
      if (strict) throw;
      continue;
    }
    files.push_back(it->path());
  }
  if (ec) throw FileError(path, "cannot list the directory " + dir.string() + ": " + ec.message());
  std::sort(files.begin(), files.end());
  gdcm::Scanner scanner;
  scanner.AddTag(kSeriesUid);
  std::vector<std::string> names;
  for (const fs::path& f : files) names.push_back(f.string());
  if (!names.empty() && !scanner.Scan(names))
    throw FileError(path, "GDCM could not scan the directory " + dir.string());
  std::map<std::string, std::vector<fs::path>> series;
  for (const fs::path& f : files) {
    if (!scanner.IsKey(f.c_str())) continue;
    const char* uid = scanner.GetValue(f.c_str(), kSeriesUid);
    series[uid ? std::string(uid) : std::string()].push_back(f);
  }
  return series;
}

/// Trims the blanks and NULs DICOM pads a UID with.
std::string trim_uid(std::string s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  return s;
}

Volume load_dicom_files(const fs::path& path) {
  GdcmWarnings warnings;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw FileError(path, "file not found (no such file or directory)");
  const bool is_dir = fs::is_directory(st);
  if (!is_dir) refuse_non_regular_file(path, "a DICOM file");

  // The files of the volume: one multi-frame file, or a series' slices.
  std::vector<fs::path> files;
  if (is_dir) {
    const auto series = scan_series(path, path, true);
    if (series.empty())
      throw FileError(path, "holds no DICOM image (a directory of one series' slices is read)");
    if (series.size() > 1) {
      std::string list;
      for (const auto& [uid, fs_] : series)
        list += "\n  " + (uid.empty() ? std::string("(no Series Instance UID)") : trim_uid(uid)) +
                ": " + std::to_string(fs_.size()) + " image(s), e.g. " +
                fs_.front().filename().string();
      throw FileError(path, "holds " + std::to_string(series.size()) +
                                " DICOM series; give one file of the series to load:" + list);
    }
    files = series.begin()->second;
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
      const auto series = scan_series(path, dir, false);
      const auto it = series.find(uid);
      files = it != series.end() ? it->second : std::vector<fs::path>{path};
    }
  }

  std::vector<Slice> slices(files.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    slices[i].file = files[i];
    read_image(path, slices[i], warnings);
  }
  const gdcm::Image& first = slices.front().reader->GetImage();
  const gdcm::PixelFormat pf = first.GetPixelFormat();
  if (pf.GetSamplesPerPixel() != 1)
    throw FileError(path, "holds " + std::to_string(pf.GetSamplesPerPixel()) +
                              " samples per pixel (colour); only grey-scale images are volumes");
  if (!supported(pf))
    throw FileError(path, std::string("pixel format ") + pf.GetScalarTypeAsString() +
                              " is not supported (8, 16 or 32-bit integers, or floats)");
  const unsigned int nx = first.GetDimension(0), ny = first.GetDimension(1);
  const unsigned int frames = first.GetNumberOfDimensions() > 2 ? first.GetDimension(2) : 1;
  if (slices.size() > 1 && frames > 1)
    throw FileError(path, "its series mixes multi-frame files (" +
                              slices.front().file.filename().string() + " holds " +
                              std::to_string(frames) + " frames); give one of them");
  const double* cos = first.GetDirectionCosines();
  std::array<double, 3> row{cos[0], cos[1], cos[2]}, col{cos[3], cos[4], cos[5]};
  const std::array<double, 3> normal{row[1] * col[2] - row[2] * col[1],
                                     row[2] * col[0] - row[0] * col[2],
                                     row[0] * col[1] - row[1] * col[0]};
  for (Slice& s : slices) {
    const gdcm::Image& im = s.reader->GetImage();
    const std::string which = " (" + s.file.filename().string() + ")";
    if (im.GetDimension(0) != nx || im.GetDimension(1) != ny)
      throw FileError(path, "its slices differ in size: " + std::to_string(nx) + " x " +
                                std::to_string(ny) + " and " + std::to_string(im.GetDimension(0)) +
                                " x " + std::to_string(im.GetDimension(1)) + which);
    if (!(im.GetPixelFormat() == pf))
      throw FileError(path, "its slices differ in pixel format" + which);
    const double* c = im.GetDirectionCosines();
    for (int k = 0; k < 6; ++k)
      if (!(std::fabs(c[k] - cos[k]) <= 1e-4))
        throw FileError(path,
                        "its slices lie in different planes (Image Orientation (Patient) "
                        "differs" +
                            which + "): not one volume");
    if (slices.size() > 1 &&
        !s.reader->GetFile().GetDataSet().FindDataElement(gdcm::Tag(0x0020, 0x0032)))
      throw FileError(path,
                      "a slice of its series has no Image Position (Patient), so its place "
                      "in the volume is unknown" +
                          which);
    const double* o = im.GetOrigin();
    s.position = o[0] * normal[0] + o[1] * normal[1] + o[2] * normal[2];
  }
  std::stable_sort(slices.begin(), slices.end(),
                   [](const Slice& a, const Slice& b) { return a.position < b.position; });

  // The spacing: columns, rows, and the slices' positions (a multi-frame
  // file's from GDCM, which reads its frame positions or offsets).
  std::array<double, 3> spacing{first.GetSpacing(0), first.GetSpacing(1), first.GetSpacing(2)};
  if (slices.size() > 1) {
    const double span = slices.back().position - slices.front().position;
    const double mean = span / static_cast<double>(slices.size() - 1);
    for (std::size_t i = 1; i < slices.size(); ++i)
      if (!(slices[i].position - slices[i - 1].position > 1e-3 * std::max(1.0, std::fabs(mean))))
        throw FileError(path, "two slices lie at the same position (" +
                                  format_mm(slices[i].position) +
                                  " mm: " + slices[i - 1].file.filename().string() + " and " +
                                  slices[i].file.filename().string() +
                                  "): several acquisitions in one series?");
    for (std::size_t i = 1; i < slices.size(); ++i) {
      const double gap = slices[i].position - slices[i - 1].position;
      if (std::fabs(gap - mean) > 0.01 * mean + 1e-3)
        throw FileError(path, "its slices are not evenly spaced: " + format_mm(gap) +
                                  " mm between " + slices[i - 1].file.filename().string() +
                                  " and " + slices[i].file.filename().string() + ", " +
                                  format_mm(mean) + " mm on average (a slice missing?)");
    }
    spacing[2] = mean;
  }
  for (double& s : spacing)
    if (!(s > 0.0) || !std::isfinite(s)) s = 1.0;

  const int64_t nz = static_cast<int64_t>(slices.size()) * frames;
  const std::array<int64_t, 3> dims{nx, ny, nz};
  // Rescale Slope and Intercept, per slice (they may differ from slice to
  // slice); a volume any slice of which is scaled loads as f32.
  bool scaled = false;
  for (const Slice& s : slices) {
    const gdcm::Image& im = s.reader->GetImage();
    if (!std::isfinite(im.GetSlope()) || !std::isfinite(im.GetIntercept()) || im.GetSlope() == 0.0)
      throw FileError(path, "Rescale Slope " + format_mm(im.GetSlope()) + " / Intercept " +
                                format_mm(im.GetIntercept()) + " of " + s.file.filename().string() +
                                " are not usable");
    scaled = scaled || im.GetSlope() != 1.0 || im.GetIntercept() != 0.0;
  }
  Volume vol(dims, scaled ? VoxelType::f32 : voxel_type(pf), spacing);
  const std::size_t per_file = static_cast<std::size_t>(nx) * ny * frames;
  std::vector<char> buf;
  float* out = vol.data().data();
  for (const Slice& s : slices) {
    const gdcm::Image& im = s.reader->GetImage();
    const unsigned long len = im.GetBufferLength();
    if (len < per_file * pf.GetPixelSize())
      throw FileError(
          path, "holds fewer pixels than its header says (" + s.file.filename().string() + ")");
    buf.resize(len);
    if (!im.GetBuffer(buf.data()))
      throw FileError(path, "GDCM could not decode the pixels of " + s.file.filename().string() +
                                " (corrupt, or a compression it cannot read)");
    convert(buf, pf, per_file, im.GetSlope(), im.GetIntercept(), out);
    out += per_file;
  }

  // Where the axes point: rows, columns and the slices' order, in DICOM's
  // LPS space. A multi-frame file's frame order is not known here.
  // (GDCM gives rows along x and columns along y where the file says
  // nothing: no orientation then.)
  const bool said =
      slices.front().reader->GetFile().GetDataSet().FindDataElement(gdcm::Tag(0x0020, 0x0037));
  if (frames == 1 && said) vol.set_orientation(closest_orientation({row, col, normal}, "LPS"));
  return vol;
}

/// load_dicom_files, GDCM's exceptions made FileErrors.
Volume load_dicom_here(const fs::path& path) {
  try {
    return load_dicom_files(path);
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {  // GDCM's own exceptions (malformed data)
    throw FileError(path, std::string("GDCM could not read it: ") + e.what());
  }
}

/// What the reading process sends back before the voxels.
struct DicomReply {
  int32_t status = 0;  ///< 0 a volume follows, 1 a FileError, 2 out of memory
  int32_t type = 0;
  int64_t dims[3] = {0, 0, 0};
  double spacing[3] = {1, 1, 1};
  char orientation[4] = {0, 0, 0, 0};
  uint32_t text_bytes = 0;  ///< status 1: the error's path, a NUL, its problem
};

/// The reading process: loads, sends the volume or the error down `fd`.
[[noreturn]] void dicom_child(const fs::path& path, int fd) {
  DicomReply reply;
  try {
    const Volume v = load_dicom_here(path);
    reply.type = static_cast<int32_t>(v.type());
    for (int a = 0; a < 3; ++a) {
      reply.dims[a] = v.dims()[a];
      reply.spacing[a] = v.spacing()[a];
    }
    std::memcpy(reply.orientation, v.orientation().data(),
                std::min<std::size_t>(3, v.orientation().size()));
    const bool ok = write_fully(fd, &reply, sizeof reply) &&
                    write_fully(fd, v.data().data(), v.data().size() * sizeof(float));
    ::_exit(ok ? 0 : 3);
  } catch (const FileError& e) {
    reply.status = 1;
    std::string text = e.path().string();
    text += '\0';
    text += e.problem();
    reply.text_bytes = static_cast<uint32_t>(text.size());
    const bool ok =
        write_fully(fd, &reply, sizeof reply) && write_fully(fd, text.data(), text.size());
    ::_exit(ok ? 0 : 3);
  } catch (const std::bad_alloc&) {
    reply.status = 2;
    ::_exit(write_fully(fd, &reply, sizeof reply) ? 0 : 3);
  } catch (...) {
    ::_exit(4);
  }
}

/// The last line a crashed reader wrote (GDCM's assertion, say), trimmed.
std::string last_line(int fd) {
  std::string all;
  ::lseek(fd, 0, SEEK_SET);
  char b[4096];
  for (ssize_t r; (r = ::read(fd, b, sizeof b)) > 0;) all.append(b, static_cast<std::size_t>(r));
  while (!all.empty() && (all.back() == '\n' || all.back() == ' ')) all.pop_back();
  const std::size_t nl = all.rfind('\n');
  std::string line = nl == std::string::npos ? all : all.substr(nl + 1);
  if (line.size() > 300) line = line.substr(0, 300) + "...";
  return line;
}

}  // namespace

Volume load_dicom(const std::filesystem::path& path) {
  // GDCM (and the codecs under it) stop the process with assert() or worse
  // on some files, valid ones among them (Debian's GDCM 3.0.21 aborts in
  // GetSpacingValue on an RT dose grid of one frame): the files are read in
  // a child process, which sends the volume back through a pipe, so that
  // such a file is an error, not the end of the program. The child's
  // messages go to a temporary file, quoted in that error.
  // SIMDVOL_DICOM_IN_PROCESS=1 reads in this process (the fuzz target).
  if (const char* e = std::getenv("SIMDVOL_DICOM_IN_PROCESS"); e && std::string(e) == "1")
    return load_dicom_here(path);
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw FileError(path, std::string("cannot make a pipe to read it: ") + std::strerror(errno));
  std::FILE* log = std::tmpfile();
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    if (log) std::fclose(log);
    throw FileError(path, std::string("cannot start a process to read it: ") + std::strerror(err));
  }
  if (pid == 0) {
    ::close(fds[0]);
    if (log) ::dup2(::fileno(log), 2);
    dicom_child(path, fds[1]);
  }
  ::close(fds[1]);
  struct Closer {
    int fd;
    std::FILE* log;
    pid_t pid;
    int status = 0;
    bool waited = false;
    ~Closer() {
      ::close(fd);
      if (!waited) ::waitpid(pid, &status, 0);
      if (log) std::fclose(log);
    }
    void wait() {
      ::close(fd);
      fd = -1;
      while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      waited = true;
    }
  } child{fds[0], log, pid};
  DicomReply reply;
  const bool got = read_fully(fds[0], &reply, sizeof reply);
  if (got && reply.status == 0) {
    const std::array<int64_t, 3> dims{reply.dims[0], reply.dims[1], reply.dims[2]};
    Volume vol(dims, static_cast<VoxelType>(reply.type),
               {reply.spacing[0], reply.spacing[1], reply.spacing[2]});
    if (read_fully(fds[0], vol.data().data(), vol.data().size() * sizeof(float))) {
      vol.set_orientation(std::string(reply.orientation, ::strnlen(reply.orientation, 3)));
      child.wait();
      return vol;
    }
  } else if (got && reply.status == 1 && reply.text_bytes < (1u << 20)) {
    std::string text(reply.text_bytes, '\0');
    if (read_fully(fds[0], text.data(), text.size())) {
      const std::size_t nul = text.find('\0');
      child.wait();
      throw FileError(fs::path(text.substr(0, nul)), text.substr(nul + 1));
    }
  } else if (got && reply.status == 2) {
    child.wait();
    throw std::bad_alloc();
  }
  child.wait();
  const std::string said = log ? last_line(::fileno(log)) : std::string();
  if (WIFSIGNALED(child.status))
    throw FileError(path, "GDCM stopped on it (signal " + std::to_string(WTERMSIG(child.status)) +
                              (said.empty() ? std::string() : ": " + said) +
                              "): a file GDCM cannot read");
  throw FileError(path, "the process reading it failed (exit status " +
                            std::to_string(WEXITSTATUS(child.status)) + ")" +
                            (said.empty() ? std::string() : ": " + said));
}

}  // namespace simdvol
