// libsimdvol_oiio: simdvol's OpenImageIO reader and writer, a module that
// host/core/image.cpp loads with dlopen when an image needs it (the
// interface and the reason are in host/core/oiio_module.hpp).
#include "oiio_module.hpp"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

namespace {

// A failure must never read as success (a null message): when the message
// itself cannot be allocated, this static one stands in (never freed).
char kOutOfMemory[] = "out of memory in the OpenImageIO module";

constexpr std::size_t kMaxReadPixels = std::size_t{1} << 28;

char* message(const std::string& s) {
  char* m = static_cast<char*>(std::malloc(s.size() + 1));
  if (!m) return kOutOfMemory;
  std::memcpy(m, s.c_str(), s.size() + 1);
  return m;
}

// Through an IOProxy on a stream of a duplicate of `fd`: the caller made
// the file (exclusively, with the mode a new file gets) and keeps it open;
// reopened by its name, it could be closed to its owner (umask 0222).
std::string write_image(const char* path, int fd, int format, int w, int h, const float* rgba) {
  if (format != 1 && format != 2) return "unknown image format code " + std::to_string(format);
  if (w <= 0 || h <= 0 || !rgba) return "cannot write an empty image";
  const char* name = format == 1 ? "openexr" : "tiff";
  // The stream, then the proxy on it, then the writer: destroyed in the
  // other order on every path, an exception's included (the writer's
  // destructor closes the file through the proxy). Close-on-exec, as the
  // caller's descriptor: PoCL runs the linker while a turntable writes.
  const int dup_fd = ::fcntl(fd, F_DUPFD_CLOEXEC, 0);
  struct Stream {
    FILE* f = nullptr;
    ~Stream() {
      if (f) std::fclose(f);
    }
  } stream;
  stream.f = dup_fd >= 0 ? ::fdopen(dup_fd, "wb") : nullptr;
  if (!stream.f) {
    const std::string e = std::strerror(errno);
    if (dup_fd >= 0) ::close(dup_fd);
    return "cannot write it: " + e;
  }
  OIIO::Filesystem::IOFile proxy(stream.f, OIIO::Filesystem::IOProxy::Write);
  auto out = OIIO::ImageOutput::create(name);
  if (!out) return "OpenImageIO has no " + std::string(name) + " writer: " + OIIO::geterror();
  if (!out->supports("ioproxy"))
    return "OpenImageIO's " + std::string(name) + " writer takes no stream";
  OIIO::ImageSpec spec(w, h, 4, format == 1 ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.alpha_channel = 3;
  spec.attribute("oiio:UnassociatedAlpha", 0);  // colour is premultiplied
  // No date: OpenImageIO stamps an EXR (capDate) and a TIFF (DateTime) with
  // the time of writing unless DateTime is given, and an empty one writes
  // neither; so the same render is the same bytes whenever it runs.
  spec.attribute("DateTime", "");
  if (format == 2) spec.attribute("compression", "zip");
  std::string problem;
  if (!(out->set_ioproxy(&proxy) && out->open(path, spec) &&
        out->write_image(OIIO::TypeDesc::FLOAT, rgba) && out->close())) {
    const std::string msg = out->geterror();
    problem = msg.empty() ? "OpenImageIO could not write the image" : msg;
  }
  out.reset();  // done with the proxy
  // The stream's buffer, its errors (a full disk, the file-size limit).
  if (std::fflush(stream.f) != 0 || std::ferror(stream.f)) {
    const int e = errno;
    if (problem.empty()) problem = "cannot write it: " + std::string(std::strerror(e));
  }
  FILE* f = stream.f;
  stream.f = nullptr;
  if (std::fclose(f) != 0 && problem.empty())
    problem = "cannot close it: " + std::string(std::strerror(errno));
  return problem;
}

std::string read_image(const char* path, int* w_out, int* h_out, float** rgba_out, int* has_alpha) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    const std::string msg = OIIO::geterror();
    return msg.empty() ? "OpenImageIO cannot open it" : msg;
  }
  // OpenImageIO's "null" reader makes a black 1024x1024 image of any file
  // named *.null: that is no image to compare.
  if (std::strcmp(in->format_name(), "null") == 0) return "not an image file";
  const OIIO::ImageSpec& spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (w <= 0 || h <= 0 || nch <= 0) return "image has no pixels";
  if (spec.depth > 1) return "3-D images are not supported";
  // A header's size is checked before the pixels are allocated: a 100-byte
  // PNG that claimed 20000x20000 took 4.8 GB and 15 s to fail.
  const std::size_t count = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  if (count > kMaxReadPixels || nch > 64)
    return "its header says " + std::to_string(w) + "x" + std::to_string(h) + " pixels, " +
           std::to_string(nch) + " channels: more than simdvol reads (2^28 pixels, 64 channels)";
  // Several images in one file (TIFF pages, EXR parts): which one was
  // meant is not known, and the first alone compared as the whole file.
  if (in->seek_subimage(1, 0))
    return "it holds several images (pages or parts); give a file of one image";
  if (!in->seek_subimage(0, 0)) {
    const std::string msg = in->geterror();
    return msg.empty() ? "OpenImageIO could not go back to its first image" : msg;
  }
  (void)in->geterror();  // what the failed seek to a second image left there
  std::vector<float> buf(count * static_cast<std::size_t>(nch));
  // read_image can return true for a TIFF or JPEG cut short (its strips
  // or scan lines left black) with the reader's complaint kept in
  // geterror(): that is a damaged file, not an image.
  const bool read = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, buf.data());
  const std::string msg = in->geterror();
  if (!read || !msg.empty())
    return msg.empty() ? "OpenImageIO could not read the pixels" : "damaged: " + msg;
  in->close();
  const int alpha = nch == 2   ? 1
                    : nch >= 4 ? (spec.alpha_channel >= 0 ? spec.alpha_channel : 3)
                               : -1;
  float* px = static_cast<float*>(std::malloc(count * 4 * sizeof(float)));
  if (!px) return "out of memory for " + std::to_string(w) + "x" + std::to_string(h) + " pixels";
  for (std::size_t i = 0; i < count; ++i) {
    const float* p = &buf[i * static_cast<std::size_t>(nch)];
    float* o = px + 4 * i;
    if (nch >= 3) {
      o[0] = p[0];
      o[1] = p[1];
      o[2] = p[2];
    } else {
      o[0] = o[1] = o[2] = p[0];
    }
    o[3] = alpha >= 0 ? p[alpha] : 1.0f;
  }
  *w_out = w;
  *h_out = h;
  *rgba_out = px;
  *has_alpha = alpha >= 0;
  return "";
}

// Exceptions must not cross the C interface.
template <class F>
char* guarded(F&& f) {
  try {
    const std::string problem = f();
    return problem.empty() ? nullptr : message(problem);
  } catch (const std::exception& e) {
    return message(e.what());
  } catch (...) {
    return message("unknown error in OpenImageIO");
  }
}

}  // namespace

extern "C" {
__attribute__((visibility("default"))) int simdvol_oiio_abi(void) {
  return SIMDVOL_OIIO_ABI;
}
__attribute__((visibility("default"))) char* simdvol_oiio_write(const char* path, int fd,
                                                                int format, int w, int h,
                                                                const float* rgba) {
  return guarded([&] { return write_image(path, fd, format, w, h, rgba); });
}
__attribute__((visibility("default"))) char* simdvol_oiio_read(const char* path, int* w, int* h,
                                                               float** rgba, int* has_alpha) {
  *rgba = nullptr;
  return guarded([&] { return read_image(path, w, h, rgba, has_alpha); });
}
__attribute__((visibility("default"))) void simdvol_oiio_free(void* p) {
  if (p != kOutOfMemory) std::free(p);
}
}
