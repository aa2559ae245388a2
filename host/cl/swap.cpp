// The swap, display and warp stages on the device (swap_cl.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>

#include "buffer_checks.hpp"
#include "simdvol/swap_cl.hpp"

namespace simdvol {

static_assert(sizeof(SwapRect) == 32, "SwapRect must match OpenCL int8");
static_assert(sizeof(Rgba) == 16, "Rgba must match float4");

namespace {

constexpr int64_t kInt32Max = std::numeric_limits<cl_int>::max();
// simdvol_swap_stage's local size: one work-item per PE, reading global ids
// only (LocalSize::at_most: fewer where the device takes fewer)
constexpr int64_t kBlock = 64;
// simdvol_swap_stages' own local arrays (size and start: 2 x (stages - 1)
// levels x 2^stages ints, SV_SWAP_GROUP = 2^kSwapFusedStages), and 1 KiB
// for the padding that aligns its four local blocks.
constexpr int64_t kSwapStagesFixedLocal =
    2 * (kSwapFusedStages - 1) * (int64_t(1) << kSwapFusedStages) * int64_t(sizeof(cl_int)) + 1024;

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

// (the intermediate and output images)
cl::Buffer float4_buffer(Device& device, int64_t n, const std::string& what) {
  const std::size_t bytes = static_cast<std::size_t>(std::max<int64_t>(n, 1)) * sizeof(cl_float4);
  check_allocation(bytes, device.info().max_alloc_bytes, what, "use a smaller --size");
  return device.buffer(CL_MEM_READ_WRITE, bytes, nullptr, what);
}

// A plan whose tables are on the device (upload_swap_plan): a table per
// level and the display's.
void check_uploaded(const DeviceSwapPlan& d) {
  const auto levels = static_cast<std::size_t>(d.plan.stages() + 1);
  if (d.rects.size() != levels || d.offsets.size() != levels || !d.xpe() || !d.ype())
    throw ArgumentError("swap plan", "its tables are not on the device (upload_swap_plan)");
}

// Level L's buffer of a swap: the plan's level_size(L) float4 pixels.
void check_level(const DeviceSwapPlan& d, int L, const cl::Buffer& b, const char* argument) {
  detail::check_buffer(b, d.plan.level_size(L), sizeof(cl_float4), argument,
                       "float4 pixels of the level");
}

void check_local_bytes(int64_t local_bytes) {
  if (local_bytes < 0)
    throw ArgumentError("local_bytes", std::to_string(local_bytes) +
                                           " is negative (0: the device's local memory size)");
}

// swap.cl takes no define, but the host builds it in one program with
// layout.cl and match.cl (stage_program_source), whose callers define WGS:
// the same defines here, so that a frame builds that program once.
cl::Kernel swap_kernel(Device& device, const std::string& name) {
  return device.kernel("swap", name, device.wgs_defines());
}

}  // namespace

DeviceSwapPlan upload_swap_plan(Device& device, SwapPlan plan) {
  DeviceSwapPlan d;
  d.plan = std::move(plan);
  upload_swap_plan(device, d, true);
  return d;
}

namespace {
// The tables' regions in the plan's buffer, in the order rects[0..N],
// offsets[0..N], xpe, ype: (offset, bytes) each, at least one element, at
// offsets aligned to the device's base-address alignment; *total = the
// buffer's size.
std::vector<std::size_t> plan_regions(Device& device, int N, std::size_t width, std::size_t height,
                                      std::size_t* total) {
  const auto levels = static_cast<std::size_t>(N + 1);
  const auto pes = static_cast<std::size_t>(int64_t(1) << N);
  const std::size_t align = std::max<std::size_t>(128, device.info().base_addr_align_bytes);
  std::vector<std::size_t> regions;
  regions.reserve(2 * (2 * levels + 2));
  std::size_t at = 0;
  auto cut = [&](std::size_t bytes) {
    regions.push_back(at);
    regions.push_back(bytes);
    at = (at + bytes + align - 1) / align * align;
  };
  for (std::size_t L = 0; L < levels; ++L) cut(pes * sizeof(SwapRect));
  for (std::size_t L = 0; L < levels; ++L) cut((pes + 1) * sizeof(cl_int));
  cut(std::max<std::size_t>(width, 1) * sizeof(cl_int));
  cut(std::max<std::size_t>(height, 1) * sizeof(cl_int));
  *total = at;
  return regions;
}
}  // namespace

bool swap_plan_held_in_map(Device& device, DeviceSwapPlan& d, int stages, int width, int height,
                           std::vector<SwapRect*>& held_out) {
  held_out.clear();
  d.held_for.reset();
  if (d.mapped == nullptr || stages < 0 || width < 1 || height < 1) return false;
  std::size_t total = 0;
  const std::vector<std::size_t> regions = plan_regions(
      device, stages, static_cast<std::size_t>(width), static_cast<std::size_t>(height), &total);
  if (total > d.mapped_bytes) return false;
  if (d.map_done()) cl_check(d.map_done.wait(), "clWaitForEvents(swap plan map)");
  auto* base = static_cast<unsigned char*>(d.mapped);
  for (int L = 0; L <= stages; ++L)
    held_out.push_back(
        reinterpret_cast<SwapRect*>(base + regions[2 * static_cast<std::size_t>(L)]));
  d.held_for = std::array<int, 3>{stages, width, height};
  return true;
}

void upload_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking) {
  const SwapPlan& plan = d.plan;
  const int N = plan.stages();
  for (int L = 0; L <= N; ++L)
    if (plan.level_size(L) > kInt32Max)
      throw ArgumentError("swap", "level " + std::to_string(L) + " exceeds 2^31 - 1 pixels");
  const auto levels = static_cast<std::size_t>(N + 1);
  const auto pes = static_cast<std::size_t>(int64_t(1) << N);
  std::size_t total = 0;
  std::vector<std::size_t> regions = plan_regions(device, N, static_cast<std::size_t>(plan.width),
                                                  static_cast<std::size_t>(plan.height), &total);
  // The tables at their regions (the gaps are never read): straight into
  // the mapped buffer where map_swap_plan mapped one large enough, else
  // into the host image that one write copies.
  const bool into_map = d.mapped != nullptr && total <= d.mapped_bytes;
  if (d.mapped != nullptr && !into_map) unmap_swap_plan(device, d);
  unsigned char* base = nullptr;
  if (into_map) {
    if (d.map_done()) cl_check(d.map_done.wait(), "clWaitForEvents(swap plan map)");
    base = static_cast<unsigned char*>(d.mapped);
    // A host image of an earlier upload is read no more (the map waited for
    // the queue's earlier commands, its write among them): its memory goes.
    std::vector<cl_int>().swap(d.staging);
  } else {
    d.staging.resize(total / sizeof(cl_int));
    base = reinterpret_cast<unsigned char*>(d.staging.data());
  }
  // (A plan made with held_out has its rectangles in the mapping already
  // and plan.held empty: swap_plan_held_in_map.)
  const bool held_kept =
      std::all_of(plan.held.begin(), plan.held.end(),
                  [&](const std::vector<SwapRect>& h) { return h.size() == pes; });
  if (!held_kept && !(into_map && d.held_for == std::array<int, 3>{N, plan.width, plan.height}))
    throw ArgumentError("swap plan",
                        "its rectangles are neither kept nor in the mapped buffer for its size");
  d.held_for.reset();
  std::size_t r = 0;
  for (std::size_t L = 0; L < levels; ++L, r += 2)
    if (held_kept) std::memcpy(base + regions[r], plan.held[L].data(), pes * sizeof(SwapRect));
  for (std::size_t L = 0; L < levels; ++L, r += 2) {
    auto* o = reinterpret_cast<cl_int*>(base + regions[r]);
    const std::vector<int64_t>& off = plan.offset[L];
    for (std::size_t p = 0; p < off.size() && p <= pes; ++p) o[p] = static_cast<cl_int>(off[p]);
  }
  for (const std::vector<int64_t>* t : {&plan.xpe, &plan.ype}) {
    auto* o = reinterpret_cast<cl_int*>(base + regions[r]);
    for (std::size_t i = 0; i < t->size(); ++i) o[i] = static_cast<cl_int>((*t)[i]);
    r += 2;
  }
  // The buffer (kept while large enough; host-allocated, so that mapping it
  // copies nothing on a CPU device) and its regions (cut again where they
  // moved or the buffer is new).
  bool fresh = false;
  if (!into_map) {
    std::size_t have = 0;
    if (d.packed()) have = buffer_size(d.packed, "clGetMemObjectInfo(CL_MEM_SIZE)");
    fresh = have < total;
    if (fresh)
      d.packed =
          device.scratch_buffer(CL_MEM_READ_ONLY | CL_MEM_ALLOC_HOST_PTR, total, "swap plan");
  }
  if (fresh || regions != d.regions) {
    auto sub = [&](std::size_t i) {
      cl_buffer_region reg{regions[2 * i], regions[2 * i + 1]};
      cl_int err = CL_SUCCESS;
      cl::Buffer b =
          d.packed.createSubBuffer(CL_MEM_READ_ONLY, CL_BUFFER_CREATE_TYPE_REGION, &reg, &err);
      if (err != CL_SUCCESS) throw CLError("clCreateSubBuffer(swap plan)", err);
      return b;
    };
    d.rects.resize(levels);
    d.offsets.resize(levels);
    std::size_t i = 0;
    for (std::size_t L = 0; L < levels; ++L) d.rects[L] = sub(i++);
    for (std::size_t L = 0; L < levels; ++L) d.offsets[L] = sub(i++);
    d.xpe = sub(i++);
    d.ype = sub(i++);
    d.regions = std::move(regions);
  }
  if (into_map) {
    cl::Event e = unmap_swap_plan(device, d);
    if (blocking) cl_check(e.wait(), "clWaitForEvents(swap plan)");
  } else {
    cl_check(device.queue().enqueueWriteBuffer(d.packed, blocking ? CL_TRUE : CL_FALSE, 0, total,
                                               d.staging.data()),
             "clEnqueueWriteBuffer(swap plan)");
  }
}

