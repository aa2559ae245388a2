// libFuzzer target for load_nrrd. Byte 0 chooses the form:
//   even: attached header; the rest is written as input.nrrd
//   odd:  detached header; the rest is split after its first blank line
//         ("\n\n"): the part up to it is input.nhdr, the remainder is written
//         as data.raw beside it (seeds name it in "data file: data.raw";
//         the fuzzer may name anything else).
// and (byte 0 / 2) mod 4 the volume index: 0 none, k the index k - 1 (so
// that 4-D headers reach the reading of one volume).
// Files the previous input left behind are removed first.
#include <optional>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  simdvol_fuzz::clear_scratch();
  const uint8_t* body = data + 1;
  const std::size_t n = size - 1;
  std::filesystem::path path;
  if ((data[0] & 1) == 0) {
    path = simdvol_fuzz::write_input("input.nrrd", body, n);
  } else {
    path = simdvol_fuzz::write_header_and_data("input.nhdr", "data.raw", body, n);
  }
  const std::optional<int64_t> index = simdvol_fuzz::volume_index(data[0], 2);
  simdvol_fuzz::run_loader([&] { return simdvol::load_nrrd(path, index); });
  return 0;
}
