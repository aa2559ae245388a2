// simdvol-embed: simdvol's kernels inside another program's OpenCL setup.
//
// The program owns everything OpenCL: it picks a device, creates the context
// and the queue with the plain C API, and allocates every large buffer
// itself (clCreateBuffer). simdvol::Device wraps the context and queue
// (retaining them, not taking them over); the stages run on the caller's
// buffers:
//   layout    flat volume (caller's buffer)   -> cells with halo (caller's)
//   shade     cells                           -> voxel cells (caller's)
//   classify  shaded voxel cells              -> RGBA voxel cells (caller's)
//   resample + local (fused), on the segments of match_reference, uploaded
//             by the caller into its own buffers -> footprints (caller's)
// and each result is checked against the serial reference: classify to
// 1e-5 (the tolerance of tests/cl/test_classify_cl.cpp: float kernels against
// the double reference), the footprints to 1e-5 (tests/cl/test_local_cl.cpp).
//
// --dump DIR writes classify's input and output buffers, its parameters and
// its program's defines for scripts/pyopencl-check.py, which rebuilds the
// classify kernel from the installed .cl files and must reproduce the output.
//
// Exit status 0 when every check passes, 1 when one fails, 2 on an error.
#include <simdvol/simdvol.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace {

using namespace simdvol;

constexpr double kTol = 1e-5;

void check(cl_int err, const char* call) {
  if (err != CL_SUCCESS) throw CLError(call, err);
}

// The caller's own device choice: the first CPU device of any platform, else
// the first device.
cl_device_id pick_device() {
  cl_uint np = 0;
  check(clGetPlatformIDs(0, nullptr, &np), "clGetPlatformIDs");
  if (np == 0) throw NoDeviceError("no OpenCL platform");
  std::vector<cl_platform_id> platforms(np);
  check(clGetPlatformIDs(np, platforms.data(), nullptr), "clGetPlatformIDs");
  cl_device_id any = nullptr;
  for (cl_platform_id p : platforms) {
    cl_uint nd = 0;
    if (clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, 0, nullptr, &nd) != CL_SUCCESS || nd == 0) continue;
    std::vector<cl_device_id> devices(nd);
    check(clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, nd, devices.data(), nullptr), "clGetDeviceIDs");
    for (cl_device_id d : devices) {
      cl_device_type type = 0;
      check(clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof type, &type, nullptr), "clGetDeviceInfo");
      if (type & CL_DEVICE_TYPE_CPU) return d;
      if (!any) any = d;
    }
  }
  if (!any) throw NoDeviceError("no OpenCL device");
  return any;
}

// A buffer the caller owns, wrapped for simdvol (cl::Buffer(mem, true)
// retains; the caller still releases its own reference).
struct OwnBuffer {
  cl_mem mem = nullptr;
  OwnBuffer(cl_context ctx, cl_mem_flags flags, std::size_t bytes, const void* host = nullptr) {
    cl_int err = CL_SUCCESS;
    mem =
        clCreateBuffer(ctx, flags, std::max<std::size_t>(bytes, 16), const_cast<void*>(host), &err);
    check(err, "clCreateBuffer");
  }
  ~OwnBuffer() {
    if (mem) clReleaseMemObject(mem);
  }
  OwnBuffer(const OwnBuffer&) = delete;
  OwnBuffer& operator=(const OwnBuffer&) = delete;
  cl::Buffer wrap() const { return cl::Buffer(mem, true); }
};

template <class T>
std::vector<T> read_raw(cl_command_queue q, cl_mem mem, std::size_t count) {
  std::vector<T> out(count);
  if (count)
    check(
        clEnqueueReadBuffer(q, mem, CL_TRUE, 0, count * sizeof(T), out.data(), 0, nullptr, nullptr),
        "clEnqueueReadBuffer");
  return out;
}

