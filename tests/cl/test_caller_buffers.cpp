// The stages on the caller's OpenCL objects (docs/KERNELS.md, "Embedding"):
// a Device wrapping the caller's context and queue, CellBuffer and
// VoxelBuffer wrapping the caller's buffers, PeArray::enqueue_layout from a
// flat volume already on the device. Exact equality where the result is a
// copy (layout); the same kernels as the owned-buffer path elsewhere, so the
// classify output must equal that path's bit for bit.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/swap_cl.hpp"
#include "stage_testing.hpp"

namespace simdvol {
namespace {

cl::Buffer own_buffer(const Device& dev, std::size_t bytes, const void* host = nullptr) {
  cl_int err = CL_SUCCESS;
  cl_mem m = clCreateBuffer(dev.context()(), CL_MEM_READ_WRITE | (host ? CL_MEM_COPY_HOST_PTR : 0),
                            bytes, const_cast<void*>(host), &err);
  cl_check(err, "clCreateBuffer");
  return cl::Buffer(m, false);  // takes over the caller's reference
}

TEST(CallerBuffers, WrappedContextAndBuffersGiveTheSameResults) {
  SIMDVOL_TEST_DEVICE(base);
  // The "caller's" context and queue: wrapped, not owned.
  Device dev(base.context()(), base.queue()());
  EXPECT_EQ(dev.context()(), base.context()());
  EXPECT_EQ(dev.queue()(), base.queue()());

  const Volume vol = shepp_logan(20);  // 20 is not a multiple of the cells
  const int64_t pes = 8;
  const CellLayout CL = make_cell_layout(vol.dims(), pes, 1);
  const VoxelLayout VL = make_voxel_layout(CL);
  PeArray array(dev, pe_grid(pes));

  cl::Buffer flat = own_buffer(dev, vol.voxel_count() * sizeof(float), vol.data().data());
  CellBuffer cells(dev, CL, own_buffer(dev, CL.bytes()));
  array.enqueue_layout(flat, cells);
  dev.finish();
  EXPECT_EQ(cells.read(dev), layout_reference(vol.data(), CL));

  const ViewGeometry view = make_view(vol, {30, 20, 10}, 32, 32, Sampling::voxel);
  const ShadeParams sp{};
  const sv_shade_params shp = shade_params(make_shade_frame(vol, view, sp), sp);
  const sv_classify_params clp = classify_params(classifier_preset("ct"), vol.range(), 1.0);
  VoxelBuffer shading(VL, own_buffer(dev, VL.bytes()));
  VoxelBuffer rgba(VL, own_buffer(dev, VL.bytes()));
  enqueue_shade(dev, cells, shp, shading);
  enqueue_classify(dev, shading, clp, rgba);

  // The same stages on buffers simdvol allocates.
  CellBuffer cells2 = array.layout(vol, 1);
  VoxelBuffer shading2(dev, VL), rgba2(dev, VL);
  enqueue_shade(dev, cells2, shp, shading2);
  enqueue_classify(dev, shading2, clp, rgba2);
  dev.finish();
  const std::vector<Rgba> a = rgba.read<Rgba>(dev), b = rgba2.read<Rgba>(dev);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Rgba)), 0);
}

// A Device wraps only a queue it can run the stages on: an out-of-order
// queue (the stages depend on the queue's order, not on events) and a
// queue of another context than the one given (buffers and programs are
// made in the given context) are ArgumentErrors that say so, before
// anything is enqueued; an in-order queue of the same device and context,
// made by the caller without profiling, is taken.
TEST(CallerBuffers, OutOfOrderOrForeignQueuesAreRejected) {
  SIMDVOL_TEST_DEVICE(base);
  const cl_context ctx = base.context()();
  const cl_device_id id = base.device()();
  auto message = [](cl_context c, cl_command_queue q) -> std::string {
    try {
      Device d(c, q);
    } catch (const ArgumentError& e) {
      return e.what();
    }
    return "";
  };
  cl_int err = CL_SUCCESS;
  cl_command_queue plain = clCreateCommandQueue(ctx, id, 0, &err);
  ASSERT_EQ(err, CL_SUCCESS);
  EXPECT_EQ(message(ctx, plain), "");
  {
    Device d(ctx, plain);
    EXPECT_FALSE(d.profiling());
  }

  cl_context other = clCreateContext(nullptr, 1, &id, nullptr, nullptr, &err);
  ASSERT_EQ(err, CL_SUCCESS);
  const std::string foreign = message(other, plain);
  EXPECT_NE(foreign.find("another cl_context"), std::string::npos) << foreign;
  clReleaseContext(other);
  clReleaseCommandQueue(plain);

  cl_command_queue ooo =
      clCreateCommandQueue(ctx, id, CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE, &err);
  if (err == CL_INVALID_QUEUE_PROPERTIES) GTEST_SKIP() << "the device has no out-of-order queues";
  ASSERT_EQ(err, CL_SUCCESS);
  const std::string out_of_order = message(ctx, ooo);
  clReleaseCommandQueue(ooo);
  EXPECT_NE(out_of_order.find("out of order"), std::string::npos) << out_of_order;
  EXPECT_NE(out_of_order.find("in-order queue"), std::string::npos) << out_of_order;
}

