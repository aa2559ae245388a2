// The OpenCL device layer: finding and choosing a device, one context and one
// in-order profiling queue, building programs from the embedded kernel
// sources (with a program cache), and error checking that names the failing
// call.
//
// How a stage is written on top of this layer (the pattern layout.cpp follows):
//   1. Validate the arguments on the host and throw ArgumentError before
//      anything is enqueued.
//   2. cl::Kernel k = device.kernel("shade", "simdvol_shade", {{"WGS", "64"}});
//      builds (once; later calls hit the cache) the program
//        "#define WGS 64" + simdvol_shared.h + common.cl + shade.cl
//      and creates the kernel. Kernel objects are not thread-safe; ask for a
//      fresh one per call (creating one from a cached program is cheap).
//   3. set_args(k, "simdvol_shade", a, b, c) sets all arguments, checking each.
//   4. device.run(k, "simdvol_shade", global, local) enqueues with an explicit
//      local size (the global size is rounded up to a multiple of it, so the
//      kernel must bounds-check its ids) and returns the profiling event.
//      A kernel that reads only its global ids passes LocalSize::at_most, so
//      that a device taking fewer work-items in a group (a GPU's 256, a
//      kernel's CL_KERNEL_WORK_GROUP_SIZE) runs it in smaller groups; one
//      whose local size is its contract (barriers, local memory,
//      reqd_work_group_size) passes LocalSize::exact, the default, and is
//      refused with an ArgumentError naming the limits where it does not fit.
// Kernel files live in kernels/<stage>.cl. Each is valid OpenCL C on its own
// (compile with -I kernels): it starts with
//   #ifndef SIMDVOL_COMMON_CL
//   #include "common.cl"
//   #endif
// (common.cl includes simdvol_shared.h the same way), and every tunable has
// an #ifndef default. In the assembled source both guards are already
// defined, so the #include lines are skipped.
//
// Errors: every failing OpenCL call throws CLError naming the call and the
// error code (CL_OUT_OF_RESOURCES, ...); a failed build throws BuildError with
// the full build log; no OpenCL platform at all throws NoDeviceError. No
// destructor throws.
#pragma once

// OpenCL 1.2 headers. The library is built with these three definitions, and
// the CMake target simdvol::simdvol passes them on as interface compile
// definitions to every file of a program that links it: simdvol's headers and
// the program's code then see one configuration of <CL/opencl.hpp> (its
// classes' inline functions depend on CL_HPP_TARGET_OPENCL_VERSION, and
// cl::Buffer, cl::Kernel, ... cross the library's interface). The guards below
// matter only where a file is compiled without them (not through the CMake
// package). A file that calls OpenCL 2.0+ functions
// (clCreateCommandQueueWithProperties, ...) raises only the C headers' version,
// first of all, before any OpenCL or simdvol header:
//   #undef CL_TARGET_OPENCL_VERSION
//   #define CL_TARGET_OPENCL_VERSION 300
// (defining it again without the #undef is a "redefined" warning); it leaves
// the two CL_HPP_ definitions as they are.
#ifndef CL_TARGET_OPENCL_VERSION
#define CL_TARGET_OPENCL_VERSION 120
#endif
#ifndef CL_HPP_TARGET_OPENCL_VERSION
#define CL_HPP_TARGET_OPENCL_VERSION 120
#endif
#ifndef CL_HPP_MINIMUM_OPENCL_VERSION
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#endif
// CL_HPP_ENABLE_EXCEPTIONS is deliberately not defined: simdvol checks the
// returned error codes itself (cl_check) and throws its own errors.
#include <CL/opencl.hpp>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "simdvol/error.hpp"

