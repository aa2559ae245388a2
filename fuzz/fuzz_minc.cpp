// libFuzzer target for load_minc. The rest of the input after byte 0 is
// written as input.mnc; (byte 0) mod 4 the volume index: 0 none, k the
// index k - 1. simdvol's own checks (the signature, the netCDF header's
// extent) run in this process, coverage-guided; libminc, HDF5 and netCDF
// in the child process load_minc reads in, so that a crash there is a
// FileError, as for a user.
#include <optional>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  simdvol_fuzz::clear_scratch();
  const std::filesystem::path path = simdvol_fuzz::write_input("input.mnc", data + 1, size - 1);
  const std::optional<int64_t> index = simdvol_fuzz::volume_index(data[0], 1);
  simdvol_fuzz::run_loader([&] { return simdvol::load_minc(path, index); });
  return 0;
}