// Non-temporal stores of float16 need each 16-float chunk 64-byte aligned.
// The fused shade + classify stores its voxel cells that way by default
// where they were stored before and hold at least 64 MiB (kc_mode & 8;
// here a 168^3 volume's second call), and with SIMDVOL_NT_STORES=1 every
// float16 kernel stores every chunk so (SV_NT; here a 24^3 volume). A
// caller's buffer over host memory that is not 64-byte aligned (here 16
// bytes past a boundary) gets ordinary stores: the same bits as simdvol's
// own buffers, for the shade, the classify, the fused kernel into planar
// and interleaved cells, and the kept classification's planes. Without the
// check the stores fault.
TEST(CallerBuffers, UnalignedHostMemoryGetsTheSameCells) {
  SIMDVOL_TEST_DEVICE(dev);
  // Host memory for a buffer of `bytes` at 16 bytes past a 64-byte boundary.
  std::vector<std::vector<float>> hosts;
  auto unaligned = [&](std::size_t bytes) {
    hosts.emplace_back(bytes / sizeof(float) + 32);
    float* p = hosts.back().data();
    while (reinterpret_cast<std::uintptr_t>(p) % 64 != 16) ++p;
    return cl::Buffer(dev.context(), CL_MEM_READ_WRITE | CL_MEM_USE_HOST_PTR, bytes, p);
  };
  auto same = [&](const VoxelBuffer& a, const VoxelBuffer& b, const char* what) {
    const std::vector<Rgba> x = a.read<Rgba>(dev), y = b.read<Rgba>(dev);
    ASSERT_EQ(x.size(), y.size());
    EXPECT_EQ(std::memcmp(x.data(), y.data(), x.size() * sizeof(Rgba)), 0) << what;
    int64_t nonzero = 0;
    for (const Rgba& c : x) nonzero += c.r != 0 || c.g != 0 || c.b != 0 || c.a != 0;
    EXPECT_GT(nonzero, 0) << what;
  };
  for (const bool every : {true, false}) {
    SCOPED_TRACE(every ? "SIMDVOL_NT_STORES=1" : "the default");
    testing::ScopedEnv env("SIMDVOL_NT_STORES", every ? "1" : nullptr);
    const Volume vol = shepp_logan(every ? 24 : 168);
    PeArray array(dev, pe_grid(8));
    CellBuffer cells = array.layout(vol, 1);
    const ViewGeometry view = make_view(vol, {30, 20, 10}, 32, 32, Sampling::voxel);
    const ShadeParams sp{};
    const sv_shade_params shp = shade_params(make_shade_frame(vol, view, sp), sp);
    const sv_classify_params clp = classify_params(classifier_preset("ct"), vol.range(), 1.0);
    if (every) {
      const VoxelLayout planar = make_voxel_layout(cells.layout(), false);
      VoxelBuffer shading(planar, unaligned(planar.bytes()));
      VoxelBuffer rgba(planar, unaligned(planar.bytes()));
      VoxelBuffer shading2(dev, planar), rgba2(dev, planar);
      EXPECT_FALSE(shading2.stored());
      enqueue_shade(dev, cells, shp, shading);
      enqueue_classify(dev, shading, clp, rgba);
      enqueue_shade(dev, cells, shp, shading2);
      enqueue_classify(dev, shading2, clp, rgba2);
      EXPECT_TRUE(shading2.stored() && rgba2.stored());
      dev.finish();
      same(shading, shading2, "shade");
      same(rgba, rgba2, "shade, classify");
    }
    for (const bool il : {false, true}) {
      SCOPED_TRACE(il ? "interleaved" : "planar");
      const VoxelLayout L = make_voxel_layout(cells.layout(), il);
      if (!every) {
        ASSERT_GE(L.bytes(), 64u << 20) << "the fused kernel's stores stay ordinary";
      }
      const std::size_t kbytes = static_cast<std::size_t>(KeptClassification::bytes(L, true));
      KeptClassification kept, kept2;
      kept.planes = unaligned(kbytes);
      kept2.planes = cl::Buffer(dev.context(), CL_MEM_READ_WRITE, kbytes);
      kept.gradient = kept2.gradient = true;
      // (planes of chunks found transparent are not written: zeros in both)
      cl_check(dev.queue().enqueueFillBuffer(kept2.planes, 0.0f, 0, kbytes), "fill");
      VoxelBuffer out(L, unaligned(L.bytes())), out2(dev, L);
      for (int frame = 0; frame < 2; ++frame) {  // the kept planes written, then read
        enqueue_shade_classify(dev, cells, shp, clp, out, ShadeKernel::vec16, nullptr, nullptr,
                               &kept);
        enqueue_shade_classify(dev, cells, shp, clp, out2, ShadeKernel::vec16, nullptr, nullptr,
                               &kept2);
        dev.finish();
        same(out, out2, frame ? "fused, the kept planes read" : "fused, the kept planes written");
      }
      std::vector<float> a(kbytes / sizeof(float)), b(a.size());
      cl_check(dev.queue().enqueueReadBuffer(kept.planes, CL_TRUE, 0, kbytes, a.data()), "read");
      cl_check(dev.queue().enqueueReadBuffer(kept2.planes, CL_TRUE, 0, kbytes, b.data()), "read");
      EXPECT_EQ(std::memcmp(a.data(), b.data(), kbytes), 0) << "the kept planes";
    }
  }
}

