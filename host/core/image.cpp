// Float RGBA images and their atomic output: PNG through libpng, the other
// formats and all reading through OpenImageIO, loaded on first use
// (oiio_module.hpp).
#include "simdvol/image.hpp"

#include <dlfcn.h>
#include <fcntl.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <system_error>

#include "file_checks.hpp"
#include "oiio_module.hpp"
#include "simdvol/error.hpp"
#include "temp_files.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

enum class Format { png, exr, tiff };

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// ------------------------------------------------------------ the module
// OpenImageIO, loaded on first use (oiio_module.hpp says why).

struct OiioModule {
  simdvol_oiio_write_fn write = nullptr;
  simdvol_oiio_read_fn read = nullptr;
  simdvol_oiio_free_fn free = nullptr;
  std::string problem;  ///< why it could not be loaded ("" when loaded)
};

// The directory of the running program and, when simdvol_core is a shared
// library, of that library.
std::vector<fs::path> own_directories() {
  std::vector<fs::path> dirs;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) dirs.push_back(exe.parent_path());
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&own_directories), &info) && info.dli_fname &&
      info.dli_fname[0] == '/')
    dirs.push_back(fs::path(info.dli_fname).parent_path());
  return dirs;
}

}  // namespace
}  // namespace simdvol

// Defined (weak) in a program linking an installed static simdvol_core
// (cmake/simdvol_oiio_module_path.cpp): that package's module.
extern "C" __attribute__((weak)) const char* simdvol_installed_oiio_module();

