// File checks shared by simdvol_core's readers (internal: not installed).
#pragma once

#include <filesystem>

namespace simdvol {

/// FileError "is a directory, not a <noun>" for a directory, and "is not a
/// regular file" for any other existing file that is not one (a FIFO would
/// block the read, a device such as /dev/zero fill the memory); nothing for
/// a regular file or a missing one (each reader says "not found" its way).
void refuse_non_regular_file(const std::filesystem::path& path, const char* noun);

}  // namespace simdvol
