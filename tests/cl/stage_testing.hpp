// Helpers shared by the shade and classify kernel tests: one device per test
// program, the skip rule when there is no OpenCL, and running the device
// stages on a volume.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/render.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap_cl.hpp"
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

// The occupancy and reach by brute force over the flat volume (kBrick^3
// bricks, a voxel counts unless all four channels are +-0).
inline void host_occupancy(const std::vector<Rgba>& v, const Dims3& d, int order,
                           std::vector<cl_uint>& occ, std::vector<cl_uchar>& reach) {
  const int64_t nb[3] = {(d[0] + kBrick - 1) / kBrick, (d[1] + kBrick - 1) / kBrick,
                         (d[2] + kBrick - 1) / kBrick};
  occ.assign(static_cast<std::size_t>(nb[0] * nb[1] * nb[2]), 0);
  for (int64_t z = 0; z < d[2]; ++z)
    for (int64_t y = 0; y < d[1]; ++y)
      for (int64_t x = 0; x < d[0]; ++x) {
        const Rgba& c = v[static_cast<std::size_t>((z * d[1] + y) * d[0] + x)];
        const bool zero = c.r == 0 && c.g == 0 && c.b == 0 && c.a == 0;  // NaN compares unequal
        if (!zero)
          occ[static_cast<std::size_t>((z / kBrick * nb[1] + y / kBrick) * nb[0] + x / kBrick)] = 1;
      }
  const int64_t lo = order >= 2 ? 1 : 0, hi = 1;
  reach.assign(occ.size(), 0);
  for (int64_t z = 0; z < nb[2]; ++z)
    for (int64_t y = 0; y < nb[1]; ++y)
      for (int64_t x = 0; x < nb[0]; ++x)
        for (int64_t k = std::max<int64_t>(z - lo, 0); k <= std::min(z + hi, nb[2] - 1); ++k)
          for (int64_t j = std::max<int64_t>(y - lo, 0); j <= std::min(y + hi, nb[1] - 1); ++j)
            for (int64_t i = std::max<int64_t>(x - lo, 0); i <= std::min(x + hi, nb[0] - 1); ++i)
              if (occ[static_cast<std::size_t>((k * nb[1] + j) * nb[0] + i)])
                reach[static_cast<std::size_t>((z * nb[1] + y) * nb[0] + x)] = 1;
}

/// The PE mask of EngineOptions::skip_pes for a frame, from the serial
/// reference: its shaded and classified voxels, host_occupancy,
/// match_active_reference.
inline std::vector<uint8_t> reference_active(const Volume& vol, const RenderOptions& opt,
                                             const KdSplit& split) {
  const ViewGeometry view = make_view(vol, opt.view, opt.width, opt.height, opt.sampling);
  const std::vector<Rgba> voxels =
      classify(vol, shade(vol, view, opt.shade), opt.classifier, view.step);
  std::vector<cl_uint> occ;
  std::vector<cl_uchar> reach;
  host_occupancy(voxels, vol.dims(), opt.order, occ, reach);
  return match_active_reference(split, std::vector<uint8_t>(reach.begin(), reach.end()));
}

// Three footprints for `rects` filled with NaN, so that a pixel a kernel
// leaves unwritten shows: `all` zeroed (enqueue_zero_footprints), `some`
// zeroed where no segment of `m` covers a pixel (enqueue_zero_uncovered),
// `none` not at all. The zero-uncovered tests run the same kernel into each.
struct NanFootprints {
  DeviceFootprints all, some, none;
};
inline NanFootprints nan_footprints(Device& dev, const DeviceMatching& m,
                                    const std::vector<sv_rect>& rects) {
  NanFootprints f{make_footprints(dev, rects), make_footprints(dev, rects),
                  make_footprints(dev, rects)};
  const std::size_t bytes = static_cast<std::size_t>(std::max<int64_t>(f.all.size(), 1)) * 16;
  for (DeviceFootprints* x : {&f.all, &f.some, &f.none})
    cl_check(
        dev.queue().enqueueFillBuffer(x->pixels, std::numeric_limits<float>::quiet_NaN(), 0, bytes),
        "fill");
  enqueue_zero_footprints(dev, f.all);
  enqueue_zero_uncovered(dev, m, f.some);
  return f;
}

/// An environment variable set to `value` (unset where nullptr) for a
/// scope, then as it was (SIMDVOL_NT_STORES, SIMDVOL_MATCH_SAVED).
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* e = std::getenv(name)) old_ = e;
    if (value)
      setenv(name, value, 1);
    else
      unsetenv(name);
  }
  ~ScopedEnv() {
    if (old_)
      setenv(name_.c_str(), old_->c_str(), 1);
    else
      unsetenv(name_.c_str());
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  std::string name_;
  std::optional<std::string> old_;
};

}  // namespace simdvol::testing