TEST(CallerBuffers, TooSmallOrNullBuffersAreRejected) {
  SIMDVOL_TEST_DEVICE(dev);
  const CellLayout CL = make_cell_layout({16, 16, 16}, 4, 1);
  const VoxelLayout VL = make_voxel_layout(CL);
  EXPECT_THROW(CellBuffer(dev, CL, own_buffer(dev, CL.bytes() - 4)), ArgumentError);
  EXPECT_THROW(VoxelBuffer(VL, own_buffer(dev, VL.bytes() - 16)), ArgumentError);
  EXPECT_THROW(VoxelBuffer(VL, cl::Buffer()), ArgumentError);
  PeArray array(dev, pe_grid(4));
  CellBuffer cells(dev, CL);
  EXPECT_THROW(array.enqueue_layout(own_buffer(dev, 16 * 16 * 16 * 4 - 4), cells), ArgumentError);
}

// `call` throws ArgumentError, its message naming `argument` first
// ("<argument>: <problem>").
template <class F>
void expect_refused(F&& call, const std::string& argument) {
  std::string what;
  EXPECT_THROW(
      {
        try {
          call();
        } catch (const ArgumentError& e) {
          what = e.what();
          throw;
        }
      },
      ArgumentError);
  EXPECT_EQ(what.rfind(argument + ": ", 0), 0u) << "the refusal: " << what;
}
#define EXPECT_REFUSED(argument, ...)               \
  do {                                              \
    SCOPED_TRACE(argument);                         \
    expect_refused([&] { __VA_ARGS__; }, argument); \
  } while (0)

// The device stages of a small frame on the host's matching (P = 64, so
// that the swap runs fused launches), every caller buffer sized exactly.
struct Frame {
  Dims3 dims{16, 16, 16};
  int64_t pes = 64;
  ViewGeometry view;
  KdSplit split;
  Matching m;
  VoxelLayout L;
  std::optional<VoxelBuffer> voxels;
  LocalSegments segs;
  ResampleTables tables;
  cl::Buffer soff;
  int64_t nsamples = 0;
  cl::Buffer samples;

  explicit Frame(Device& dev)
      : view(make_view(std::array<int64_t, 3>{16, 16, 16}, {1.0, 1.0, 1.0}, {20, 35, 10}, 24, 24,
                       Sampling::voxel)),
        split(kd_split(dims, pes)),
        m(match_reference(view, split)),
        L(make_voxel_layout(make_cell_layout(dims, pes, 1))) {
    voxels.emplace(dev, L);
    std::vector<Rgba> cells(static_cast<std::size_t>(L.elements()));
    for (std::size_t i = 0; i < cells.size(); ++i) {
      const float a = static_cast<float>(i % 7) / 8.0f;
      cells[i] = {a * 0.5f, a * 0.25f, a * 0.75f, a};
    }
    voxels->write(dev, cells);
    segs = upload_segments(dev, m);
    tables = make_resample_tables(dev, L, view);
    soff = upload_sample_offsets(dev, m);
    nsamples = sample_offsets(m).back();
    samples = sized(dev, nsamples * 16);
  }
  static cl::Buffer sized(Device& dev, int64_t bytes) {
    return cl::Buffer(dev.context(), CL_MEM_READ_WRITE,
                      static_cast<std::size_t>(std::max<int64_t>(bytes, 16)));
  }
  // Footprints for the matching with buffers of exactly their sizes.
  DeviceFootprints footprints(Device& dev) const {
    DeviceFootprints fp = make_footprints(dev, segs.host_rects);
    fp.pixels = sized(dev, fp.size() * 16);
    cl_check(
        dev.queue().enqueueFillBuffer(fp.pixels, 0.0f, 0, static_cast<std::size_t>(fp.size()) * 16),
        "fill");
    return fp;
  }
};

// A copy of `segs` with one of its buffers replaced.
LocalSegments with_buffer(const LocalSegments& segs, cl::Buffer LocalSegments::*member,
                          cl::Buffer b) {
  LocalSegments s = segs;
  s.*member = std::move(b);
  return s;
}

