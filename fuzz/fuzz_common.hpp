// Shared by the loader fuzz targets. The loaders take paths, so each input is
// written to a file in a per-process temporary directory (removed at exit)
// and loaded from there. A simdvol::Error is the expected way to reject an
// input; any other exception escapes to libFuzzer and is reported as a crash,
// as are ASan/UBSan reports, aborts, leaks and allocations over the limit.
#pragma once

#include <unistd.h>
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "simdvol/error.hpp"
#include "simdvol/volume.hpp"

namespace simdvol_fuzz {

/// The process's own scratch directory (mkdtemp under $TMPDIR or /tmp).
inline const std::filesystem::path& scratch_dir() {
  static const std::filesystem::path dir = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string tmpl = std::string(tmp && *tmp ? tmp : "/tmp") + "/simdvol-fuzz-XXXXXX";
    if (!::mkdtemp(tmpl.data())) {
      std::perror("mkdtemp");
      std::abort();
    }
    std::filesystem::path p(tmpl);
    static const std::filesystem::path for_atexit = p;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(for_atexit, ec);
    });
    return p;
  }();
  return dir;
}

/// Writes `size` bytes to scratch_dir()/name (replacing it) and returns the path.
inline std::filesystem::path write_input(const std::string& name, const uint8_t* data,
                                         std::size_t size) {
  const std::filesystem::path p = scratch_dir() / name;
  std::FILE* f = std::fopen(p.c_str(), "wb");
  if (!f) {
    std::perror("fopen");
    std::abort();
  }
  if (size > 0 && std::fwrite(data, 1, size, f) != size) {
    std::perror("fwrite");
    std::abort();
  }
  std::fclose(f);
  return p;
}

/// Removes every file left in the scratch directory by the previous input.
inline void clear_scratch() {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(scratch_dir(), ec))
    std::filesystem::remove_all(e.path(), ec);
}

/// Writes `size` bytes gzip-compressed (zlib, level 1) to scratch_dir()/name,
/// so that mutations reach a loader's header and data through the
/// compression layer; an empty path where zlib refuses (never, in practice).
inline std::filesystem::path write_gzipped(const std::string& name, const uint8_t* data,
                                           std::size_t size) {
  z_stream z{};
  if (deflateInit2(&z, 1, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) return {};
  std::vector<uint8_t> out(deflateBound(&z, static_cast<uLong>(size)) + 64);
  z.next_in = const_cast<Bytef*>(data);
  z.avail_in = static_cast<uInt>(size);
  z.next_out = out.data();
  z.avail_out = static_cast<uInt>(out.size());
  const int r = deflate(&z, Z_FINISH);
  const std::size_t len = out.size() - z.avail_out;
  deflateEnd(&z);
  if (r != Z_STREAM_END) return {};
  return write_input(name, out.data(), len);
}

/// The three forms of a format that is read plain or gzipped (NIfTI's
/// .nii / .nii.gz, MGH's .mgh / .mgz): form 0 the bytes as `plain`, 1 the
/// bytes gzip-compressed as `gz` (write_gzipped), 2 the bytes unchanged as
/// `gz` (corrupt or truncated gzip streams, or plain bytes under a .gz
/// name). The path; empty where zlib refused.
inline std::filesystem::path write_plain_or_gzipped(int form, const std::string& plain,
                                                    const std::string& gz, const uint8_t* data,
                                                    std::size_t size) {
  if (form == 0) return write_input(plain, data, size);
  if (form == 1) return write_gzipped(gz, data, size);
  return write_input(gz, data, size);
}

/// A header and its data file from one input: the part up to its first
/// blank line ("\n\n", kept) is written as `header`, the rest as `data`
/// beside it; the header's path.
inline std::filesystem::path write_header_and_data(const std::string& header,
                                                   const std::string& data, const uint8_t* body,
                                                   std::size_t n) {
  const std::string_view s(reinterpret_cast<const char*>(body), n);
  const std::size_t cut = s.find("\n\n");
  const std::size_t hlen = cut == std::string_view::npos ? n : cut + 2;
  write_input(data, body + hlen, n - hlen);
  return write_input(header, body, hlen);
}

/// The volume index a control byte asks for: (byte / divisor) mod 4, 0 for
/// none and k for the index k - 1 (so that 4-D headers reach the reading
/// of one volume).
inline std::optional<int64_t> volume_index(uint8_t byte, int divisor) {
  const int k = (byte / divisor) % 4;
  return k == 0 ? std::nullopt : std::optional<int64_t>(static_cast<int64_t>(k - 1));
}

/// Runs `load` and checks what it returns: a loaded volume must be
/// self-consistent (dims positive, voxel count their product). A
/// simdvol::Error is a clean rejection.
template <typename F>
void run_loader(F&& load) {
  try {
    const simdvol::Volume v = load();
    const auto& d = v.dims();
    if (d[0] <= 0 || d[1] <= 0 || d[2] <= 0 ||
        v.voxel_count() != static_cast<std::size_t>(d[0] * d[1] * d[2]))
      std::abort();
    for (double s : v.spacing())
      // (positive and finite, as Volume holds it; a NIfTI-2 double may be
      // near DBL_MAX: 1.2e308 is a spacing, the view refuses what it cannot
      // frame)
      if (!(s > 0.0) || !(s <= std::numeric_limits<double>::max())) std::abort();
  } catch (const simdvol::Error&) {
  }
}

}  // namespace simdvol_fuzz
