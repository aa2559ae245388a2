// DICOM through GDCM: a series of single-frame slices (a directory, or any
// one slice of it) or one multi-frame file, as a 3-D volume.
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPhotometricInterpretation.h>
#include <gdcmPixelFormat.h>
#include <gdcmScanner.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
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

/// Appends `n` decoded pixels of `pf` from `buf` to `out`, times `slope`
/// plus `inter`.
void convert(const std::vector<char>& buf, const gdcm::PixelFormat& pf, std::size_t n, double slope,
             double inter, float* out) {
  auto copy = [&](auto tag) {
    using T = decltype(tag);
    for (std::size_t i = 0; i < n; ++i) {
      T v;
      std::memcpy(&v, buf.data() + i * sizeof(T), sizeof(T));
      out[i] = static_cast<float>(static_cast<double>(v) * slope + inter);
    }
  };
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8:
      copy(uint8_t{});
      break;
    case gdcm::PixelFormat::INT8:
      copy(int8_t{});
      break;
    case gdcm::PixelFormat::UINT16:
      copy(uint16_t{});
      break;
    case gdcm::PixelFormat::INT16:
      copy(int16_t{});
      break;
    case gdcm::PixelFormat::UINT32:
      copy(uint32_t{});
      break;
    case gdcm::PixelFormat::INT32:
      copy(int32_t{});
      break;
    case gdcm::PixelFormat::FLOAT32:
      copy(float{});
      break;
    case gdcm::PixelFormat::FLOAT64:
      copy(double{});
      break;
    default:
      break;  // refused before
  }
}

/// Whether GDCM decodes `pf` to one of the scalar types convert() takes.
bool supported(const gdcm::PixelFormat& pf) {
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8:
    case gdcm::PixelFormat::INT8:
    case gdcm::PixelFormat::UINT16:
    case gdcm::PixelFormat::INT16:
    case gdcm::PixelFormat::UINT32:
    case gdcm::PixelFormat::INT32:
    case gdcm::PixelFormat::FLOAT32:
    case gdcm::PixelFormat::FLOAT64:
      return true;
    default:
      return false;
  }
}

/// The series a directory's images belong to, by Series Instance UID, with
/// their files (in name order); files GDCM does not read as DICOM, and
/// DICOMDIR, are skipped.
std::map<std::string, std::vector<fs::path>> scan_series(const fs::path& path,
                                                         const fs::path& dir) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code sec;
    if (!it->is_regular_file(sec)) continue;
    const std::string name = it->path().filename().string();
    if (name == "DICOMDIR" || name.starts_with(".")) continue;
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
    const auto series = scan_series(path, path);
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
    if (!scanner.Scan({path.string()}) || !scanner.IsKey(path.c_str()))
      throw FileError(path, "is not a DICOM file GDCM can read");
    const char* frames = scanner.GetValue(path.c_str(), kNumberOfFrames);
    const char* uid = scanner.GetValue(path.c_str(), kSeriesUid);
    if ((frames && std::atol(frames) > 1) || !uid) {
      files = {path};  // a multi-frame volume, or a file with no series to look for
    } else {
      // The slices of its series beside it.
      const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
      const auto series = scan_series(path, dir);
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
  if (frames == 1) vol.set_orientation(closest_orientation({row, col, normal}, "LPS"));
  return vol;
}

}  // namespace

Volume load_dicom(const std::filesystem::path& path) {
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

}  // namespace simdvol
