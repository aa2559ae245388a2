// The swap, display and warp stages on the device (swap_cl.hpp).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "simdvol/swap_cl.hpp"

namespace simdvol {

static_assert(sizeof(SwapRect) == 32, "SwapRect must match OpenCL int8");
static_assert(sizeof(Rgba) == 16, "Rgba must match float4");

namespace {

constexpr int64_t kInt32Max = std::numeric_limits<cl_int>::max();
constexpr int64_t kBlock = 64;  // local size

template <class T>
cl::Buffer upload(Device& device, const std::vector<T>& v, const std::string& what) {
  std::vector<T> tmp;
  const std::vector<T>* src = &v;
  if (v.empty()) {
    tmp.resize(1);
    src = &tmp;
  }
  return device.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, src->size() * sizeof(T),
                       const_cast<T*>(src->data()), what);
}

cl::Buffer float4_buffer(Device& device, int64_t n, const std::string& what) {
  return device.buffer(CL_MEM_READ_WRITE,
                       static_cast<std::size_t>(std::max<int64_t>(n, 1)) * sizeof(cl_float4),
                       nullptr, what);
}

// swap.cl takes no define, but the host builds it in one program with
// layout.cl and match.cl (stage_program_source), whose callers define WGS:
// the same defines here, so that a frame builds that program once.
cl::Kernel swap_kernel(Device& device, const std::string& name) {
  static const Defines d{{"WGS", "64"}};
  return device.kernel("swap", name, d);
}

}  // namespace

void swap_chunk_table_into(const std::vector<int64_t>& off, std::vector<cl_int2>& t) {
  if (off.size() < 2) throw ArgumentError("offsets", "need P + 1 entries");
  std::size_t n = 0;
  for (std::size_t p = 0; p + 1 < off.size(); ++p)
    n += static_cast<std::size_t>((off[p + 1] - off[p] + kSwapChunk - 1) / kSwapChunk);
  t.resize(n);
  cl_int2* e = t.data();
  for (std::size_t p = 0; p + 1 < off.size(); ++p)
    for (int64_t s = 0; s < off[p + 1] - off[p]; s += kSwapChunk) {
      e->s[0] = static_cast<cl_int>(p);
      e->s[1] = static_cast<cl_int>(s);
      ++e;
    }
}

std::vector<cl_int2> swap_chunk_table(const std::vector<int64_t>& off) {
  std::vector<cl_int2> t;
  swap_chunk_table_into(off, t);
  return t;
}

namespace {

// Writes v to buffer b, blocking or not: b is kept if it holds v, else
// replaced (blocking: by a copy of v, as upload(); else by a scratch
// buffer, then written). An empty table writes nothing (the
// buffer holds at least one element: kernels take no null buffer).
template <class T>
void stage(Device& device, cl::Buffer& b, const std::vector<T>& v, bool blocking,
           const char* what) {
  const std::size_t bytes = std::max<std::size_t>(v.size(), 1) * sizeof(T);
  std::size_t have = 0;
  if (b()) cl_check(b.getInfo(CL_MEM_SIZE, &have), "clGetMemObjectInfo(CL_MEM_SIZE)");
  if (have < bytes && blocking) {
    b = upload(device, v, what);
    return;
  }
  if (have < bytes) b = device.scratch_buffer(CL_MEM_READ_ONLY, bytes, what);
  if (v.empty()) return;
  cl_check(device.queue().enqueueWriteBuffer(b, blocking ? CL_TRUE : CL_FALSE, 0,
                                             v.size() * sizeof(T), v.data()),
           "clEnqueueWriteBuffer(swap plan)");
}

}  // namespace

DeviceSwapPlan upload_swap_plan(Device& device, SwapPlan plan) {
  DeviceSwapPlan d;
  d.plan = std::move(plan);
  upload_swap_plan(device, d, true);
  return d;
}

void upload_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking) {
  const SwapPlan& plan = d.plan;
  const int N = plan.stages();
  for (int L = 0; L <= N; ++L)
    if (plan.level_size(L) > kInt32Max)
      throw ArgumentError("swap", "level " + std::to_string(L) + " exceeds 2^31 - 1 pixels");
  const auto levels = static_cast<std::size_t>(N + 1);
  d.offsets32.resize(levels);
  d.chunk_tables.resize(static_cast<std::size_t>(N));
  d.chunk_count.assign(static_cast<std::size_t>(N), 0);
  for (int L = 1; L <= N; ++L) {
    auto& t = d.chunk_tables[static_cast<std::size_t>(L - 1)];
    swap_chunk_table_into(plan.offset[static_cast<std::size_t>(L)], t);
    if (static_cast<int64_t>(t.size()) * kSwapChunk > kInt32Max)
      throw ArgumentError("swap", "level " + std::to_string(L) + " exceeds 2^31 - 1 work-items");
    d.chunk_count[static_cast<std::size_t>(L - 1)] = static_cast<int64_t>(t.size());
  }
  d.rects.resize(levels);
  d.offsets.resize(levels);
  d.chunks.resize(static_cast<std::size_t>(N));
  for (std::size_t L = 0; L < levels; ++L) {
    stage(device, d.rects[L], plan.held[L], blocking, "swap rectangles");
    d.offsets32[L].assign(plan.offset[L].begin(), plan.offset[L].end());
    stage(device, d.offsets[L], d.offsets32[L], blocking, "swap offsets");
    if (L > 0) stage(device, d.chunks[L - 1], d.chunk_tables[L - 1], blocking, "swap chunk table");
  }
  d.xpe32.assign(plan.xpe.begin(), plan.xpe.end());
  d.ype32.assign(plan.ype.begin(), plan.ype.end());
  stage(device, d.xpe, d.xpe32, blocking, "display x table");
  stage(device, d.ype, d.ype32, blocking, "display y table");
}

