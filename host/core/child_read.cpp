// Reading a volume in a child process (child_read.hpp): GDCM's asserts,
// and the HDF5 and netCDF under libminc, stop the process on some files.
#include "child_read.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <new>
#include <string>

#include "file_checks.hpp"
#include "read_watch.hpp"
#include "simdvol/error.hpp"
#include "temp_files.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

/// What the reading process sends back before the voxels.
struct Reply {
  int32_t status = 0;  ///< 0 a volume follows, 1 a FileError, 2 out of memory
  int32_t type = 0;
  int64_t dims[3] = {0, 0, 0};
  double spacing[3] = {1, 1, 1};
  char orientation[4] = {0, 0, 0, 0};
  int64_t volumes = 1;       ///< 3-D volumes in the file (status 0 and 1)
  uint32_t text_bytes = 0;   ///< status 1: the error's path, a NUL, its problem
  uint32_t note_bytes = 0;   ///< status 0: the notes after the voxels, each ending in a NUL
  uint32_t watch_bytes = 0;  ///< status 0 and 1: the files read (watched_files), last
};

/// The files the read met (watched_files), for the parent's load_volume to
/// watch: each its identity (a byte saying whether it has one, then the
/// struct), its name's length (uint32) and its name.
std::string watched_files_bytes() {
  std::string b;
  for (const WatchedFile& f : watched_files()) {
    const FileIdentity id = f.identity.value_or(FileIdentity{});
    const std::string name = f.path.string();
    const auto length = static_cast<uint32_t>(name.size());
    b += f.identity ? '\1' : '\0';
    b.append(reinterpret_cast<const char*>(&id), sizeof id);
    b.append(reinterpret_cast<const char*>(&length), sizeof length);
    b += name;
  }
  return b;
}

/// Reads watched_files_bytes' `bytes` bytes from `fd` and watches the files
/// (watch_file: nothing unless a load_volume reads on this thread).
void watch_files_from(int fd, uint32_t bytes) {
  if (bytes == 0 || bytes >= (1u << 30)) return;
  std::string b(bytes, '\0');
  if (!read_fully(fd, b.data(), b.size())) return;
  constexpr std::size_t fixed = 1 + sizeof(FileIdentity) + sizeof(uint32_t);
  for (std::size_t at = 0; b.size() - at >= fixed;) {
    FileIdentity id;
    uint32_t length = 0;
    std::memcpy(&id, b.data() + at + 1, sizeof id);
    std::memcpy(&length, b.data() + at + 1 + sizeof id, sizeof length);
    if (b.size() - at - fixed < length) return;
    watch_file(fs::path(b.substr(at + fixed, length)),
               b[at] ? std::optional<FileIdentity>(id) : std::nullopt);
    at += fixed + length;
  }
}

/// The reading process: loads, sends the volume or the error down `fd`.
[[noreturn]] void child(const std::function<Volume(int64_t*)>& read, int fd) {
  Reply reply;
  try {
    const Volume v = read(&reply.volumes);
    reply.type = static_cast<int32_t>(v.type());
    for (int a = 0; a < 3; ++a) {
      reply.dims[a] = v.dims()[a];
      reply.spacing[a] = v.spacing()[a];
    }
    std::memcpy(reply.orientation, v.orientation().data(),
                std::min<std::size_t>(3, v.orientation().size()));
    std::string notes;
    for (const std::string& n : v.notes()) notes += n + '\0';
    reply.note_bytes = static_cast<uint32_t>(notes.size());
    const std::string watched = watched_files_bytes();
    reply.watch_bytes = static_cast<uint32_t>(watched.size());
    const bool ok = write_fully(fd, &reply, sizeof reply) &&
                    write_fully(fd, v.data().data(), v.data().size() * sizeof(float)) &&
                    write_fully(fd, notes.data(), notes.size()) &&
                    write_fully(fd, watched.data(), watched.size());
    ::_exit(ok ? 0 : 3);
  } catch (const FileError& e) {
    reply.status = 1;
    std::string text = e.path().string();
    text += '\0';
    text += e.problem();
    reply.text_bytes = static_cast<uint32_t>(text.size());
    const std::string watched = watched_files_bytes();
    reply.watch_bytes = static_cast<uint32_t>(watched.size());
    const bool ok = write_fully(fd, &reply, sizeof reply) &&
                    write_fully(fd, text.data(), text.size()) &&
                    write_fully(fd, watched.data(), watched.size());
    ::_exit(ok ? 0 : 3);
  } catch (const std::bad_alloc&) {
    reply.status = 2;
    ::_exit(write_fully(fd, &reply, sizeof reply) ? 0 : 3);
  } catch (...) {
    ::_exit(4);
  }
}