namespace simdvol {

/// Name of an OpenCL error code ("CL_OUT_OF_RESOURCES"), or "unknown OpenCL error".
std::string_view cl_error_name(cl_int code);

/// An OpenCL call failed. what() is "<call>: <CL_NAME> (<code>)" plus ": <detail>"
/// when a detail is given.
class CLError : public Error {
 public:
  CLError(const std::string& call, cl_int code, const std::string& detail = "");
  const std::string& call() const { return call_; }
  cl_int code() const { return code_; }

 private:
  std::string call_;
  cl_int code_;
};

/// Whether an OpenCL error code says that memory ran out
/// (CL_OUT_OF_HOST_MEMORY, CL_MEM_OBJECT_ALLOCATION_FAILURE,
/// CL_OUT_OF_RESOURCES).
bool is_allocation_failure(cl_int code);

/// clBuildProgram failed. log() is the device's full build log (also in what()).
class BuildError : public CLError {
 public:
  BuildError(cl_int code, const std::string& options, const std::string& log);
  const std::string& options() const { return options_; }
  const std::string& log() const { return log_; }

 private:
  std::string options_;
  std::string log_;
};

/// There is no OpenCL platform or no device. The message says what to install.
class NoDeviceError : public Error {
 public:
  using Error::Error;
};

/// Throws CLError(call, code) unless code == CL_SUCCESS.
inline void cl_check(cl_int code, const char* call) {
  if (code != CL_SUCCESS) throw CLError(call, code);
}

/// The size in bytes of `buffer` (CL_MEM_SIZE); CLError(call, code) if the
/// query fails.
inline std::size_t buffer_size(const cl::Buffer& buffer, const char* call) {
  std::size_t bytes = 0;
  cl_check(buffer.getInfo(CL_MEM_SIZE, &bytes), call);
  return bytes;
}

/// One OpenCL device as `simdvol devices` lists it.
struct DeviceInfo {
  int index = -1;  ///< position in list_devices() (-1 for a wrapped external device)
  int platform_index = 0;
  std::string platform;
  std::string name;
  std::string vendor;
  std::string version;         ///< CL_DEVICE_VERSION
  std::string driver_version;  ///< CL_DRIVER_VERSION
  std::string type;            ///< "CPU", "GPU", "accelerator", "other"
  bool is_cpu = false;
  unsigned compute_units = 0;
  std::uint64_t local_mem_bytes = 0;
  std::uint64_t global_mem_bytes = 0;
  std::uint64_t max_alloc_bytes = 0;
  std::size_t max_work_group_size = 0;
  /// CL_DEVICE_MAX_WORK_ITEM_SIZES: the most work-items of a group along x, y, z
  std::array<std::size_t, 3> max_work_item_sizes{};
  std::size_t base_addr_align_bytes = 0;  ///< CL_DEVICE_MEM_BASE_ADDR_ALIGN (in bytes)
};

/// The most work-items one launch of a kernel may put in a work-group: along
/// each dimension (the device's CL_DEVICE_MAX_WORK_ITEM_SIZES) and in all
/// (the smaller of the device's CL_DEVICE_MAX_WORK_GROUP_SIZE and the
/// kernel's CL_KERNEL_WORK_GROUP_SIZE, which a GPU's compiler may set lower
/// for a kernel of many registers). Device::work_group_limits queries them.
struct WorkGroupLimits {
  std::array<std::size_t, 3> per_dimension{};  ///< CL_DEVICE_MAX_WORK_ITEM_SIZES
  std::size_t device_total = 0;                ///< CL_DEVICE_MAX_WORK_GROUP_SIZE
  std::size_t kernel_total = 0;                ///< CL_KERNEL_WORK_GROUP_SIZE
  /// The most work-items in all: min(device_total, kernel_total).
  std::size_t total() const { return device_total < kernel_total ? device_total : kernel_total; }
};

/// Whether a work-group of `local` (its first `dims` entries, 1 .. 3) fits
/// `limits`: each entry at least 1 and within its dimension's limit, their
/// product within total().
bool work_group_fits(const std::array<std::size_t, 3>& local, unsigned dims,
                     const WorkGroupLimits& limits);

/// The local size Device::run launches a LocalSize::at_most kernel with:
/// `wanted` where it fits; else each dimension halved (rounding up) until it
/// fits its own limit, then the last dimension above 1 halved, then the one
/// before it, ..., until the product fits total() (the first dimension, the
/// kernels' vector lanes and consecutive addresses, is kept longest; 2-D
/// and 3-D ranges give up PEs or rows per group first). A power of two stays
/// a power of two, so a global size rounded up to a multiple of `wanted`
/// stays a multiple of the result. Never below 1 (also for limits of 0).
std::array<std::size_t, 3> fit_work_group(std::array<std::size_t, 3> wanted, unsigned dims,
                                          const WorkGroupLimits& limits);

/// The largest power of two at most `most` (>= 1) that a 1-D work-group
/// takes under `limits` (1 where `limits` take none).
std::size_t largest_pow2_group(std::size_t most, const WorkGroupLimits& limits);

/// "CL_DEVICE_MAX_WORK_GROUP_SIZE 64, CL_DEVICE_MAX_WORK_ITEM_SIZES 64 x 64
/// x 64, the kernel's CL_KERNEL_WORK_GROUP_SIZE 64": the limits, for
/// messages.
std::string describe_work_group_limits(const WorkGroupLimits& limits);

/// WGS, the work-group size of the kernels declared
/// reqd_work_group_size(WGS, 1, 1) (layout.cl, match.cl, balance.cl: the
/// frame's program of layout, match, balance and swap), on a device
/// described by `info`: 64, or where the device takes fewer work-items in
/// a group (CL_DEVICE_MAX_WORK_GROUP_SIZE) or along x
/// (CL_DEVICE_MAX_WORK_ITEM_SIZES[0]), the largest power of two it takes.
/// Those kernels read only their global ids, so any WGS gives the same
/// results.
std::size_t fixed_group_size(const DeviceInfo& info);

/// What a launch's local size is to its kernel (Device::run).
enum class LocalSize {
  /// The kernel needs this size (barriers or local memory between its
  /// work-items, or reqd_work_group_size): where the device or the kernel
  /// takes fewer work-items, run() throws ArgumentError naming the kernel,
  /// the size and the limits, before anything is enqueued.
  exact,
  /// A choice for speed alone (the kernel reads only its global ids and
  /// bounds-checks them, so any local size gives the same results): where
  /// it does not fit, run() launches with fit_work_group(local) instead.
  at_most,
};

/// Every device of every platform, platforms in ICD order, indices 0, 1, ...
/// Throws NoDeviceError if there is no platform or no device.
std::vector<DeviceInfo> list_devices();

/// A human-readable table of the devices (for `simdvol devices`); `chosen`
/// marks the default device.
std::string describe_devices(const std::vector<DeviceInfo>& devices, int chosen = -1);

/// Picks a device index: `requested` (e.g. --device N) if given, else the
/// environment variable SIMDVOL_DEVICE if set, else the first CPU device,
/// else device 0. Throws ArgumentError (naming "--device" or "SIMDVOL_DEVICE")
/// for an index that is not listed or not a number.
int choose_device(const std::vector<DeviceInfo>& devices, std::optional<int> requested = {});

/// Preprocessor definitions for a program: {"WGS", "64"} becomes "#define WGS 64".
using Defines = std::vector<std::pair<std::string, std::string>>;

/// The embedded text of one kernel file ("layout.cl", "common.cl",
/// "simdvol_shared.h"). Throws ArgumentError if there is no such file.
std::string_view kernel_file(std::string_view name);
/// Names of all embedded kernel files.
std::vector<std::string> kernel_files();

/// The program source of a stage: the #define lines, simdvol_shared.h,
/// common.cl and <stage>.cl, each part preceded by a #line directive naming
/// its file so that build logs point into the right file.
std::string program_source(std::string_view stage, const Defines& defines = {});
/// One program of several stages: program_source(stage, defines) followed by
/// the files <then[0]>.cl, <then[1]>.cl, ... each with its #line directive
/// (they see the first stage's defines, and simdvol_shared.h and common.cl
/// once). Throws ArgumentError if a file is missing.
std::string program_source(std::string_view stage, const Defines& defines,
                           std::initializer_list<std::string_view> then);
/// What Device::program builds for a stage: program_source(stage, defines),
/// except that layout, match, balance and swap are built together, one
/// program of program_source("layout", defines) followed by match.cl,
/// balance.cl and swap.cl (each with its #line directive): a program build
/// costs PoCL about the same whatever its size, and a frame uses all four.
/// Each file also builds on its own (program_source).
std::string stage_program_source(std::string_view stage, const Defines& defines = {});
/// A key for Device::build_keyed naming program_source(stage, defines, then)
/// (`then` empty: program_source(stage, defines)) or, with a `kind` of
/// "stage", stage_program_source(stage, defines): each part with its length,
/// so that different arguments never give the same key.
std::string program_key(std::string_view kind, std::string_view stage, const Defines& defines,
                        std::initializer_list<std::string_view> then = {});

/// Where Device::build keeps program binaries: $SIMDVOL_CACHE_DIR; nullopt
/// (not kept) when it is unset, empty or "off". Files are named by a hash
/// of the device, options and source; delete the directory to clear it.
/// The first build of a program with it set costs more (PoCL compiles
/// every kernel of the program for the binary: 0.7-4 s for simdvol's
/// stages); later processes build the program from the file in 2-10 ms
/// instead of 45-75 (a one-frame brainsmall render 0.44-0.53 -> 0.17-0.21 s).
std::optional<std::filesystem::path> program_cache_dir();
/// Why program_cache_dir() cannot keep binaries (it names a file, or a
/// directory that cannot be made or written), as a sentence naming
/// SIMDVOL_CACHE_DIR; nullopt where it can or where it is unset. Device::build
/// then only builds from source (the library says nothing; the CLI prints
/// this as a note). Makes the directory if it is missing, as build() would.
std::optional<std::string> program_cache_problem();

/// Throws ArgumentError naming `what` if a buffer of `bytes` exceeds the
/// device's largest allocation `max_alloc_bytes` (or is zero). `hint`, if
/// given, ends the message: what makes the buffer smaller ("use a smaller
/// volume or fewer PEs" for the voxel cells, "use a smaller --size" for an
/// image); Device::buffer gives none, since it cannot tell.
void check_allocation(std::uint64_t bytes, std::uint64_t max_alloc_bytes, const std::string& what,
                      const std::string& hint = "");

/// Rounds n up to a multiple of m (m > 0).
inline std::size_t round_up(std::size_t n, std::size_t m) {
  return (n + m - 1) / m * m;
}

/// A device with its context, in-order queue and program cache.
/// Movable, not copyable; thread-safe for build()/program()/kernel(),
/// buffer() and run() (ReuseScope and the launch log are per thread).
class Device {
 public:
  /// Opens device `index` as listed by list_devices(), or the one
  /// choose_device() picks. The queue is in-order with profiling enabled.
  explicit Device(std::optional<int> index = std::nullopt);
  /// Wraps an existing context and queue (both retained, not taken over), for
  /// programs that embed simdvol's kernels. The device is the queue's device.
  /// ArgumentError for a null handle, a queue of another context, or an
  /// out-of-order queue (the stages depend on the queue's order).
  Device(cl_context context, cl_command_queue queue);
  Device(Device&&) noexcept;
  Device& operator=(Device&&) noexcept;
  Device(const Device&) = delete;
  Device& operator=(const Device&) = delete;
  ~Device();

