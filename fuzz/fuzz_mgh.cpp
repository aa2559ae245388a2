// libFuzzer target for load_mgh. Byte 0 mod 3 chooses the form:
//   0: the rest is written as input.mgh
//   1: the rest is gzip-compressed (zlib, level 1) and written as
//      input.mgz, so mutations reach the header and voxels through the
//      compression layer
//   2: the rest is written as input.mgz unchanged (corrupt or truncated
//      gzip streams, or plain bytes under a .mgz name)
// and (byte 0 / 3) mod 4 the volume index: 0 none, k the index k - 1.
// Files the previous input left behind are removed first.
#include <optional>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  simdvol_fuzz::clear_scratch();
  const uint8_t* body = data + 1;
  const std::size_t n = size - 1;
  const std::filesystem::path path =
      simdvol_fuzz::write_plain_or_gzipped(data[0] % 3, "input.mgh", "input.mgz", body, n);
  if (path.empty()) return 0;
  const std::optional<int64_t> index = simdvol_fuzz::volume_index(data[0], 3);
  simdvol_fuzz::run_loader([&] { return simdvol::load_mgh(path, index); });
  return 0;
}
