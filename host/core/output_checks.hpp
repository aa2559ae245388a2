// The checks of an output file named on a command line, made before any
// work (internal: not installed): the simdvol CLI's and the bench tools'
// one rule, so that a run of minutes does not end in a file it cannot
// write, or write over what it read.
#pragma once

#include <filesystem>
#include <vector>

#include "simdvol/volume.hpp"

namespace simdvol {

/// Throws ArgumentError (naming `arg`) where the output `p` cannot be
/// written: an empty name, a path that is a directory or not a regular
/// file (a FIFO, socket or device), one that cannot be looked up (a name
/// too long for the file system), a missing directory; a directory in
/// which no file can be made and removed (no permission, a read-only file
/// system, a file system such as /proc, an append-only directory): a
/// temporary file is made there as the writers make theirs (TempFile) and
/// removed at once; and an existing file that a rename cannot replace
/// (immutable or append-only, another user's in a sticky directory such as
/// /tmp). Symbolic links are followed to where the write goes.
void check_output_path(const std::filesystem::path& p, const char* arg);

/// check_output_path for each of `paths` (a turntable's frames), the
/// directory's temporary file made once per directory.
void check_output_paths(const std::vector<std::filesystem::path>& paths, const char* arg);

/// Throws ArgumentError (naming `arg`) where no file can be made in the
/// existing directory `dir` (check_output_path's last check, for a tool that
/// writes several files there).
void check_can_make_files_in(const std::filesystem::path& dir, const char* arg);

/// Throws ArgumentError (naming `arg`) where writing the output `out` would
/// replace a file the command reads: one of `inputs` (a volume, the files
/// its loader read beside it, a classifier file), followed through
/// symbolic links; and, where `dicom_dir` is not empty (a DICOM volume: its
/// series is every slice in that directory and below), an existing DICOM
/// file there.
void check_not_an_input(const std::filesystem::path& out,
                        const std::vector<std::filesystem::path>& inputs,
                        const std::filesystem::path& dicom_dir, const char* arg);

/// What reading a volume from `file` read, for check_not_an_input: the file,
/// the files its loader read beside it (Volume::companion_files: a pair's
/// other half, a detached header's data files) and, for a DICOM series,
/// the directory it was read from (the directory given, or the file's).
/// Nothing for the built-in phantom (an empty `file`).
struct ReadFiles {
  std::vector<std::filesystem::path> files;
  std::filesystem::path dicom_dir;
};
ReadFiles read_files(const Volume& vol, const std::filesystem::path& file);

}  // namespace simdvol
