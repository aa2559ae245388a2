// FreeSurfer's MGH volumes (.mgh, and .mgz: the same gzipped), what
// FreeSurfer writes for every subject (orig.mgz, T1.mgz, brain.mgz,
// aseg.mgz). No C or C++ library for the format is packaged (FreeSurfer
// itself is not in Debian; nibabel reads it in Python), and it is a fixed
// header, so it is read here, as nibabel's freesurfer/mghformat.py lays it
// out: at byte 0, big-endian, version (1), width, height, depth, frames,
// type, dof (int32 each), goodRASFlag (int16), then the voxel sizes, the
// direction cosines (3 x 3, row i axis i's direction in RAS) and the
// centre (float32 each); the voxels from byte 284, big-endian, x fastest,
// frame after frame; optional tags after them (TR, flip angle, ...), not
// read. zlib's gz functions read both forms (a plain file as it is).
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <climits>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "file_checks.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kHeaderBytes = 284;

/// A big-endian value (MGH's byte order).
template <typename T>
T big_endian(const unsigned char* p) {
  return load_scalar<T>(p, std::endian::native == std::endian::little);
}

/// A gzFile that closes itself.
struct Gz {
  gzFile f = nullptr;
  ~Gz() {
    if (f) gzclose(f);
  }
};

/// Reads `n` bytes (in pieces gzread can take); the count read.
std::size_t read_gz(gzFile f, unsigned char* to, std::size_t n) {
  std::size_t got = 0;
  while (got < n) {
    const auto want = static_cast<unsigned>(std::min<std::size_t>(n - got, 1u << 30));
    const int r = gzread(f, to + got, want);
    if (r <= 0) break;
    got += static_cast<std::size_t>(r);
  }
  return got;
}

/// zlib's words where a gzipped file's stream is corrupt; "" otherwise.
std::string zlib_problem(gzFile f) {
  int err = Z_OK;
  const char* said = gzerror(f, &err);
  return err != Z_OK && err != Z_BUF_ERROR && said && *said ? std::string(said) : std::string();
}

}  // namespace

