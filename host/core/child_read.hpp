// Reading a volume in a child process, for the libraries that stop the
// process on some files (internal: not installed).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>

#include "simdvol/volume.hpp"

namespace simdvol {

/// A reading child's time limit without SIMDVOL_READ_TIMEOUT
/// (default_read_time_limit): kReadTimeBase seconds, kReadSecondsPerMiB
/// more for each MiB of its files and kReadSecondsPerFile for each file.
inline constexpr double kReadTimeBase = 60;
inline constexpr double kReadSecondsPerMiB = 10;
inline constexpr double kReadSecondsPerFile = 1;

/// What a read may meet: its files' bytes, and how many files.
struct ReadSize {
  uint64_t bytes = 0;
  uint64_t files = 0;
};

/// What the reading child sends back first, in its memory file, before the
/// voxels (status 0), the error (status 1) or nothing (status 2), then the
/// notes, companion files and files read that its byte counts give: the
/// memory file holds exactly these. Here for the tests that forge a reply.
struct ChildReply {
  int32_t status = 0;  ///< 0 a volume follows, 1 a FileError, 2 out of memory
  int32_t type = 0;
  int64_t dims[3] = {0, 0, 0};
  double spacing[3] = {1, 1, 1};
  char orientation[4] = {0, 0, 0, 0};
  int64_t volumes = 1;           ///< 3-D volumes in the file (status 0 and 1)
  uint32_t text_bytes = 0;       ///< status 1: the error's path, a NUL, its problem
  uint32_t note_bytes = 0;       ///< status 0: the notes after the voxels, each ending in a NUL
  uint32_t watch_bytes = 0;      ///< status 0 and 1: the files read (watched_files), last
  uint32_t companion_bytes = 0;  ///< status 0: companion_files after the notes, each + NUL
};

/// Runs `read` in a child process (fork) and returns what it loaded: the
/// child sends the volume (dims, type, spacing, orientation, notes, voxels)
/// or its FileError back in a memory file (memfd), its stderr into a
/// temporary file; and the files it read beside the path (watched_files,
/// with what each was when first read), which this process's load_volume
/// then watches as if it had read them. A child that dies (an assert() in `library`, a signal)
/// is a FileError of `path` quoting the last line it wrote ("GDCM stopped
/// on it (signal 6: ...): a file GDCM cannot read"); std::bad_alloc in the
/// child is one here. `volumes`, if given, receives what `read` put in its
/// argument (how many 3-D volumes the file holds), also where it threw.
///
/// The child is given a time limit (a library looping on a crafted file
/// hung the load for ever): read_timeout_setting() where the user set one,
/// else default_read_time_limit(`size()`, `base_seconds`), `size` giving
/// the files the read may meet (asked for once, and only where the read is
/// still running after `base_seconds`; none where `size` is empty). A
/// child still reading at its limit is killed (SIGKILL) and reaped, and
/// the read is a FileError of `path`: "LIBRARY did not finish reading it
/// within N s ...". The volume's other files (Volume::companion_files: a
/// series' other slices) come back with it. `base_seconds` other than
/// kReadTimeBase: for the tests.
Volume read_in_child(const std::filesystem::path& path, const char* library,
                     const std::function<Volume(int64_t* volumes)>& read, int64_t* volumes,
                     const std::function<ReadSize()>& size = {},
                     double base_seconds = kReadTimeBase);

/// A reading child's time limit where SIMDVOL_READ_TIMEOUT is not set, in
/// seconds: `base_seconds`, kReadSecondsPerMiB more for each MiB (started)
/// of `size`'s bytes and kReadSecondsPerFile for each of its files. (Not
/// by bytes alone: compressed slices of little but air, 1.1 KB each in
/// JPEG 2000, took 13 ms a slice of 512x512 to read here, 11 s a MiB.)
double default_read_time_limit(ReadSize size, double base_seconds = kReadTimeBase);

/// The volume in a reading child's memory file `fd` (ChildReply, then what
/// its counts give), for read_in_child once the child has exited 0: the
/// volume; its FileError (status 1) thrown; std::bad_alloc (status 2). A
/// reply whose counts are not what the file holds (its size, fstat), or
/// whose type, dims, spacing, orientation or status is none, is a
/// FileError of `path` ("LIBRARY's reading process sent back a malformed
/// reply: ..."), found before anything is allocated for its counts.
/// `volumes` as read_in_child's.
Volume volume_from_reply(int fd, const std::filesystem::path& path, const char* library,
                         int64_t* volumes);

/// SIMDVOL_READ_TIMEOUT, the limit in seconds the user set: a whole number
/// 1 .. 10,000,000 (blanks either side allowed); nullopt where it is unset
/// or empty; anything else an ArgumentError naming the variable.
std::optional<long> read_timeout_setting();

}  // namespace simdvol
