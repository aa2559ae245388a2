// The temporary files of writes in progress, and the signal handlers that
// remove them (remove_temporary_files_on_signals, simdvol/io.hpp).
#include "temp_files.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <string>

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

}  // namespace

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