Volume load_mgh(const std::filesystem::path& path, std::optional<int64_t> volume_index,
                int64_t* volumes) {
  if (volumes) *volumes = 1;
  const uint64_t file_bytes = require_regular_file(path);
  Gz gz;
  gz.f = gzopen(path.c_str(), "rb");
  if (!gz.f) throw FileError(path, "could not be opened");
  unsigned char h[kHeaderBytes];
  const std::size_t got = read_gz(gz.f, h, kHeaderBytes);
  if (got < kHeaderBytes && !zlib_problem(gz.f).empty())
    throw FileError(path, "its header could not be read (zlib: " + zlib_problem(gz.f) + ")");
  if (got < kHeaderBytes)
    throw FileError(path, "holds " + std::to_string(got) + " of the 284 bytes of an MGH header" +
                              (gzdirect(gz.f) ? "" : " (after inflating)") +
                              ": truncated, or not an MGH file");
  const int32_t version = big_endian<int32_t>(h);
  if (version != 1)
    throw FileError(path, "version " + std::to_string(version) +
                              ", not 1: not an MGH file (or not one this reader knows)");
  std::array<int64_t, 3> dims{};
  for (int i = 0; i < 3; ++i) {
    dims[i] = big_endian<int32_t>(h + 4 + 4 * i);
    if (dims[i] <= 0)
      throw FileError(path, std::string("its ") + "xyz"[i] + " size is " + std::to_string(dims[i]) +
                                " (must be positive)");
  }
  const int64_t frames = big_endian<int32_t>(h + 16);
  if (frames <= 0)
    throw FileError(path, "its frame count is " + std::to_string(frames) + " (must be positive)");
  const int32_t type = big_endian<int32_t>(h + 20);
  // MRI_UCHAR 0, MRI_INT 1, MRI_FLOAT 3, MRI_SHORT 4, as nibabel and
  // FreeSurfer's own reader take them.
  const std::size_t ebytes = type == 0 ? 1 : type == 4 ? 2 : type == 1 || type == 3 ? 4 : 0;
  if (ebytes == 0)
    throw FileError(path, "type " + std::to_string(type) +
                              " is not one MGH defines (0 uchar, 1 int, 3 float, 4 short)");
  const std::size_t n = checked_count(path, dims, ebytes);
  const std::size_t bytes = n * ebytes;
  if (static_cast<uint64_t>(frames) > std::numeric_limits<uint64_t>::max() / bytes)
    throw FileError(path, "its " + std::to_string(frames) + " frames of " + dims_text(dims) +
                              " overflow a byte count");
  if (volumes) *volumes = frames;
  const int64_t index = pick_volume(path, frames, volume_index, "(frames: a 4-D image)");
  // What must be there to read that frame: a plain file must hold it; a
  // gzipped one must be able to, before the buffer is allocated.
  const uint64_t need = kHeaderBytes + static_cast<uint64_t>(index + 1) * bytes;
  if (gzdirect(gz.f) && file_bytes < need)
    throw FileError(path, "holds " + std::to_string(file_bytes) + " bytes, not the " +
                              std::to_string(need) + " its header and frame " +
                              std::to_string(index) + " take (truncated?)");
  if (!gzdirect(gz.f) && !deflate_could_hold(file_bytes, need))
    throw FileError(path, "its " + std::to_string(file_bytes) +
                              " compressed bytes cannot hold the " + std::to_string(need) +
                              " its header promises (corrupt header?)");

  std::vector<unsigned char> stored(bytes);
  const z_off_t at = static_cast<z_off_t>(kHeaderBytes + static_cast<uint64_t>(index) * bytes);
  const bool placed = gzseek(gz.f, at, SEEK_SET) == at;
  const std::size_t read = placed ? read_gz(gz.f, stored.data(), bytes) : 0;
  if (read < bytes && !zlib_problem(gz.f).empty())
    throw FileError(path, "its voxels could not be read (zlib: " + zlib_problem(gz.f) + ")");
  if (read < bytes)
    throw FileError(path, "holds " + std::to_string(read) + " of the " + std::to_string(bytes) +
                              " bytes of frame " + std::to_string(index) + " (truncated?)");

  const VoxelType vtype = type == 0 ? VoxelType::u8 : type == 4 ? VoxelType::i16 : VoxelType::f32;
  const bool ras = big_endian<int16_t>(h + 28) > 0;
  // The voxel sizes and cosines count only where goodRASFlag is set: without
  // it FreeSurfer's readers (mriio's mghRead, load_mgh.m) skip those bytes
  // and take 1 mm voxels, as nibabel does, whatever the bytes hold.
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  std::array<std::array<double, 3>, 3> dirs{};
  for (int i = 0; ras && i < 3; ++i) {
    spacing[i] = big_endian<float>(h + 30 + 4 * i);
    for (int j = 0; j < 3; ++j) dirs[i][j] = big_endian<float>(h + 42 + 12 * i + 4 * j);
  }
  Volume vol(dims, vtype, sane_spacing(spacing));
  float* out = vol.data().data();
  const unsigned char* p = stored.data();
  for (std::size_t i = 0; i < n; ++i, p += ebytes)
    out[i] = type == 0   ? static_cast<float>(p[0])
             : type == 4 ? static_cast<float>(big_endian<int16_t>(p))
             : type == 1 ? static_cast<float>(big_endian<int32_t>(p))
                         : big_endian<float>(p);
  // Where the axes point: only where goodRASFlag says the cosines are
  // valid (FreeSurfer assumes a coronal slab otherwise; that is a guess).
  if (ras) vol.set_orientation(closest_orientation(dirs, "RAS"));
  return vol;
}

}  // namespace simdvol