cl::Event enqueue_swap_stage(Device& device, const DeviceSwapPlan& d, int k, const cl::Buffer& in,
                             const cl::Buffer& out) {
  if (k < 0 || k >= d.plan.stages()) throw ArgumentError("stage", "outside 0 .. N-1");
  const std::string name = "simdvol_swap_stage";
  cl::Kernel kern = swap_kernel(device, name);
  const auto kk = static_cast<std::size_t>(k);
  const cl_int n = static_cast<cl_int>(d.chunk_count[kk]);
  set_args(kern, name, in, d.rects[kk], d.offsets[kk], out, d.rects[kk + 1], d.offsets[kk + 1],
           d.chunks[kk], n, static_cast<cl_int>(k), static_cast<cl_int>(d.plan.front[kk]));
  return device.run(kern, name,
                    cl::NDRange(round_up(static_cast<std::size_t>(std::max(n, 1)), kBlock)),
                    cl::NDRange(kBlock));
}

DeviceSwapRun enqueue_swap(Device& device, const DeviceSwapPlan& d, const DeviceFootprints& fp) {
  if (fp.rect_offset != d.plan.offset[0])
    throw ArgumentError("footprints", "do not match the swap plan's rectangles");
  DeviceSwapRun r;
  const int N = d.plan.stages();
  int64_t most = 0;
  for (int L = 1; L <= N; ++L) most = std::max(most, d.plan.level_size(L));
  r.last = fp.pixels;
  if (N == 0) return r;
  const std::size_t level_bytes =
      static_cast<std::size_t>(std::max<int64_t>(most, 1)) * sizeof(cl_float4);
  r.ping = device.scratch_buffer(CL_MEM_READ_WRITE, level_bytes, "swap level buffer");
  r.pong =
      N > 1 ? device.scratch_buffer(CL_MEM_READ_WRITE, level_bytes, "swap level buffer") : r.ping;
  cl::Buffer in = fp.pixels;
  for (int k = 0; k < N; ++k) {
    const cl::Buffer& out = (k % 2 == 0) ? r.ping : r.pong;
    if (d.plan.level_size(k + 1) > 0) r.stages.push_back(enqueue_swap_stage(device, d, k, in, out));
    in = out;
  }
  r.last = in;
  return r;
}

cl::Event enqueue_display(Device& device, const DeviceSwapPlan& d, const cl::Buffer& last,
                          cl::Buffer& image) {
  const int w = d.plan.width, h = d.plan.height;
  const auto N = static_cast<std::size_t>(d.plan.stages());
  image = float4_buffer(device, int64_t(w) * h, "intermediate image");
  const std::string name = "simdvol_display";
  cl::Kernel k = swap_kernel(device, name);
  set_args(k, name, last, d.rects[N], d.offsets[N], d.xpe, d.ype, static_cast<cl_int>(w),
           static_cast<cl_int>(h), image);
  return device.run(k, name,
                    cl::NDRange(round_up(static_cast<std::size_t>(w), 64),
                                round_up(static_cast<std::size_t>(h), 4)),
                    cl::NDRange(64, 4));
}

cl::Event enqueue_warp(Device& device, const ViewGeometry& view, const cl::Buffer& intermediate,
                       cl::Buffer& out) {
  const int ow = view.out_width, oh = view.out_height;
  std::vector<cl_int> ix(static_cast<std::size_t>(ow)), iy(static_cast<std::size_t>(oh));
  std::vector<cl_float> tx(ix.size()), ty(iy.size());
  for (int x = 0; x < ow; ++x) {
    const double fx = view.output_to_intermediate(x, 0)[0], x0 = std::floor(fx);
    if (x0 < -2.0 || x0 > double(kInt32Max - 2)) throw ArgumentError("view", "warp out of range");
    ix[static_cast<std::size_t>(x)] = static_cast<cl_int>(x0);
    tx[static_cast<std::size_t>(x)] = static_cast<float>(fx - x0);
  }
  for (int y = 0; y < oh; ++y) {
    const double fy = view.output_to_intermediate(0, y)[1], y0 = std::floor(fy);
    if (y0 < -2.0 || y0 > double(kInt32Max - 2)) throw ArgumentError("view", "warp out of range");
    iy[static_cast<std::size_t>(y)] = static_cast<cl_int>(y0);
    ty[static_cast<std::size_t>(y)] = static_cast<float>(fy - y0);
  }
  cl::Buffer bix = upload(device, ix, "warp x"), btx = upload(device, tx, "warp x"),
             biy = upload(device, iy, "warp y"), bty = upload(device, ty, "warp y");
  out = float4_buffer(device, int64_t(ow) * oh, "output image");
  const std::string name = "simdvol_warp";
  cl::Kernel k = swap_kernel(device, name);
  set_args(k, name, intermediate, static_cast<cl_int>(view.width()),
           static_cast<cl_int>(view.height()), bix, btx, biy, bty, static_cast<cl_int>(ow),
           static_cast<cl_int>(oh), out);
  return device.run(k, name,
                    cl::NDRange(round_up(static_cast<std::size_t>(ow), 64),
                                round_up(static_cast<std::size_t>(oh), 4)),
                    cl::NDRange(64, 4));
}

Image read_device_image(Device& device, const cl::Buffer& image, int width, int height) {
  Image im(width, height);
  cl_check(device.queue().enqueueReadBuffer(image, CL_TRUE, 0, im.pixels().size() * sizeof(Rgba),
                                            im.pixels().data()),
           "clEnqueueReadBuffer(image)");
  return im;
}

}  // namespace simdvol
