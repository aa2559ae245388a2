// libFuzzer target for load_mgh. Byte 0 mod 3 chooses the form:
//   0: the rest is written as input.mgh
//   1: the rest is gzip-compressed (zlib, level 1) and written as
//      input.mgz, so mutations reach the header and voxels through the
//      compression layer
//   2: the rest is written as input.mgz unchanged (corrupt or truncated
//      gzip streams, or plain bytes under a .mgz name)
// and (byte 0 / 3) mod 4 the volume index: 0 none, k the index k - 1.
// Files the previous input left behind are removed first.
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
      path = simdvol_fuzz::write_input("input.mgh", body, n);
      break;
    case 1: {
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
      path = simdvol_fuzz::write_input("input.mgz", out.data(), len);
      break;
    }
    default:
      path = simdvol_fuzz::write_input("input.mgz", body, n);
      break;
  }
  const int k = (data[0] / 3) % 4;
  const std::optional<int64_t> index =
      k == 0 ? std::nullopt : std::optional<int64_t>(static_cast<int64_t>(k - 1));
  simdvol_fuzz::run_loader([&] { return simdvol::load_mgh(path, index); });
  return 0;
}
