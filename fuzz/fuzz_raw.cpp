// libFuzzer target for load_raw. The first 16 bytes choose the layout the
// caller would pass (so the layout checks are fuzzed too), the rest is the
// file:
//   byte 0      voxel type (value mod 5: u8, u16, i16, f32, or an invalid enum)
//   byte 1      endianness (bit 0: big)
//   bytes 2-7   dims: three little-endian int16 (negative and zero included)
//   bytes 8-9   header bytes: little-endian uint16; 0xFFFF means 2^64 - 1
//   bytes 10-15 spacing per axis: two bytes each, mapped to values that
//               include 0, negative, NaN and infinity
#include <cmath>
#include <cstring>
#include <limits>

#include "fuzz_common.hpp"
#include "simdvol/io.hpp"

namespace {

double spacing_from(uint8_t a, uint8_t b) {
  switch (a & 7) {
    case 0:
      return 0.0;
    case 1:
      return -1.0 - b;
    case 2:
      return std::numeric_limits<double>::quiet_NaN();
    case 3:
      return std::numeric_limits<double>::infinity();
    case 4:
      return std::numeric_limits<double>::denorm_min();
    default:
      return 0.25 + b / 16.0;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  constexpr std::size_t prefix = 16;
  if (size < prefix) return 0;
  simdvol::RawLayout layout;
  layout.type = static_cast<simdvol::VoxelType>(data[0] % 5);
  layout.endian = (data[1] & 1) ? simdvol::Endian::big : simdvol::Endian::little;
  for (int a = 0; a < 3; ++a) {
    int16_t d;
    std::memcpy(&d, data + 2 + 2 * a, 2);  // little-endian host assumed (x86-64)
    layout.dims[a] = d;
  }
  const uint16_t hb = static_cast<uint16_t>(data[8] | (data[9] << 8));
  layout.header_bytes = hb == 0xFFFF ? std::numeric_limits<uint64_t>::max() : hb;
  for (int a = 0; a < 3; ++a) layout.spacing[a] = spacing_from(data[10 + 2 * a], data[11 + 2 * a]);
  const auto path = simdvol_fuzz::write_input("input.raw", data + prefix, size - prefix);
  simdvol_fuzz::run_loader([&] { return simdvol::load_raw(path, layout); });
  return 0;
}