  const DeviceInfo& info() const { return info_; }
  const cl::Context& context() const { return context_; }
  const cl::Device& device() const { return device_; }
  const cl::CommandQueue& queue() const { return queue_; }
  /// Whether the queue has CL_QUEUE_PROFILING_ENABLE (always for our own queues).
  bool profiling() const { return profiling_; }
  /// fixed_group_size(info()): the WGS this device's frame program is built
  /// with and its reqd_work_group_size kernels are launched with.
  std::size_t wgs() const { return wgs_; }
  /// The defines of the frame's program (stage_program_source of layout,
  /// match, balance, swap): {{"WGS", wgs()}}. Every stage that takes a
  /// kernel of that program passes them, so that a frame builds it once.
  const Defines& wgs_defines() const { return wgs_defines_; }
  /// The work-group limits of a launch of `kernel` on this device (one
  /// clGetKernelWorkGroupInfo; CLError naming `what` if it fails).
  WorkGroupLimits work_group_limits(const cl::Kernel& kernel, const std::string& what) const;

  /// The build options actually used: `options` plus SIMDVOL_CL_OPTIONS.
  static std::string build_options(const std::string& options);
  /// Builds `source` with build_options(options), cached by (source, options)
  /// in memory and, with SIMDVOL_CACHE_DIR set, as the device's program
  /// binary on disk (program_cache_dir()). Throws BuildError with the build
  /// log on failure.
  cl::Program build(const std::string& source, const std::string& options = "");
  /// build(source(), options), found first by `key` (program_key(): a short
  /// text that determines what `source` assembles), so that a program built
  /// before is returned without assembling and comparing its source again
  /// (the frame's launches ask for their programs some 90 times a frame).
  cl::Program build_keyed(const std::string& key, const std::function<std::string()>& source,
                          const std::string& options = "");
  /// build(stage_program_source(stage, defines), options), by
  /// build_keyed(program_key(stage, defines), ...).
  cl::Program program(std::string_view stage, const Defines& defines = {},
                      const std::string& options = "");
  /// A fresh kernel `name` from program(stage, defines, options).
  cl::Kernel kernel(std::string_view stage, const std::string& name, const Defines& defines = {},
                    const std::string& options = "");
  /// Number of programs in the cache.
  std::size_t cached_programs() const;
  /// Of those, how many were built from a binary in program_cache_dir().
  std::size_t programs_from_disk() const;

