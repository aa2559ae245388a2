// Reading a volume in a child process, for the libraries that stop the
// process on some files (internal: not installed).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>

#include "simdvol/volume.hpp"

namespace simdvol {

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
Volume read_in_child(const std::filesystem::path& path, const char* library,
                     const std::function<Volume(int64_t* volumes)>& read, int64_t* volumes);

}  // namespace simdvol
