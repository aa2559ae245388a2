// The classify stage on the device, the fused shade + classify launch and the
// gather of voxel cells (stages.hpp).
#include <cmath>
#include <string>

#include "chunk_ranges.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/stages.hpp"
#include "voxel_ranges.hpp"

namespace simdvol {

static_assert(sizeof(sv_materials) == 10 * SV_MAX_MATERIALS * 4, "sv_materials must be plain");
static_assert(sizeof(sv_ramp) == 4 * 4 + 2 * SV_MAX_KNOTS * 4, "sv_ramp must be plain");
static_assert(sizeof(sv_classify_params) == 8 * 4 + sizeof(sv_materials) + 5 * sizeof(sv_ramp),
              "sv_classify_params must be plain floats/ints");

namespace {

void fill_ramp(sv_ramp& r, const Ramp& in, const std::string& what) {
  if (in.x.size() != in.y.size())
    throw ArgumentError(what, "ramp has " + std::to_string(in.x.size()) + " x values but " +
                                  std::to_string(in.y.size()) + " y values");
  if (in.x.size() > SV_MAX_KNOTS)
    throw ArgumentError(what, "ramp has " + std::to_string(in.x.size()) +
                                  " points; the OpenCL classify kernel takes at most " +
                                  std::to_string(SV_MAX_KNOTS));
  r = sv_ramp{};
  r.count = static_cast<sv_i32>(in.x.size());
  for (std::size_t k = 0; k < in.x.size(); ++k) {
    r.x[k] = in.x[k];
    r.y[k] = in.y[k];
  }
}

void check_same(const VoxelLayout& a, const VoxelLayout& b, const char* what) {
  if (!a.same_cells(b))
    throw ArgumentError(what, "voxel buffers were made for different volumes or PE counts");
}

cl::Buffer params_buffer(Device& device, const void* p, std::size_t bytes, const char* what) {
  return device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes, const_cast<void*>(p), what);
}

// The fused program: shade.cl followed by classify.cl (which then also
// compiles simdvol_shade_classify), with the classifier's specialisation.
cl::Kernel fused_kernel(Device& device, const std::string& name, const Defines& defines) {
  cl::Program program =
      device.build_keyed(program_key("source", "shade", defines, {"classify"}),
                         [&] { return program_source("shade", defines, {"classify"}); });
  cl_int err = CL_SUCCESS;
  cl::Kernel k(program, name.c_str(), &err);
  if (err != CL_SUCCESS) throw CLError("clCreateKernel(" + name + ")", err);
  return k;
}

}  // namespace

sv_classify_params classify_params(const Classifier& c, const ValueRange& range,
                                   double opacity_step) {
  if (!(opacity_step > 0.0) || !std::isfinite(opacity_step))
    throw ArgumentError("opacity_step",
                        "must be positive and finite (got " + std::to_string(opacity_step) + ")");
  {
    // The reference's own validation (throws ArgumentError naming the problem).
    float col[3];
    classify_voxel(c, range, 0.0f, 0.0f, col);
  }
  sv_classify_params p{};
  p.step_is_one = opacity_step == 1.0 ? 1 : 0;
  p.opacity_step = static_cast<float>(opacity_step);
  if (c.kind == Classifier::Kind::transfer) {
    p.kind = SV_CLASSIFY_TRANSFER;
    fill_ramp(p.density, c.transfer.density, "classifier.density");
    fill_ramp(p.gradient, c.transfer.gradient, "classifier.gradient");
    fill_ramp(p.red, c.transfer.red, "classifier.red");
    fill_ramp(p.green, c.transfer.green, "classifier.green");
    fill_ramp(p.blue, c.transfer.blue, "classifier.blue");
    return p;
  }
  p.kind = SV_CLASSIFY_MIXTURE;
  const auto& m = c.mixture.materials;
  if (m.size() > SV_MAX_MATERIALS)
    throw ArgumentError("classifier", "has " + std::to_string(m.size()) +
                                          " materials; the OpenCL classify kernel takes at most " +
                                          std::to_string(SV_MAX_MATERIALS));
  p.material_count = static_cast<sv_i32>(m.size());
  sv_materials& s = p.materials;
  for (std::size_t i = 0; i < m.size(); ++i) {
    s.mean[i] = m[i].mean;
    s.sigma[i] = m[i].sigma;
    if (i + 1 < m.size()) {  // (validated above: finite in float)
      const MixturePair q = mixture_pair(m[i], m[i + 1]);
      s.pair_c[i] = static_cast<float>(q.c);
      s.pair_qa[i] = static_cast<float>(q.qa);
      s.pair_qb[i] = static_cast<float>(q.qb);
      s.pair_qc[i] = static_cast<float>(q.qc);
    }
    s.r[i] = m[i].r;
    s.g[i] = m[i].g;
    s.b[i] = m[i].b;
    s.opacity[i] = m[i].opacity;
  }
  p.relative = c.mixture.relative ? 1 : 0;
  if (c.mixture.relative) {
    if (!std::isfinite(range.min) || !std::isfinite(range.max))
      throw ArgumentError("range", "the value range must be finite for a relative mixture");
    p.range_min = range.min;
    p.range_scale = mixture_range_scale(range);  // (the reference's mixture_index)
  }
  return p;
}