// The resample and local stages (local_cl.hpp) check the sizes of the
// segments', samples', tables', footprints', lane order's and occupancy's
// buffers on the host before they enqueue: each one a buffer too small
// for what the kernels index is an ArgumentError naming it (without the
// checks the kernels read or write past it).
TEST(CallerBuffers, ResampleAndLocalStagesRefuseUndersizedBuffers) {
  SIMDVOL_TEST_DEVICE(dev);
  Frame f(dev);
  ASSERT_GT(f.segs.count, 8);
  ASSERT_GT(f.nsamples, 8);
  ASSERT_EQ(f.segs.sample_count, f.nsamples);
  const VoxelBuffer& vb = *f.voxels;
  DeviceFootprints fp = f.footprints(dev);
  ASSERT_GT(fp.size(), 8);
  const cl::Buffer small = Frame::sized(dev, 16);

  // The samples: one float4 short, and sample_off one int short.
  const cl::Buffer few_samples = Frame::sized(dev, (f.nsamples - 1) * 16);
  const cl::Buffer few_offsets = Frame::sized(dev, f.segs.count * 4);
  for (const LocalKernel variant : {LocalKernel::vector8, LocalKernel::segment}) {
    EXPECT_REFUSED("samples",
                   enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, few_samples, variant));
    EXPECT_REFUSED("sample_off",
                   enqueue_resample(dev, f.segs, few_offsets, f.tables, vb, 1, f.samples, variant));
  }
  EXPECT_REFUSED("samples", enqueue_local(dev, f.segs, f.soff, few_samples, fp));
  EXPECT_REFUSED("sample_off", enqueue_local(dev, f.segs, few_offsets, f.samples, fp));
  {  // the message names the sizes
    std::string what;
    try {
      enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, few_samples);
    } catch (const ArgumentError& e) {
      what = e.what();
    }
    EXPECT_NE(what.find(std::to_string((f.nsamples - 1) * 16) + " bytes"), std::string::npos)
        << what;
    EXPECT_NE(what.find(std::to_string(f.nsamples * 16) + " bytes"), std::string::npos) << what;
  }

  // The segments' buffers (every stage that takes them).
  for (const auto& [member, name] :
       std::vector<std::pair<cl::Buffer LocalSegments::*, std::string>>{
           {&LocalSegments::segments, "segs.segments"},
           {&LocalSegments::seg_offset, "segs.seg_offset"},
           {&LocalSegments::rects, "segs.rects"}}) {
    const LocalSegments bad = with_buffer(f.segs, member, small);
    EXPECT_REFUSED(name, enqueue_resample(dev, bad, f.soff, f.tables, vb, 1, f.samples));
    EXPECT_REFUSED(name, enqueue_local(dev, bad, f.soff, f.samples, fp));
    EXPECT_REFUSED(name, enqueue_resample_local(dev, bad, f.tables, vb, 1, fp));
    EXPECT_REFUSED(name,
                   enqueue_resample_local(dev, bad, f.tables, vb, 1, fp, LocalKernel::segment));
    EXPECT_REFUSED(name, enqueue_segment_order(dev, bad));
  }
  {  // pending bounds: one short2 per segment
    LocalSegments pending = f.segs;
    pending.bounds_pending = true;
    pending.bounds = small;
    EXPECT_REFUSED("segs.bounds", enqueue_segment_order(dev, pending));
    EXPECT_REFUSED("segs.bounds", enqueue_resample_local(dev, pending, f.tables, vb, 1, fp));
  }

  // The footprints: their pixels and their offsets.
  for (const bool pixels : {true, false}) {
    const std::string name = pixels ? "fp.pixels" : "fp.offsets";
    DeviceFootprints bad = fp;
    (pixels ? bad.pixels : bad.offsets) =
        pixels ? Frame::sized(dev, (fp.size() - 1) * 16) : Frame::sized(dev, (f.pes - 1) * 4);
    EXPECT_REFUSED(name, enqueue_resample_local(dev, f.segs, f.tables, vb, 1, bad));
    EXPECT_REFUSED(name,
                   enqueue_resample_local(dev, f.segs, f.tables, vb, 1, bad, LocalKernel::segment));
    EXPECT_REFUSED(name, enqueue_local(dev, f.segs, f.soff, f.samples, bad));
    if (pixels) EXPECT_REFUSED(name, enqueue_zero_footprints(dev, bad));
  }

  // The tables: the address table, the view and the pair table (planar
  // cells too: a caller's table is checked wherever it is set).
  for (const int which : {0, 1, 2}) {
    const std::string name = which == 0   ? "tables.table"
                             : which == 1 ? "tables.view"
                                          : "tables.pairs";
    ResampleTables bad = f.tables;
    (which == 0 ? bad.table : which == 1 ? bad.view : bad.pairs) = small;
    EXPECT_REFUSED(name, enqueue_resample_local(dev, f.segs, bad, vb, 1, fp));
    EXPECT_REFUSED(name, enqueue_resample_local(dev, f.segs, bad, vb, 1, fp, LocalKernel::segment));
    EXPECT_REFUSED(name, enqueue_resample(dev, f.segs, f.soff, bad, vb, 1, f.samples));
    EXPECT_REFUSED(
        name, enqueue_resample(dev, f.segs, f.soff, bad, vb, 1, f.samples, LocalKernel::segment));
  }

  // The lane order and the occupancy.
  SegmentOrder lanes = enqueue_segment_order(dev, f.segs);
  lanes.order = Frame::sized(dev, f.segs.count * 4);  // without the PEs after the positions
  EXPECT_REFUSED("lanes.order", enqueue_resample_local(dev, f.segs, f.tables, vb, 1, fp,
                                                       LocalKernel::vector8, nullptr, &lanes));
  EXPECT_REFUSED("lanes.order", enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, f.samples,
                                                 LocalKernel::vector8, &lanes));
  DeviceOccupancy skip = enqueue_occupancy(dev, vb, 1);
  ASSERT_GT(skip.count(), 1);
  skip.reach =
      cl::Buffer(dev.context(), CL_MEM_READ_WRITE, static_cast<std::size_t>(skip.count() - 1));
  EXPECT_REFUSED("skip.reach", enqueue_resample_local(dev, f.segs, f.tables, vb, 1, fp,
                                                      LocalKernel::vector8, &skip));
  EXPECT_REFUSED("skip.reach", enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, f.samples,
                                                LocalKernel::vector8, nullptr, &skip));

  // The footprints of enqueue_zero_uncovered (match.cl).
  DeviceMatching dm = enqueue_match(dev, f.view, f.split);
  const LocalSegments ds = device_segments(dev, dm);
  DeviceFootprints dfp = make_footprints(dev, ds.host_rects);
  ASSERT_GT(dfp.size(), 1);
  dfp.pixels = Frame::sized(dev, (dfp.size() - 1) * 16);
  EXPECT_REFUSED("fp.pixels", enqueue_zero_uncovered(dev, dm, dfp));
  dev.finish();
}