namespace simdvol {
namespace {

// Where the module may be: $SIMDVOL_OIIO_MODULE alone if set; else beside
// the program or library (the build tree), in its installed place relative
// to them (bin/../lib/simdvol, lib/simdvol), then the build tree's and the
// install prefix's absolute paths.
std::vector<fs::path> module_candidates(const char* env) {
  if (env && *env) return {fs::path(env)};
  const fs::path name = fs::path(SIMDVOL_OIIO_INSTALL_PATH).filename();
  std::vector<fs::path> c;
  for (const fs::path& d : own_directories()) {
    c.push_back(d / name);
    c.push_back((d / SIMDVOL_OIIO_BIN_TO_MODULE / name).lexically_normal());
    c.push_back(d / "simdvol" / name);
  }
  // The installed package a program was built against (its find_package
  // says where), before the build tree's path (a package installed from a
  // build that is later removed) and the configured prefix's (installed
  // elsewhere with --prefix).
  if (simdvol_installed_oiio_module != nullptr) c.push_back(simdvol_installed_oiio_module());
  c.push_back(SIMDVOL_OIIO_BUILD_PATH);
  c.push_back(SIMDVOL_OIIO_INSTALL_PATH);
  std::vector<fs::path> unique;
  for (const fs::path& p : c)
    if (std::find(unique.begin(), unique.end(), p) == unique.end()) unique.push_back(p);
  return unique;
}

OiioModule load_oiio_module() {
  OiioModule m;
  const char* env = std::getenv("SIMDVOL_OIIO_MODULE");
  std::string tried;
  for (const fs::path& path : module_candidates(env)) {
    std::error_code ec;
    // A bare name (from SIMDVOL_OIIO_MODULE) goes to dlopen's own search.
    if (path.has_parent_path() && !fs::is_regular_file(path, ec)) {
      tried += "\n  " + path.string() + ": not there";
      continue;
    }
    void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!h) {
      const char* e = dlerror();
      tried += "\n  " + path.string() + ": " + (e ? e : "dlopen failed");
      continue;
    }
    auto abi = reinterpret_cast<simdvol_oiio_abi_fn>(dlsym(h, "simdvol_oiio_abi"));
    m.write = reinterpret_cast<simdvol_oiio_write_fn>(dlsym(h, "simdvol_oiio_write"));
    m.read = reinterpret_cast<simdvol_oiio_read_fn>(dlsym(h, "simdvol_oiio_read"));
    m.free = reinterpret_cast<simdvol_oiio_free_fn>(dlsym(h, "simdvol_oiio_free"));
    if (abi && m.write && m.read && m.free && abi() == SIMDVOL_OIIO_ABI) return m;  // kept loaded
    tried += "\n  " + path.string() + ": not a simdvol OpenImageIO module of interface version " +
             std::to_string(SIMDVOL_OIIO_ABI);
    m = OiioModule{};
    dlclose(h);
  }
  m.problem =
      "simdvol's OpenImageIO module (" + fs::path(SIMDVOL_OIIO_INSTALL_PATH).filename().string() +
      ", for .exr and .tif output and for reading images) could not be loaded; tried:" + tried +
      (env && *env ? "\n  (only SIMDVOL_OIIO_MODULE's path is tried when it is set)"
                   : "\n  (SIMDVOL_OIIO_MODULE=<path> names it)");
  return m;
}

const OiioModule& oiio_module() {
  static const OiioModule m = load_oiio_module();
  return m;
}

// A message from the module, freed.
std::string take_message(char* msg) {
  std::string s = msg ? msg : "";
  if (msg) oiio_module().free(msg);
  return s;
}

// 8-bit RGB over black: premultiplied colour over black is the colour
// itself; alpha is dropped.
std::vector<unsigned char> png_bytes(const Image& img) {
  const std::vector<Rgba>& px = img.pixels();
  std::vector<unsigned char> rgb(px.size() * 3);
  auto q = [](float v) {
    if (!(v > 0.0f)) return static_cast<unsigned char>(0);  // also NaN
    if (v >= 1.0f) return static_cast<unsigned char>(255);
    return static_cast<unsigned char>(std::lround(v * 255.0f));
  };
  for (std::size_t i = 0; i < px.size(); ++i) {
    rgb[3 * i + 0] = q(px[i].r);
    rgb[3 * i + 1] = q(px[i].g);
    rgb[3 * i + 2] = q(px[i].b);
  }
  return rgb;
}

// libpng reports errors through this (then longjmps back to write_png).
struct PngError {
  char message[256] = "";
  int errno_at_fail = 0;  // libpng's "Write Error" does not say why
};
void png_fail(png_structp png, png_const_charp msg) {
  auto* e = static_cast<PngError*>(png_get_error_ptr(png));
  e->errno_at_fail = errno;
  std::snprintf(e->message, sizeof e->message, "%s", msg ? msg : "libpng error");
  png_longjmp(png, 1);
}
void png_warn(png_structp, png_const_charp) {}

// 8-bit RGB rows (w * 3 bytes each, h rows) to the open file `fd` (not
// closed: a stream on a duplicate of it) through libpng:
// compression level 3 with the "up" filter, which on rendered frames
// writes files as small as libpng's default (level 6, every filter tried
// per row) in about a third of the time (a 256^2 brainsmall frame: 3.2
// against 11.0 ms, 26.8 against 27.0 KB). Only plain C objects live here:
// libpng's errors longjmp back to the setjmp below. Returns false with
// `err` set on failure.
bool write_png(int fd, const unsigned char* rgb, int w, int h, PngError* err) {
  const int dup_fd = ::fcntl(fd, F_DUPFD_CLOEXEC, 0);  // (PoCL runs the linker meanwhile)
  FILE* f = dup_fd >= 0 ? ::fdopen(dup_fd, "wb") : nullptr;
  if (!f) {
    std::snprintf(err->message, sizeof err->message, "cannot write it: %s", std::strerror(errno));
    if (dup_fd >= 0) ::close(dup_fd);
    return false;
  }
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, err, png_fail, png_warn);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    std::snprintf(err->message, sizeof err->message, "out of memory for libpng");
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    if (std::ferror(f) && err->errno_at_fail != 0)
      std::snprintf(err->message, sizeof err->message, "cannot write it: %s",
                    std::strerror(err->errno_at_fail));
    std::fclose(f);
    return false;
  }
  png_init_io(png, f);
  png_set_compression_level(png, 3);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
  png_set_IHDR(png, info, static_cast<png_uint_32>(w), static_cast<png_uint_32>(h), 8,
               PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < h; ++y)
    png_write_row(png, rgb + static_cast<std::size_t>(y) * static_cast<std::size_t>(w) * 3);
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  if (std::fflush(f) != 0 || std::ferror(f)) {
    std::snprintf(err->message, sizeof err->message, "cannot write it: %s", std::strerror(errno));
    std::fclose(f);
    return false;
  }
  if (std::fclose(f) != 0) {
    std::snprintf(err->message, sizeof err->message, "cannot close it: %s", std::strerror(errno));
    return false;
  }
  return true;
}

// Writes `img` in `format` to the open file `fd` (`file` names it in the
// messages); returns an error message ("" on success). PNG through libpng,
// the others through the OpenImageIO module.
std::string write_file(const Image& img, int fd, const fs::path& file, Format format) {
  if (format == Format::png) {
    const std::vector<unsigned char> rgb = png_bytes(img);
    PngError err;
    return write_png(fd, rgb.data(), img.width(), img.height(), &err) ? "" : err.message;
  }
  const OiioModule& m = oiio_module();
  if (!m.problem.empty()) return m.problem;
  static_assert(sizeof(Rgba) == 4 * sizeof(float));
  return take_message(m.write(file.c_str(), fd, format == Format::exr ? 1 : 2, img.width(),
                              img.height(), &img.pixels().data()->r));
}

