// libFuzzer target for load_nifti. Byte 0 chooses the form:
//   0 mod 3: the rest is written as input.nii
//   1 mod 3: the rest is gzip-compressed (zlib, level 1) and written as
//            input.nii.gz, so mutations reach the header and data through
//            the compression layer
//   2 mod 3: the rest is written as input.nii.gz unchanged (corrupt or
//            truncated gzip streams, or plain bytes under a .gz name)
// and (byte 0 / 3) mod 4 the volume index: 0 none, k the index k - 1 (so
// that 4-D headers reach the reading of one volume)
#include <zlib.h>

#include <optional>
#include <vector>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  simdvol_fuzz::clear_scratch();
  const uint8_t* body = data + 1;
  const std::size_t n = size - 1;
  std::filesystem::path path;
  switch (data[0] % 3) {
    case 0:
      path = simdvol_fuzz::write_input("input.nii", body, n);
      break;
    case 1: {
      // A gzip stream: deflate with a gzip wrapper (windowBits 15 + 16).
      z_stream z{};
      if (deflateInit2(&z, 1, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) return 0;
      std::vector<uint8_t> out(deflateBound(&z, static_cast<uLong>(n)) + 64);
      z.next_in = const_cast<Bytef*>(body);
      z.avail_in = static_cast<uInt>(n);
      z.next_out = out.data();
      z.avail_out = static_cast<uInt>(out.size());
      const int r = deflate(&z, Z_FINISH);
      const std::size_t len = out.size() - z.avail_out;
      deflateEnd(&z);
      if (r != Z_STREAM_END) return 0;
      path = simdvol_fuzz::write_input("input.nii.gz", out.data(), len);
      break;
    }
    default:
      path = simdvol_fuzz::write_input("input.nii.gz", body, n);
      break;
  }
  const int k = (data[0] / 3) % 4;
  const std::optional<int64_t> index =
      k == 0 ? std::nullopt : std::optional<int64_t>(static_cast<int64_t>(k - 1));
  simdvol_fuzz::run_loader([&] { return simdvol::load_nifti(path, index); });
  return 0;
}