bool map_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking) {
  if (d.mapped != nullptr) return true;
  if (!d.packed()) return false;
  const std::size_t bytes = buffer_size(d.packed, "clGetMemObjectInfo(CL_MEM_SIZE)");
  cl_int err = CL_SUCCESS;
  cl::Event done;
  void* p = device.queue().enqueueMapBuffer(d.packed, blocking ? CL_TRUE : CL_FALSE,
                                            CL_MAP_WRITE_INVALIDATE_REGION, 0, bytes, nullptr,
                                            blocking ? nullptr : &done, &err);
  if (err != CL_SUCCESS) throw CLError("clEnqueueMapBuffer(swap plan)", err);
  d.mapped = p;
  d.mapped_bytes = bytes;
  d.map_done = done;
  return true;
}

void map_swap_plan(Device& device, DeviceSwapPlan& d, bool blocking, int stages, int width,
                   int height) {
  if (stages < 0 || stages > 30)
    throw ArgumentError("stages", std::to_string(stages) + " is outside 0 .. 30");
  if (width < 1 || height < 1)
    throw ArgumentError("size", std::to_string(width) + "x" + std::to_string(height) +
                                    ": width and height must be positive");
  std::size_t total = 0;
  (void)plan_regions(device, stages, static_cast<std::size_t>(width),
                     static_cast<std::size_t>(height), &total);
  if (d.mapped != nullptr && d.mapped_bytes >= total) return;
  if (d.mapped != nullptr) (void)unmap_swap_plan(device, d);
  const std::size_t have =
      d.packed() ? buffer_size(d.packed, "clGetMemObjectInfo(CL_MEM_SIZE)") : 0;
  if (have < total) {
    // (as upload_swap_plan makes it; its regions are cut at the upload)
    d.packed = device.scratch_buffer(CL_MEM_READ_ONLY | CL_MEM_ALLOC_HOST_PTR, total, "swap plan");
    d.regions.clear();
  }
  (void)map_swap_plan(device, d, blocking);
}

