// The OpenCL render engine: the pipeline of thesis figure 1.2 on the PE
// array. Direct compositing, every stage on the device: layout -> shade ->
// classify -> match -> balance -> resample + local (fused) -> binary swap
// (one launch per stage, swap_cl.hpp) -> display (the final cut-and-stack or
// hierarchical layout -> intermediate image) -> warp (voxel sampling), then
// one read of the output image. The host reads only the footprint
// rectangles (to size the buffers) and plans the swap from them while the
// device resamples. Adaptive and Monte Carlo compositing keep the earlier
// path: the classified voxels are gathered back and render_classified does
// the rest.
#pragma once

#include <cstdint>
#include <vector>

#include "simdvol/device.hpp"
#include "simdvol/image.hpp"
#include "simdvol/render.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

/// Per-stage times of one render_opencl call. Device stages: kernel time
/// from the profiling events (0 when the queue does not profile).
struct EngineTimes {
  double layout_ms = 0;          ///< flat volume -> PE-major cells with halo
  double shade_ms = 0;           ///< 0 when fused
  double classify_ms = 0;        ///< shade + classify when fused
  double gather_ms = 0;          ///< classified voxel cells -> flat RGBA (adaptive/mc only)
  double match_ms = 0;           ///< matching (host reference time until on the device)
  double balance_ms = 0;         ///< balancing (host reference time until on the device)
  double resample_local_ms = 0;  ///< zero footprints + fused resample + local
  double plan_ms = 0;  ///< host: swap plan from the rectangles + its upload (overlaps the device)
  double swap_ms = 0;  ///< all swap stages
  std::vector<double> swap_stage_ms;  ///< per launched stage
  double display_ms = 0;              ///< final layout -> intermediate image
  double warp_ms = 0;                 ///< intermediate -> output (voxel sampling)
  double composite_ms = 0;            ///< swap + display + warp
  double device_wall_ms = 0;  ///< host wall time of the device part (allocation, builds, transfers)
  RenderTimes host{};         ///< the stages still run by the reference
};

/// Renders `vol` with the OpenCL stages on `pes` PEs (a power of two,
/// default 8192 as the DECmpp 12000). `fused` runs shade and classify as one
/// launch (same results). `layout` is the swap's final layout (the image is
/// the same either way). Throws ArgumentError for bad options or a volume
/// whose buffers exceed the device's largest allocation.
Image render_opencl(Device& device, const Volume& vol, const RenderOptions& opt,
                    EngineTimes* times = nullptr, int64_t pes = 8192, bool fused = false,
                    SwapLayout layout = SwapLayout::cut_and_stack);

}  // namespace simdvol
