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
#include <string>
#include <vector>

#include "simdvol/classify.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/stages.hpp"
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

}  // namespace
}  // namespace simdvol
