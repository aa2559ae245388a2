// Reading a volume in a child process (child_read.hpp): GDCM's asserts,
// and the HDF5 and netCDF under libminc, stop the process on some files.
#include "child_read.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "file_checks.hpp"
#include "read_watch.hpp"
#include "simdvol/error.hpp"
#include "temp_files.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

using Reply = ChildReply;

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
    std::string companions;
    for (const fs::path& c : v.companion_files()) companions += c.string() + '\0';
    reply.companion_bytes = static_cast<uint32_t>(companions.size());
    const std::string watched = watched_files_bytes();
    reply.watch_bytes = static_cast<uint32_t>(watched.size());
    const bool ok = write_fully(fd, &reply, sizeof reply) &&
                    write_fully(fd, v.data().data(), v.data().size() * sizeof(float)) &&
                    write_fully(fd, notes.data(), notes.size()) &&
                    write_fully(fd, companions.data(), companions.size()) &&
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

/// The NUL-ended strings of `text`, in order.
std::vector<std::string> nul_ended(const std::string& text) {
  std::vector<std::string> out;
  for (std::size_t at = 0; at < text.size();) {
    const std::size_t end = text.find('\0', at);
    out.push_back(text.substr(at, end - at));
    at = end == std::string::npos ? text.size() : end + 1;
  }
  return out;
}

using Clock = std::chrono::steady_clock;

/// Waits for the child `pid` to end, until `deadline`: true, with its
/// `status`, once it has ended (and been reaped); false where it still
/// runs then. `pidfd` (pidfd_open's, or -1 where the kernel has none)
/// becomes readable as the child ends; without it the child is looked at
/// every 0.1 ms at first, every 10 ms at most.
bool wait_until(pid_t pid, int pidfd, Clock::time_point deadline, int* status) {
  auto nap = std::chrono::microseconds(100);
  for (;;) {
    const pid_t r = ::waitpid(pid, status, WNOHANG);
    if (r == pid) return true;
    if (r < 0 && errno != EINTR) {
      // ECHILD: reaped by the system (SIGCHLD ignored), so it has ended;
      // its status is lost, and what it wrote is read as before.
      *status = 0;
      return true;
    }
    const Clock::time_point now = Clock::now();
    if (now >= deadline) return false;
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - now);
    if (pidfd >= 0) {
      pollfd p{pidfd, POLLIN, 0};
      ::poll(&p, 1,
             static_cast<int>(std::min<long long>(left.count(), INT_MAX)));  // (EINTR: again)
    } else {
      std::this_thread::sleep_for(std::min<Clock::duration>(nap, left));
      nap = std::min<std::chrono::microseconds>(nap * 2, std::chrono::milliseconds(10));
    }
  }
}

/// Kills the child `pid` (SIGKILL): through `pidfd` where there is one
/// (pidfd_send_signal, Linux 5.1: the signal reaches the process the pidfd
/// was opened for and no other, even one that has ended since), else by
/// its pid. The pid is safe as it is used here: the last look
/// (wait_until's waitpid) found the child running, and a child that ends
/// after it stays a zombie, its pid kept from any other process, until
/// this process reaps it (after the kill). Not so where the program
/// ignores SIGCHLD (SIG_IGN: the kernel reaps a child as it ends), where a
/// child ending between that look and the kill could free its pid for
/// another process: the pidfd closes that window. A pidfd the kernel
/// cannot signal through (ENOSYS: a kernel before 5.1, or a seccomp filter)
/// falls back to the pid.
void kill_child(pid_t pid, int pidfd) {
#ifdef SYS_pidfd_send_signal
  // (ESRCH: the child has ended since the last look; nothing to kill, and
  // its pid, where the kernel reaped it, no longer its own)
  if (pidfd >= 0 &&
      (::syscall(SYS_pidfd_send_signal, pidfd, SIGKILL, nullptr, 0) == 0 || errno == ESRCH))
    return;
#else
  (void)pidfd;
#endif
  ::kill(pid, SIGKILL);
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

// The byte counts of a reply that is not what the child writes (a child
// whose memory file was cut short or written over, or a bug of ours) are
// checked against what the memory file holds before anything is allocated
// for them or read: before, a reply that claimed 1 GiB of companion files
// was given 1 GiB, then failed to read as "the process reading it failed
// (exit status 0)", and one that claimed dims of 2^20 each asked for
// 2^62 bytes of voxels (std::bad_alloc: "out of memory").
FileError malformed_reply(const fs::path& path, const char* library, const std::string& problem) {
  return FileError(
      path, std::string(library) + "'s reading process sent back a malformed reply: " + problem);
}

}  // namespace