Defines classify_defines(const sv_classify_params& p) {
  Defines d{{"SV_KIND", std::to_string(p.kind)}};
  if (p.step_is_one) d.emplace_back("SV_STEP_ONE", "1");
  if (p.kind == SV_CLASSIFY_MIXTURE) {
    d.emplace_back("SV_NMAT", std::to_string(p.material_count));
  } else {
    d.emplace_back("SV_NK_DENSITY", std::to_string(p.density.count));
    d.emplace_back("SV_NK_GRADIENT", std::to_string(p.gradient.count));
    d.emplace_back("SV_NK_RED", std::to_string(p.red.count));
    d.emplace_back("SV_NK_GREEN", std::to_string(p.green.count));
    d.emplace_back("SV_NK_BLUE", std::to_string(p.blue.count));
  }
  return d;
}

namespace {

// The classify kernel of `variant` over voxel cells of layout V: from
// `shading` into `out`, or in place (in `out`) without `shading`.
cl::Event run_classify(Device& device, const sv_classify_params& params, ClassifyKernel variant,
                       const VoxelLayout& V, const cl::Buffer* shading, const cl::Buffer& out) {
  if (V.interleaved)
    throw ArgumentError("classify output",
                        "classify writes planar voxel cells; interleaved ones come from the fused "
                        "shade + classify (enqueue_shade_classify, ShadeKernel::vec16)");
  cl::Buffer pbuf = params_buffer(device, &params, sizeof params, "classify parameters");
  const bool vec = variant == ClassifyKernel::vec16;
  const std::string name =
      std::string(vec ? "simdvol_classify16" : "simdvol_classify") + (shading ? "" : "_in_place");
  Defines defines = classify_defines(params);
  if (vec && detail::nt_stores() && detail::nt_aligned({&out})) defines.emplace_back("SV_NT", "1");
  cl::Kernel k = device.kernel("classify", name, defines);
  const cl_int stride = static_cast<cl_int>(V.stride), pes = static_cast<cl_int>(V.pes());
  if (shading)
    set_args(k, name, *shading, out, stride, pes, pbuf);
  else
    set_args(k, name, out, stride, pes, pbuf);
  const detail::PlaneRange r = vec ? detail::chunk_range(V) : detail::plane_range(V);
  return device.run(k, name, r.global, r.local, LocalSize::at_most);
}

}  // namespace

cl::Event enqueue_classify(Device& device, const VoxelBuffer& shading,
                           const sv_classify_params& params, VoxelBuffer& out,
                           ClassifyKernel variant) {
  check_same(shading.layout(), out.layout(), "classify output");
  if (shading.buffer()() == out.buffer()())
    throw ArgumentError("classify output",
                        "must not be the shading buffer (enqueue_classify_in_place classifies "
                        "in place)");
  out.mark_stored();
  return run_classify(device, params, variant, out.layout(), &shading.buffer(), out.buffer());
}

