// Helpers shared by the shade and classify kernel tests: one device per test
// program, the skip rule when there is no OpenCL, and running the device
// stages on a volume.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/volume.hpp"

namespace simdvol::testing {

/// The test program's device, opened once; nullptr when there is no OpenCL
/// platform (the test then skips).
inline Device* test_device() {
  static std::unique_ptr<Device> dev;
  static bool tried = false;
  static std::string why;
  if (!tried) {
    tried = true;
    try {
      dev = std::make_unique<Device>();
    } catch (const NoDeviceError& e) {
      why = e.what();
    }
  }
  return dev.get();
}

#define SIMDVOL_TEST_DEVICE(dev)                                         \
  Device* dev##_ptr = ::simdvol::testing::test_device();                 \
  if (!dev##_ptr) GTEST_SKIP() << "no OpenCL platform: nothing to test"; \
  [[maybe_unused]] Device& dev = *dev##_ptr

/// Runs layout + shade on `pes` PEs; returns the voxel cells read back.
struct ShadeRun {
  VoxelLayout layout;
  std::vector<ShadeSample> cells;  ///< PE-major, as on the device
  std::vector<ShadeSample> flat;   ///< gathered, x fastest
};
inline ShadeRun run_shade(Device& dev, const Volume& vol, const sv_shade_params& sp, int64_t pes,
                          ShadeKernel variant = ShadeKernel::rows) {
  PeArray array(dev, pe_grid(pes));
  CellBuffer cells = array.layout(vol, 1);
  ShadeRun r{make_voxel_layout(cells.layout()), {}, {}};
  VoxelBuffer out(dev, r.layout);
  enqueue_shade(dev, cells, sp, out, variant);
  dev.finish();
  r.cells = out.read<ShadeSample>(dev);
  r.flat = voxels_from_cells(r.cells, r.layout);
  return r;
}

/// A volume of random values in [lo, hi) with the given spacing.
inline Volume random_volume(Dims3 dims, float lo, float hi, std::array<double, 3> spacing,
                            unsigned seed) {
  Volume v(dims, VoxelType::f32, spacing);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  for (float& x : v.data()) x = u(rng);
  return v;
}

}  // namespace simdvol::testing