cl::Event unmap_swap_plan(Device& device, DeviceSwapPlan& d) {
  cl::Event e;
  if (d.mapped == nullptr) return e;
  void* p = d.mapped;
  d.mapped = nullptr;
  d.mapped_bytes = 0;
  d.map_done = cl::Event();
  cl_check(device.queue().enqueueUnmapMemObject(d.packed, p, nullptr, &e),
           "clEnqueueUnmapMemObject(swap plan)");
  return e;
}

namespace {

// enqueue_swap_stage's launch, its arguments checked by the caller
// (enqueue_swap sizes its own level buffers: no check per stage).
cl::Event swap_stage(Device& device, const DeviceSwapPlan& d, int k, const cl::Buffer& in,
                     const cl::Buffer& out) {
  const std::string name = "simdvol_swap_stage";
  cl::Kernel kern = swap_kernel(device, name);
  const auto kk = static_cast<std::size_t>(k);
  const std::size_t pes = std::size_t(1) << d.plan.stages();
  set_args(kern, name, in, d.rects[kk], d.offsets[kk], out, d.rects[kk + 1], d.offsets[kk + 1],
           static_cast<cl_int>(pes), static_cast<cl_int>(k), static_cast<cl_int>(d.plan.front[kk]));
  return device.run(kern, name, cl::NDRange(round_up(pes, kBlock)), cl::NDRange(kBlock),
                    LocalSize::at_most);
}

}  // namespace

