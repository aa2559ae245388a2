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
  /// Must be set: the default, a mixture of no materials, cannot be rendered
  /// (render_reference, render_opencl and RenderEngine::render throw
  /// ArgumentError "classifier: the material mixture has no materials").
  /// For example classifier_preset("ct") (classify.hpp lists the presets).
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

/// Per sub-ray Monte Carlo (ch. 7.4, eq 7.15) with the serial references:
/// the rays cut into sub-rays by the PE cells of kd_split(dims, pes), matched
/// with every PE (match_reference) and balanced with `balance_sweeps` sweeps
/// (balance_reference; 0: none) as the OpenCL engine's McScope::subray does,
/// the samples of resample_reference, each sub-ray estimated on its own
/// (mc_sub_reference: opt.composite.samples walks each, or with `allocate`
/// the ray's budget allocated to its sub-rays by opacity, ch. 7.5 (b)), the
/// sub-rays combined with over in depth order (composite_segments), then the
/// warp of voxel sampling. Throws ArgumentError unless opt.composite.mode is
/// CompositeMode::mc, `pes` a power of two from 1 to 2^20 and
/// `balance_sweeps` in 0..kMaxBalanceSweeps. `times`: shade, classify,
/// resample_composite (matching, balancing, resampling, walks) and warp.
Image render_subray_reference(const Volume& vol, const RenderOptions& opt, int64_t pes,
                              int balance_sweeps, bool allocate, RenderTimes* times = nullptr);

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