// The Monte Carlo stages (mc_cl.hpp) check the segments', samples', ray
// lists', image's, footprints' and allocation's buffers the same way, and
// refuse stratified picks without exact opacity as the reference does
// (before building: the kernels' #error made it a BuildError).
TEST(CallerBuffers, MonteCarloStagesRefuseUndersizedBuffers) {
  SIMDVOL_TEST_DEVICE(dev);
  Frame f(dev);
  enqueue_resample(dev, f.segs, f.soff, f.tables, *f.voxels, 1, f.samples);
  DeviceRayLists rays = enqueue_ray_lists(dev, f.segs, f.view);
  const int W = f.view.width(), H = f.view.height();
  const cl::Buffer image = Frame::sized(dev, int64_t(W) * H * 16);
  DeviceFootprints fp = f.footprints(dev);
  CompositeParams p;
  p.mode = CompositeMode::mc;
  p.samples = 4;
  p.exact_opacity = true;
  const cl::Buffer small = Frame::sized(dev, 16);
  const cl::Buffer few_samples = Frame::sized(dev, (f.nsamples - 1) * 16);
  const cl::Buffer few_offsets = Frame::sized(dev, f.segs.count * 4);
  const DeviceAllocation alloc = enqueue_mc_allocation(dev, f.segs, f.soff, f.samples, rays, 8);

  EXPECT_REFUSED("image", enqueue_mc_whole(dev, f.segs, f.soff, f.samples, rays, p,
                                           Frame::sized(dev, (int64_t(W) * H - 1) * 16)));
  EXPECT_REFUSED("samples", enqueue_mc_whole(dev, f.segs, f.soff, few_samples, rays, p, image));
  EXPECT_REFUSED("sample_off",
                 enqueue_mc_whole(dev, f.segs, few_offsets, f.samples, rays, p, image));
  EXPECT_REFUSED("samples", enqueue_mc_local(dev, f.segs, f.soff, few_samples, W, p, nullptr, fp));
  EXPECT_REFUSED("sample_off",
                 enqueue_mc_local(dev, f.segs, few_offsets, f.samples, W, p, nullptr, fp));
  EXPECT_REFUSED("samples", enqueue_mc_allocation(dev, f.segs, f.soff, few_samples, rays, 8));
  EXPECT_REFUSED("segs.segments",
                 enqueue_mc_whole(dev, with_buffer(f.segs, &LocalSegments::segments, small), f.soff,
                                  f.samples, rays, p, image));
  EXPECT_REFUSED(
      "segs.segments",
      enqueue_ray_lists(dev, with_buffer(f.segs, &LocalSegments::segments, small), f.view));
  for (const auto& [member_binding, name] :
       std::vector<std::pair<cl::Buffer LocalSegments::*, std::string>>{
           {&LocalSegments::segments, "segs.segments"},
           {&LocalSegments::seg_offset, "segs.seg_offset"},
           {&LocalSegments::rects, "segs.rects"}}) {
    // A plain variable for the lambda of EXPECT_REFUSED: capturing a
    // structured binding is C++20 that clang implements only from 16.
    const auto member = member_binding;
    EXPECT_REFUSED(name, enqueue_mc_local(dev, with_buffer(f.segs, member, small), f.soff,
                                          f.samples, W, p, nullptr, fp));
  }
  {
    DeviceRayLists bad = rays;
    bad.offset = Frame::sized(dev, int64_t(W) * H * 4);
    EXPECT_REFUSED("rays.offset", enqueue_mc_whole(dev, f.segs, f.soff, f.samples, bad, p, image));
  }
  for (const bool pixels : {true, false}) {
    DeviceFootprints bad = fp;
    (pixels ? bad.pixels : bad.offsets) =
        pixels ? Frame::sized(dev, (fp.size() - 1) * 16) : Frame::sized(dev, (f.pes - 1) * 4);
    EXPECT_REFUSED(pixels ? "fp.pixels" : "fp.offsets",
                   enqueue_mc_local(dev, f.segs, f.soff, f.samples, W, p, nullptr, bad));
  }
  {
    DeviceAllocation bad = alloc;
    bad.walks = Frame::sized(dev, (f.segs.count - 1) * 4);
    EXPECT_REFUSED("alloc.walks", enqueue_mc_local(dev, f.segs, f.soff, f.samples, W, p, &bad, fp));
  }
  CompositeParams strat = p;
  strat.stratified = true;
  strat.exact_opacity = false;
  EXPECT_REFUSED("--mc-stratified",
                 enqueue_mc_whole(dev, f.segs, f.soff, f.samples, rays, strat, image));
  EXPECT_REFUSED("--mc-stratified",
                 enqueue_mc_local(dev, f.segs, f.soff, f.samples, W, strat, nullptr, fp));
  dev.finish();
}

