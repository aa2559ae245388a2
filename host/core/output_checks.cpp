#include "output_checks.hpp"

#include <fcntl.h>
#include <linux/fs.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <string>

#include "file_checks.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"
#include "temp_files.hpp"

namespace fs = std::filesystem;

namespace simdvol {

namespace {

// The inode flags of `path` (FS_IOC_GETFLAGS), or 0 where the file system
// keeps none or they cannot be read: the check is then left to the write.
long inode_flags(const fs::path& path, bool directory) {
  const int fd = ::open(
      path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY | (directory ? O_DIRECTORY : 0));
  if (fd < 0) return 0;
  long flags = 0;
  if (::ioctl(fd, FS_IOC_GETFLAGS, &flags) != 0) flags = 0;
  ::close(fd);
  return flags;
}

// Why the writers could not put a new file in `dir` (a temporary file
// made there, then renamed over the output), or "": checked by making the
// writers' own temporary file there (TempFile) and removing it. Each of
// these failed only as the output was written, after all the work: a
// directory without write permission, or on a read-only file system or
// /proc (access(2) says yes to root there), or append-only (its files
// cannot be replaced; the probe's could not be removed either).
std::string dir_problem(const fs::path& dir) {
  if (inode_flags(dir, true) & FS_APPEND_FL)
    return "its directory " + dir.string() +
           " is append-only (chattr +a): no file there can be replaced";
  try {
    TempFile probe(dir / "simdvol-write-check", dir);
    if (const int e = probe.remove(); e != 0)
      return "a file made in " + dir.string() + " cannot be removed (" + errno_text(e) + ")";
  } catch (const FileError& e) {
    // ("cannot create a temporary file in DIR: Permission denied", without
    // the file-size limit's note, which cannot be why)
    std::string problem = e.problem();
    const std::string note = file_size_limit_note();
    if (!note.empty() && problem.size() >= note.size() &&
        problem.compare(problem.size() - note.size(), note.size(), note) == 0)
      problem.resize(problem.size() - note.size());
    return problem;
  }
  return std::string();
}

// Why an existing output `target` in `dir` cannot be replaced by a rename,
// or "" (nothing there, or nothing in the way): immutable or append-only
// (even root's rename fails), or another user's file in a sticky directory
// such as /tmp (only its owner, the directory's or root may replace it).
std::string target_problem(const fs::path& target, const fs::path& dir) {
  struct stat t = {};
  if (::stat(target.c_str(), &t) != 0) return std::string();
  if (inode_flags(target, false) & (FS_IMMUTABLE_FL | FS_APPEND_FL))
    return "it is immutable or append-only (chattr): it cannot be replaced";
  const uid_t me = ::geteuid();
  struct stat d = {};
  if (::stat(dir.c_str(), &d) == 0 && (d.st_mode & S_ISVTX) && me != 0 && d.st_uid != me &&
      t.st_uid != me)
    return "it belongs to another user in the sticky directory " + dir.string() +
           ", where only its owner may replace it";
  return std::string();
}

// Where an output goes: the end of its symbolic links, and its directory.
struct Destination {
  fs::path target, dir;
};

// check_output_path without the probe.
Destination check_output_name(const fs::path& p, const char* arg) {
  if (p.empty()) throw ArgumentError(arg, "empty output path");
  // Where the write goes: through symbolic links (a dangling link into a
  // missing directory failed only after the render).
  const fs::path t = write_target(p);
  // Error codes, not exceptions: a name too long for the file system (or
  // any other failure to look it up) is the argument's problem.
  std::error_code ec;
  const fs::file_status st = fs::status(t, ec);
  if (ec && st.type() != fs::file_type::not_found)
    throw ArgumentError(arg, p.string() + ": " + ec.message());
  if (fs::is_directory(st)) throw ArgumentError(arg, p.string() + " is a directory");
  // A FIFO, socket or device was replaced by a regular file, not written.
  if (fs::exists(st) && !fs::is_regular_file(st))
    throw ArgumentError(arg, p.string() +
                                 " is not a regular file (a FIFO, socket or device): the output "
                                 "is written to a new file put in its place");
  const fs::path dir = t.has_parent_path() ? t.parent_path() : fs::path(".");
  if (!fs::is_directory(dir, ec))
    throw ArgumentError(
        arg, (fs::exists(dir, ec)
                  ? dir.string() + ", the directory of " + p.string() + ", is not a directory"
                  : "directory " + dir.string() + " of " + p.string() + " does not exist"));
  return {t, dir};
}

}  // namespace

void check_output_path(const fs::path& p, const char* arg) {
  check_output_paths({p}, arg);
}

void check_output_paths(const std::vector<fs::path>& paths, const char* arg) {
  // The directory's probe once per directory (a turntable's frames share
  // one), the rest for every name.
  std::vector<fs::path> probed;
  for (const fs::path& p : paths) {
    const Destination d = check_output_name(p, arg);
    std::string problem = target_problem(d.target, d.dir);
    if (problem.empty() && std::find(probed.begin(), probed.end(), d.dir) == probed.end()) {
      problem = dir_problem(d.dir);
      probed.push_back(d.dir);
    }
    if (!problem.empty()) throw ArgumentError(arg, p.string() + ": " + problem);
  }
}

void check_can_make_files_in(const fs::path& dir, const char* arg) {
  if (const std::string problem = dir_problem(dir); !problem.empty())
    throw ArgumentError(arg, problem);
}

void check_not_an_input(const fs::path& out, const std::vector<fs::path>& inputs,
                        const fs::path& dicom_dir, const char* arg) {
  // Through symbolic links: "-o out.png" with out.png a link to the volume
  // wrote the image over the volume.
  const fs::path target = write_target(out);
  std::error_code ec;
  if (!fs::exists(target, ec)) return;  // nothing there to replace
  for (const fs::path& in : inputs)
    if (!in.empty() && fs::equivalent(target, in, ec))
      throw ArgumentError(arg, "writing " + out.string() + " would replace " + in.string() +
                                   ", which this command reads");
  // A DICOM slice is told by its contents, under any name (slice.tif), and
  // the series is read from its whole directory.
  if (dicom_dir.empty() || volume_file_kind(target) != VolumeFileKind::dicom) return;
  for (fs::path d = fs::absolute(target, ec).parent_path(); !d.empty(); d = d.parent_path()) {
    if (fs::equivalent(d, dicom_dir, ec))
      throw ArgumentError(arg, "writing " + out.string() +
                                   " would replace a DICOM file of the series being read (in " +
                                   dicom_dir.string() + ")");
    if (d == d.parent_path()) break;
  }
}

ReadFiles read_files(const Volume& vol, const fs::path& file) {
  ReadFiles r;
  r.files = vol.companion_files();
  if (file.empty()) return r;
  r.files.push_back(file);
  if (volume_file_kind(file) == VolumeFileKind::dicom) {
    std::error_code ec;
    r.dicom_dir = fs::is_directory(file, ec) ? file : fs::absolute(file, ec).parent_path();
  }
  return r;
}

}  // namespace simdvol