cl::Event enqueue_swap_stage(Device& device, const DeviceSwapPlan& d, int k, const cl::Buffer& in,
                             const cl::Buffer& out) {
  if (k < 0 || k >= d.plan.stages()) throw ArgumentError("stage", "outside 0 .. N-1");
  check_uploaded(d);
  check_level(d, k, in, "in");
  check_level(d, k + 1, out, "out");
  if (in() == out()) throw ArgumentError("out", "is `in`: a stage writes another buffer");
  return swap_stage(device, d, k, in, out);
}

int64_t swap_group_pixels(const SwapPlan& plan, int k0, int m, int L) {
  const int N = plan.stages();
  if (m < 1 || m > kSwapFusedStages || k0 < 0 || k0 + m > N || L < 0 || L > N)
    throw ArgumentError("stages", "k0 = " + std::to_string(k0) + ", m = " + std::to_string(m) +
                                      ", level " + std::to_string(L) + " outside the plan");
  const std::vector<int64_t>& off = plan.offset[static_cast<std::size_t>(L)];
  const std::size_t pes = std::size_t(1) << N, groups = pes >> m;
  if (k0 == 0) {  // (the engine's) groups of consecutive PEs: differences of the prefix
    int64_t most = 0;
    for (std::size_t g = 0; g < groups; ++g) most = std::max(most, off[(g + 1) << m] - off[g << m]);
    return most;
  }
  const std::size_t lowmask = (std::size_t(1) << k0) - 1;
  std::vector<int64_t> sum(groups, 0);
  for (std::size_t p = 0; p < pes; ++p)
    sum[(p & lowmask) | ((p >> (k0 + m)) << k0)] += off[p + 1] - off[p];
  return sum.empty() ? 0 : *std::max_element(sum.begin(), sum.end());
}

std::array<int64_t, 2> swap_stages_local_bytes(const SwapPlan& plan, int k0, int m) {
  std::array<int64_t, 2> most{0, 0};
  for (int s = 1; s < m; ++s) {
    int64_t& b = most[static_cast<std::size_t>((s & 1) ? 0 : 1)];
    b = std::max(b, swap_group_pixels(plan, k0, m, k0 + s) * int64_t(sizeof(cl_float4)));
  }
  return most;
}

namespace {

int64_t local_budget(const Device& device, int64_t local_bytes) {
  return local_bytes > 0 ? local_bytes : static_cast<int64_t>(device.info().local_mem_bytes);
}

// All the local memory of a launch whose two buffers take `b` bytes, the
// kernel's own arrays and their alignment `own` (kSwapStagesFixedLocal, or
// more where the device's compiler says so: StagesKernel).
int64_t local_need(const std::array<int64_t, 2>& b, int64_t own = kSwapStagesFixedLocal) {
  return b[0] + b[1] + own;
}

// simdvol_swap_stages on this device: the kernel, the most stages one
// launch may run (a work-group of 2^m work-items: its barriers and local
// memory need exactly that many), and the local memory of its own arrays,
// 6,144 bytes, plus 1 KiB for the alignment of its blocks (the kernel's
// CL_KERNEL_LOCAL_MEM_SIZE before any local argument is set, where a
// device reports more than those 6,144).
struct StagesKernel {
  cl::Kernel kernel;
  int most_stages = 0;
  int64_t own_local = kSwapStagesFixedLocal;
  WorkGroupLimits limits;
};

StagesKernel stages_kernel(Device& device) {
  const std::string name = "simdvol_swap_stages";
  StagesKernel s;
  s.kernel = swap_kernel(device, name);
  s.limits = device.work_group_limits(s.kernel, name);
  const std::size_t most = largest_pow2_group(std::size_t(1) << kSwapFusedStages, s.limits);
  while ((std::size_t(1) << (s.most_stages + 1)) <= most) ++s.most_stages;
  cl_ulong own = 0;
  cl_check(clGetKernelWorkGroupInfo(s.kernel(), device.device()(), CL_KERNEL_LOCAL_MEM_SIZE,
                                    sizeof own, &own, nullptr),
           "clGetKernelWorkGroupInfo(simdvol_swap_stages, CL_KERNEL_LOCAL_MEM_SIZE)");
  s.own_local = std::max<int64_t>(kSwapStagesFixedLocal, static_cast<int64_t>(own) + 1024);
  return s;
}

}  // namespace