// The swap, display and warp (swap_cl.hpp) check their level buffers
// against the plan's level sizes, the intermediate image against the
// view's grid, and refuse a negative local memory budget.
TEST(CallerBuffers, SwapDisplayAndWarpRefuseUndersizedBuffers) {
  SIMDVOL_TEST_DEVICE(dev);
  Frame f(dev);
  const DeviceSwapPlan plan = upload_swap_plan(
      dev, plan_swap(f.m.rects, f.split, f.view, pe_grid(f.pes), SwapLayout::cut_and_stack));
  const int N = plan.plan.stages();
  ASSERT_GE(N, kSwapFusedMin);
  DeviceFootprints fp = f.footprints(dev);
  auto level = [&](int L, int64_t less) {
    return Frame::sized(dev, (plan.plan.level_size(L) - less) * 16);
  };
  int k = 0;  // a stage whose levels each hold two pixels at least
  while (k < N - 1 && (plan.plan.level_size(k) < 2 || plan.plan.level_size(k + 1) < 2)) ++k;
  ASSERT_GE(plan.plan.level_size(k), 2);
  ASSERT_GE(plan.plan.level_size(k + 1), 2);
  EXPECT_REFUSED("in", enqueue_swap_stage(dev, plan, k, level(k, 1), level(k + 1, 0)));
  EXPECT_REFUSED("out", enqueue_swap_stage(dev, plan, k, level(k, 0), level(k + 1, 1)));
  const int m = kSwapFusedMin;
  ASSERT_GE(plan.plan.level_size(0), 2);
  ASSERT_GE(plan.plan.level_size(m), 2);
  EXPECT_REFUSED("in", enqueue_swap_stages(dev, plan, 0, m, level(0, 1), level(m, 0)));
  EXPECT_REFUSED("out", enqueue_swap_stages(dev, plan, 0, m, level(0, 0), level(m, 1)));
  const cl::Buffer same = level(0, 0);
  EXPECT_REFUSED("out", enqueue_swap_stages(dev, plan, 0, m, same, same));
  EXPECT_REFUSED("local_bytes", enqueue_swap_stages(dev, plan, 0, m, level(0, 0), level(m, 0), -1));
  EXPECT_REFUSED("local_bytes", enqueue_swap(dev, plan, fp, kSwapFusedStages, -1));
  {
    DeviceFootprints bad = fp;
    bad.pixels = level(0, 1);
    EXPECT_REFUSED("fp.pixels", enqueue_swap(dev, plan, bad));
  }
  cl::Buffer image;
  ASSERT_GE(plan.plan.level_size(N), 2);
  EXPECT_REFUSED("last", enqueue_display(dev, plan, level(N, 1), image));
  cl::Buffer out;
  const int64_t npx = int64_t(f.view.width()) * f.view.height();
  EXPECT_REFUSED("intermediate", enqueue_warp(dev, f.view, Frame::sized(dev, (npx - 1) * 16), out));
  dev.finish();
}