void check_same_size(const Image& a, const Image& b, const char* what) {
  if (a.width() != b.width() || a.height() != b.height())
    throw ArgumentError(what, "image sizes differ: " + std::to_string(a.width()) + "x" +
                                  std::to_string(a.height()) + " vs " + std::to_string(b.width()) +
                                  "x" + std::to_string(b.height()));
}

Format format_of(const fs::path& path) {
  const std::string ext = lower(path.extension().string());
  if (ext == ".png") return Format::png;
  if (ext == ".exr") return Format::exr;
  if (ext == ".tif" || ext == ".tiff") return Format::tiff;
  throw FileError(path, "unknown image extension '" + path.extension().string() +
                            "' (expected .png, .exr, .tif or .tiff)");
}

}  // namespace

std::size_t image_pixels(int width, int height) {
  if (width <= 0 || height <= 0)
    throw ArgumentError("image size", "width and height must be positive, got " +
                                          std::to_string(width) + "x" + std::to_string(height));
  return static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
}

Image::Image(int width, int height) : w_(width), h_(height), px_(image_pixels(width, height)) {}

Image::Image(int width, int height, std::vector<Rgba> pixels) : w_(width), h_(height) {
  if (pixels.size() != image_pixels(width, height))
    throw ArgumentError("image pixels", std::to_string(pixels.size()) + " pixels for a " +
                                            std::to_string(width) + "x" + std::to_string(height) +
                                            " image");
  px_ = std::move(pixels);
}

void check_image_extension(const fs::path& path) {
  (void)format_of(path);
}

namespace {

// `img` written for `path` to a temporary file beside it (or beside its
// symbolic link's target: the link stays a link), not yet to disk or in
// place; marked as entry `index` of `marks` where given. FileError on a
// failure, the temporary file removed.
std::unique_ptr<TempFile> write_temporary(const Image& img, const fs::path& path,
                                          TempFileMarks* marks, std::size_t index) {
  const Format format = format_of(path);
  if (img.width() <= 0 || img.height() <= 0 ||
      img.pixels().size() != static_cast<std::size_t>(img.width()) * img.height())
    throw FileError(path, "cannot write an empty image");

  const fs::path target = write_target(path);
  const fs::path dir = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw FileError(path, "output directory '" + dir.string() + "' does not exist");

  auto tmp = marks ? std::make_unique<TempFile>(target, path, *marks, index)
                   : std::make_unique<TempFile>(target, path);
  std::string problem;
  try {
    problem = write_file(img, tmp->fd(), path, format);
  } catch (const std::exception& e) {
    problem = e.what();
  }
  if (!problem.empty()) tmp->fail(problem);
  return tmp;
}

}  // namespace

void write_image(const Image& img, const fs::path& path) {
  write_temporary(img, path, nullptr, 0)->commit();
}

struct ImageBatch::Impl {
  explicit Impl(std::size_t count) : marks(count) {}
  TempFileMarks marks;
  std::vector<std::unique_ptr<TempFile>> files;  // (destroyed first: they unmark)
  std::vector<fs::path> paths;
  bool committed = false;
};

ImageBatch::ImageBatch(std::size_t count) : impl_(std::make_unique<Impl>(count)) {}

ImageBatch::~ImageBatch() {
  // The temporary files not renamed into place are removed (TempFile's
  // destructor), in reverse order.
  while (!impl_->files.empty()) impl_->files.pop_back();
}

void ImageBatch::write(const Image& img, const fs::path& path) {
  Impl& b = *impl_;
  if (b.committed) throw ArgumentError("ImageBatch::write", "the batch was committed already");
  if (b.files.size() >= b.marks.size())
    throw ArgumentError("ImageBatch::write",
                        "more than the batch's " + std::to_string(b.marks.size()) + " images");
  b.files.reserve(b.marks.size());
  b.paths.reserve(b.marks.size());
  std::unique_ptr<TempFile> tmp = write_temporary(img, path, &b.marks, b.files.size());
  // To disk and closed now (a batch of 100,000 would run out of
  // descriptors), so that commit() is the renames alone.
  tmp->finish();
  b.paths.push_back(path);
  b.files.push_back(std::move(tmp));
}

void ImageBatch::commit() {
  Impl& b = *impl_;
  if (b.committed) throw ArgumentError("ImageBatch::commit", "the batch was committed already");
  b.committed = true;
  for (std::size_t i = 0; i < b.files.size(); ++i) {
    try {
      b.files[i]->commit();
    } catch (const FileError& e) {
      const std::size_t after = b.files.size() - i - 1;
      std::string said = e.problem() + "; ";
      if (i == 0)
        said += "no file of the batch was replaced";
      else if (i == 1)
        said += "the file before it, " + b.paths[0].string() + ", was replaced already";
      else
        said += "the " + std::to_string(i) + " files before it, " + b.paths[0].string() + " .. " +
                b.paths[i - 1].filename().string() + ", were replaced already";
      said += after == 0 ? std::string("; it keeps its file")
                         : "; it and the " + std::to_string(after) + " after it keep their files";
      throw FileError(e.path(), said);
    }
  }
}

