// The OpenCL device layer (see device.hpp).
#include "simdvol/device.hpp"

#include <unistd.h>
#ifdef __linux__
#include <sys/mman.h>
#endif

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <thread>

#include "../core/file_checks.hpp"
#include "../core/temp_files.hpp"
#include "env_switch.hpp"
#include "kernel_files.hpp"

namespace simdvol {

std::string_view cl_error_name(cl_int code) {
  switch (code) {
#define SIMDVOL_CL_CODE(c) \
  case c:                  \
    return #c;
    SIMDVOL_CL_CODE(CL_SUCCESS)
    SIMDVOL_CL_CODE(CL_DEVICE_NOT_FOUND)
    SIMDVOL_CL_CODE(CL_DEVICE_NOT_AVAILABLE)
    SIMDVOL_CL_CODE(CL_COMPILER_NOT_AVAILABLE)
    SIMDVOL_CL_CODE(CL_MEM_OBJECT_ALLOCATION_FAILURE)
    SIMDVOL_CL_CODE(CL_OUT_OF_RESOURCES)
    SIMDVOL_CL_CODE(CL_OUT_OF_HOST_MEMORY)
    SIMDVOL_CL_CODE(CL_PROFILING_INFO_NOT_AVAILABLE)
    SIMDVOL_CL_CODE(CL_MEM_COPY_OVERLAP)
    SIMDVOL_CL_CODE(CL_IMAGE_FORMAT_MISMATCH)
    SIMDVOL_CL_CODE(CL_IMAGE_FORMAT_NOT_SUPPORTED)
    SIMDVOL_CL_CODE(CL_BUILD_PROGRAM_FAILURE)
    SIMDVOL_CL_CODE(CL_MAP_FAILURE)
    SIMDVOL_CL_CODE(CL_MISALIGNED_SUB_BUFFER_OFFSET)
    SIMDVOL_CL_CODE(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST)
    SIMDVOL_CL_CODE(CL_COMPILE_PROGRAM_FAILURE)
    SIMDVOL_CL_CODE(CL_LINKER_NOT_AVAILABLE)
    SIMDVOL_CL_CODE(CL_LINK_PROGRAM_FAILURE)
    SIMDVOL_CL_CODE(CL_DEVICE_PARTITION_FAILED)
    SIMDVOL_CL_CODE(CL_KERNEL_ARG_INFO_NOT_AVAILABLE)
    SIMDVOL_CL_CODE(CL_INVALID_VALUE)
    SIMDVOL_CL_CODE(CL_INVALID_DEVICE_TYPE)
    SIMDVOL_CL_CODE(CL_INVALID_PLATFORM)
    SIMDVOL_CL_CODE(CL_INVALID_DEVICE)
    SIMDVOL_CL_CODE(CL_INVALID_CONTEXT)
    SIMDVOL_CL_CODE(CL_INVALID_QUEUE_PROPERTIES)
    SIMDVOL_CL_CODE(CL_INVALID_COMMAND_QUEUE)
    SIMDVOL_CL_CODE(CL_INVALID_HOST_PTR)
    SIMDVOL_CL_CODE(CL_INVALID_MEM_OBJECT)
    SIMDVOL_CL_CODE(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR)
    SIMDVOL_CL_CODE(CL_INVALID_IMAGE_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_SAMPLER)
    SIMDVOL_CL_CODE(CL_INVALID_BINARY)
    SIMDVOL_CL_CODE(CL_INVALID_BUILD_OPTIONS)
    SIMDVOL_CL_CODE(CL_INVALID_PROGRAM)
    SIMDVOL_CL_CODE(CL_INVALID_PROGRAM_EXECUTABLE)
    SIMDVOL_CL_CODE(CL_INVALID_KERNEL_NAME)
    SIMDVOL_CL_CODE(CL_INVALID_KERNEL_DEFINITION)
    SIMDVOL_CL_CODE(CL_INVALID_KERNEL)
    SIMDVOL_CL_CODE(CL_INVALID_ARG_INDEX)
    SIMDVOL_CL_CODE(CL_INVALID_ARG_VALUE)
    SIMDVOL_CL_CODE(CL_INVALID_ARG_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_KERNEL_ARGS)
    SIMDVOL_CL_CODE(CL_INVALID_WORK_DIMENSION)
    SIMDVOL_CL_CODE(CL_INVALID_WORK_GROUP_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_WORK_ITEM_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_GLOBAL_OFFSET)
    SIMDVOL_CL_CODE(CL_INVALID_EVENT_WAIT_LIST)
    SIMDVOL_CL_CODE(CL_INVALID_EVENT)
    SIMDVOL_CL_CODE(CL_INVALID_OPERATION)
    SIMDVOL_CL_CODE(CL_INVALID_GL_OBJECT)
    SIMDVOL_CL_CODE(CL_INVALID_BUFFER_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_MIP_LEVEL)
    SIMDVOL_CL_CODE(CL_INVALID_GLOBAL_WORK_SIZE)
    SIMDVOL_CL_CODE(CL_INVALID_PROPERTY)
    SIMDVOL_CL_CODE(CL_INVALID_IMAGE_DESCRIPTOR)
    SIMDVOL_CL_CODE(CL_INVALID_COMPILER_OPTIONS)
    SIMDVOL_CL_CODE(CL_INVALID_LINKER_OPTIONS)
    SIMDVOL_CL_CODE(CL_INVALID_DEVICE_PARTITION_COUNT)
#undef SIMDVOL_CL_CODE
    case -1001:
      return "CL_PLATFORM_NOT_FOUND_KHR";
    default:
      return "unknown OpenCL error";
  }
}

namespace {

std::string cl_error_message(const std::string& call, cl_int code, const std::string& detail) {
  std::string m =
      call + ": " + std::string(cl_error_name(code)) + " (" + std::to_string(code) + ")";
  if (!detail.empty()) m += ": " + detail;
  return m;
}

constexpr const char* kInstallHint =
    "no OpenCL platform found: install an OpenCL driver, e.g. the pocl-opencl-icd package "
    "(apt-get install pocl-opencl-icd) for the CPU";

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\0' || s.back() == ' ' || s.back() == '\n')) s.pop_back();
  return s;
}

template <cl_device_info Name, typename T>
T device_query(const cl::Device& d, const char* what) {
  T value{};
  cl_int err = d.getInfo(Name, &value);
  if (err != CL_SUCCESS) throw CLError(std::string("clGetDeviceInfo(") + what + ")", err);
  return value;
}

std::string type_name(cl_device_type t) {
  if (t & CL_DEVICE_TYPE_CPU) return "CPU";
  if (t & CL_DEVICE_TYPE_GPU) return "GPU";
  if (t & CL_DEVICE_TYPE_ACCELERATOR) return "accelerator";
  return "other";
}

DeviceInfo query_device(const cl::Device& d) {
  DeviceInfo info;
  info.name = trim(device_query<CL_DEVICE_NAME, std::string>(d, "CL_DEVICE_NAME"));
  info.vendor = trim(device_query<CL_DEVICE_VENDOR, std::string>(d, "CL_DEVICE_VENDOR"));
  info.version = trim(device_query<CL_DEVICE_VERSION, std::string>(d, "CL_DEVICE_VERSION"));
  info.driver_version = trim(device_query<CL_DRIVER_VERSION, std::string>(d, "CL_DRIVER_VERSION"));
  auto type = device_query<CL_DEVICE_TYPE, cl_device_type>(d, "CL_DEVICE_TYPE");
  info.type = type_name(type);
  info.is_cpu = (type & CL_DEVICE_TYPE_CPU) != 0;
  info.compute_units =
      device_query<CL_DEVICE_MAX_COMPUTE_UNITS, cl_uint>(d, "CL_DEVICE_MAX_COMPUTE_UNITS");
  info.local_mem_bytes =
      device_query<CL_DEVICE_LOCAL_MEM_SIZE, cl_ulong>(d, "CL_DEVICE_LOCAL_MEM_SIZE");
  info.global_mem_bytes =
      device_query<CL_DEVICE_GLOBAL_MEM_SIZE, cl_ulong>(d, "CL_DEVICE_GLOBAL_MEM_SIZE");
  info.max_alloc_bytes =
      device_query<CL_DEVICE_MAX_MEM_ALLOC_SIZE, cl_ulong>(d, "CL_DEVICE_MAX_MEM_ALLOC_SIZE");
  info.max_work_group_size =
      device_query<CL_DEVICE_MAX_WORK_GROUP_SIZE, std::size_t>(d, "CL_DEVICE_MAX_WORK_GROUP_SIZE");
  {  // (at least 3 entries: CL_DEVICE_MAX_WORK_ITEM_DIMENSIONS >= 3)
    const auto sizes = device_query<CL_DEVICE_MAX_WORK_ITEM_SIZES, cl::vector<cl::size_type>>(
        d, "CL_DEVICE_MAX_WORK_ITEM_SIZES");
    for (std::size_t i = 0; i < 3; ++i)
      info.max_work_item_sizes[i] = i < sizes.size() ? sizes[i] : 1;
  }
  info.base_addr_align_bytes =  // (the query answers in bits)
      device_query<CL_DEVICE_MEM_BASE_ADDR_ALIGN, cl_uint>(d, "CL_DEVICE_MEM_BASE_ADDR_ALIGN") / 8;
  return info;
}

// PoCL 3.1 reads these when the platforms are asked for, and stops the
// process on some values: POCL_CACHE_DIR set but empty fails an assertion
// (signal 6), POCL_MAX_PTHREAD_COUNT=-1 or 2147483647 is a segmentation
// fault. Refused first, naming the variable.
void check_pocl_environment() {
  if (const char* dir = std::getenv("POCL_CACHE_DIR"); dir && *dir == '\0')
    throw ArgumentError("POCL_CACHE_DIR",
                        "is set but empty (PoCL stops on it): unset it or name a directory");
  if (const char* n = std::getenv("POCL_MAX_PTHREAD_COUNT"); n && *n) {
    if (!detail::whole_number(n, 65536))
      throw ArgumentError("POCL_MAX_PTHREAD_COUNT",
                          std::string("\"") + n +
                              "\" is not a thread count 0 .. 65536 (PoCL stops on some such "
                              "values)");
  }
}

// Where PoCL keeps its cache, for the message when it finds no device (it
// finds none where it cannot make that directory).
std::string pocl_cache_place() {
  if (const char* d = std::getenv("POCL_CACHE_DIR"); d && *d)
    return std::string("POCL_CACHE_DIR=") + d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/pocl";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/pocl";
  return "$HOME/.cache/pocl, with HOME unset";
}

std::vector<cl::Platform> platforms_or_throw() {
  check_pocl_environment();
  std::vector<cl::Platform> platforms;
  cl_int err = cl::Platform::get(&platforms);
  // ocl-icd answers CL_PLATFORM_NOT_FOUND_KHR (-1001) when no ICD is installed.
  if (err == -1001 || (err == CL_SUCCESS && platforms.empty())) throw NoDeviceError(kInstallHint);
  if (err != CL_SUCCESS)
    throw NoDeviceError(cl_error_message("clGetPlatformIDs", err, kInstallHint));
  return platforms;
}

struct Found {
  cl::Device device;
  int platform_index;
  std::string platform;
};

std::vector<Found> all_devices() {
  std::vector<Found> out;
  auto platforms = platforms_or_throw();
  for (std::size_t p = 0; p < platforms.size(); ++p) {
    std::string pname;
    platforms[p].getInfo(CL_PLATFORM_NAME, &pname);
    std::vector<cl::Device> devices;
    cl_int err = platforms[p].getDevices(CL_DEVICE_TYPE_ALL, &devices);
    if (err == CL_DEVICE_NOT_FOUND) continue;
    cl_check(err, "clGetDeviceIDs");
    for (auto& d : devices) out.push_back({d, static_cast<int>(p), trim(pname)});
  }
  if (out.empty())
    throw NoDeviceError(
        "no OpenCL device found on any platform: install an OpenCL driver, e.g. "
        "the pocl-opencl-icd package (apt-get install pocl-opencl-icd); where it is "
        "installed, PoCL also finds no device when it cannot make its cache directory (" +
        pocl_cache_place() +
        "): make that a directory this user can write, or set "
        "POCL_CACHE_DIR to one");
  return out;
}

std::string mib(std::uint64_t bytes) {
  std::ostringstream s;
  s << (bytes >> 20) << " MiB";
  return s.str();
}

}  // namespace