// The same stages with every caller buffer of exactly the size asked for
// (no byte to spare) run, and give what the stages give on simdvol's own
// buffers; a byte less is refused.
TEST(CallerBuffers, ExactSizesAreTakenAByteLessRefused) {
  SIMDVOL_TEST_DEVICE(dev);
  Frame f(dev);
  const VoxelBuffer& vb = *f.voxels;
  const SegmentOrder lanes = enqueue_segment_order(dev, f.segs);
  const DeviceOccupancy skip = enqueue_occupancy(dev, vb, 1);
  EXPECT_NO_THROW(enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, f.samples,
                                   LocalKernel::vector8, &lanes, &skip));
  DeviceFootprints fp1 = f.footprints(dev), fp2 = f.footprints(dev);
  EXPECT_NO_THROW(enqueue_local(dev, f.segs, f.soff, f.samples, fp1));
  EXPECT_NO_THROW(enqueue_resample_local(dev, f.segs, f.tables, vb, 1, fp2));
  const Footprints a = read_footprints(dev, fp1), b = read_footprints(dev, fp2);
  ASSERT_EQ(a.pixels.size(), b.pixels.size());
  EXPECT_EQ(std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(Rgba)), 0);
  int64_t lit = 0;
  for (const Rgba& c : a.pixels) lit += c.a > 0;
  EXPECT_GT(lit, 0);

  // Monte Carlo, whole ray and per sub-ray, stratified with exact opacity.
  DeviceRayLists rays = enqueue_ray_lists(dev, f.segs, f.view);
  const int W = f.view.width(), H = f.view.height();
  const cl::Buffer image = Frame::sized(dev, int64_t(W) * H * 16);
  CompositeParams p;
  p.mode = CompositeMode::mc;
  p.samples = 4;
  p.exact_opacity = p.stratified = true;
  EXPECT_NO_THROW(enqueue_mc_whole(dev, f.segs, f.soff, f.samples, rays, p, image));
  const DeviceAllocation alloc = enqueue_mc_allocation(dev, f.segs, f.soff, f.samples, rays, 8);
  DeviceAllocation exact = alloc;
  exact.walks = Frame::sized(dev, f.segs.count * 4);
  cl_check(dev.queue().enqueueCopyBuffer(alloc.walks, exact.walks, 0, 0,
                                         static_cast<std::size_t>(f.segs.count) * 4),
           "copy");
  DeviceFootprints mfp = f.footprints(dev);
  EXPECT_NO_THROW(enqueue_mc_local(dev, f.segs, f.soff, f.samples, W, p, &exact, mfp));

  // The swap from exactly sized levels, the display and the warp.
  const DeviceSwapPlan plan = upload_swap_plan(
      dev, plan_swap(f.m.rects, f.split, f.view, pe_grid(f.pes), SwapLayout::cut_and_stack));
  const int N = plan.plan.stages();
  std::vector<cl::Buffer> levels{fp1.pixels};
  for (int L = 1; L <= N; ++L) levels.push_back(Frame::sized(dev, plan.plan.level_size(L) * 16));
  // (fewer stages in one launch, or none, where the device takes fewer than
  // 2^4 work-items in a group: POCL_MAX_WORK_GROUP_SIZE)
  const int m = std::min(kSwapFusedMin, swap_fused_stages_limit(dev));
  if (m > 0) {
    EXPECT_NO_THROW(
        enqueue_swap_stages(dev, plan, 0, m, levels[0], levels[static_cast<std::size_t>(m)]));
  }
  for (int k = m; k < N; ++k)
    EXPECT_NO_THROW(enqueue_swap_stage(dev, plan, k, levels[static_cast<std::size_t>(k)],
                                       levels[static_cast<std::size_t>(k + 1)]));
  const DeviceSwapRun run = enqueue_swap(dev, plan, fp1);
  cl::Buffer im, im2, out;
  EXPECT_NO_THROW(enqueue_display(dev, plan, levels[static_cast<std::size_t>(N)], im));
  enqueue_display(dev, plan, run.last, im2);
  const Image x = read_device_image(dev, im, W, H), y = read_device_image(dev, im2, W, H);
  EXPECT_EQ(std::memcmp(x.pixels().data(), y.pixels().data(), x.pixels().size() * sizeof(Rgba)), 0);
  const cl::Buffer inter = Frame::sized(dev, int64_t(W) * H * 16);
  cl_check(dev.queue().enqueueCopyBuffer(im, inter, 0, 0, static_cast<std::size_t>(W) * H * 16),
           "copy");
  EXPECT_NO_THROW(enqueue_warp(dev, f.view, inter, out));
  // Into a HostImage (the engine's output): the same pixels, written into
  // the returned Image's own memory (the buffer's host pointer).
  const int ow = f.view.out_width, oh = f.view.out_height;
  {
    HostImage hd(dev, W, H, "intermediate image"), hw(dev, ow, oh, "output image");
    void* at = nullptr;
    ASSERT_EQ(hd.buffer().getInfo(CL_MEM_HOST_PTR, &at), CL_SUCCESS);
    EXPECT_NO_THROW(enqueue_display_into(dev, plan, run.last, hd.buffer()));
    EXPECT_NO_THROW(enqueue_warp_into(dev, f.view, inter, hw.buffer()));
    const Image z = hd.take(), zw = hw.take();
    EXPECT_EQ(at, static_cast<const void*>(z.pixels().data()));
    EXPECT_EQ(std::memcmp(z.pixels().data(), y.pixels().data(), y.pixels().size() * sizeof(Rgba)),
              0);
    const Image warped = read_device_image(dev, out, ow, oh);
    ASSERT_EQ(zw.pixels().size(), warped.pixels().size());
    EXPECT_EQ(std::memcmp(zw.pixels().data(), warped.pixels().data(),
                          warped.pixels().size() * sizeof(Rgba)),
              0);
    EXPECT_REFUSED("image", hd.take());
  }
  {
    // Not taken: its destructor waits for what may still write the pixels
    // (the display has run once it is gone; PoCL starts a command at a
    // flush or a wait, and nothing else here flushes).
    cl::Event display;
    {
      HostImage pending(dev, W, H, "intermediate image");
      display = enqueue_display_into(dev, plan, run.last, pending.buffer());
    }
    EXPECT_EQ(display.getInfo<CL_EVENT_COMMAND_EXECUTION_STATUS>(), CL_COMPLETE);
  }
  EXPECT_REFUSED("what", HostImage(dev, 0, H, "what"));

  // A byte less.
  auto less = [&](int64_t bytes) { return Frame::sized(dev, bytes - 1); };
  EXPECT_REFUSED("samples",
                 enqueue_resample(dev, f.segs, f.soff, f.tables, vb, 1, less(f.nsamples * 16)));
  DeviceFootprints short_fp = fp2;
  short_fp.pixels = less(fp2.size() * 16);
  EXPECT_REFUSED("fp.pixels", enqueue_resample_local(dev, f.segs, f.tables, vb, 1, short_fp));
  EXPECT_REFUSED("image", enqueue_mc_whole(dev, f.segs, f.soff, f.samples, rays, p,
                                           less(int64_t(W) * H * 16)));
  const int mo = std::max(m, 1);  // (the buffers are checked before the work-group's size)
  EXPECT_REFUSED(
      "out", enqueue_swap_stages(dev, plan, 0, mo, levels[0], less(plan.plan.level_size(mo) * 16)));
  EXPECT_REFUSED("intermediate", enqueue_warp(dev, f.view, less(int64_t(W) * H * 16), out));
  EXPECT_REFUSED("image", enqueue_display_into(dev, plan, run.last, less(int64_t(W) * H * 16)));
  EXPECT_REFUSED("out", enqueue_warp_into(dev, f.view, inter, less(int64_t(ow) * oh * 16)));
  dev.finish();
}