Image read_image(const fs::path& path) {
  return read_image_with_alpha(path, nullptr);
}

Image read_image_with_alpha(const fs::path& path, bool* has_alpha) {
  std::error_code ec;
  refuse_non_regular_file(path, "an image file");
  if (!fs::is_regular_file(path, ec))
    throw FileError(path, ec && ec != std::errc::no_such_file_or_directory
                              ? ec.message()  // a loop of symbolic links, no permission, ...
                              : "no such image file");
  const OiioModule& m = oiio_module();
  if (!m.problem.empty()) throw FileError(path, m.problem);
  int w = 0, h = 0;
  float* rgba = nullptr;
  int alpha = 0;
  const std::string problem = take_message(m.read(path.c_str(), &w, &h, &rgba, &alpha));
  if (!problem.empty()) throw FileError(path, problem);
  struct Free {
    const OiioModule& m;
    float* p;
    ~Free() { m.free(p); }
  } owner{m, rgba};
  Image img(w, h);
  static_assert(sizeof(Rgba) == 4 * sizeof(float));
  std::vector<Rgba>& px = img.pixels();
  for (std::size_t i = 0; i < px.size(); ++i)
    px[i] = Rgba{rgba[4 * i], rgba[4 * i + 1], rgba[4 * i + 2], rgba[4 * i + 3]};
  if (has_alpha) *has_alpha = alpha != 0;
  return img;
}

double psnr(const Image& a, const Image& b) {
  check_same_size(a, b, "psnr");
  const std::vector<Rgba>& pa = a.pixels();
  const std::vector<Rgba>& pb = b.pixels();
  double sum = 0.0;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    const double dr = static_cast<double>(pa[i].r) - pb[i].r;
    const double dg = static_cast<double>(pa[i].g) - pb[i].g;
    const double db = static_cast<double>(pa[i].b) - pb[i].b;
    sum += dr * dr + dg * dg + db * db;
  }
  if (sum == 0.0) return std::numeric_limits<double>::infinity();
  const double mse = sum / (3.0 * static_cast<double>(pa.size()));
  return -10.0 * std::log10(mse);
}

float max_abs_diff(const Image& a, const Image& b) {
  check_same_size(a, b, "max_abs_diff");
  const std::vector<Rgba>& pa = a.pixels();
  const std::vector<Rgba>& pb = b.pixels();
  float m = 0.0f;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    for (float d : {pa[i].r - pb[i].r, pa[i].g - pb[i].g, pa[i].b - pb[i].b, pa[i].a - pb[i].a}) {
      if (std::isnan(d)) return std::numeric_limits<float>::quiet_NaN();  // never hide a NaN
      m = std::max(m, std::fabs(d));
    }
  }
  return m;
}

PixelsOver pixels_over(const Image& a, const Image& b, float tolerance) {
  check_same_size(a, b, "pixels_over");
  if (!(tolerance >= 0.0f))
    throw ArgumentError("tolerance", "must be 0 or more, not " + std::to_string(tolerance));
  const std::vector<Rgba>& pa = a.pixels();
  const std::vector<Rgba>& pb = b.pixels();
  PixelsOver out;
  float worst = 0.0f;
  std::size_t worst_i = 0;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    float m = 0.0f;
    for (float d : {pa[i].r - pb[i].r, pa[i].g - pb[i].g, pa[i].b - pb[i].b, pa[i].a - pb[i].a})
      m = std::isnan(d) ? std::numeric_limits<float>::infinity() : std::max(m, std::fabs(d));
    if (m > tolerance) ++out.count;
    if (!(std::fabs(pa[i].a - pb[i].a) <= tolerance)) ++out.alpha_count;
    if (m > worst) {
      worst = m;
      worst_i = i;
    }
  }
  out.worst_x = static_cast<int>(worst_i % static_cast<std::size_t>(a.width()));
  out.worst_y = static_cast<int>(worst_i / static_cast<std::size_t>(a.width()));
  return out;
}

std::size_t invalid_premultiplied(const Image& img) {
  const float s = kPremultipliedSlack;
  std::size_t n = 0;
  for (const Rgba& p : img.pixels()) {
    // Written so that a NaN fails every comparison and so counts.
    const bool alpha_ok = p.a >= -s && p.a <= 1.0f + s;
    const bool colours_ok =
        p.r >= -s && p.g >= -s && p.b >= -s && p.r <= p.a + s && p.g <= p.a + s && p.b <= p.a + s;
    n += !(alpha_ok && colours_ok);
  }
  return n;
}

}  // namespace simdvol