CLError::CLError(const std::string& call, cl_int code, const std::string& detail)
    : Error(cl_error_message(call, code, detail)), call_(call), code_(code) {}

BuildError::BuildError(cl_int code, const std::string& options, const std::string& log)
    : CLError("clBuildProgram", code, "options \"" + options + "\", build log:\n" + log),
      options_(options),
      log_(log) {}

std::vector<DeviceInfo> list_devices() {
  std::vector<DeviceInfo> out;
  auto found = all_devices();
  for (std::size_t i = 0; i < found.size(); ++i) {
    DeviceInfo info = query_device(found[i].device);
    info.index = static_cast<int>(i);
    info.platform_index = found[i].platform_index;
    info.platform = found[i].platform;
    out.push_back(std::move(info));
  }
  return out;
}

std::string describe_devices(const std::vector<DeviceInfo>& devices, int chosen) {
  std::ostringstream s;
  for (const auto& d : devices) {
    s << (d.index == chosen ? "* " : "  ") << d.index << ": " << d.name << " [" << d.type << "]\n"
      << "     platform " << d.platform_index << ": " << d.platform << "\n"
      << "     vendor: " << d.vendor << "\n"
      << "     version: " << d.version << ", driver " << d.driver_version << "\n"
      << "     compute units: " << d.compute_units << ", max work-group size "
      << d.max_work_group_size << "\n"
      << "     work-items of a group along x, y, z at most: " << d.max_work_item_sizes[0] << " x "
      << d.max_work_item_sizes[1] << " x " << d.max_work_item_sizes[2] << "\n"
      << "     global memory: " << mib(d.global_mem_bytes) << ", max allocation "
      << mib(d.max_alloc_bytes) << ", local memory " << (d.local_mem_bytes >> 10) << " KiB\n";
  }
  return s.str();
}