double max_diff(const std::vector<Rgba>& a, const std::vector<Rgba>& b) {
  if (a.size() != b.size()) return INFINITY;
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const float x[4] = {a[i].r, a[i].g, a[i].b, a[i].a}, y[4] = {b[i].r, b[i].g, b[i].b, b[i].a};
    for (int c = 0; c < 4; ++c) {
      const double e = std::fabs(static_cast<double>(x[c]) - y[c]);
      if (!(e <= d)) d = std::isnan(e) ? INFINITY : e;
    }
  }
  return d;
}

// Planar voxel cells (the device layout, stages.hpp) to one Rgba per position.
std::vector<Rgba> from_planar(const std::vector<float>& planar, const VoxelLayout& L) {
  std::vector<Rgba> out(static_cast<std::size_t>(L.elements()));
  const std::size_t st = static_cast<std::size_t>(L.stride);
  for (std::size_t p = 0; p < static_cast<std::size_t>(L.pes()); ++p)
    for (std::size_t e = 0; e < st; ++e) {
      const float* b = planar.data() + p * 4 * st + e;
      out[p * st + e] = Rgba{b[0], b[st], b[2 * st], b[3 * st]};
    }
  return out;
}

void write_file(const std::filesystem::path& path, const void* data, std::size_t bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
  if (!f) throw FileError(path.string(), "cannot write");
}

