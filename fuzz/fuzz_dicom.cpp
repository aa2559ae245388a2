// libFuzzer target for load_dicom: the input is one whole DICOM file
// (input.dcm, alone in its directory, so no series is looked for beside
// it). load_dicom reads in a child process (GDCM aborts on some files), so
// this target checks the production path: that no input stops or hangs
// the caller, and that each ends as a volume or a simdvol::Error. The
// child's coverage does not reach libFuzzer; with SIMDVOL_DICOM_IN_PROCESS=1
// in the environment the reading runs here instead, coverage-guided, and
// GDCM's own assertions then show as findings (GDCM's, not simdvol's).
#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  simdvol_fuzz::clear_scratch();
  const auto path = simdvol_fuzz::write_input("input.dcm", data, size);
  simdvol_fuzz::run_loader([&] { return simdvol::load_dicom(path); });
  return 0;
}