Volume volume_from_reply(int fd, const std::filesystem::path& path, const char* library,
                         int64_t* volumes) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int e = errno;
    throw FileError(path, "cannot look up the memory file it was read into: " + errno_text(e));
  }
  const auto held = static_cast<uint64_t>(std::max<off_t>(st.st_size, 0));
  const auto bad = [&](const std::string& problem) {
    return malformed_reply(path, library, problem);
  };
  const auto count = [](uint64_t n) { return std::to_string(n) + (n == 1 ? " byte" : " bytes"); };
  Reply reply;
  if (held < sizeof reply)
    throw bad("its memory file holds " + count(held) + ", less than the reply's " +
              count(sizeof reply));
  if (::lseek(fd, 0, SEEK_SET) != 0 || !read_fully(fd, &reply, sizeof reply))
    throw bad("its reply could not be read back");
  const uint64_t after = held - sizeof reply;  // what follows the reply
  // What the counts come to, against what follows: equal, or refused.
  const auto check_total = [&](uint64_t total, const char* what) {
    if (total != after)
      throw bad("its reply gives " + count(total) + " of " + what + " after it, its memory file " +
                "holds " + count(after));
  };
  constexpr uint32_t kMostText = 1u << 20, kMostList = 1u << 30;
  const auto check_cap = [&](uint32_t bytes, uint32_t most, const char* what) {
    if (bytes >= most)
      throw bad("its reply gives " + count(bytes) + " of " + what + " (less than " + count(most) +
                " allowed)");
  };
  check_cap(reply.watch_bytes, kMostList, "files read");
  if (reply.status == 0) {
    if (reply.type < 0 || reply.type > static_cast<int32_t>(VoxelType::f32))
      throw bad("voxel type " + std::to_string(reply.type) + " is none of simdvol's");
    check_cap(reply.note_bytes, kMostText, "notes");
    check_cap(reply.companion_bytes, kMostList, "companion files");
    // The voxels' bytes, each dimension at least 1 and the product no more
    // than what follows (checked before it is multiplied: no overflow).
    const uint64_t most_voxels = after / sizeof(float);
    uint64_t voxels = 1;
    for (int a = 0; a < 3; ++a) {
      const int64_t d = reply.dims[a];
      if (d < 1 || static_cast<uint64_t>(d) > most_voxels / voxels)
        throw bad("its dims " + std::to_string(reply.dims[0]) + " x " +
                  std::to_string(reply.dims[1]) + " x " + std::to_string(reply.dims[2]) +
                  (d < 1 ? std::string(" are not all positive")
                         : " need more voxels than its memory file's " + count(after) + " hold"));
      voxels *= static_cast<uint64_t>(d);
    }
    check_total(
        voxels * sizeof(float) + reply.note_bytes + reply.companion_bytes + reply.watch_bytes,
        "voxels, notes, companion files and files read");
    if (volumes && reply.volumes >= 1) *volumes = reply.volumes;
    const std::array<int64_t, 3> dims{reply.dims[0], reply.dims[1], reply.dims[2]};
    std::optional<Volume> vol;
    try {
      vol.emplace(dims, static_cast<VoxelType>(reply.type),
                  std::array<double, 3>{reply.spacing[0], reply.spacing[1], reply.spacing[2]});
      vol->set_orientation(std::string(reply.orientation, ::strnlen(reply.orientation, 3)));
    } catch (const ArgumentError& e) {  // (a spacing or orientation that is none)
      throw bad(e.what());
    }
    std::string notes(reply.note_bytes, '\0');
    std::string companions(reply.companion_bytes, '\0');
    if (!read_fully(fd, vol->data().data(), vol->data().size() * sizeof(float)) ||
        !read_fully(fd, notes.data(), notes.size()) ||
        !read_fully(fd, companions.data(), companions.size()))
      throw bad("its memory file could not be read back");
    watch_files_from(fd, reply.watch_bytes);
    for (const std::string& n : nul_ended(notes)) vol->add_note(n);
    for (const std::string& c : nul_ended(companions)) vol->add_companion_file(c);
    return std::move(*vol);
  }
  if (reply.status == 1) {
    check_cap(reply.text_bytes, kMostText, "error message");
    check_total(uint64_t{reply.text_bytes} + reply.watch_bytes, "error message and files read");
    if (volumes && reply.volumes >= 1) *volumes = reply.volumes;
    std::string text(reply.text_bytes, '\0');
    if (!read_fully(fd, text.data(), text.size()))
      throw bad("its memory file could not be read back");
    watch_files_from(fd, reply.watch_bytes);
    const std::size_t nul = text.find('\0');
    if (nul == std::string::npos) throw bad("its error message has no path");
    throw FileError(fs::path(text.substr(0, nul)), text.substr(nul + 1));
  }
  if (reply.status == 2) {
    check_total(0, "anything");
    throw std::bad_alloc();
  }
  throw bad("status " + std::to_string(reply.status) + " is none of 0 (a volume), 1 (an error) " +
            "and 2 (out of memory)");
}

