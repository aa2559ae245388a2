// File checks shared by simdvol_core's readers and writers (internal: not
// installed).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>

namespace simdvol {

/// FileError "is a directory, not <noun>" (noun with its article: "a volume
/// file") for a directory, and "is not a regular file" for any other
/// existing file that is not one (a FIFO would block the read, a device such
/// as /dev/zero fill the memory); nothing for a regular file or a missing
/// one (each reader says "not found" its way).
void refuse_non_regular_file(const std::filesystem::path& path, const char* noun);

/// The file a writer replaces for `path`: path itself, or where its chain of
/// symbolic links ends (followed as the kernel would, each relative link
/// from its own directory; the end may not exist yet), so that writing an
/// output through a link replaces the link's target and keeps the link.
/// FileError after 40 links (a loop).
std::filesystem::path write_target(const std::filesystem::path& path);

/// errno's text ("No space left on device"), for the messages.
std::string errno_text(int e);

/// Writes all `n` bytes to `fd` (retrying short writes and EINTR); false
/// on an error, errno set.
bool write_fully(int fd, const void* p, std::size_t n);
/// Reads exactly `n` bytes from `fd` (retrying short reads and EINTR);
/// false on an error or an early end.
bool read_fully(int fd, void* p, std::size_t n);

/// Whether `name` (already lower case) ends in one of `suffixes` and has
/// something before it.
bool has_suffix(std::string_view name, std::initializer_list<std::string_view> suffixes);

/// The size of the regular file a loader was given: FileError "file not
/// found", "is a directory", "is not a regular file", "file is empty".
uint64_t require_regular_file(const std::filesystem::path& path);
/// checked_voxel_count (for the float copy and for `bytes_per_voxel` each),
/// but malformed dims are a FileError of `path`.
std::size_t checked_count(const std::filesystem::path& path, const std::array<int64_t, 3>& dims,
                          std::size_t bytes_per_voxel);
/// "181 x 217 x 3".
std::string dims_text(const std::array<int64_t, 3>& d);
/// The volume `index` picks of the `count` 3-D volumes a file holds (0
/// where none is given). FileError "holds 5 3-D volumes <what>: give the
/// index of one, 0..4 (simdvol: --volume-index)" where count > 1 and none is
/// given (`what`: "(a 4-D image)", say), and "volume index 7 is outside
/// 0..4 (the <holder> holds 5 volumes)" for one outside.
int64_t pick_volume(const std::filesystem::path& path, int64_t count, std::optional<int64_t> index,
                    const std::string& what, const char* holder = "file");
/// A value of T stored at `p`, its bytes reversed where `swap` (a file in
/// the other byte order); `p` need not be aligned.
template <typename T>
T load_scalar(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

/// Whether `compressed` bytes of deflate data (zlib, gzip) could inflate
/// to `need` bytes: deflate packs at most about 1032 bytes into one, so a
/// header that claims more is refused before anything is allocated.
inline bool deflate_could_hold(uint64_t compressed, uint64_t need) {
  return need / 1032 <= compressed + 1024;
}

/// Each spacing made positive; 0, NaN and infinities become 1.
std::array<double, 3> sane_spacing(std::array<double, 3> s);

}  // namespace simdvol