int choose_device(const std::vector<DeviceInfo>& devices, std::optional<int> requested) {
  const int n = static_cast<int>(devices.size());
  auto check = [&](long i, const std::string& argument) {
    if (i < 0 || i >= n)
      throw ArgumentError(argument,
                          "no OpenCL device " + std::to_string(i) + " (there " +
                              (n == 1 ? "is 1 device" : "are " + std::to_string(n) + " devices") +
                              ", numbered from 0; see `simdvol devices`)");
    return static_cast<int>(i);
  };
  if (requested) return check(*requested, "--device");
  if (const char* env = std::getenv("SIMDVOL_DEVICE"); env && *env) {
    const std::optional<long> i = detail::whole_number(env, std::numeric_limits<int>::max());
    if (!i)
      throw ArgumentError("SIMDVOL_DEVICE", std::string("\"") + env +
                                                "\" is not a device index (see `simdvol devices`)");
    return check(*i, "SIMDVOL_DEVICE");
  }
  for (const auto& d : devices)
    if (d.is_cpu) return d.index;
  if (n == 0) throw NoDeviceError(kInstallHint);
  return 0;
}

std::string_view kernel_file(std::string_view name) {
  for (const auto& f : detail::embedded_kernel_files())
    if (f.name == name) return f.source;
  throw ArgumentError("kernel file", "no embedded kernel file \"" + std::string(name) + "\"");
}

namespace {
// The file of a stage named as program_source takes it; a file name given
// instead ("classify.cl") is said to be one.
std::string stage_file(std::string_view stage) {
  std::string file = std::string(stage) + ".cl";
  if (stage.size() > 3 && stage.substr(stage.size() - 3) == ".cl")
    throw ArgumentError("kernel file", "no embedded kernel file \"" + file +
                                           "\" (program_source takes the stage's name, \"" +
                                           std::string(stage.substr(0, stage.size() - 3)) +
                                           "\", without .cl)");
  return file;
}
}  // namespace

std::vector<std::string> kernel_files() {
  std::vector<std::string> names;
  for (const auto& f : detail::embedded_kernel_files()) names.emplace_back(f.name);
  return names;
}

namespace {
// Appends one file of a program: a #line directive naming it, its text, and a
// final newline if the text lacks one.
void append_part(std::string& s, std::string_view file, std::string_view text) {
  s += "#line 1 \"";
  s += file;
  s += "\"\n";
  s += text;
  if (!text.empty() && text.back() != '\n') s += '\n';
}
}  // namespace

std::string program_source(std::string_view stage, const Defines& defines) {
  const std::string file = stage_file(stage);
  std::string_view stage_text = kernel_file(file);  // throws first if missing
  std::string s;
  for (const auto& [name, value] : defines) s += "#define " + name + " " + value + "\n";
  append_part(s, "simdvol_shared.h", kernel_file("simdvol_shared.h"));
  if (stage != "common") append_part(s, "common.cl", kernel_file("common.cl"));
  append_part(s, file, stage_text);
  return s;
}

std::string program_source(std::string_view stage, const Defines& defines,
                           std::initializer_list<std::string_view> then) {
  std::string s = program_source(stage, defines);
  for (std::string_view next : then) {
    const std::string file = stage_file(next);
    append_part(s, file, kernel_file(file));
  }
  return s;
}

namespace {
// Stages the host builds as one program: PoCL spends 40-60 ms on each
// program build, its cache warm or not and whatever the program's size
// (these four took 65-69 ms as one source against 183-205 ms apart, warm),
// and a frame uses them all (balance.cl with balancing; it holds its
// kernels for both widths of the bounds, so no define of its own keeps it
// apart). swap.cl last: its FP_CONTRACT OFF pragma holds to the end of the
// program, and the others keep the default.
constexpr std::array<std::string_view, 4> kFrameGroup{"layout", "match", "balance", "swap"};
}  // namespace

std::string stage_program_source(std::string_view stage, const Defines& defines) {
  if (std::find(kFrameGroup.begin(), kFrameGroup.end(), stage) == kFrameGroup.end())
    return program_source(stage, defines);
  return program_source(kFrameGroup[0], defines, {kFrameGroup[1], kFrameGroup[2], kFrameGroup[3]});
}

std::string program_key(std::string_view kind, std::string_view stage, const Defines& defines,
                        std::initializer_list<std::string_view> then) {
  std::string key;
  auto part = [&](std::string_view t) {
    key += std::to_string(t.size());
    key += ':';
    key += t;
  };
  part(kind);
  part(stage);
  key += std::to_string(defines.size());
  key += 'd';
  for (const auto& [name, value] : defines) {
    part(name);
    part(value);
  }
  key += std::to_string(then.size());
  key += 't';
  for (std::string_view t : then) part(t);
  return key;
}

void check_allocation(std::uint64_t bytes, std::uint64_t max_alloc_bytes, const std::string& what,
                      const std::string& hint) {
  if (bytes == 0) throw ArgumentError(what, "buffer of 0 bytes");
  if (bytes > max_alloc_bytes)
    throw ArgumentError(what, "needs a buffer of " + std::to_string(bytes) +
                                  " bytes, more than the device's largest allocation of " +
                                  std::to_string(max_alloc_bytes) +
                                  " bytes (CL_DEVICE_MAX_MEM_ALLOC_SIZE)" +
                                  (hint.empty() ? std::string() : ": " + hint));
}

namespace {

// The entry of thread `id` in a vector of (thread, value) pairs, or end().
template <typename Pairs>
auto find_thread(Pairs& pairs, std::thread::id id) {
  return std::find_if(pairs.begin(), pairs.end(), [&](const auto& p) { return p.first == id; });
}

}  // namespace

// The launch logs of the threads that have one on (log_launches).
struct Device::LaunchLogs {
  std::mutex mutex;
  std::atomic<bool> any{false};  // some thread logs (run() takes the mutex only then)
  std::vector<std::pair<std::thread::id, std::vector<Launch>>> threads;
};

struct Device::Pool {
  struct Entry {
    cl::Buffer buffer;
    cl_mem_flags flags = 0;
    std::size_t bytes = 0;
    bool busy = false;  // handed out in the open scope, or still held by someone
    // Busy only because someone held it when the last scope closed: handed
    // out again once its reference count says only the pool holds it.
    bool held_at_close = false;
    int idle = 0;      // closed scopes since it was last handed out
    std::string what;  // the request it was last handed out for
  };
  std::mutex mutex;
  // Open scopes per thread (one entry per thread with a scope open): each
  // thread's frames open and close their own, and a thread's outermost close
  // frees what has been released while other threads' frames go on.
  std::vector<std::pair<std::thread::id, int>> depths;
  int keep = 2;  // closed scopes a released buffer waits to be handed out again
  std::vector<Entry> entries;
  std::size_t misses = 0;  // fresh buffers made for requests with a scope open

  // The open scopes of thread `id` (0 when none).
  int depth(std::thread::id id) const {
    const auto it = find_thread(depths, id);
    return it == depths.end() ? 0 : it->second;
  }
};

// Releases the pool's buffers that only the pool holds (reference count 1;
// the implementation keeps a released buffer alive for the commands still
// using it). Returns how many. The pool's mutex must be held.
std::size_t Device::release_unheld(Pool& pool) {
  const std::size_t before = pool.entries.size();
  std::vector<Pool::Entry> kept;
  for (Pool::Entry& e : pool.entries) {
    cl_uint refs = 0;
    if (e.buffer.getInfo(CL_MEM_REFERENCE_COUNT, &refs) == CL_SUCCESS && refs <= 1) continue;
    kept.push_back(std::move(e));
  }
  pool.entries = std::move(kept);
  return before - pool.entries.size();
}

