// The temporary files of writes in progress, and the signal handlers that
// remove them (remove_temporary_files_on_signals, simdvol/io.hpp).
#include "temp_files.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <fstream>
#include <string>
#include <system_error>
#include <vector>

#include "simdvol/error.hpp"
#include "simdvol/io.hpp"

namespace simdvol {

namespace {

// A fixed table, so that a signal handler can walk it: it may only read
// lock-free atomics and call async-signal-safe functions (unlink, raise).
// A slot is free (0), being written (1) or holds a path (2).
constexpr int kSlots = 64;
constexpr std::size_t kPathBytes = 4096;
struct Slot {
  std::atomic<int> state{0};
  char path[kPathBytes];
};
std::array<Slot, kSlots> g_slots;
static_assert(std::atomic<int>::is_always_lock_free);

constexpr std::array<int, 4> kEndingSignals = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};

extern "C" void remove_temporary_files_and_end(int sig) {
  const int saved = errno;
  for (Slot& s : g_slots)
    if (s.state.load(std::memory_order_acquire) == 2) ::unlink(s.path);
  // The handler was installed with SA_RESETHAND: the signal's default action
  // is back, and the signal raised again ends the process when the handler
  // returns (it is blocked until then), as it would have without us.
  ::raise(sig);
  errno = saved;
}

// Whether `sig` would end the process as it is (its default action, no
// handler): a signal the program ignores (nohup's SIGHUP) or handles itself
// is left so.
bool at_default(int sig) {
  struct sigaction old {};
  return ::sigaction(sig, nullptr, &old) == 0 && !(old.sa_flags & SA_SIGINFO) &&
         old.sa_handler == SIG_DFL;
}

std::string errno_text(int e) {
  return std::generic_category().message(e);
}

// The process's umask, read where it cannot change it (umask(2) sets it to
// read it, which another thread's file creation could see): Linux's
// /proc/self/status, else the usual 022.
mode_t current_umask() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("Umask:", 0) == 0)
      return static_cast<mode_t>(std::stoul(line.substr(6), nullptr, 8));
  return 022;
}

}  // namespace

TempFile::TempFile(const std::filesystem::path& target, const std::filesystem::path& named)
    : target_(target), named_(named) {
  const std::filesystem::path dir =
      target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
  // The extension kept where it is short (an image's); a long one (a name
  // "a.<250 bytes>") is cut with the rest, so that the name stays within
  // the file system's 255 bytes.
  const bool keep_ext = target.extension().string().size() <= 16;
  const std::string ext = keep_ext ? target.extension().string() : "", tag = ".tmp-XXXXXX";
  const std::string base = keep_ext ? target.stem().string() : target.filename().string();
  // Shorter where the directory's path is long: the whole path within 4,095
  // bytes (a frame within 20 bytes of it failed as "File name too long"
  // where its own name fits).
  const std::size_t around = dir.string().size() + 1 + tag.size() + ext.size();
  const std::size_t room = around < 4095 ? 4095 - around : 0;
  const std::string stem = base.substr(0, std::min<std::size_t>(64, room));
  const std::string name = (dir / (stem + tag + ext)).string();
  std::vector<char> buf(name.begin(), name.end());
  buf.push_back('\0');
  fd_ = ::mkstemps(buf.data(), static_cast<int>(ext.size()));
  if (fd_ < 0)
    throw FileError(named_, "cannot create a temporary file in " + dir.string() + ": " +
                                errno_text(errno) + file_size_limit_note());
  path_ = buf.data();
  mark_.emplace(path_);
  ::fchmod(fd_, 0666 & ~current_umask());  // mkstemps makes it 0600
}

TempFile::~TempFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!done_) ::unlink(path_.c_str());
}

void TempFile::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void TempFile::fail(const std::string& problem) {
  close();
  ::unlink(path_.c_str());
  done_ = true;
  throw FileError(named_, problem + file_size_limit_note());
}

void TempFile::commit() {
  if (fd_ < 0) fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);  // fsync needs a descriptor
  if (fd_ < 0) fail("cannot reopen the temporary file: " + errno_text(errno));
  if (::fsync(fd_) != 0 && errno != EINVAL) {
    const int e = errno;
    fail("fsync failed: " + errno_text(e));
  }
  const int closed = ::close(fd_), e = errno;
  fd_ = -1;
  if (closed != 0) fail("close failed: " + errno_text(e));
  std::error_code ec;
  std::filesystem::rename(path_, target_, ec);
  if (ec) fail("cannot rename the temporary file into place: " + ec.message());
  done_ = true;
}

TempFileMark::TempFileMark(const std::filesystem::path& path) noexcept {
  const std::string& p = path.native();
  if (p.empty() || p.size() >= kPathBytes) return;
  for (int i = 0; i < kSlots; ++i) {
    int expected = 0;
    if (!g_slots[i].state.compare_exchange_strong(expected, 1, std::memory_order_acquire)) continue;
    std::memcpy(g_slots[i].path, p.c_str(), p.size() + 1);
    g_slots[i].state.store(2, std::memory_order_release);
    slot_ = i;
    return;
  }
}

TempFileMark::~TempFileMark() {
  if (slot_ >= 0) g_slots[slot_].state.store(0, std::memory_order_release);
}

void remove_temporary_files_on_signals() {
  for (int sig : kEndingSignals) {
    if (!at_default(sig)) continue;
    struct sigaction sa {};
    sa.sa_handler = remove_temporary_files_and_end;
    sigemptyset(&sa.sa_mask);
    for (int other : kEndingSignals) sigaddset(&sa.sa_mask, other);
    sa.sa_flags = SA_RESETHAND;
    ::sigaction(sig, &sa, nullptr);
  }
  // A write past the file-size limit (ulimit -f) fails with EFBIG, and the
  // writer's FileError says so, instead of SIGXFSZ ending the process with
  // the temporary file cut short.
  if (at_default(SIGXFSZ)) std::signal(SIGXFSZ, SIG_IGN);
}

std::optional<unsigned long long> file_size_limit() {
  struct rlimit lim {};
  if (::getrlimit(RLIMIT_FSIZE, &lim) != 0 || lim.rlim_cur == RLIM_INFINITY) return std::nullopt;
  return static_cast<unsigned long long>(lim.rlim_cur);
}

std::string file_size_limit_note() {
  const std::optional<unsigned long long> limit = file_size_limit();
  return limit ? " (the file-size limit, ulimit -f, is " + std::to_string(*limit) + " bytes)" : "";
}

}  // namespace simdvol
