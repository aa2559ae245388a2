// The stages on the caller's OpenCL objects (docs/KERNELS.md, "Embedding"):
// a Device wrapping the caller's context and queue, CellBuffer and
// VoxelBuffer wrapping the caller's buffers, PeArray::enqueue_layout from a
// flat volume already on the device. Exact equality where the result is a
// copy (layout); the same kernels as the owned-buffer path elsewhere, so the
// classify output must equal that path's bit for bit.
#include <gtest/gtest.h>

#include <cstring>

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