bool is_allocation_failure(cl_int code) {
  return code == CL_OUT_OF_HOST_MEMORY || code == CL_MEM_OBJECT_ALLOCATION_FAILURE ||
         code == CL_OUT_OF_RESOURCES;
}

std::size_t Device::release_pooled() {
  if (!pool_) return 0;
  std::lock_guard<std::mutex> lock(pool_->mutex);
  return release_unheld(*pool_);
}

Device::Device(std::optional<int> index)
    : cache_(std::make_unique<Cache>()),
      logs_(std::make_unique<LaunchLogs>()),
      pool_(std::make_unique<Pool>()) {
  auto found = all_devices();
  std::vector<DeviceInfo> infos;
  for (std::size_t i = 0; i < found.size(); ++i) {
    DeviceInfo info = query_device(found[i].device);
    info.index = static_cast<int>(i);
    infos.push_back(std::move(info));
  }
  int chosen = choose_device(infos, index);
  device_ = found[chosen].device;
  cl_int err = CL_SUCCESS;
  context_ = cl::Context(device_, nullptr, nullptr, nullptr, &err);
  cl_check(err, "clCreateContext");
  queue_ = cl::CommandQueue(context_, device_, CL_QUEUE_PROFILING_ENABLE, &err);
  cl_check(err, "clCreateCommandQueue");
  profiling_ = true;
  describe_self(chosen, found[chosen].platform_index, found[chosen].platform);
  read_fail_allocation();
}

Device::Device(cl_context context, cl_command_queue queue)
    : cache_(std::make_unique<Cache>()),
      logs_(std::make_unique<LaunchLogs>()),
      pool_(std::make_unique<Pool>()) {
  if (!context || !queue) throw ArgumentError("Device", "null cl_context or cl_command_queue");
  context_ = cl::Context(context, /*retainObject=*/true);
  queue_ = cl::CommandQueue(queue, /*retainObject=*/true);
  cl_device_id id = nullptr;
  cl_check(clGetCommandQueueInfo(queue, CL_QUEUE_DEVICE, sizeof(id), &id, nullptr),
           "clGetCommandQueueInfo(CL_QUEUE_DEVICE)");
  device_ = cl::Device(id, /*retainObject=*/true);
  cl_context queue_context = nullptr;
  cl_check(clGetCommandQueueInfo(queue, CL_QUEUE_CONTEXT, sizeof(queue_context), &queue_context,
                                 nullptr),
           "clGetCommandQueueInfo(CL_QUEUE_CONTEXT)");
  if (queue_context != context)
    throw ArgumentError("Device",
                        "the cl_command_queue belongs to another cl_context than the one "
                        "given (buffers and programs are made in the given context)");
  cl_command_queue_properties props = 0;
  cl_check(clGetCommandQueueInfo(queue, CL_QUEUE_PROPERTIES, sizeof(props), &props, nullptr),
           "clGetCommandQueueInfo(CL_QUEUE_PROPERTIES)");
  // The stages enqueued one after another depend on each other through the
  // queue's order, not through events: out of order, they read what the
  // stage before has not written yet (on PoCL the matching then faulted).
  if ((props & CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE) != 0)
    throw ArgumentError("Device",
                        "the cl_command_queue executes out of order "
                        "(CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE); simdvol's stages "
                        "depend on the queue's order: give an in-order queue");
  profiling_ = (props & CL_QUEUE_PROFILING_ENABLE) != 0;
  cl_platform_id platform = nullptr;
  cl_check(clGetDeviceInfo(id, CL_DEVICE_PLATFORM, sizeof(platform), &platform, nullptr),
           "clGetDeviceInfo(CL_DEVICE_PLATFORM)");
  std::string pname;
  cl::Platform(platform, false).getInfo(CL_PLATFORM_NAME, &pname);
  describe_self(-1, -1, trim(pname));
  read_fail_allocation();
}

void Device::read_fail_allocation() {
  fail_count_ = std::make_unique<std::atomic<int>>(0);
  const char* env = std::getenv("SIMDVOL_FAIL_ALLOCATION");
  if (!env || !*env) return;
  std::string spec = env;
  int at = 1;
  if (const std::size_t colon = spec.rfind(':'); colon != std::string::npos) {
    at = static_cast<int>(detail::whole_number(spec.substr(colon + 1), 999999).value_or(0));
    if (at < 1)
      throw ArgumentError("SIMDVOL_FAIL_ALLOCATION",
                          "'" + spec + "' is not WHAT or WHAT:N with N a positive integer");
    spec.resize(colon);
  }
  if (spec.empty())
    throw ArgumentError("SIMDVOL_FAIL_ALLOCATION", "names no buffer ('" + std::string(env) + "')");
  fail_what_ = spec;
  fail_at_ = at;
}

Device::Device(Device&&) noexcept = default;
Device& Device::operator=(Device&&) noexcept = default;
Device::~Device() = default;

void Device::describe_self(int index, int platform_index, const std::string& platform) {
  info_ = query_device(device_);
  info_.index = index;
  info_.platform_index = platform_index;
  info_.platform = platform;
  wgs_ = fixed_group_size(info_);
  wgs_defines_ = {{"WGS", std::to_string(wgs_)}};
}

// ------------------------------------------------------- work-group sizes

bool work_group_fits(const std::array<std::size_t, 3>& local, unsigned dims,
                     const WorkGroupLimits& limits) {
  std::size_t product = 1;
  for (unsigned d = 0; d < dims && d < 3; ++d) {
    if (local[d] < 1 || local[d] > limits.per_dimension[d]) return false;
    product *= local[d];
  }
  return product <= limits.total();
}

std::array<std::size_t, 3> fit_work_group(std::array<std::size_t, 3> wanted, unsigned dims,
                                          const WorkGroupLimits& limits) {
  dims = std::clamp(dims, 1u, 3u);
  for (unsigned d = dims; d < 3; ++d) wanted[d] = 1;
  if (work_group_fits(wanted, dims, limits)) return wanted;
  auto halve = [](std::size_t& n) { n = (n + 1) / 2; };
  for (unsigned d = 0; d < dims; ++d) {
    wanted[d] = std::max<std::size_t>(wanted[d], 1);
    while (wanted[d] > 1 && wanted[d] > limits.per_dimension[d]) halve(wanted[d]);
  }
  auto product = [&] { return wanted[0] * wanted[1] * wanted[2]; };
  for (unsigned d = dims; d-- > 0;)
    while (wanted[d] > 1 && product() > limits.total()) halve(wanted[d]);
  return wanted;
}

std::size_t largest_pow2_group(std::size_t most, const WorkGroupLimits& limits) {
  const std::size_t cap =
      std::min({std::max<std::size_t>(most, 1), limits.per_dimension[0], limits.total()});
  std::size_t p = 1;
  while (p <= cap / 2) p <<= 1;
  return p;
}

std::string describe_work_group_limits(const WorkGroupLimits& limits) {
  const auto& s = limits.per_dimension;
  return "CL_DEVICE_MAX_WORK_GROUP_SIZE " + std::to_string(limits.device_total) +
         ", CL_DEVICE_MAX_WORK_ITEM_SIZES " + std::to_string(s[0]) + " x " + std::to_string(s[1]) +
         " x " + std::to_string(s[2]) + ", the kernel's CL_KERNEL_WORK_GROUP_SIZE " +
         std::to_string(limits.kernel_total);
}

