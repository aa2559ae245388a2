// The checks of an output file named on a command line, made before any
// work (internal: not installed): the simdvol CLI's and the bench tools'
// one rule, so that a run of minutes does not end in a file it cannot
// write, or write over what it read.
#pragma once

#include <filesystem>
#include <vector>

namespace simdvol {

/// Throws ArgumentError (naming `arg`) where the output `p` cannot be
/// written: an empty name, a path that is a directory or not a regular
/// file (a FIFO, socket or device), one that cannot be looked up (a name
/// too long for the file system), a missing directory, or a directory in
/// which no file can be made (no permission, a read-only file system, a
/// file system such as /proc): a temporary file is made there (as the
/// writers make theirs, TempFile) and removed at once. Symbolic links are
/// followed to where the write goes.
void check_output_path(const std::filesystem::path& p, const char* arg);

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

/// The directory a DICOM volume's series is read from (the directory given,
/// or the file's), for check_not_an_input; empty for any other kind of file.
std::filesystem::path dicom_series_dir(const std::filesystem::path& volume);

}  // namespace simdvol
