// Typed errors thrown by simdvol. Every message names what failed (a file, an
// argument, an OpenCL call) and the problem; nothing is kept in global state.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>

namespace simdvol {

/// Base of every error simdvol throws.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A file could not be read or written, or its contents are malformed.
/// what() is "<path>: <problem>".
class FileError : public Error {
 public:
  FileError(const std::filesystem::path& path, const std::string& problem)
      : Error(path.string() + ": " + problem), path_(path), problem_(problem) {}
  const std::filesystem::path& path() const { return path_; }
  const std::string& problem() const { return problem_; }

 private:
  std::filesystem::path path_;
  std::string problem_;
};

/// An argument or option is out of range or inconsistent.
/// what() is "<argument>: <problem>".
class ArgumentError : public Error {
 public:
  ArgumentError(const std::string& argument, const std::string& problem)
      : Error(argument + ": " + problem) {}
};

}  // namespace simdvol
