#include "output_checks.hpp"

#include "file_checks.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"
#include "temp_files.hpp"

namespace fs = std::filesystem;

namespace simdvol {

namespace {

// Why no file can be made in `dir` ("cannot create a temporary file in
// DIR: Permission denied"), or "" where one can: the writers' temporary file
// made there (TempFile) and removed as it goes out of scope. A directory
// without write permission, or on a read-only file system or /proc, failed
// only as the output was written, after all the work (and access(2) says
// yes to root on /proc).
std::string make_file_problem(const fs::path& dir) {
  try {
    TempFile probe(dir / "simdvol-write-check", dir);
  } catch (const FileError& e) {
    return e.problem();
  }
  return std::string();
}

}  // namespace

void check_output_path(const fs::path& p, const char* arg) {
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
  if (const std::string problem = make_file_problem(dir); !problem.empty())
    throw ArgumentError(arg, p.string() + ": " + problem);
}

void check_can_make_files_in(const fs::path& dir, const char* arg) {
  if (const std::string problem = make_file_problem(dir); !problem.empty())
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

fs::path dicom_series_dir(const fs::path& volume) {
  if (volume.empty() || volume_file_kind(volume) != VolumeFileKind::dicom) return {};
  std::error_code ec;
  return fs::is_directory(volume, ec) ? volume : fs::absolute(volume, ec).parent_path();
}

}  // namespace simdvol
