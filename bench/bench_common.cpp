// Shared benchmark pieces (bench_common.hpp).
#include "bench_common.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <thread>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace simdvol::bench {

Summary summarize(std::vector<double> v) {
  Summary s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  s.median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  s.min = v.front();
  s.max = v.back();
  s.count = static_cast<int>(n);
  return s;
}

double median(std::vector<double> v) {
  return summarize(std::move(v)).median;
}

double triad_gbs(std::size_t bytes) {
  const std::size_t n = bytes / sizeof(float);
  std::vector<float> a(n), b(n, 1.0f), c(n, 2.0f);
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  double best = 1e30;
  for (int rep = 0; rep < 4; ++rep) {
    const auto t0 = Clock::now();
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        const std::size_t lo = n * t / threads, hi = n * (t + 1) / threads;
        for (std::size_t i = lo; i < hi; ++i) a[i] = b[i] + 3.0f * c[i];
      });
    for (auto& th : pool) th.join();
    if (rep > 0) best = std::min(best, ms_since(t0));  // rep 0 touches the pages
  }
  if (a[n / 2] != 7.0f) std::fprintf(stderr, "triad check failed\n");
  return 3.0 * static_cast<double>(bytes) / (best * 1e-3) / 1e9;
}

std::filesystem::path data_dir() {
  if (const char* d = std::getenv("SIMDVOL_DATA_DIR"); d && *d) return d;
  return SIMDVOL_BENCH_DATA_DIR;
}

void note_brainsmall_missing(const std::string& path) {
  std::printf(
      "(%s not found: brainsmall skipped; scripts/fetch-data fetches it, into "
      "$SIMDVOL_DATA_DIR where set; --brain PATH names another)\n",
      path.c_str());
}

HostInfo host_info(const Device& device) {
  HostInfo h;
  h.cpu_model = "unknown";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        h.cpu_model = line.substr(line.find_first_not_of(" \t", colon + 1));
        break;
      }
    }
  }
  h.hardware_threads = std::thread::hardware_concurrency();
  if (const char* e = std::getenv("POCL_MAX_PTHREAD_COUNT")) h.pocl_max_pthread_count = e;
  cl_platform_id platform = nullptr;
  if (device.device().getInfo(CL_DEVICE_PLATFORM, &platform) == CL_SUCCESS && platform) {
    std::string v;
    if (cl::Platform(platform, true).getInfo(CL_PLATFORM_VERSION, &v) == CL_SUCCESS)
      h.platform_version = v.c_str();  // drop a trailing NUL
  }
  return h;
}

#if defined(__GLIBC__)
KeepHeap::KeepHeap() {
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, INT32_MAX);
}
KeepHeap::~KeepHeap() {
  mallopt(M_MMAP_MAX, 65536);                   // glibc's default
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);  // its dynamic threshold's ceiling
  mallopt(M_TRIM_THRESHOLD, 64 * 1024 * 1024);  // twice that, as glibc sets it
}
#else
KeepHeap::KeepHeap() = default;
KeepHeap::~KeepHeap() = default;
#endif

}  // namespace simdvol::bench