int run(const std::string& dump_dir) {
  // ---- the caller's OpenCL objects
  cl_device_id dev_id = pick_device();
  cl_int err = CL_SUCCESS;
  cl_context ctx = clCreateContext(nullptr, 1, &dev_id, nullptr, nullptr, &err);
  check(err, "clCreateContext");
  cl_command_queue queue = clCreateCommandQueue(ctx, dev_id, 0, &err);  // no profiling
  if (err != CL_SUCCESS) clReleaseContext(ctx);
  check(err, "clCreateCommandQueue");
  bool ok = true;
  {
    Device device(ctx, queue);
    std::printf("device: %s (%s), caller's context %s\n", device.info().name.c_str(),
                device.info().platform.c_str(),
                device.context()() == ctx ? "shared" : "NOT shared");
    ok = ok && device.context()() == ctx && device.queue()() == queue;

    // ---- a small volume, its view and the parameters
    const int n = 32;
    const int64_t pes = 16;
    const Volume vol = shepp_logan(n);
    const ViewGeometry view = make_view(vol, ViewAngles{30.0, 20.0, 10.0}, 48, 48, Sampling::voxel);
    const ShadeParams sp{};
    const Classifier cls = classifier_preset("ct");
    const CellLayout CL = make_cell_layout(vol.dims(), pes, 1);
    const VoxelLayout VL = make_voxel_layout(CL);
    std::printf("volume: Shepp-Logan %d^3 on %lld PEs, cells %lldx%lldx%lld (+halo 1)\n", n,
                static_cast<long long>(pes), static_cast<long long>(CL.cell()[0]),
                static_cast<long long>(CL.cell()[1]), static_cast<long long>(CL.cell()[2]));

    // ---- the caller's buffers
    OwnBuffer flat(ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, vol.voxel_count() * sizeof(float),
                   vol.data().data());
    OwnBuffer cells_mem(ctx, CL_MEM_READ_WRITE, CL.bytes());
    OwnBuffer shade_mem(ctx, CL_MEM_READ_WRITE, VL.bytes());
    OwnBuffer rgba_mem(ctx, CL_MEM_READ_WRITE, VL.bytes());

    // ---- layout -> shade -> classify on them
    PeArray array(device, pe_grid(pes));
    CellBuffer cells(device, CL, cells_mem.wrap());
    VoxelBuffer shading(VL, shade_mem.wrap());
    VoxelBuffer rgba(VL, rgba_mem.wrap());
    const sv_shade_params shade_p = shade_params(make_shade_frame(vol, view, sp), sp);
    const sv_classify_params class_p =
        classify_params(cls, mixture_range(vol, cls.mixture), view.step);
    array.enqueue_layout(flat.wrap(), cells);
    enqueue_shade(device, cells, shade_p, shading);
    enqueue_classify(device, shading, class_p, rgba);
    check(clFinish(queue), "clFinish");

    const std::vector<float> rgba_planar =
        read_raw<float>(queue, rgba_mem.mem, static_cast<std::size_t>(VL.elements()) * 4);
    const std::vector<Rgba> got = voxels_from_cells(from_planar(rgba_planar, VL), VL);
    const std::vector<Rgba> want = classify(vol, shade(vol, view, sp), cls, view.step);
    const double dc = max_diff(got, want);
    double alpha_sum = 0;
    for (const Rgba& v : got) alpha_sum += v.a;
    std::printf(
        "classify: %zu voxels, sum of alpha %.4f, max |device - reference| %.3g (tol %g) %s\n",
        got.size(), alpha_sum, dc, kTol, dc <= kTol ? "ok" : "FAIL");
    ok = ok && dc <= kTol;

    // ---- compositing: the segments of the serial matching, uploaded by the
    // caller, then the fused resample + local stage into its footprints
    const Matching m = match_reference(view, kd_split(vol.dims(), pes));
    std::vector<cl_int> seg_off(m.seg_offset.begin(), m.seg_offset.end());
    std::vector<cl_int> rect_off(static_cast<std::size_t>(pes));
    int64_t pixels = 0;
    for (int64_t p = 0; p < pes; ++p) {
      rect_off[static_cast<std::size_t>(p)] = static_cast<cl_int>(pixels);
      pixels +=
          int64_t(m.rects[static_cast<std::size_t>(p)].w) * m.rects[static_cast<std::size_t>(p)].h;
    }
    cl_int cs = 0;
    const std::vector<cl_int> table = resample_address_table(VL, &cs);
    const cl_mem_flags ro = CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR;
    OwnBuffer segs_mem(ctx, ro, m.segments.size() * sizeof(sv_segment), m.segments.data());
    OwnBuffer segoff_mem(ctx, ro, seg_off.size() * sizeof(cl_int), seg_off.data());
    OwnBuffer rects_mem(ctx, ro, m.rects.size() * sizeof(sv_rect), m.rects.data());
    OwnBuffer view_mem(ctx, ro, sizeof(sv_view), &view.grid);
    OwnBuffer table_mem(ctx, ro, table.size() * sizeof(cl_int), table.data());
    OwnBuffer rectoff_mem(ctx, ro, rect_off.size() * sizeof(cl_int), rect_off.data());
    OwnBuffer foot_mem(ctx, CL_MEM_READ_WRITE, static_cast<std::size_t>(pixels) * 16);

    LocalSegments segs;
    segs.pes = pes;
    segs.count = static_cast<int64_t>(m.segments.size());
    segs.segments = segs_mem.wrap();
    segs.seg_offset = segoff_mem.wrap();
    segs.rects = rects_mem.wrap();
    segs.host_rects = m.rects;
    ResampleTables tables;
    tables.dims = vol.dims();
    tables.pes = pes;
    tables.view = view_mem.wrap();
    tables.table = table_mem.wrap();
    tables.channel_stride = cs;
    DeviceFootprints fp;
    fp.rect_offset = rect_offsets(m);
    fp.offsets = rectoff_mem.wrap();
    fp.pixels = foot_mem.wrap();
    const cl_float zero[4] = {0, 0, 0, 0};
    check(clEnqueueFillBuffer(queue, foot_mem.mem, zero, sizeof zero, 0,
                              static_cast<std::size_t>(std::max<int64_t>(pixels, 1)) * 16, 0,
                              nullptr, nullptr),
          "clEnqueueFillBuffer");
    const int order = 1;
    enqueue_resample_local(device, segs, tables, rgba, order, fp);
    check(clFinish(queue), "clFinish");

    Footprints dev_fp;
    dev_fp.rect_offset = fp.rect_offset;
    dev_fp.pixels = read_raw<Rgba>(queue, foot_mem.mem, static_cast<std::size_t>(pixels));
    const Footprints ref_fp =
        footprints_reference(m, local_reference(m, got, vol.dims(), view, order));
    const double df = max_diff(dev_fp.pixels, ref_fp.pixels);
    std::printf(
        "local: %zu segments, %lld footprint pixels, max |device - reference| %.3g (tol %g) %s\n",
        m.segments.size(), static_cast<long long>(pixels), df, kTol, df <= kTol ? "ok" : "FAIL");
    ok = ok && df <= kTol;

    // The intermediate image from the footprints (depth order, on the host).
    const Image img = composite_footprints(m, dev_fp, view.width(), view.height());
    const Image ref_img = composite_footprints(m, ref_fp, view.width(), view.height());
    double img_alpha = 0, di = 0;
    int covered = 0;
    for (int y = 0; y < img.height(); ++y)
      for (int x = 0; x < img.width(); ++x) {
        const Rgba& a = img.at(x, y);
        const Rgba& b = ref_img.at(x, y);
        img_alpha += a.a;
        covered += a.a > 0;
        di = std::max({di, std::fabs(double(a.r) - b.r), std::fabs(double(a.g) - b.g),
                       std::fabs(double(a.b) - b.b), std::fabs(double(a.a) - b.a)});
      }
    std::printf(
        "image: %dx%d intermediate, %d pixels covered, mean alpha %.4f, max |device - "
        "reference| %.3g %s\n",
        img.width(), img.height(), covered, img_alpha / (img.width() * img.height()), di,
        di <= kTol ? "ok" : "FAIL");
    ok = ok && di <= kTol;

    if (!dump_dir.empty()) {
      // classify's program, input, parameters and output, for a second host.
      const std::filesystem::path dir(dump_dir);
      std::filesystem::create_directories(dir);
      const std::vector<float> in =
          read_raw<float>(queue, shade_mem.mem, static_cast<std::size_t>(VL.elements()) * 4);
      write_file(dir / "classify_in.f32", in.data(), in.size() * sizeof(float));
      write_file(dir / "classify_out.f32", rgba_planar.data(), rgba_planar.size() * sizeof(float));
      write_file(dir / "classify_params.bin", &class_p, sizeof class_p);
      std::ofstream t(dir / "classify.txt");
      t << "kernel simdvol_classify16\n"
        << "pes " << VL.pes() << "\n"
        << "vstride " << VL.stride << "\n";
      for (const auto& [name, value] : classify_defines(class_p))
        t << "define " << name << " " << value << "\n";
      t << "options " << Device::build_options("") << "\n";
      if (!t) throw FileError((dir / "classify.txt").string(), "cannot write");
      std::printf("dump: classify buffers written to %s\n", dump_dir.c_str());
    }
  }  // simdvol's references are released here; the caller's remain
  clReleaseCommandQueue(queue);
  clReleaseContext(ctx);
  std::printf("%s\n", ok ? "embed: all checks passed" : "embed: FAILED");
  return ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dump, exr;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--dump") == 0 && i + 1 < argc) {
      dump = argv[++i];
    } else if (std::strcmp(argv[i], "--exr") == 0 && i + 1 < argc) {
      exr = argv[++i];
    } else {
      std::fprintf(stderr, "usage: %s [--dump DIR] [--exr FILE]\n", argv[0]);
      return 2;
    }
  }
  std::printf("simdvol kernels installed in %s\n", SIMDVOL_KERNEL_DIR);
  try {
    const int rc = run(dump);
    // --exr: an image through the library's OpenImageIO module, which the
    // installed package's simdvolConfig.cmake told this program where to find.
    if (rc == 0 && !exr.empty()) {
      simdvol::Image img(4, 4);
      for (simdvol::Rgba& p : img.pixels()) p = {0.25f, 0.5f, 0.75f, 1.0f};
      simdvol::write_image(img, exr);
      std::printf("wrote %s\n", exr.c_str());
    }
    return rc;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "simdvol-embed: %s\n", e.what());
    return 2;
  }
}
