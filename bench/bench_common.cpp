// Shared benchmark pieces (bench_common.hpp).
#include "bench_common.hpp"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>

#include "simdvol/error.hpp"

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

int64_t parse_int(const std::string& s, const std::string& option) {
  int64_t v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
    throw ArgumentError(option, "'" + s + "' is not an integer");
  return v;
}

double parse_double(const std::string& s, const std::string& option) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size())
    throw ArgumentError(option, "'" + s + "' is not a number");
  return v;
}

std::vector<std::string> split_list(const std::string& s, const std::string& option) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string tok; std::getline(ss, tok, ',');) {
    if (tok.empty()) throw ArgumentError(option, "empty item in '" + s + "'");
    out.push_back(tok);
  }
  if (out.empty() || s.back() == ',') throw ArgumentError(option, "empty list '" + s + "'");
  return out;
}

std::vector<int64_t> parse_int_list(const std::string& s, const std::string& option, int64_t lo,
                                    int64_t hi) {
  std::vector<int64_t> out;
  for (const std::string& tok : split_list(s, option)) {
    const int64_t v = parse_int(tok, option);
    if (v < lo || v > hi)
      throw ArgumentError(option, std::to_string(v) + " is outside " + std::to_string(lo) + ".." +
                                      std::to_string(hi));
    out.push_back(v);
  }
  return out;
}

}  // namespace simdvol::bench