  /// Allocates a buffer, checking the size against the device's max
  /// allocation first (ArgumentError naming `what`). While a ReuseScope is
  /// open, a request without a host pointer may get a buffer released in an
  /// earlier scope (of the same flags, bytes <= size <= 2 * bytes + 64 KiB,
  /// the smallest, preferring one last handed out for the same `what`;
  /// contents unspecified, as for a fresh buffer). With SIMDVOL_HUGE_PAGES=1
  /// on a Linux CPU device a fresh buffer of 4 MiB or more without a host
  /// pointer is made over host memory of the Device's own, 2 MiB-aligned and
  /// advised for transparent huge pages (its CL_MEM_FLAGS then show
  /// CL_MEM_USE_HOST_PTR; device.cpp has the trade-off).
  cl::Buffer buffer(cl_mem_flags flags, std::size_t bytes, void* host_ptr, const std::string& what);
  /// buffer() for scratch whose size changes from frame to frame (the
  /// matching's segments, footprints, swap levels, ...): when no pooled
  /// buffer fits, the fresh one is a quarter larger than asked (within the
  /// device's largest allocation), so that the next frames' slightly larger
  /// requests find it in the pool instead of touching new pages (on PoCL a
  /// fresh buffer is new host memory: a page fault per 4 KiB in the kernels);
  /// and a pooled buffer last handed out for the same `what` fits it up to
  /// 4 * bytes + 64 KiB (not only 2 * bytes + 64 KiB), so that the views of a
  /// turntable, whose requests drift by more than twice, keep theirs.
  cl::Buffer scratch_buffer(cl_mem_flags flags, std::size_t bytes, const std::string& what);