int swap_fused_stages_limit(Device& device) {
  return stages_kernel(device).most_stages;
}

namespace {

// enqueue_swap_stages with its kernel made and its local buffers' sizes
// (swap_stages_local_bytes of the same k0, m) already computed and checked.
cl::Event enqueue_swap_stages_sized(Device& device, const DeviceSwapPlan& d, int k0, int m,
                                    const cl::Buffer& in, const cl::Buffer& out,
                                    const std::array<int64_t, 2>& lbytes, cl::Kernel& kern) {
  const int N = d.plan.stages();
  const std::string name = "simdvol_swap_stages";
  // Levels k0 .. k0 + m; the slots past them repeat the last (not read).
  std::array<const cl::Buffer*, 8> r{}, o{};
  for (int s = 0; s < 8; ++s) {
    const auto L = static_cast<std::size_t>(k0 + std::min(s, m));
    r[static_cast<std::size_t>(s)] = &d.rects[L];
    o[static_cast<std::size_t>(s)] = &d.offsets[L];
  }
  cl_int fronts = 0;
  for (int s = 0; s < m; ++s)
    if (d.plan.front[static_cast<std::size_t>(k0 + s)]) fronts |= cl_int(1) << s;
  set_args(kern, name, in, out,
           cl::Local(static_cast<std::size_t>(std::max<int64_t>(lbytes[0], 16))),
           cl::Local(static_cast<std::size_t>(std::max<int64_t>(lbytes[1], 16))), *r[0], *r[1],
           *r[2], *r[3], *r[4], *r[5], *r[6], *r[7], *o[0], *o[1], *o[2], *o[3], *o[4], *o[5],
           *o[6], *o[7], static_cast<cl_int>(k0), static_cast<cl_int>(m), fronts);
  const std::size_t pes = std::size_t(1) << N;
  return device.run(kern, name, cl::NDRange(pes), cl::NDRange(std::size_t(1) << m),
                    LocalSize::exact);
}

}  // namespace

int64_t swap_stages_local_need(const SwapPlan& plan, int k0, int m) {
  return local_need(swap_stages_local_bytes(plan, k0, m));
}

cl::Event enqueue_swap_stages(Device& device, const DeviceSwapPlan& d, int k0, int m,
                              const cl::Buffer& in, const cl::Buffer& out, int64_t local_bytes) {
  const int N = d.plan.stages();
  if (m < 1 || m > kSwapFusedStages || k0 < 0 || k0 + m > N)
    throw ArgumentError("stages", "k0 = " + std::to_string(k0) + ", m = " + std::to_string(m) +
                                      " outside 0 .. N-1 (N = " + std::to_string(N) +
                                      ") or m outside 1 .. " + std::to_string(kSwapFusedStages));
  check_local_bytes(local_bytes);
  check_uploaded(d);
  check_level(d, k0, in, "in");
  check_level(d, k0 + m, out, "out");
  if (in() == out()) throw ArgumentError("out", "is `in`: the launch writes another buffer");
  StagesKernel sk = stages_kernel(device);
  if (m > sk.most_stages)
    throw ArgumentError(
        "stages",
        "k0 = " + std::to_string(k0) + ", m = " + std::to_string(m) +
            ": simdvol_swap_stages runs a work-group of 2^m = " + std::to_string(int64_t(1) << m) +
            " work-items, more than this device takes for it (" +
            describe_work_group_limits(sk.limits) + "): " +
            (sk.most_stages >= 1
                 ? "pass m <= " + std::to_string(sk.most_stages)
                 : std::string("run the stages one launch each (enqueue_swap_stage)")));
  // PoCL checks a launch's local memory only with an assertion: too much
  // aborts the process, so it is checked here.
  const std::array<int64_t, 2> lbytes = swap_stages_local_bytes(d.plan, k0, m);
  const int64_t need = local_need(lbytes, sk.own_local);
  const int64_t have = local_budget(device, local_bytes);
  if (need > have)
    throw ArgumentError("stages", "k0 = " + std::to_string(k0) + ", m = " + std::to_string(m) +
                                      ": the levels between need " + std::to_string(need) +
                                      " bytes of local memory, more than the " +
                                      std::to_string(have) + " available");
  return enqueue_swap_stages_sized(device, d, k0, m, in, out, lbytes, sk.kernel);
}

