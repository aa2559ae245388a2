// The temporary files of writes in progress, and the signal handlers that
// remove them (remove_temporary_files_on_signals, simdvol/io.hpp).
#include "temp_files.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <system_error>

#include "file_checks.hpp"
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

}  // namespace

// A batch's marks (TempFileMarks): each entry a path of its own (malloc'd,
// so that 100,000 of them are not 400 MB of fixed slots), swapped in and
// out atomically; the batches in a fixed table of 8 for the handler.
struct TempFileMarks::Entry {
  std::atomic<char*> path{nullptr};
};
struct TempFileMarks::Table {
  const Entry* entries = nullptr;
  std::size_t count = 0;
};

namespace {

constexpr int kBatches = 8;
std::array<std::atomic<const TempFileMarks::Table*>, kBatches> g_batches{};
static_assert(std::atomic<char*>::is_always_lock_free);
static_assert(std::atomic<const TempFileMarks::Table*>::is_always_lock_free);

extern "C" void remove_temporary_files_and_end(int sig) {
  const int saved = errno;
  for (Slot& s : g_slots)
    if (s.state.load(std::memory_order_acquire) == 2) ::unlink(s.path);
  for (const auto& b : g_batches)
    if (const TempFileMarks::Table* t = b.load(std::memory_order_acquire))
      for (std::size_t i = 0; i < t->count; ++i)
        if (const char* p = t->entries[i].path.load(std::memory_order_acquire)) ::unlink(p);
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

// Six characters for a temporary file's name, different in each call
// (a counter from a random start, with the process id: a forked child's
// counter goes on from its parent's; mixed: splitmix64) and thread-safe.
std::string random_tag() {
  static std::atomic<std::uint64_t> counter{std::uint64_t{std::random_device{}()} << 32};
  std::uint64_t x = counter.fetch_add(0x9E3779B97F4A7C15ULL) + 0x9E3779B97F4A7C15ULL +
                    (static_cast<std::uint64_t>(::getpid()) << 40);
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  x ^= x >> 31;
  static constexpr char kChars[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789";
  std::string tag(6, ' ');
  for (char& c : tag) {
    c = kChars[x % 62];
    x /= 62;
  }
  return tag;
}

}  // namespace

TempFile::TempFile(const std::filesystem::path& target, const std::filesystem::path& named)
    : target_(target), named_(named) {
  make();
}

TempFile::TempFile(const std::filesystem::path& target, const std::filesystem::path& named,
                   TempFileMarks& marks, std::size_t index)
    : target_(target), named_(named), marks_(&marks), mark_index_(index) {
  make();
}

void TempFile::make() {
  const std::filesystem::path& target = target_;
  const std::filesystem::path dir =
      target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
  // At most the first 64 bytes of the name, so that a name near the file
  // system's 255 bytes has room for the tag; shorter where the directory's
  // path is long: the whole path within 4,095 bytes (a frame within 20
  // bytes of it failed as "File name too long" where its own name fits).
  const std::size_t around = dir.string().size() + 1 + std::strlen(".tmp-XXXXXX");
  const std::size_t room = around < 4095 ? 4095 - around : 0;
  const std::string stem = target.filename().string().substr(0, std::min<std::size_t>(64, room));
  // Made here with O_EXCL and mode 0666, so that the kernel gives it what a
  // new file gets (the umask, a directory's default ACL); mkstemp's 0600
  // and a chmod could not. Marked before the open: a signal handled as the
  // open returns (it is taken then) found the file unmarked, and 522 of
  // 2000 writes ended by SIGTERM left it on tmpfs. A name already taken
  // (O_EXCL) is unmarked at once; random, it is in practice one of this
  // program's own leftovers. Everything that can throw is done before the
  // open: after it, only moves.
  int e = 0;
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::filesystem::path candidate = dir / (stem + ".tmp-" + random_tag());
    if (marks_)
      marks_->mark(mark_index_, candidate);
    else
      mark_.emplace(candidate);
    fd_ = ::open(candidate.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    e = errno;
    if (fd_ >= 0) {
      path_ = std::move(candidate);
      return;
    }
    if (marks_)
      marks_->unmark(mark_index_);
    else
      mark_.reset();
    if (e != EEXIST) break;
  }
  throw FileError(named_, "cannot create a temporary file in " + dir.string() + ": " +
                              errno_text(e) + file_size_limit_note());
}

TempFile::~TempFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!done_) ::unlink(path_.c_str());
  if (marks_) marks_->unmark(mark_index_);
}

void TempFile::fail(const std::string& problem) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ::unlink(path_.c_str());
  done_ = true;
  throw FileError(named_, problem + file_size_limit_note());
}

int TempFile::remove() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  done_ = true;
  return ::unlink(path_.c_str()) == 0 ? 0 : errno;
}

void TempFile::finish() {
  if (finished_) return;
  if (::fsync(fd_) != 0 && errno != EINVAL) {
    const int e = errno;
    fail("fsync failed: " + errno_text(e));
  }
  const int closed = ::close(fd_), e = errno;
  fd_ = -1;
  if (closed != 0) fail("close failed: " + errno_text(e));
  finished_ = true;
}

void TempFile::commit() {
  finish();
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

TempFileMarks::TempFileMarks(std::size_t count)
    : entries_(new Entry[count]), table_(new Table{nullptr, count}), count_(count) {
  table_->entries = entries_.get();
  for (int i = 0; i < kBatches; ++i) {
    const Table* expected = nullptr;
    if (g_batches[i].compare_exchange_strong(expected, table_.get(), std::memory_order_acq_rel)) {
      slot_ = i;
      return;
    }
  }
}

TempFileMarks::~TempFileMarks() {
  if (slot_ >= 0) g_batches[slot_].store(nullptr, std::memory_order_release);
  for (std::size_t i = 0; i < count_; ++i) std::free(entries_[i].path.exchange(nullptr));
}

void TempFileMarks::mark(std::size_t i, const std::filesystem::path& path) noexcept {
  if (i >= count_) return;
  const std::string& p = path.native();
  char* copy = static_cast<char*>(std::malloc(p.size() + 1));
  if (copy) std::memcpy(copy, p.c_str(), p.size() + 1);
  // (A handler on another thread that read the old path a moment before
  // may unlink it after the free: the process is ending then, and it is,
  // as TempFileMark's slot rewritten under a handler, best effort.)
  std::free(entries_[i].path.exchange(copy, std::memory_order_acq_rel));
}

void TempFileMarks::unmark(std::size_t i) noexcept {
  if (i < count_) std::free(entries_[i].path.exchange(nullptr, std::memory_order_acq_rel));
}

void forget_temporary_files() noexcept {
  for (Slot& s : g_slots) s.state.store(0, std::memory_order_release);
  for (auto& b : g_batches) b.store(nullptr, std::memory_order_release);
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
