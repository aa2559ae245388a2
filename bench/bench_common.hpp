// Pieces the benchmark tools share: wall-clock timing, median / min / max
// over repeats, the host's triad bandwidth, what the machine is (CPU model,
// OpenCL platform version, POCL_MAX_PTHREAD_COUNT), where the data files
// are (data_dir) and, from bench_args.hpp, strict parsing of option values
// (ArgumentError naming the option), and the serial reference timed warm
// (KeepHeap, time_warm).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_args.hpp"
#include "simdvol/device.hpp"

namespace simdvol::bench {

using Clock = std::chrono::steady_clock;

inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// Median (the mean of the middle two for an even count), min, max; 0 when empty.
struct Summary {
  double median = 0, min = 0, max = 0;
  int count = 0;
};
Summary summarize(std::vector<double> v);
/// summarize(v).median.
double median(std::vector<double> v);

/// Triad a = b + 3 c over three float arrays of `bytes` each, one host thread
/// per hardware thread, best of 3 runs after one that touches the pages;
/// GB/s counting 3 arrays (write-allocate traffic not counted).
double triad_gbs(std::size_t bytes);

/// Where the fetched real volumes (brainsmall.den, ch2.nii.gz) are looked
/// for: $SIMDVOL_DATA_DIR where set and not empty (as the tests and
/// scripts/fetch-data take it; a relative one from the working directory),
/// else the source tree's data/ (compiled in), so that a tool finds them
/// from any working directory.
std::filesystem::path data_dir();
/// "(PATH not found: brainsmall skipped; ...)" on stdout: how to get it.
void note_brainsmall_missing(const std::string& path);

/// The machine a benchmark ran on.
struct HostInfo {
  std::string cpu_model;               ///< /proc/cpuinfo "model name" ("unknown" if absent)
  unsigned hardware_threads = 0;       ///< std::thread::hardware_concurrency()
  std::string pocl_max_pthread_count;  ///< the environment variable ("" when unset)
  std::string platform_version;        ///< CL_PLATFORM_VERSION of the device's platform
};
HostInfo host_info(const Device& device);

/// While one lives, memory the process frees stays in its heap (glibc): no
/// block is mapped apart (glibc maps each block of 32 MiB or more on its own
/// and unmaps it on free, so the next call faults every page in again) and
/// the heap is not trimmed. The serial reference allocates its shaded and
/// classified volumes (hundreds of MiB for the 256^3 phantom) afresh each
/// call; on the Firecracker VMs of these machines faulting them in took from
/// 0.1 s to 1.3 s of a phantom frame, depending on the host's state and not
/// on the code. At destruction glibc's settled values come back (blocks of
/// 32 MiB or more mapped apart, the heap trimmed above 64 MiB: where its
/// dynamic threshold ends up), and the kept memory is handed back at the next
/// free above the trim threshold. No effect without glibc.
class KeepHeap {
 public:
  KeepHeap();
  ~KeepHeap();
  KeepHeap(const KeepHeap&) = delete;
  KeepHeap& operator=(const KeepHeap&) = delete;
};

/// One call's time measured as the engines' frames are: an untimed warm-up
/// call (its time in *first_ms where given), then `runs` (>= 1) timed calls, their
/// median in `ms`, all under one KeepHeap, so that a serial reference's
/// figure counts its arithmetic and not the VM's page faults (the engines
/// keep their buffers in the device's pool between frames). Returns the
/// last call's result.
template <class F>
auto time_warm(int runs, F&& f, double& ms, double* first_ms = nullptr,
               Summary* summary = nullptr) {
  KeepHeap keep;
  auto t0 = Clock::now();
  auto result = f();
  if (first_ms) *first_ms = ms_since(t0);
  std::vector<double> t;
  for (int r = 0; r < runs || t.empty(); ++r) {
    t0 = Clock::now();
    result = f();
    t.push_back(ms_since(t0));
  }
  const Summary s = summarize(std::move(t));
  ms = s.median;
  if (summary) *summary = s;
  return result;
}

}  // namespace simdvol::bench