DeviceSwapRun enqueue_swap(Device& device, const DeviceSwapPlan& d, const DeviceFootprints& fp,
                           int max_fused, int64_t local_bytes, FootprintsAfterSwap after) {
  if (fp.rect_offset != d.plan.offset[0])
    throw ArgumentError("footprints", "do not match the swap plan's rectangles");
  if (max_fused < 1 || max_fused > kSwapFusedStages)
    throw ArgumentError("max_fused", "outside 1 .. " + std::to_string(kSwapFusedStages));
  check_local_bytes(local_bytes);
  check_uploaded(d);
  // (level 0: fp.rect_offset is the plan's offsets, fp.size() its size)
  check_footprints(fp, static_cast<int64_t>(fp.rect_offset.size()) - 1);
  DeviceSwapRun r;
  const int N = d.plan.stages();
  r.last = fp.pixels;
  if (N == 0) return r;
  // The first stages, kSwapFusedMin or more of them, in one launch (a
  // work-group per 2^m consecutive PEs), no more than local memory holds
  // the levels between of; the rest one launch per stage. Later runs in
  // one launch were slower (simdvol-bench-swap --swap-only: stages 6 .. 11
  // of the 256^3 phantom at 256^2, 8,192 PEs, 3.1 ms against 2.3 one launch
  // per stage; brainsmall 1.5 against 0.8): their levels are small (in the
  // L3 cache either way), and a group of PEs 2^6 apart reads a few hundred
  // scattered bytes per PE where the stage kernel streams consecutive PEs.
  // The launch's local buffers are sized once, here (their sums are a pass
  // over the PEs per level). No more stages than the device takes 2^m
  // work-items in a work-group of simdvol_swap_stages for (a GPU's 64 or
  // 256, say; the levels are the same whatever m).
  int m0 = std::min(max_fused, N);
  StagesKernel sk;
  if (m0 >= kSwapFusedMin) {
    sk = stages_kernel(device);
    m0 = std::min(m0, sk.most_stages);
  }
  std::array<int64_t, 2> lbytes{0, 0};
  for (; m0 >= kSwapFusedMin; --m0) {
    lbytes = swap_stages_local_bytes(d.plan, 0, m0);
    if (local_need(lbytes, sk.own_local) <= local_budget(device, local_bytes)) break;
  }
  const int first = m0 >= kSwapFusedMin ? m0 : 1;  // the first level written to memory
  // Level L (first .. N) in slot (L - 1) mod S, S = 2 (ping and pong): a
  // launch writes the level after the one it reads (the fused launch reads
  // the footprints), so never into the slot it reads; each slot sized by
  // the largest level it holds.
  const int S = std::min(N - first + 1, 2);
  std::vector<int64_t> most(static_cast<std::size_t>(S), 1);
  for (int L = first; L <= N; ++L) {
    int64_t& m = most[static_cast<std::size_t>((L - 1) % S)];
    m = std::max(m, d.plan.level_size(L));
  }
  // The launch that writes level `first` is the only one that reads the
  // footprints: the other slot's levels (first + 1, first + 3, ...) are
  // written after it, so they may go into the footprints' buffer where the
  // caller reads it no more (FootprintsAfterSwap::overwritten).
  const int after_first = S == 2 ? first % 2 : -1;
  for (int s = 0; s < S; ++s) {
    const std::size_t bytes =
        static_cast<std::size_t>(most[static_cast<std::size_t>(s)]) * sizeof(cl_float4);
    if (s == after_first && after == FootprintsAfterSwap::overwritten &&
        buffer_size(fp.pixels, "clGetMemObjectInfo(fp.pixels)") >= bytes) {
      r.slots.push_back(fp.pixels);
      continue;
    }
    r.slots.push_back(device.scratch_buffer(CL_MEM_READ_WRITE, bytes, "swap level buffer"));
    ++r.allocated_slots;
    r.allocated_bytes += static_cast<int64_t>(bytes);
  }
  auto slot = [&](int L) -> const cl::Buffer& {
    return r.slots[static_cast<std::size_t>((L - 1) % S)];
  };
  cl::Buffer in = fp.pixels;
  int k = 0;
  if (m0 >= kSwapFusedMin) {
    r.stages.push_back(
        enqueue_swap_stages_sized(device, d, 0, m0, in, slot(m0), lbytes, sk.kernel));
    r.first_stage.push_back(0);
    k = m0;
    in = slot(k);
  }
  for (; k < N; ++k) {
    if (d.plan.level_size(k + 1) > 0) {
      r.stages.push_back(swap_stage(device, d, k, in, slot(k + 1)));
      r.first_stage.push_back(k);
    }
    in = slot(k + 1);
  }
  r.last = in;
  return r;
}