  /// Reuse of scratch buffers from frame to frame. A frame allocates tens of
  /// MB of buffers that live only for that frame; on PoCL each is fresh host
  /// memory, and touching it costs a page fault per 4 KiB inside the
  /// kernels (about 33,000 per 256^3 frame). While a thread has a scope
  /// open, buffer() called from that thread records what it hands out; when
  /// the thread's outermost scope closes it waits for the queue and keeps the
  /// buffers that nobody else holds any more (their reference count is 1:
  /// only the pool's), for the next scope. A kept buffer not handed out again
  /// in the next two scopes (set_reuse_keep) is released. Buffers still held
  /// by the caller (a RenderEngine's persistent cells, say) are never handed
  /// out twice; one held at the close and dropped since (PoCL keeps a
  /// finished command's references a moment after clFinish returns) is
  /// handed out once its reference count is 1. Scopes are per thread
  /// (RenderEngine::render opens one per frame): engines rendering on one
  /// Device from several threads free each other's released buffers at each
  /// of their frames' ends, so the pool stays bounded while their frames
  /// overlap. Close a scope on the thread that opened it.
  class ReuseScope {
   public:
    explicit ReuseScope(Device& device);
    ~ReuseScope();
    ReuseScope(const ReuseScope&) = delete;
    ReuseScope& operator=(const ReuseScope&) = delete;