cl::Event enqueue_classify_in_place(Device& device, VoxelBuffer& voxels,
                                    const sv_classify_params& params, ClassifyKernel variant) {
  voxels.mark_stored();
  return run_classify(device, params, variant, voxels.layout(), nullptr, voxels.buffer());
}

cl::Event enqueue_shade_classify(Device& device, const CellBuffer& cells,
                                 const sv_shade_params& shade, const sv_classify_params& classify,
                                 VoxelBuffer& out, ShadeKernel variant, DeviceOccupancy* mark,
                                 const cl::Buffer* live, KeptClassification* kept) {
  const CellLayout& C = cells.layout();
  const VoxelLayout& V = out.layout();
  if (C.halo < 1) throw ArgumentError("cells", "the shade stage needs a halo of at least 1");
  if (C.dims() != V.dims() || C.pes() != V.pes() || C.cell() != V.cell())
    throw ArgumentError("shade_classify output",
                        "voxel buffer was made for a different volume or PE count");
  cl::Buffer sbuf = params_buffer(device, &shade, sizeof shade, "shade parameters");
  cl::Buffer cbuf = params_buffer(device, &classify, sizeof classify, "classify parameters");
  const int rw = detail::shade_row_width(V.cell()[0]);
  const bool vec = variant == ShadeKernel::vec16;  // every cx has a float16 form
  if (V.interleaved && !vec)
    throw ArgumentError("shade_classify output",
                        "only the float16 fused kernel writes interleaved voxel cells");
  const std::string name =
      vec ? detail::voxel_kernel("simdvol_shade_classify16", V) : "simdvol_shade_classify";
  Defines defines = classify_defines(classify);
  for (auto& d : shade_defines(shade)) defines.push_back(std::move(d));
  if (vec) defines.emplace_back("SV_RW", std::to_string(rw));
  if (vec && detail::nt_stores() &&
      detail::nt_aligned({&out.buffer(), kept ? &kept->planes : nullptr}))
    defines.emplace_back("SV_NT", "1");
  const bool kept_read = kept && kept->filled && kept->filled_gradient == kept->gradient;
  // kc_mode & 8: `out` stored non-temporally (detail::nt_out), where it was
  // stored before and is large
  const bool nt_out =
      vec && out.stored() && detail::nt_out(V.bytes()) && detail::nt_aligned({&out.buffer()});
  out.mark_stored();
  if (mark && !vec) throw ArgumentError("occupancy", "only the float16 fused kernel marks it");
  if (mark && mark->dims != V.dims())
    throw ArgumentError("occupancy", "was made for a volume of other dimensions");
  if (live && !vec) throw ArgumentError("live", "only the float16 fused kernel takes a PE mask");
  if (live) {
    const std::size_t have = buffer_size(*live, "clGetMemObjectInfo(live)");
    if (have < static_cast<std::size_t>(C.pes()))
      throw ArgumentError("live", "holds " + std::to_string(have) + " flags for " +
                                      std::to_string(C.pes()) + " PEs");
  }
  if (kept && !vec)
    throw ArgumentError("kept classification", "only the float16 fused kernel keeps it");
  if (kept) {
    const std::size_t need = static_cast<std::size_t>(KeptClassification::bytes(V, kept->gradient));
    const std::size_t have =
        kept->planes() ? buffer_size(kept->planes, "clGetMemObjectInfo(kept)") : std::size_t(0);
    if (have < need)
      throw ArgumentError("kept classification",
                          "holds " + std::to_string(have) + " bytes for " + std::to_string(need));
  }
  cl::Kernel k = fused_kernel(device, name, defines);
  set_args(k, name, cells.cells(), out.buffer(), cells.origins(), cells.dims_arg(),
           cells.cell_arg(), cells.block_arg(), static_cast<cl_int>(C.pes()),
           static_cast<cl_int>(V.stride), sbuf, cbuf);
  if (vec) {
    // Without marking the occupancy argument is never read, nor `live`
    // without a mask: any buffer will do.
    // (nor the kept classification without one: kc_mode 0)
    set_args_from(
        k, name, 10, mark ? mark->occupied : cbuf, mark ? mark->bricks[0] : cl_int(0),
        mark ? mark->bricks[1] : cl_int(0), cl_int(mark ? 1 : 0), live ? *live : cbuf,
        cl_int(live ? 1 : 0), kept ? kept->planes : cbuf,
        cl_int((kept ? (kept_read ? 2 : 1) | (kept->gradient ? 4 : 0) : 0) | (nt_out ? 8 : 0)));
    const detail::PlaneRange r = detail::chunk_range(V);
    cl::Event e = device.run(k, name, r.global, r.local, LocalSize::at_most);
    if (kept) {
      kept->filled = true;
      kept->filled_gradient = kept->gradient;
    }
    return e;
  }
  const detail::CellRange r = detail::cell_range(V);
  return device.run(k, name, r.global, r.local, LocalSize::at_most);
}

