// The OpenCL render engine: the pipeline of thesis figure 1.2 on the PE
// array. Now: layout -> shade -> classify on the device, then the classified
// voxels are gathered back and the remaining stages (match, resample,
// composite, warp) run in the serial reference (render_classified) until
// their kernels exist.
#pragma once

#include <cstdint>

#include "simdvol/device.hpp"
#include "simdvol/image.hpp"
#include "simdvol/render.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

/// Per-stage times of one render_opencl call. Device stages: kernel time
/// from the profiling events (0 when the queue does not profile).
struct EngineTimes {
  double layout_ms = 0;       ///< flat volume -> PE-major cells with halo
  double shade_ms = 0;        ///< 0 when fused
  double classify_ms = 0;     ///< shade + classify when fused
  double gather_ms = 0;       ///< classified voxel cells -> flat RGBA
  double device_wall_ms = 0;  ///< host wall time of the device part (allocation, builds, transfers)
  RenderTimes host{};         ///< the stages still run by the reference
};

/// Renders `vol` with the OpenCL stages on `pes` PEs (a power of two,
/// default 8192 as the DECmpp 12000). `fused` runs shade and classify as one
/// launch (same results). Throws ArgumentError for bad options or a volume
/// whose buffers exceed the device's largest allocation.
Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt,
                    EngineTimes* times = nullptr, int64_t pes = 8192, bool fused = false);

}  // namespace simdvol