namespace {

// The device's own limits; the kernel's total taken as the device's until
// a kernel is asked (Device::work_group_limits).
WorkGroupLimits device_limits(const DeviceInfo& info) {
  WorkGroupLimits limits;
  limits.per_dimension = info.max_work_item_sizes;
  limits.device_total = limits.kernel_total = info.max_work_group_size;
  return limits;
}

// A cl::NDRange of the first `dims` (1 .. 3) entries of `n`.
cl::NDRange nd_range(const std::size_t* n, cl_uint dims) {
  return dims == 1   ? cl::NDRange(n[0])
         : dims == 2 ? cl::NDRange(n[0], n[1])
                     : cl::NDRange(n[0], n[1], n[2]);
}

}  // namespace

std::size_t fixed_group_size(const DeviceInfo& info) {
  return largest_pow2_group(64, device_limits(info));
}

WorkGroupLimits Device::work_group_limits(const cl::Kernel& kernel, const std::string& what) const {
  WorkGroupLimits limits = device_limits(info_);
  std::size_t kernel_total = 0;
  const cl_int err = clGetKernelWorkGroupInfo(kernel(), device_(), CL_KERNEL_WORK_GROUP_SIZE,
                                              sizeof kernel_total, &kernel_total, nullptr);
  if (err != CL_SUCCESS)
    throw CLError("clGetKernelWorkGroupInfo(" + what + ", CL_KERNEL_WORK_GROUP_SIZE)", err);
  limits.kernel_total = kernel_total;
  return limits;
}

std::string Device::build_options(const std::string& options) {
  std::string all = options;
  if (const char* env = std::getenv("SIMDVOL_CL_OPTIONS"); env && *env) {
    if (!all.empty()) all += ' ';
    all += env;
  }
  return all;
}

// ------------------------------------------------ program binaries on disk
// PoCL's clBuildProgram from source runs clang's preprocessor over the
// source and OpenCL's builtin declarations every time, even when its own
// cache (POCL_CACHE_DIR) holds the compiled program: 45-75 ms per program,
// six programs in a direct frame, most of a one-shot `simdvol render`. From
// the binary that CL_PROGRAM_BINARIES returned, the same build takes 2-10
// ms. With SIMDVOL_CACHE_DIR set, build() keeps each program's binary in a
// file named by a 64-bit hash of (the device's platform, name, version and
// driver version, the options, the source), with a second, independent
// 64-bit hash inside to check and a hash of the binary's bytes; a file that
// is missing, short, of another hash, whose bytes changed, or that the
// device will not build is ignored and written again from a source build.
// (The bytes' hash is what keeps a damaged file from the device: PoCL 3.1
// parses a binary it is given without checking it, and aborted the process
// on one whose bytes had been changed: pocl_binary.c, `len > 0'.) Off by
// default: asking PoCL for a binary compiles every kernel of the program
// (not only those launched), about 0.7-4 s per program the first time.

namespace {

namespace fs = std::filesystem;

// File: magic, check hash, size of the binary, FNV-1a of the binary's bytes,
// the binary (the first version had no bytes' hash).
constexpr char kBinaryMagic[8] = {'S', 'V', 'C', 'L', 'B', 'I', 'N', '2'};
constexpr std::size_t kBinaryHeader = 32;
constexpr std::uint64_t kFnvOffset = 0xcbf29ce484222325ull;  // FNV-1a's offset basis

std::uint64_t fnv1a(std::string_view s, std::uint64_t h) {
  for (unsigned char c : s) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

void put_u64(std::string& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out += static_cast<char>((v >> (8 * i)) & 0xff);
}
std::uint64_t get_u64(const char* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v |= static_cast<std::uint64_t>(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}

// The binary stored for `check`, or empty.
std::vector<unsigned char> load_binary(const fs::path& file, std::uint64_t check) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return {};
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.size() < kBinaryHeader || data.compare(0, 8, kBinaryMagic, 8) != 0 ||
      get_u64(data.data() + 8) != check ||
      get_u64(data.data() + 16) != data.size() - kBinaryHeader ||
      get_u64(data.data() + 24) != fnv1a(std::string_view(data).substr(kBinaryHeader), kFnvOffset))
    return {};
  return std::vector<unsigned char>(data.begin() + kBinaryHeader, data.end());
}

// Writes atomically (a temporary file renamed into place); any failure only
// leaves the program uncached.
void store_binary(const fs::path& file, std::uint64_t check,
                  const std::vector<unsigned char>& bin) {
  std::error_code ec;
  fs::create_directories(file.parent_path(), ec);
  if (ec) return;
  std::string data(kBinaryMagic, 8);
  put_u64(data, check);
  put_u64(data, bin.size());
  put_u64(data, fnv1a(std::string_view(reinterpret_cast<const char*>(bin.data()), bin.size()),
                      kFnvOffset));
  data.append(bin.begin(), bin.end());
  try {
    TempFile tmp(file, file);
    if (!write_fully(tmp.fd(), data.data(), data.size())) tmp.fail("write failed");
    tmp.commit();
  } catch (const FileError&) {
  }
}

}  // namespace

std::optional<std::filesystem::path> program_cache_dir() {
  const char* env = std::getenv("SIMDVOL_CACHE_DIR");
  if (!env || !*env || std::string_view(env) == "off") return std::nullopt;
  return fs::path(env);
}

std::optional<std::string> program_cache_problem() {
  const std::optional<fs::path> dir = program_cache_dir();
  if (!dir) return std::nullopt;
  const std::string what = "SIMDVOL_CACHE_DIR=" + dir->string();
  const std::string then = ": programs are built from source every run, not kept";
  std::error_code ec;
  const fs::file_status st = fs::status(*dir, ec);
  if (fs::exists(st)) {
    if (!fs::is_directory(st)) return what + " is not a directory" + then;
  } else if (fs::create_directories(*dir, ec); ec) {
    return what + " cannot be made (" + ec.message() + ")" + then;
  }
  if (::access(dir->c_str(), W_OK | X_OK) != 0)
    return what + " cannot be written (" + std::strerror(errno) + ")" + then;
  return std::nullopt;
}