cl::Event enqueue_gather_voxels(Device& device, const VoxelBuffer& voxels, const cl::Buffer& flat) {
  const VoxelLayout& V = voxels.layout();
  const std::size_t n = static_cast<std::size_t>(V.dims()[0] * V.dims()[1] * V.dims()[2]);
  const std::size_t size = buffer_size(flat, "clGetMemObjectInfo(flat voxels)");
  if (size < n * 16)
    throw ArgumentError("flat voxels", "buffer of " + std::to_string(size) + " bytes is too small");
  // The origins table comes from a cell buffer of the same geometry; build it
  // here (PE count small against the voxels).
  std::vector<cl_int4> origins(static_cast<std::size_t>(V.pes()));
  for (int64_t p = 0; p < V.pes(); ++p) {
    const Dims3 o = V.cells.split.cell_origin(p);
    origins[p] = cl_int4{
        {static_cast<cl_int>(o[0]), static_cast<cl_int>(o[1]), static_cast<cl_int>(o[2]), 0}};
  }
  cl::Buffer obuf =
      device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, origins.size() * sizeof(cl_int4),
                    origins.data(), "PE origin table");
  const std::string name = detail::voxel_kernel("simdvol_gather_voxels", V);
  cl::Kernel k = device.kernel("classify", name);
  const cl_int4 dims{{static_cast<cl_int>(V.dims()[0]), static_cast<cl_int>(V.dims()[1]),
                      static_cast<cl_int>(V.dims()[2]), 0}};
  const cl_int4 cell{{static_cast<cl_int>(V.cell()[0]), static_cast<cl_int>(V.cell()[1]),
                      static_cast<cl_int>(V.cell()[2]), 0}};
  set_args(k, name, voxels.buffer(), flat, obuf, dims, cell, static_cast<cl_int>(V.pes()),
           static_cast<cl_int>(V.stride));
  const detail::CellRange r = detail::cell_range(V);
  return device.run(k, name, r.global, r.local, LocalSize::at_most);
}

void gather_rgba(Device& device, const VoxelBuffer& voxels, Rgba* out, cl::Event* event) {
  if (!out) throw ArgumentError("gather", "null output");
  const Dims3& d = voxels.layout().dims();
  const std::size_t bytes = static_cast<std::size_t>(d[0] * d[1] * d[2]) * sizeof(Rgba);
  static_assert(sizeof(Rgba) == 16, "Rgba is four floats");
  cl::Buffer flat = device.buffer(CL_MEM_WRITE_ONLY | CL_MEM_USE_HOST_PTR, bytes, out,
                                  "classified voxels (flat)");
  cl::Event e = enqueue_gather_voxels(device, voxels, flat);
  // Map/unmap makes the results visible in `out` (no copy on PoCL).
  cl_int err = CL_SUCCESS;
  void* p =
      device.queue().enqueueMapBuffer(flat, CL_TRUE, CL_MAP_READ, 0, bytes, nullptr, nullptr, &err);
  cl_check(err, "clEnqueueMapBuffer(classified voxels)");
  cl_check(device.queue().enqueueUnmapMemObject(flat, p), "clEnqueueUnmapMemObject");
  device.finish();
  if (event) *event = e;
}

}  // namespace simdvol
