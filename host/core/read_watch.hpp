// The files a load reads, watched for a change while it reads (internal:
// not installed). load_volume reads a volume again where one changed.
#pragma once

#include <sys/stat.h>

#include <ctime>
#include <filesystem>
#include <optional>
#include <vector>

namespace simdvol {

/// What tells one file at a path from another: which file (device, inode)
/// and its size and last change (content and status, to the nanosecond).
/// A file renamed over the path is another inode, made (so changed) later.
struct FileIdentity {
  dev_t dev = 0;
  ino_t ino = 0;
  off_t size = 0;
  struct timespec mtime {};
  struct timespec ctime {};
  bool operator==(const FileIdentity& o) const {
    return dev == o.dev && ino == o.ino && size == o.size && mtime.tv_sec == o.mtime.tv_sec &&
           mtime.tv_nsec == o.mtime.tv_nsec && ctime.tv_sec == o.ctime.tv_sec &&
           ctime.tv_nsec == o.ctime.tv_nsec;
  }
};

/// `path`'s identity now (one stat), or none where it cannot be looked up.
/// A directory (a DICOM series) by which it is alone: its times change with
/// any file made or removed in it, the series' or not.
std::optional<FileIdentity> file_identity(const std::filesystem::path& path);

/// A file a load read, and its identity when the loader first looked at it.
struct WatchedFile {
  std::filesystem::path path;
  std::optional<FileIdentity> identity;
};

/// Whether a load_volume is reading on this thread (so that watch_file
/// records).
bool watching_files();

/// While a load_volume reads on this thread: records `file`, with its
/// identity now, or with `identity` (what it was when the loader looked
/// at it first), unless it is recorded already. The loaders call it for
/// each file they read beside the path (a detached header's data files, a
/// pair's other half, a series' slices) before they first open it. Nothing
/// outside load_volume.
void watch_file(const std::filesystem::path& file);
void watch_file(const std::filesystem::path& file, const std::optional<FileIdentity>& identity);

/// The files recorded so far on this thread (none outside load_volume):
/// read_in_child's child sends them back, for its parent to record.
std::vector<WatchedFile> watched_files();

}  // namespace simdvol