cl::Program Device::build(const std::string& source, const std::string& options) {
  const std::string opts = build_options(options);
  std::lock_guard<std::mutex> lock(cache_->mutex);
  auto key = std::make_pair(source, opts);
  if (auto it = cache_->programs.find(key); it != cache_->programs.end()) return it->second;
  const std::vector<cl::Device> devices{device_};
  // The on-disk binary, if there is one this device builds.
  const std::optional<fs::path> dir = program_cache_dir();
  std::uint64_t check = 0;
  fs::path file;
  if (dir) {
    std::string id;
    for (const std::string_view part :
         {std::string_view(info_.platform), std::string_view(info_.name),
          std::string_view(info_.version), std::string_view(info_.driver_version),
          std::string_view(opts), std::string_view(source)}) {
      id += part;
      id += '\0';
    }
    check = fnv1a(id, 0x9e3779b97f4a7c15ull);
    char name[32];
    std::snprintf(name, sizeof name, "%016llx.bin",
                  static_cast<unsigned long long>(fnv1a(id, kFnvOffset)));
    file = *dir / name;
    const std::vector<unsigned char> bin = load_binary(file, check);
    if (!bin.empty()) {
      cl_int err = CL_SUCCESS;
      std::vector<cl_int> status;
      cl::Program program(context_, devices, cl::Program::Binaries{bin}, &status, &err);
      if (err == CL_SUCCESS && program.build(devices, opts.c_str()) == CL_SUCCESS) {
        ++cache_->from_disk;
        cache_->programs.emplace(std::move(key), program);
        return program;
      }
    }
  }
  cl_int err = CL_SUCCESS;
  cl::Program program(context_, source, /*build=*/false, &err);
  cl_check(err, "clCreateProgramWithSource");
  err = program.build(devices, opts.c_str());
  if (err != CL_SUCCESS) {
    std::string log;
    program.getBuildInfo(device_, CL_PROGRAM_BUILD_LOG, &log);
    log = trim(log);
    // A log of many errors (a bad -D in SIMDVOL_CL_OPTIONS repeated made one
    // of 5.7 MB): its head, which names the first errors.
    constexpr std::size_t kLogHead = 8192;
    if (log.size() > kLogHead)
      log = log.substr(0, kLogHead) + "\n[... " + std::to_string(log.size() - kLogHead) +
            " more bytes of build log]";
    // Say where options came from the environment; and PoCL's failure to
    // write its cache shows as a build failure without a compiler message.
    if (const char* env = std::getenv("SIMDVOL_CL_OPTIONS"); env && *env)
      log += "\n(the options include SIMDVOL_CL_OPTIONS from the environment)";
    if (const std::optional<unsigned long long> limit = file_size_limit();
        err == CL_BUILD_PROGRAM_FAILURE && log.find("error") == std::string::npos)
      log +=
          "\n(no compiler error in the log: PoCL fails so where it cannot write its cache "
          "directory, " +
          pocl_cache_place() +
          (limit ? ", or where the file-size limit (ulimit -f, " + std::to_string(*limit) +
                       " bytes) cuts its files short"
                 : std::string()) +
          "; POCL_DEBUG=all shows more)";
    throw BuildError(err, opts, log);
  }
  if (dir) {
    std::vector<std::vector<unsigned char>> bins;
    if (program.getInfo(CL_PROGRAM_BINARIES, &bins) == CL_SUCCESS && bins.size() == 1 &&
        !bins[0].empty())
      store_binary(file, check, bins[0]);
  }
  cache_->programs.emplace(std::move(key), program);
  return program;
}

std::size_t Device::programs_from_disk() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return cache_->from_disk;
}

cl::Program Device::build_keyed(const std::string& key, const std::function<std::string()>& source,
                                const std::string& options) {
  std::string k = key;
  k += '\0';
  k += build_options(options);  // SIMDVOL_CL_OPTIONS may change between calls
  {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    if (auto it = cache_->by_key.find(k); it != cache_->by_key.end()) return it->second;
  }
  cl::Program program = build(source(), options);
  std::lock_guard<std::mutex> lock(cache_->mutex);
  cache_->by_key.emplace(std::move(k), program);
  return program;
}

cl::Program Device::program(std::string_view stage, const Defines& defines,
                            const std::string& options) {
  return build_keyed(
      program_key("stage", stage, defines), [&] { return stage_program_source(stage, defines); },
      options);
}

cl::Kernel Device::kernel(std::string_view stage, const std::string& name, const Defines& defines,
                          const std::string& options) {
  cl::Program p = program(stage, defines, options);
  cl_int err = CL_SUCCESS;
  cl::Kernel k(p, name.c_str(), &err);
  if (err != CL_SUCCESS) throw CLError("clCreateKernel(" + name + ")", err);
  return k;
}

std::size_t Device::cached_programs() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return cache_->programs.size();
}

cl::Buffer Device::buffer(cl_mem_flags flags, std::size_t bytes, void* host_ptr,
                          const std::string& what) {
  return allocate(flags, bytes, bytes, host_ptr, what, false);
}

cl::Buffer Device::scratch_buffer(cl_mem_flags flags, std::size_t bytes, const std::string& what) {
  // A quarter more, rounded up to 64 KiB, within the device's largest
  // allocation (never less than asked).
  constexpr std::size_t kGrain = 65536;
  std::size_t room = bytes;
  if (bytes <= info_.max_alloc_bytes && bytes <= SIZE_MAX / 4) {
    room = (bytes + bytes / 4 + kGrain - 1) / kGrain * kGrain;
    room = std::max(bytes,
                    static_cast<std::size_t>(std::min<std::uint64_t>(room, info_.max_alloc_bytes)));
  }
  return allocate(flags, bytes, room, nullptr, what, true);
}

namespace {

// Large host buffers on transparent huge pages, with SIMDVOL_HUGE_PAGES=1
// (Linux, where the kernel's setting is "madvise", Debian's default, or
// "always"): the frame's kernels walk hundreds of MB (the 256^3 phantom's
// RGBA cells are 268 MB, the kept classification and the value cells 100 MB
// or more), and with 4 KiB pages most of their cache misses also miss the
// TLB. The buffer is then made over memory of our own (CL_MEM_USE_HOST_PTR:
// PoCL's CPU devices take it as the buffer's storage, no copy), 2
// MiB-aligned and advised MADV_HUGEPAGE before any page is touched, and
// freed by the buffer's destructor callback. Not for a GPU (info.is_cpu
// false), not below kHugeMin.
// Off by default: on the 2-core Intel Xeon (family 6, model 167; a
// Firecracker VM with virtio-balloon, 2026-12-05, ninth session) each fresh
// 2 MiB page took about 1.4 ms to fault in (the host's faults, invisible to
// the guest's counters: no compaction stall), so the frames that touch new
// buffers lost more than the later ones gained. The phantom's first frame
// (`simdvol render --view 20,35,10 --times`, 3 s apart) 221-227 ms against
// 561-752 with huge pages; a 36-frame turntable (`--frames 36 --step 5`,
// whose scratch buffers grow with the views) 2.21 / 2.24 s against 3.09 /
// 3.13 s. The frames after: scripts/bench-ab with it as B, the frame's
// wall, the 256^3 phantom 48.29 -> 46.08 ms (0.976, 6 pairs), at 512^2
// 0.955, ch2 0.924, brainsmall 0.966 (4 pairs); in one process, two runs
// each: shade + classify 8.22 / 8.82 -> 7.76 / 7.81 ms, resample + local
// 26.08 / 27.09 -> 25.30 / 25.45.
constexpr std::size_t kHugePage = std::size_t(2) << 20;
constexpr std::size_t kHugeMin = std::size_t(4) << 20;

bool huge_pages_wanted() {  // (read at each fresh large buffer: a few a render)
  return detail::env_switch("SIMDVOL_HUGE_PAGES").value_or(false);
}

// Device::own_host_bytes: the memory huge_alloc handed out, not yet freed.
std::atomic<std::size_t> g_own_host_bytes{0};

// A block huge_alloc hands out: the memory and its size.
struct OwnBlock {
  void* base;
  std::size_t bytes;
};

// Memory for a buffer of `bytes` on huge pages, or nullptr (not Linux, or
// no memory: the caller takes the device's own allocation). Freed by
// free_host_memory, the buffer's destructor callback.
OwnBlock* huge_alloc(std::size_t bytes) {
#ifdef __linux__
  const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* p = nullptr;
  if (posix_memalign(&p, kHugePage, rounded) != 0) return nullptr;
  madvise(p, rounded, MADV_HUGEPAGE);  // a hint: pages of 4 KiB where refused
  g_own_host_bytes += rounded;
  return new OwnBlock{p, rounded};
#else
  (void)bytes;
  return nullptr;
#endif
}

void CL_CALLBACK free_host_memory(cl_mem, void* block) {
  auto* b = static_cast<OwnBlock*>(block);
  std::free(b->base);
  g_own_host_bytes -= b->bytes;
  delete b;
}

}  // namespace