/// The last line a crashed reader wrote (GDCM's assertion, say), trimmed.
std::string last_line(int fd) {
  std::string all;
  ::lseek(fd, 0, SEEK_SET);
  char b[4096];
  for (ssize_t r; (r = ::read(fd, b, sizeof b)) > 0;) all.append(b, static_cast<std::size_t>(r));
  while (!all.empty() && (all.back() == '\n' || all.back() == ' ')) all.pop_back();
  const std::size_t nl = all.rfind('\n');
  std::string line = nl == std::string::npos ? all : all.substr(nl + 1);
  if (line.size() > 300) line = line.substr(0, 300) + "...";
  return line;
}

}  // namespace

Volume read_in_child(const std::filesystem::path& path, const char* library,
                     const std::function<Volume(int64_t* volumes)>& read, int64_t* volumes) {
  if (volumes) *volumes = 1;
  // The child writes its reply and the voxels into a memory file that this
  // process reads once the child has ended (through a pipe, the two
  // processes took turns over each MiB: 0.4 s more for a 300-slice CT).
  struct Files {
    int mem = -1;
    std::FILE* log = nullptr;
    ~Files() {
      if (mem >= 0) ::close(mem);
      if (log) std::fclose(log);
    }
  } f;
  f.mem = ::memfd_create("simdvol-read", MFD_CLOEXEC);
  if (f.mem < 0)
    throw FileError(
        path, std::string("cannot make a memory file to read it into: ") + std::strerror(errno));
  f.log = std::tmpfile();
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0)
    throw FileError(path,
                    std::string("cannot start a process to read it: ") + std::strerror(errno));
  if (pid == 0) {
    // The parent's temporary files are its own: a signal that ends this
    // child alone (SIGTERM to its pid) must not remove them.
    forget_temporary_files();
    if (f.log) ::dup2(::fileno(f.log), 2);
    child(read, f.mem);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  Reply reply;
  const bool got = WIFEXITED(status) && WEXITSTATUS(status) == 0 &&
                   ::lseek(f.mem, 0, SEEK_SET) == 0 && read_fully(f.mem, &reply, sizeof reply);
  if (got && volumes && reply.volumes >= 1) *volumes = reply.volumes;
  if (got && reply.status == 0) {
    const std::array<int64_t, 3> dims{reply.dims[0], reply.dims[1], reply.dims[2]};
    Volume vol(dims, static_cast<VoxelType>(reply.type),
               {reply.spacing[0], reply.spacing[1], reply.spacing[2]});
    std::string notes(reply.note_bytes < (1u << 20) ? reply.note_bytes : 0, '\0');
    if (reply.note_bytes < (1u << 20) &&
        read_fully(f.mem, vol.data().data(), vol.data().size() * sizeof(float)) &&
        read_fully(f.mem, notes.data(), notes.size())) {
      watch_files_from(f.mem, reply.watch_bytes);
      vol.set_orientation(std::string(reply.orientation, ::strnlen(reply.orientation, 3)));
      for (std::size_t at = 0; at < notes.size();) {
        const std::size_t end = notes.find('\0', at);
        vol.add_note(notes.substr(at, end - at));
        at = end == std::string::npos ? notes.size() : end + 1;
      }
      return vol;
    }
  } else if (got && reply.status == 1 && reply.text_bytes < (1u << 20)) {
    std::string text(reply.text_bytes, '\0');
    if (read_fully(f.mem, text.data(), text.size())) {
      watch_files_from(f.mem, reply.watch_bytes);
      const std::size_t nul = text.find('\0');
      throw FileError(fs::path(text.substr(0, nul)), text.substr(nul + 1));
    }
  } else if (got && reply.status == 2) {
    throw std::bad_alloc();
  }
  const std::string said = f.log ? last_line(::fileno(f.log)) : std::string();
  if (WIFSIGNALED(status))
    throw FileError(path, std::string(library) + " stopped on it (signal " +
                              std::to_string(WTERMSIG(status)) +
                              (said.empty() ? std::string() : ": " + said) + "): a file " +
                              library + " cannot read");
  throw FileError(path, "the process reading it failed (exit status " +
                            std::to_string(WEXITSTATUS(status)) + ")" +
                            (said.empty() ? std::string() : ": " + said));
}

}  // namespace simdvol
