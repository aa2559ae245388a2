// libFuzzer target for load_nifti. Byte 0 chooses the form:
//   0 mod 4: the rest is written as input.nii
//   1 mod 4: the rest is gzip-compressed (zlib, level 1) and written as
//            input.nii.gz, so mutations reach the header and data through
//            the compression layer
//   2 mod 4: the rest is written as input.nii.gz unchanged (corrupt or
//            truncated gzip streams, or plain bytes under a .gz name)
//   3 mod 4: a .hdr/.img pair (NIfTI-1, NIfTI-2 or Analyze 7.5): the rest's
//            first 540 bytes go to input.hdr if it starts with 540 (either
//            byte order), else its first 348, and what follows to
//            input.img; loaded by the .hdr name, or by the .img name when
//            bit 4 of byte 0 is set
// and (byte 0 / 4) mod 4 the volume index: 0 none, k the index k - 1 (so
// that 4-D headers reach the reading of one volume)
#include <algorithm>
#include <optional>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  simdvol_fuzz::clear_scratch();
  const uint8_t* body = data + 1;
  const std::size_t n = size - 1;
  std::filesystem::path path;
  if (data[0] % 4 < 3) {
    path = simdvol_fuzz::write_plain_or_gzipped(data[0] % 4, "input.nii", "input.nii.gz", body, n);
    if (path.empty()) return 0;
  } else {
    const bool v2 =
        n >= 4 && ((body[0] == 0x1c && body[1] == 0x02 && body[2] == 0 && body[3] == 0) ||
                   (body[0] == 0 && body[1] == 0 && body[2] == 0x02 && body[3] == 0x1c));
    const std::size_t split = std::min<std::size_t>(n, v2 ? 540 : 348);
    const auto hdr = simdvol_fuzz::write_input("input.hdr", body, split);
    const auto img = simdvol_fuzz::write_input("input.img", body + split, n - split);
    path = (data[0] & 16) ? img : hdr;
  }
  const std::optional<int64_t> index = simdvol_fuzz::volume_index(data[0], 4);
  simdvol_fuzz::run_loader([&] { return simdvol::load_nifti(path, index); });
  return 0;
}