std::size_t Device::own_host_bytes() {
  return g_own_host_bytes.load();
}

cl::Buffer Device::allocate(cl_mem_flags flags, std::size_t bytes, std::size_t fresh_bytes,
                            void* host_ptr, const std::string& what, bool scratch) {
  check_allocation(bytes, info_.max_alloc_bytes, what);
  if (fail_at_ > 0 && what == fail_what_ && fail_count_ && ++*fail_count_ == fail_at_)
    throw CLError("clCreateBuffer(" + what + ", " + std::to_string(bytes) + " bytes)",
                  CL_MEM_OBJECT_ALLOCATION_FAILURE, "injected by SIMDVOL_FAIL_ALLOCATION");
  // On a CPU device a buffer is host memory; PoCL (3.1) allocates it only
  // when a command first uses it, and where the host has no memory left
  // then it aborts the process inside the queue (an assertion in
  // pocl_create_migration_commands) instead of reporting an error. Asked
  // for host memory (CL_MEM_ALLOC_HOST_PTR), it allocates at once and
  // clCreateBuffer reports the failure: a CLError naming `what`, which the
  // caller can catch (the kept classification does) or report. The same
  // host memory either way; a GPU keeps its device memory.
  if (info_.is_cpu && host_ptr == nullptr && (flags & CL_MEM_USE_HOST_PTR) == 0)
    flags |= CL_MEM_ALLOC_HOST_PTR;
  const bool pooled = pool_ && host_ptr == nullptr && bytes > 0;
  std::unique_lock<std::mutex> lock;
  if (pooled) {
    lock = std::unique_lock<std::mutex>(pool_->mutex);
    if (pool_->depth(std::this_thread::get_id()) > 0) {
      // The smallest that fits, preferring one last handed out for the same
      // `what`: a frame's requests keep their buffers from frame to frame
      // as their sizes drift, instead of taking each other's.
      // A scratch request takes its own buffer (last handed out for the
      // same `what`) up to four times its size: the turntable's views ask
      // for the matching's segments in sizes that differ by more than the
      // rule's two (the 256^3 phantom at 256^2: 31.1 to 50.1 MB over a
      // half turn, made 1.25 times that), so each half turn dropped the
      // largest and made three fresh ones (about 1 MB of new pages a frame
      // in the matching's kernels; PERFORMANCE.md, "page faults in a frame").
      const std::size_t most = 2 * bytes + 65536, own_most = 4 * bytes + 65536;
      Pool::Entry* best = nullptr;
      for (Pool::Entry& e : pool_->entries) {
        if (e.flags != flags || e.bytes < bytes) continue;
        if (e.bytes > (scratch && e.what == what ? own_most : most)) continue;
        if (e.busy) {
          // Held at the last close, perhaps only by the implementation:
          // PoCL drops a finished command's references to its buffers a
          // moment after clFinish returns, so on a loaded machine the
          // frame's last buffers (the footprints, a swap level) could read
          // as held and the next frame made them afresh (25.8 MB of new
          // pages at 192^2). Dropped since, it is the pool's alone: nobody
          // can enqueue on it, and the one in-order queue runs whatever
          // was enqueued before the next user's commands.
          cl_uint refs = 0;
          if (!e.held_at_close || e.buffer.getInfo(CL_MEM_REFERENCE_COUNT, &refs) != CL_SUCCESS ||
              refs > 1)
            continue;
          e.busy = e.held_at_close = false;
        }
        if (!best) {
          best = &e;
          continue;
        }
        const bool same = e.what == what, best_same = best->what == what;
        if (same != best_same ? same : e.bytes < best->bytes) best = &e;
      }
      if (best) {
        best->busy = true;
        best->held_at_close = false;
        best->idle = 0;
        best->what = what;
        return best->buffer;
      }
    }
  }
  cl_int err = CL_SUCCESS;
  cl::Buffer b;
  if (info_.is_cpu && host_ptr == nullptr && fresh_bytes >= kHugeMin && huge_pages_wanted()) {
    // (flags keeps CL_MEM_ALLOC_HOST_PTR for the pool's matching)
    if (OwnBlock* block = huge_alloc(fresh_bytes)) {
      const cl_mem_flags uf = (flags & ~cl_mem_flags(CL_MEM_ALLOC_HOST_PTR)) | CL_MEM_USE_HOST_PTR;
      b = cl::Buffer(context_, uf, fresh_bytes, block->base, &err);
      if (err == CL_SUCCESS &&
          clSetMemObjectDestructorCallback(b(), free_host_memory, block) != CL_SUCCESS)
        err = CL_OUT_OF_RESOURCES;
      if (err != CL_SUCCESS) {
        b = cl::Buffer();  // released (nothing uses it yet): the block is free to go
        free_host_memory(nullptr, block);
      }
    }
  }
  if (!b()) {
    err = CL_SUCCESS;
    b = cl::Buffer(context_, flags, fresh_bytes, host_ptr, &err);
    if (err != CL_SUCCESS && fresh_bytes != bytes)  // no room for the headroom: exactly as asked
      b = cl::Buffer(context_, flags, fresh_bytes = bytes, host_ptr, &err);
  }
  if (is_allocation_failure(err) && pool_) {
    // The pool's buffers that nobody holds any more (kept for later
    // frames) released, then once more.
    if (!lock.owns_lock()) lock = std::unique_lock<std::mutex>(pool_->mutex);
    if (release_unheld(*pool_) > 0) b = cl::Buffer(context_, flags, bytes, host_ptr, &err);
  }
  if (err != CL_SUCCESS)
    throw CLError("clCreateBuffer(" + what + ", " + std::to_string(bytes) + " bytes)", err,
                  is_allocation_failure(err) ? "the device (for a CPU device, the host) has no "
                                               "memory left for it"
                                             : "");
  if (pooled && pool_->depth(std::this_thread::get_id()) > 0) {
    pool_->entries.push_back({b, flags, fresh_bytes, true, false, 0, what});
    ++pool_->misses;
  }
  return b;
}

Device::ReuseScope::ReuseScope(Device& device)
    : device_(&device), thread_(std::this_thread::get_id()) {
  if (!device_->pool_) throw ArgumentError("device", "was moved from");
  std::lock_guard<std::mutex> lock(device_->pool_->mutex);
  auto& depths = device_->pool_->depths;
  const auto it = find_thread(depths, thread_);
  if (it == depths.end())
    depths.emplace_back(thread_, 1);
  else
    ++it->second;
}