double default_read_time_limit(ReadSize size, double base_seconds) {
  constexpr uint64_t mib = uint64_t{1} << 20;
  const uint64_t started = size.bytes / mib + (size.bytes % mib != 0);
  return base_seconds + static_cast<double>(started) * kReadSecondsPerMiB +
         static_cast<double>(size.files) * kReadSecondsPerFile;
}

std::optional<long> read_timeout_setting() {
  constexpr const char* kName = "SIMDVOL_READ_TIMEOUT";
  constexpr long kMost = 10000000;
  const char* e = std::getenv("SIMDVOL_READ_TIMEOUT");
  if (!e || !*e) return std::nullopt;
  std::string_view text(e);
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  long value = 0;
  bool ok = !text.empty() && text.find_first_not_of("0123456789") == std::string_view::npos;
  for (std::size_t i = 0; ok && i < text.size(); ++i) {
    value = value * 10 + (text[i] - '0');
    ok = value <= kMost;
  }
  if (!ok || value < 1)
    throw ArgumentError(kName, std::string("\"") + e +
                                   "\" is not a time limit in whole seconds, 1 .. 10000000 (the "
                                   "longest a DICOM or MINC file's read may take)");
  return value;
}

Volume read_in_child(const std::filesystem::path& path, const char* library,
                     const std::function<Volume(int64_t* volumes)>& read, int64_t* volumes,
                     const std::function<ReadSize()>& size, double base_seconds) {
  if (volumes) *volumes = 1;
  // (a bad SIMDVOL_READ_TIMEOUT is refused before a child is started)
  const std::optional<long> set_limit = read_timeout_setting();
  // The child writes its reply and the voxels into a memory file that this
  // process reads once the child has ended (through a pipe, the two
  // processes took turns over each MiB: 0.4 s more for a 300-slice CT).
  struct Files {
    int mem = -1, pidfd = -1;
    std::FILE* log = nullptr;
    ~Files() {
      if (mem >= 0) ::close(mem);
      if (pidfd >= 0) ::close(pidfd);
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
  const Clock::time_point start = Clock::now();
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
  // The child is given its time limit, then killed: a library looping on
  // a file (or a child deadlocked) had hung the load for ever. Without the
  // user's limit it is `base_seconds` at first, and once those have
  // passed, what the files' size gives: an honest read of a large series
  // is not stopped, and the files are looked up only for a long read.
#ifdef SYS_pidfd_open
  f.pidfd = static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
#else
  f.pidfd = -1;  // (headers older than Linux 5.3's: the child is polled)
#endif
  double limit = set_limit ? static_cast<double>(*set_limit) : base_seconds;
  bool sized = set_limit.has_value();
  int status = 0;
  for (;;) {
    // (past some 290 years, the limit is none)
    const auto ends = start + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(std::min(limit, 9e9)));
    if (wait_until(pid, f.pidfd, ends, &status)) break;
    if (!sized) {
      sized = true;
      ReadSize met;
      try {
        if (size) met = size();
      } catch (...) {  // (a size not found: the base limit alone)
      }
      limit = default_read_time_limit(met, base_seconds);
      continue;
    }
    kill_child(pid, f.pidfd);
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", limit);
    throw FileError(path, std::string(library) + " did not finish reading it within " + text +
                              " s (looping on the file?), and was stopped; "
                              "SIMDVOL_READ_TIMEOUT=SECONDS sets the limit");
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0)
    return volume_from_reply(f.mem, path, library, volumes);
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