   private:
    Device* device_;
    std::thread::id thread_;  ///< the thread that opened it
  };
  /// A buffer released in one scope can be handed out in the next `scopes`
  /// scopes (default 2); not handed out in those, it is released. A program
  /// that renders with k engines in turn on one device (the bench harness,
  /// which interleaves the frames of its cases) keeps them for k or more,
  /// or each engine's frame finds its buffers gone. ArgumentError if < 0.
  void set_reuse_keep(int scopes);
  /// Says that the caller's last command on `buffer` is enqueued and that
  /// neither it nor anything it gave the buffer to holds another handle to
  /// it: while the calling thread's ReuseScope is open, the pool may hand it
  /// out again to a later request of the same frame, or of another thread's
  /// frame on this Device (any request made with a scope open; the same rule
  /// as between scopes: flags, bytes <= size <= 2 * bytes + 64 KiB). The
  /// queue is one and in order, so the new owner's commands run after those
  /// enqueued on it so far; nothing waits. A frame's peak is then the
  /// buffers alive at once rather than every buffer it made. Resets
  /// `buffer`; a buffer the pool did not hand out (one over a host pointer,
  /// one made with no scope open) is only let go. The device's own queue
  /// only: a buffer used on another queue must not be released here.
  void release(cl::Buffer& buffer);
  /// Bytes of buffers the pool holds (handed out or free), for tests.
  std::size_t pooled_bytes() const;
  /// How many fresh buffers requests without a host pointer made while a
  /// ReuseScope was open (none fitting in the pool), for tests: a frame
  /// whose requests the pool met makes none.
  std::size_t pool_misses() const;
  /// One buffer of the pool: its size, the request it was last handed out
  /// for, and whether it is free to be handed out (for tests).
  struct PooledBuffer {
    std::size_t bytes = 0;
    std::string what;
    bool free = false;
  };
  /// The pool's buffers, in the order they were made (for tests).
  std::vector<PooledBuffer> pooled_buffers() const;
  /// Bytes of host memory that Devices allocated themselves for their
  /// buffers and that are not freed yet (with SIMDVOL_HUGE_PAGES=1, on Linux
  /// CPU devices, buffers of 4 MiB or more: over memory advised for
  /// transparent huge pages, freed with the buffer), for tests.
  static std::size_t own_host_bytes();
  /// Releases the pool's buffers that nobody else holds any more (kept for
  /// later scopes); returns how many. buffer() does so itself, and tries
  /// once more, where the device has no memory left for a request.
  std::size_t release_pooled();

