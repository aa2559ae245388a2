// The temporary files simdvol_core's writers have open, for the signal
// handlers of remove_temporary_files_on_signals() (internal: not installed).
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace simdvol {

/// Marks `path` as a temporary file of a write in progress, for as long as
/// the mark lives: a signal that remove_temporary_files_on_signals() handles
/// removes the file before the process ends. Best effort: a path longer
/// than 4,095 bytes, or one beyond the 64 marks kept at once, is not
/// marked. Mark before the file is made (or at once after mkstemp), and
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

/// The process's file-size limit (ulimit -f) in bytes, if it has one.
std::optional<unsigned long long> file_size_limit();

/// " (the file-size limit, ulimit -f, is N bytes)" where the process has
/// one, else "": for the messages of writes that failed (a limit cuts a
/// write short with EFBIG, and a library's message may not say why).
std::string file_size_limit_note();

}  // namespace simdvol
