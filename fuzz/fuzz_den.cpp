// libFuzzer target for load_den: the input is the whole .den file.
#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto path = simdvol_fuzz::write_input("input.den", data, size);
  simdvol_fuzz::run_loader([&] { return simdvol::load_den(path); });
  return 0;
}
