// libFuzzer target for load_classifier, the transfer-function / material
// mixture text files of `render --classify FILE`: the input is the whole
// file. A classifier it returns is then evaluated as both engines would:
// the reference's classify_voxel over values across and beyond its range
// (ramp ends, material means and the points between them, NaN), which
// validates it again, and mixture_pair, the constants the kernels take in
// float (classify_params), which must be finite there.
#include <cmath>
#include <limits>
#include <vector>

#include "fuzz_common.hpp"
#include "simdvol/classify.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto path = simdvol_fuzz::write_input("input.tf", data, size);
  try {
    const simdvol::Classifier c = simdvol::load_classifier(path);
    std::vector<float> values = {0.0f,
                                 -1.0f,
                                 1.0f,
                                 std::numeric_limits<float>::quiet_NaN(),
                                 std::numeric_limits<float>::max(),
                                 -std::numeric_limits<float>::max()};
    for (const simdvol::Material& m : c.mixture.materials) values.push_back(m.mean);
    for (std::size_t i = 1; i < c.mixture.materials.size(); ++i)
      values.push_back(0.5f * c.mixture.materials[i - 1].mean + 0.5f * c.mixture.materials[i].mean);
    for (float x : c.transfer.density.x) values.push_back(x);
    const simdvol::ValueRange range{-1000.0f, 3000.0f};
    for (float v : values) {
      float col[3];
      const float a = simdvol::classify_voxel(c, range, v, 1.0f, col);
      if (!(a >= 0.0f && a <= 1.0f)) std::abort();
      for (float x : col)
        if (!(x >= 0.0f && x <= 1.0f + 1e-6f)) std::abort();
    }
    const auto& m = c.mixture.materials;
    for (std::size_t i = 1; c.kind == simdvol::Classifier::Kind::mixture && i < m.size(); ++i) {
      const simdvol::MixturePair q = simdvol::mixture_pair(m[i - 1], m[i]);
      for (double x : {q.c, q.qa, q.qb, q.qc})
        if (!std::isfinite(static_cast<float>(x))) std::abort();
    }
  } catch (const simdvol::Error&) {
  }
  return 0;
}