cl::Event enqueue_display(Device& device, const DeviceSwapPlan& d, const cl::Buffer& last,
                          cl::Buffer& image) {
  check_uploaded(d);
  check_level(d, d.plan.stages(), last, "last");
  image = float4_buffer(device, int64_t(d.plan.width) * d.plan.height, "intermediate image");
  return enqueue_display_into(device, d, last, image);
}

cl::Event enqueue_display_into(Device& device, const DeviceSwapPlan& d, const cl::Buffer& last,
                               const cl::Buffer& image) {
  const int w = d.plan.width, h = d.plan.height;
  const auto N = static_cast<std::size_t>(d.plan.stages());
  check_uploaded(d);
  check_level(d, d.plan.stages(), last, "last");
  detail::check_buffer(image, int64_t(w) * h, sizeof(cl_float4), "image",
                       "float4 pixels (width x height)");
  const std::string name = "simdvol_display";
  cl::Kernel k = swap_kernel(device, name);
  set_args(k, name, last, d.rects[N], d.offsets[N], d.xpe, d.ype, static_cast<cl_int>(w),
           static_cast<cl_int>(h), image);
  return device.run(k, name,
                    cl::NDRange(round_up(static_cast<std::size_t>(w), 64),
                                round_up(static_cast<std::size_t>(h), 4)),
                    cl::NDRange(64, 4), LocalSize::at_most);
}

namespace {

// An output pixel's first tap and fraction along one axis of an intermediate
// image of n pixels. Where both taps fall outside (an image far wider than the
// volume's sphere, whose empty columns make_view cuts off) they read zeros, as
// the reference's warp does: they are moved to -2 or n, so that the index
// stays a small int however far out the pixel lies.
std::pair<cl_int, cl_float> warp_tap(double f, int n) {
  double f0 = std::floor(f);
  float t = static_cast<float>(f - f0);
  if (f0 < -1.0 || f0 >= n) {
    f0 = f0 < 0.0 ? -2.0 : double(n);
    t = 0.0f;
  }
  if (!(f0 >= -2.0 && f0 <= double(kInt32Max - 2)))
    throw ArgumentError("view", "warp out of range");
  return {static_cast<cl_int>(f0), t};
}

}  // namespace

cl::Event enqueue_warp(Device& device, const ViewGeometry& view, const cl::Buffer& intermediate,
                       cl::Buffer& out) {
  detail::check_buffer(intermediate, int64_t(view.width()) * view.height(), sizeof(cl_float4),
                       "intermediate", "float4 pixels (width x height)");
  out = float4_buffer(device, int64_t(view.out_width) * view.out_height, "output image");
  return enqueue_warp_into(device, view, intermediate, out);
}

cl::Event enqueue_warp_into(Device& device, const ViewGeometry& view,
                            const cl::Buffer& intermediate, const cl::Buffer& out) {
  const int ow = view.out_width, oh = view.out_height;
  detail::check_buffer(intermediate, int64_t(view.width()) * view.height(), sizeof(cl_float4),
                       "intermediate", "float4 pixels (width x height)");
  detail::check_buffer(out, int64_t(ow) * oh, sizeof(cl_float4), "out",
                       "float4 pixels (out_width x out_height)");
  std::vector<cl_int> ix(static_cast<std::size_t>(ow)), iy(static_cast<std::size_t>(oh));
  std::vector<cl_float> tx(ix.size()), ty(iy.size());
  for (int x = 0; x < ow; ++x) {
    const auto [x0, t] = warp_tap(view.output_to_intermediate(x, 0)[0], view.width());
    ix[static_cast<std::size_t>(x)] = x0;
    tx[static_cast<std::size_t>(x)] = t;
  }
  for (int y = 0; y < oh; ++y) {
    const auto [y0, t] = warp_tap(view.output_to_intermediate(0, y)[1], view.height());
    iy[static_cast<std::size_t>(y)] = y0;
    ty[static_cast<std::size_t>(y)] = t;
  }
  cl::Buffer bix = upload(device, ix, "warp x"), btx = upload(device, tx, "warp x"),
             biy = upload(device, iy, "warp y"), bty = upload(device, ty, "warp y");
  const std::string name = "simdvol_warp";
  cl::Kernel k = swap_kernel(device, name);
  set_args(k, name, intermediate, static_cast<cl_int>(view.width()),
           static_cast<cl_int>(view.height()), bix, btx, biy, bty, static_cast<cl_int>(ow),
           static_cast<cl_int>(oh), out);
  return device.run(k, name,
                    cl::NDRange(round_up(static_cast<std::size_t>(ow), 64),
                                round_up(static_cast<std::size_t>(oh), 4)),
                    cl::NDRange(64, 4), LocalSize::at_most);
}