// A HostImage's buffer is the Device's request under the HostImage's name
// (Device::buffer with the image's pixels as its host pointer, never
// pooled), as the output's device buffer was before it: the test hook
// SIMDVOL_FAIL_ALLOCATION fails it by that name (and where the device has
// no memory left, the pool's unheld buffers are let go and it is asked for
// again). It was made with clCreateBuffer directly: the engine's "output
// image" (voxel sampling) and pixel sampling's "intermediate image" were
// out of the hook's reach, and a frame rendered where the hook asked for
// the failure.
TEST(CallerBuffers, HostImageBufferIsTheDevicesRequest) {
  SIMDVOL_TEST_DEVICE(dev);
  struct Env {
    explicit Env(const char* v) { setenv("SIMDVOL_FAIL_ALLOCATION", v, 1); }
    ~Env() { unsetenv("SIMDVOL_FAIL_ALLOCATION"); }
  };
  {
    Env env("output image:2");
    Device d(dev.info().index);
    HostImage first(d, 4, 3, "output image");
    try {
      HostImage second(d, 4, 3, "output image");
      ADD_FAILURE() << "the second request did not fail";
    } catch (const CLError& e) {
      EXPECT_EQ(e.code(), CL_MEM_OBJECT_ALLOCATION_FAILURE);
      EXPECT_NE(std::string(e.what()).find("clCreateBuffer(output image, 192 bytes)"),
                std::string::npos)
          << e.what();
    }
    Device::ReuseScope scope(d);  // (never pooled, even with a scope open)
    HostImage third(d, 4, 3, "output image");
    EXPECT_EQ(d.pooled_bytes(), 0u);
    EXPECT_EQ(third.take().width(), 4);
  }
  // The engine's outputs: each sampling's frame fails at its image.
  const Volume vol = shepp_logan(16);
  for (const Sampling sampling : {Sampling::pixel, Sampling::voxel}) {
    const char* what = sampling == Sampling::pixel ? "intermediate image" : "output image";
    SCOPED_TRACE(what);
    Env env(what);
    Device d(dev.info().index);
    EngineOptions eo;
    eo.pes = 8;
    RenderEngine engine(d, eo);
    RenderOptions opt;
    opt.width = opt.height = 16;
    opt.sampling = sampling;
    opt.classifier = classifier_preset("ct");
    try {
      engine.render(vol, opt);
      ADD_FAILURE() << "the frame rendered";
    } catch (const CLError& e) {
      EXPECT_NE(std::string(e.what()).find("clCreateBuffer(" + std::string(what)),
                std::string::npos)
          << e.what();
    }
  }
}

// A moved-from RenderEngine holds no state: render and options refuse it
// (they dereferenced a null state before).
TEST(CallerBuffers, MovedFromEngineIsRefused) {
  SIMDVOL_TEST_DEVICE(dev);
  EngineOptions eo;
  eo.pes = 8;
  RenderEngine a(dev, eo);
  RenderEngine b(std::move(a));
  EXPECT_EQ(b.options().pes, 8);
  const Volume vol = shepp_logan(16);
  RenderOptions opt;
  opt.width = opt.height = 16;
  opt.classifier = classifier_preset("ct");
  EXPECT_REFUSED("engine", a.render(vol, opt));  // NOLINT(bugprone-use-after-move)
  EXPECT_REFUSED("engine", a.options());         // NOLINT(bugprone-use-after-move)
  RenderEngine c(dev, eo);
  c = std::move(b);
  EXPECT_REFUSED("engine", b.render(vol, opt));  // NOLINT(bugprone-use-after-move)
  EXPECT_EQ(c.render(vol, opt).width(), 16);
}

}  // namespace
}  // namespace simdvol
