// Helpers shared by the tests: where the fetched real data lives, and the
// rule for tests that need it.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace simdvol::testing {

inline std::filesystem::path data_dir() {
  if (const char* d = std::getenv("SIMDVOL_DATA_DIR")) return d;
  return SIMDVOL_DATA_DIR;
}

/// True when the real-data files must be present (the test command sets
/// SIMDVOL_REQUIRE_DATA=1 after running scripts/fetch-data).
inline bool data_required() {
  const char* r = std::getenv("SIMDVOL_REQUIRE_DATA");
  return r && std::string(r) == "1";
}

/// Whether the tests run under AddressSanitizer (GCC's __SANITIZE_ADDRESS__,
/// Clang's __has_feature): for the few that its shadow memory or its
/// allocator rule out, each saying why it skips.
#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kUnderAsan = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kUnderAsan = true;
#else
inline constexpr bool kUnderAsan = false;
#endif
#else
inline constexpr bool kUnderAsan = false;
#endif

}  // namespace simdvol::testing

/// Skips (or, when data is required, fails) a test whose real-data file is missing.
#define SIMDVOL_REQUIRE_FILE(path)                                                        \
  do {                                                                                    \
    if (!std::filesystem::exists(path)) {                                                 \
      if (::simdvol::testing::data_required())                                            \
        FAIL() << "missing " << (path) << ": run scripts/fetch-data";                     \
      else                                                                                \
        GTEST_SKIP() << "missing " << (path) << ": run scripts/fetch-data to include it"; \
    }                                                                                     \
  } while (0)
