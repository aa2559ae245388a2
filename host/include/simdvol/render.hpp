// The serial CPU reference renderer: the same mathematics as the kernels,
// written for clarity. Pipeline: shade -> classify -> (match, resample) ->
// composite -> (voxel sampling) 2-D scale to the output size.
#pragma once

#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/composite.hpp"
#include "simdvol/image.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/view.hpp"
#include "simdvol/volume.hpp"

namespace simdvol {

struct RenderOptions {
  ViewAngles view{};
  int width = 256, height = 256;
  Sampling sampling = Sampling::voxel;
  Framing framing = Framing::longest;  ///< what spans the image: the longest side or the diagonal
  int order = 1;                       ///< 0..3
  CompositeParams composite{};
  ShadeParams shade{};
  Classifier classifier{};
};

/// Checks every option; throws ArgumentError naming the option.
void validate(const RenderOptions& opt);

struct RenderTimes {
  double shade_ms = 0, classify_ms = 0, resample_composite_ms = 0, warp_ms = 0;
};

/// Renders with the serial reference. `intermediate`, if given, receives the
/// composited viewing-grid image before the 2-D scale (voxel sampling) — in
/// pixel sampling it equals the result.
Image render_reference(const Volume& vol, const RenderOptions& opt, RenderTimes* times = nullptr,
                       Image* intermediate = nullptr);

/// The stages after classification (match, resample, composite, warp), from
/// classified premultiplied RGBA voxels (x fastest, the volume's dims). The
/// OpenCL engine uses this while its own later stages are being built.
Image render_classified(const std::vector<Rgba>& voxels, const Volume& vol,
                        const ViewGeometry& view, const RenderOptions& opt,
                        RenderTimes* times = nullptr, Image* intermediate = nullptr);

/// Bilinear 2-D scale of the intermediate image to the output size (the
/// final warp of voxel sampling); outside the intermediate image is
/// transparent black.
Image warp_to_output(const Image& intermediate, const ViewGeometry& view);

}  // namespace simdvol
