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

/// SIMDVOL_READ_TIMEOUT, the limit in seconds the user set: a whole number
/// 1 .. 10,000,000 (blanks either side allowed); nullopt where it is unset
/// or empty; anything else an ArgumentError naming the variable.
std::optional<long> read_timeout_setting();

}  // namespace simdvol
