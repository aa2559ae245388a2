// The temporary files simdvol_core's writers have open, for the signal
// handlers of remove_temporary_files_on_signals() (internal: not installed).
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

namespace simdvol {

/// Marks `path` as a temporary file of a write in progress, for as long as
/// the mark lives: a signal that remove_temporary_files_on_signals() handles
/// removes the file before the process ends. Best effort: a path longer
/// than 4,095 bytes, or one beyond the 64 marks kept at once, is not
/// marked. Mark before the file is made, and
/// let the mark go after the file is renamed into place or removed.
class TempFileMark {
 public:
  explicit TempFileMark(const std::filesystem::path& path) noexcept;
  ~TempFileMark();
  TempFileMark(const TempFileMark&) = delete;
  TempFileMark& operator=(const TempFileMark&) = delete;

 private:
  int slot_ = -1;
};

/// Marks for the temporary files of a batch of writes that exist together
/// until they are renamed into place together (ImageBatch: a turntable's
/// frames, as many as 100,000, beyond TempFileMark's 64): `count` entries,
/// each marked (mark) and let go (unmark) by its index; a signal that
/// remove_temporary_files_on_signals() handles removes every marked file,
/// as TempFileMark's. At most 8 batches at once; a ninth, and a path that
/// cannot be copied (no memory), is not marked (best effort, as
/// TempFileMark).
class TempFileMarks {
 public:
  explicit TempFileMarks(std::size_t count);
  ~TempFileMarks();
  TempFileMarks(const TempFileMarks&) = delete;
  TempFileMarks& operator=(const TempFileMarks&) = delete;

  std::size_t size() const { return count_; }
  /// Marks entry `i` (< size()) as `path`, in place of what it marked.
  void mark(std::size_t i, const std::filesystem::path& path) noexcept;
  /// Lets entry `i` go (the file is renamed into place or removed).
  void unmark(std::size_t i) noexcept;

  struct Entry;
  struct Table;

 private:
  std::unique_ptr<Entry[]> entries_;
  std::unique_ptr<Table> table_;
  std::size_t count_ = 0;
  int slot_ = -1;
};

/// The temporary file of a write that replaces a file at once: a new file
/// beside `target` (in its directory, so that the rename is atomic), made
/// exclusively (O_EXCL: never someone's existing file) with mode 0666, so
/// that it gets what any new file gets there (the umask, a default ACL),
/// named after at most the first 64 bytes of target's name, then
/// ".tmp-" and six random characters, the whole path within Linux's 4,095
/// bytes; marked (TempFileMark) while it exists. Written through fd() (the
/// image writers take it too: a file reopened by its name can be closed to
/// its owner by a umask such as 0222). Removed by the destructor unless
/// commit() put it in place. The errors are FileError naming `named` (the
/// path the user gave, where target is its symbolic link's end), each
/// ending in file_size_limit_note().
class TempFile {
 public:
  /// FileError "cannot create a temporary file in DIR: ..." when it cannot
  /// be made.
  TempFile(const std::filesystem::path& target, const std::filesystem::path& named);
  /// The same, marked as entry `index` of `marks` (a batch's file) instead
  /// of by a TempFileMark of its own; `marks` outlives it.
  TempFile(const std::filesystem::path& target, const std::filesystem::path& named,
           TempFileMarks& marks, std::size_t index);
  ~TempFile();
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;

  const std::filesystem::path& path() const { return path_; }
  /// Open for reading and writing until commit() or fail().
  int fd() const { return fd_; }
  /// To disk (fsync), closed, renamed over the target; on a failure
  /// removed, and FileError. (finish() then rename: where finish() was
  /// called already, the rename alone.)
  void commit();
  /// To disk (fsync) and closed, not yet renamed: a batch's file, which
  /// waits for the others (and holds no descriptor meanwhile); on a failure
  /// removed, and FileError.
  void finish();
  /// Removes the file and throws FileError(named, problem + the note).
  [[noreturn]] void fail(const std::string& problem);
  /// Closes and removes the file (a probe's: output_checks); 0, or the
  /// errno of the failed unlink (the file then stays: a directory made
  /// append-only, chattr +a).
  int remove() noexcept;

 private:
  void make();

  std::filesystem::path target_, named_, path_;
  int fd_ = -1;
  bool done_ = false, finished_ = false;
  std::optional<TempFileMark> mark_;
  TempFileMarks* marks_ = nullptr;
  std::size_t mark_index_ = 0;
};

/// Lets go of every mark, without removing the files: for a forked child
/// (read_in_child), whose copy of the marks names its parent's files. A
/// signal that ends the child alone then leaves them to the parent.
/// Async-signal-safe.
void forget_temporary_files() noexcept;

/// The process's file-size limit (ulimit -f) in bytes, if it has one.
std::optional<unsigned long long> file_size_limit();

/// " (the file-size limit, ulimit -f, is N bytes)" where the process has
/// one, else "": for the messages of writes that failed (a limit cuts a
/// write short with EFBIG, and a library's message may not say why).
std::string file_size_limit_note();

}  // namespace simdvol