  /// Enqueues a 1-D, 2-D or 3-D range; each global size is rounded up to a
  /// multiple of the local size. Returns the event (profiling info available
  /// when profiling()). `what` names the kernel in errors. The local size is
  /// checked against work_group_limits(kernel) first: with LocalSize::exact
  /// (the default) one that does not fit is an ArgumentError naming `what`,
  /// the size and the limits (not CL_INVALID_WORK_GROUP_SIZE from the
  /// queue); with LocalSize::at_most the launch takes fit_work_group(local)
  /// instead (and rounds the global size up to that).
  cl::Event run(const cl::Kernel& kernel, const std::string& what, const cl::NDRange& global,
                const cl::NDRange& local, LocalSize size = LocalSize::exact);
  /// clFinish on the queue.
  void finish();

  /// One kernel launch of run() while the launch log is on.
  struct Launch {
    std::string kernel;  ///< run()'s `what`
    cl::Event event;
  };
  /// Starts (clearing it) or stops the calling thread's log of its run()
  /// launches, for a timeline of the device's work (RenderEngine::render
  /// with `times`). Each thread has its own log: engines on several threads
  /// each see their own launches.
  void log_launches(bool on);
  /// The calling thread's launches logged since its log_launches(true), in
  /// launch order; the log is left empty (and on, if it was).
  std::vector<Launch> take_launches();

 private:
  void describe_self(int index, int platform_index, const std::string& platform);
  void read_fail_allocation();
  cl::Buffer allocate(cl_mem_flags flags, std::size_t bytes, std::size_t fresh_bytes,
                      void* host_ptr, const std::string& what, bool scratch);

  DeviceInfo info_;
  std::size_t wgs_ = 64;
  Defines wgs_defines_;
  cl::Context context_;
  cl::Device device_;
  cl::CommandQueue queue_;
  bool profiling_ = false;
  struct Cache {
    std::mutex mutex;
    std::map<std::pair<std::string, std::string>, cl::Program> programs;
    std::map<std::string, cl::Program> by_key;  // build_keyed: (key, options)
    std::size_t from_disk = 0;
  };
  std::unique_ptr<Cache> cache_;
  struct LaunchLogs;
  std::unique_ptr<LaunchLogs> logs_;
  struct Pool;
  static std::size_t release_unheld(Pool& pool);
  std::unique_ptr<Pool> pool_;
  // SIMDVOL_FAIL_ALLOCATION=WHAT[:N] (a test hook, read at construction):
  // the N-th request (default the first) for a buffer named WHAT fails as
  // if the device had no memory left for it.
  std::string fail_what_;
  int fail_at_ = 0;
  std::unique_ptr<std::atomic<int>> fail_count_;
};

/// Sets arguments `first`, `first` + 1, ... of `kernel`, throwing CLError
/// naming the kernel and the argument index if one fails.
template <typename... Args>
void set_args_from(cl::Kernel& kernel, const std::string& what, cl_uint first,
                   const Args&... args) {
  cl_uint index = first;
  auto one = [&](const auto& arg) {
    cl_int err = kernel.setArg(index, arg);
    if (err != CL_SUCCESS)
      throw CLError("clSetKernelArg(" + what + ", " + std::to_string(index) + ")", err);
    ++index;
  };
  (one(args), ...);
}

/// Sets every argument of `kernel` (set_args_from argument 0).
template <typename... Args>
void set_args(cl::Kernel& kernel, const std::string& what, const Args&... args) {
  set_args_from(kernel, what, 0, args...);
}

/// Duration of a profiled event in nanoseconds (end - start); 0 if the
/// information is not available.
std::uint64_t event_ns(const cl::Event& event);
/// Start and end of a profiled event on the device's clock (ns); (0, 0) if
/// the information is not available.
std::array<std::uint64_t, 2> event_span_ns(const cl::Event& event);

}  // namespace simdvol
