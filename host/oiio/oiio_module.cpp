// libsimdvol_oiio: simdvol's OpenImageIO reader and writer, a module that
// host/core/image.cpp loads with dlopen when an image needs it (the
// interface and the reason are in host/core/oiio_module.hpp).
#include "oiio_module.hpp"

#include <OpenImageIO/imageio.h>

#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

namespace {

// A failure must never read as success (a null message): when the message
// itself cannot be allocated, this static one stands in (never freed).
char kOutOfMemory[] = "out of memory in the OpenImageIO module";

char* message(const std::string& s) {
  char* m = static_cast<char*>(std::malloc(s.size() + 1));
  if (!m) return kOutOfMemory;
  std::memcpy(m, s.c_str(), s.size() + 1);
  return m;
}

std::string write_image(const char* path, int format, int w, int h, const float* rgba) {
  if (format != 1 && format != 2) return "unknown image format code " + std::to_string(format);
  if (w <= 0 || h <= 0 || !rgba) return "cannot write an empty image";
  const char* name = format == 1 ? "openexr" : "tiff";
  auto out = OIIO::ImageOutput::create(name);
  if (!out) return "OpenImageIO has no " + std::string(name) + " writer: " + OIIO::geterror();
  OIIO::ImageSpec spec(w, h, 4, format == 1 ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.alpha_channel = 3;
  spec.attribute("oiio:UnassociatedAlpha", 0);  // colour is premultiplied
  if (format == 2) spec.attribute("compression", "zip");
  if (out->open(path, spec) && out->write_image(OIIO::TypeDesc::FLOAT, rgba) && out->close())
    return "";
  const std::string msg = out->geterror();
  return msg.empty() ? "OpenImageIO could not write the image" : msg;
}

std::string read_image(const char* path, int* w_out, int* h_out, float** rgba_out) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    const std::string msg = OIIO::geterror();
    return msg.empty() ? "OpenImageIO cannot open it" : msg;
  }
  const OIIO::ImageSpec& spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (w <= 0 || h <= 0 || nch <= 0) return "image has no pixels";
  if (spec.depth > 1) return "3-D images are not supported";
  const std::size_t count = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  std::vector<float> buf(count * static_cast<std::size_t>(nch));
  if (!in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, buf.data())) {
    const std::string msg = in->geterror();
    return msg.empty() ? "OpenImageIO could not read the pixels" : msg;
  }
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
__attribute__((visibility("default"))) char* simdvol_oiio_write(const char* path, int format, int w,
                                                                int h, const float* rgba) {
  return guarded([&] { return write_image(path, format, w, h, rgba); });
}
__attribute__((visibility("default"))) char* simdvol_oiio_read(const char* path, int* w, int* h,
                                                               float** rgba) {
  *rgba = nullptr;
  return guarded([&] { return read_image(path, w, h, rgba); });
}
__attribute__((visibility("default"))) void simdvol_oiio_free(void* p) {
  if (p != kOutOfMemory) std::free(p);
}
}
