// Pieces the benchmark tools share: wall-clock timing, median / min / max
// over repeats, the host's triad bandwidth, what the machine is (CPU model,
// OpenCL platform version, POCL_MAX_PTHREAD_COUNT) and, from bench_args.hpp,
// strict parsing of option values (ArgumentError naming the option).
#pragma once

#include <chrono>
#include <cstdint>
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

/// The machine a benchmark ran on.
struct HostInfo {
  std::string cpu_model;               ///< /proc/cpuinfo "model name" ("unknown" if absent)
  unsigned hardware_threads = 0;       ///< std::thread::hardware_concurrency()
  std::string pocl_max_pthread_count;  ///< the environment variable ("" when unset)
  std::string platform_version;        ///< CL_PLATFORM_VERSION of the device's platform
};
HostInfo host_info(const Device& device);

}  // namespace simdvol::bench