Device::ReuseScope::~ReuseScope() {
  Pool& pool = *device_->pool_;
  std::lock_guard<std::mutex> lock(pool.mutex);
  const auto it = find_thread(pool.depths, thread_);
  if (it == pool.depths.end() || --it->second > 0) return;
  pool.depths.erase(it);
  // This thread's outermost scope. Whatever nobody but the pool holds any
  // more (its reference count is 1) can take no new commands, so once the
  // queue has finished the commands enqueued so far, it is free to be handed
  // out again. Where no other thread has a scope open, the counts are read
  // after the wait, as ever (a conforming implementation keeps a buffer
  // alive for its pending commands, but need not show that in the count;
  // PoCL's may). Where another thread's frame goes on, they are read before
  // it: a buffer that frame releases during the wait may have had a command
  // enqueued after the wait began, and it waits for the next close. So each
  // thread's frames free buffers while the others' go on, instead of the
  // pool growing until no scope is open anywhere.
  std::vector<char> unheld;  // per entry: 0 held, 1 only the pool's, 2 unknown (drop it)
  auto read_counts = [&] {
    unheld.assign(pool.entries.size(), 0);
    for (std::size_t i = 0; i < pool.entries.size(); ++i) {
      cl_uint refs = 0;
      unheld[i] = pool.entries[i].buffer.getInfo(CL_MEM_REFERENCE_COUNT, &refs) != CL_SUCCESS
                      ? 2
                      : refs <= 1;
    }
  };
  const bool alone = pool.depths.empty();
  if (!alone) read_counts();
  if (device_->queue_.finish() != CL_SUCCESS) {
    pool.entries.clear();  // unknown state: keep nothing
    return;
  }
  if (alone) read_counts();
  std::vector<Pool::Entry> kept;
  for (std::size_t i = 0; i < pool.entries.size(); ++i) {
    Pool::Entry& e = pool.entries[i];
    if (unheld[i] == 2) continue;
    if (unheld[i]) {
      e.busy = e.held_at_close = false;
      if (++e.idle > pool.keep) continue;  // not used lately: release it
    } else {
      e.busy = e.held_at_close = true;  // (released in the frame, yet someone holds it still)
    }
    kept.push_back(std::move(e));
  }
  pool.entries = std::move(kept);
}

void Device::set_reuse_keep(int scopes) {
  if (scopes < 0) throw ArgumentError("scopes", "must not be negative");
  if (!pool_) throw ArgumentError("device", "was moved from");
  std::lock_guard<std::mutex> lock(pool_->mutex);
  pool_->keep = scopes;
}

void Device::release(cl::Buffer& buffer) {
  if (pool_ && buffer()) {
    std::lock_guard<std::mutex> lock(pool_->mutex);
    if (pool_->depth(std::this_thread::get_id()) > 0) {
      for (Pool::Entry& e : pool_->entries) {
        if (e.buffer() != buffer()) continue;
        e.busy = e.held_at_close = false;  // (idle stays 0: handed out in this scope)
        break;
      }
    }
  }
  buffer = cl::Buffer();
}

std::vector<Device::PooledBuffer> Device::pooled_buffers() const {
  std::vector<PooledBuffer> out;
  if (!pool_) return out;
  std::lock_guard<std::mutex> lock(pool_->mutex);
  for (const Pool::Entry& e : pool_->entries) out.push_back({e.bytes, e.what, !e.busy});
  return out;
}

std::size_t Device::pool_misses() const {
  if (!pool_) return 0;
  std::lock_guard<std::mutex> lock(pool_->mutex);
  return pool_->misses;
}

std::size_t Device::pooled_bytes() const {
  if (!pool_) return 0;
  std::lock_guard<std::mutex> lock(pool_->mutex);
  std::size_t n = 0;
  for (const Pool::Entry& e : pool_->entries) n += e.bytes;
  return n;
}

cl::Event Device::run(const cl::Kernel& kernel, const std::string& what, const cl::NDRange& global,
                      const cl::NDRange& local, LocalSize size) {
  if (global.dimensions() != local.dimensions() || global.dimensions() == 0)
    throw ArgumentError(what, "global and local ranges must have the same 1-3 dimensions");
  const cl_uint dims = global.dimensions();
  std::array<std::size_t, 3> l{1, 1, 1};
  for (cl_uint d = 0; d < dims; ++d) {
    l[d] = local.get()[d];
    if (l[d] == 0) throw ArgumentError(what, "local size 0");
  }
  // The device's and the kernel's limits (one query, a few ns on PoCL): a
  // local size they do not take fails the launch with
  // CL_INVALID_WORK_GROUP_SIZE, which names neither the size nor the limit.
  const WorkGroupLimits limits = work_group_limits(kernel, what);
  if (!work_group_fits(l, dims, limits)) {
    if (size == LocalSize::exact) {
      std::string sz = std::to_string(l[0]);
      for (cl_uint d = 1; d < dims; ++d) sz += " x " + std::to_string(l[d]);
      throw ArgumentError(what, "needs work-groups of " + sz + " work-items (its local size), " +
                                    "more than this device takes for it (" +
                                    describe_work_group_limits(limits) + ")");
    }
    l = fit_work_group(l, dims, limits);
  }
  std::size_t g[3] = {1, 1, 1};
  for (cl_uint d = 0; d < dims; ++d) {
    g[d] = round_up(global.get()[d], l[d]);
    if (g[d] == 0) throw ArgumentError(what, "empty global range");
  }
  cl::Event event;
  cl_int err = queue_.enqueueNDRangeKernel(kernel, cl::NullRange, nd_range(g, dims),
                                           nd_range(l.data(), dims), nullptr, &event);
  if (err != CL_SUCCESS) throw CLError("clEnqueueNDRangeKernel(" + what + ")", err);
  if (logs_ && logs_->any.load(std::memory_order_relaxed)) {
    std::lock_guard<std::mutex> lock(logs_->mutex);
    const auto it = find_thread(logs_->threads, std::this_thread::get_id());
    if (it != logs_->threads.end()) it->second.push_back({what, event});
  }
  return event;
}

void Device::log_launches(bool on) {
  if (!logs_) throw ArgumentError("device", "was moved from");
  std::lock_guard<std::mutex> lock(logs_->mutex);
  auto& threads = logs_->threads;
  const auto id = std::this_thread::get_id();
  const auto it = find_thread(threads, id);
  if (!on) {
    if (it != threads.end()) threads.erase(it);
  } else if (it == threads.end()) {
    threads.emplace_back(id, std::vector<Launch>());
  } else {
    it->second.clear();
  }
  logs_->any = !threads.empty();
}

std::vector<Device::Launch> Device::take_launches() {
  std::vector<Launch> v;
  if (!logs_) return v;
  std::lock_guard<std::mutex> lock(logs_->mutex);
  const auto it = find_thread(logs_->threads, std::this_thread::get_id());
  if (it != logs_->threads.end()) v.swap(it->second);
  return v;
}

void Device::finish() {
  cl_check(queue_.finish(), "clFinish");
}

std::array<std::uint64_t, 2> event_span_ns(const cl::Event& event) {
  cl_ulong start = 0, end = 0;
  if (event.getProfilingInfo(CL_PROFILING_COMMAND_START, &start) != CL_SUCCESS ||
      event.getProfilingInfo(CL_PROFILING_COMMAND_END, &end) != CL_SUCCESS || end < start)
    return {0, 0};
  return {start, end};
}

std::uint64_t event_ns(const cl::Event& event) {
  const auto [start, end] = event_span_ns(event);
  return end - start;
}

}  // namespace simdvol