HostImage::HostImage(Device& device, int width, int height, const std::string& what)
    : device_(&device) {
  if (width <= 0 || height <= 0)
    throw ArgumentError(what, "width and height must be positive, got " + std::to_string(width) +
                                  "x" + std::to_string(height));
  const std::size_t n = image_pixels(width, height);
  check_allocation(std::uint64_t(n) * sizeof(cl_float4), device.info().max_alloc_bytes, what,
                   "use a smaller --size");
  image_ = Image(width, height);
  static_assert(sizeof(Rgba) == sizeof(cl_float4));
  // Through Device::buffer (never pooled: a host pointer), as the output's
  // device buffer was: SIMDVOL_FAIL_ALLOCATION reaches it by `what`, and
  // where the device has no memory left the pool's unheld buffers are let
  // go and the buffer asked for once more.
  buffer_ = device.buffer(CL_MEM_READ_WRITE | CL_MEM_USE_HOST_PTR, n * sizeof(cl_float4),
                          image_.pixels().data(), what);
}

HostImage::~HostImage() {
  if (!buffer_()) return;
  // Commands enqueued on the buffer may still write the pixels, which go
  // with the image: waited for (an error here is the frame's to report).
  (void)device_->queue().finish();
}

Image HostImage::take() {
  if (!buffer_()) throw ArgumentError("image", "was taken already");
  const std::size_t bytes = image_.pixels().size() * sizeof(cl_float4);
  cl_int err = CL_SUCCESS;
  void* p = device_->queue().enqueueMapBuffer(buffer_, CL_TRUE, CL_MAP_READ, 0, bytes, nullptr,
                                              nullptr, &err);
  if (err != CL_SUCCESS) throw CLError("clEnqueueMapBuffer(image)", err);
  // (a buffer made with CL_MEM_USE_HOST_PTR maps at that pointer, its
  // latest contents there)
  cl_check(device_->queue().enqueueUnmapMemObject(buffer_, p), "clEnqueueUnmapMemObject(image)");
  cl_check(device_->queue().finish(), "clFinish");
  buffer_ = cl::Buffer();
  return std::move(image_);
}

Image read_device_image(Device& device, const cl::Buffer& image, int width, int height) {
  // Mapped (on a CPU device the buffer's own memory) and copied once into
  // the image's storage: a read into an Image zeroed it first, 1 MB a frame
  // at 256^2 (about 0.15 ms of host work beside the kernels).
  const std::size_t n = image_pixels(width, height);  // (checks the size)
  const std::size_t have = buffer_size(image, "clGetMemObjectInfo(image)");
  if (have / sizeof(Rgba) < n)
    throw ArgumentError("image", "a buffer of " + std::to_string(have) +
                                     " bytes holds fewer than " + std::to_string(width) + "x" +
                                     std::to_string(height) + " RGBA pixels");
  cl_int err = CL_SUCCESS;
  void* p = device.queue().enqueueMapBuffer(image, CL_TRUE, CL_MAP_READ, 0, n * sizeof(Rgba),
                                            nullptr, nullptr, &err);
  if (err != CL_SUCCESS) throw CLError("clEnqueueMapBuffer(image)", err);
  const auto* px = static_cast<const Rgba*>(p);
  std::vector<Rgba> pixels;
  try {
    pixels.assign(px, px + n);
  } catch (...) {
    (void)device.queue().enqueueUnmapMemObject(image, p);
    throw;
  }
  cl_check(device.queue().enqueueUnmapMemObject(image, p), "clEnqueueUnmapMemObject(image)");
  return Image(width, height, std::move(pixels));
}

}  // namespace simdvol
