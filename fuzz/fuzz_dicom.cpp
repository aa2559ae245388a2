// libFuzzer target for load_dicom: the input is one whole DICOM file
// (input.dcm, alone in its directory, so no series is looked for beside
// it): GDCM's parsing and decoding, and the loader's checks.
#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  simdvol_fuzz::clear_scratch();
  const auto path = simdvol_fuzz::write_input("input.dcm", data, size);
  simdvol_fuzz::run_loader([&] { return simdvol::load_dicom(path); });
  return 0;
}
