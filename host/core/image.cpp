// Float RGBA images and their atomic output through OpenImageIO.
#include "simdvol/image.hpp"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <system_error>

#include "simdvol/error.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

enum class Format { png, exr, tiff };

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// A name beside `path` that keeps its extension, e.g. "out.tmp-3f2a-1.png".
fs::path temp_path_for(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  static const unsigned salt = std::random_device{}();
  const unsigned n = counter.fetch_add(1);
  char tag[40];
  std::snprintf(tag, sizeof tag, ".tmp-%08x-%u", salt, n);
  fs::path name = path.stem();
  name += tag;
  name += path.extension();
  return path.parent_path() / name;
}

// Writes `img` to `file` in `format`; returns an error message ("" on success).
std::string write_with_oiio(const Image& img, const fs::path& file, Format format) {
  const int w = img.width(), h = img.height();
  const std::size_t count = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  const char* format_name = format == Format::png   ? "png"
                            : format == Format::exr ? "openexr"
                                                    : "tiff";
  auto out = OIIO::ImageOutput::create(format_name);
  if (!out)
    return "OpenImageIO has no " + std::string(format_name) + " writer: " + OIIO::geterror();

  bool ok = false;
  if (format == Format::png) {
    // Premultiplied colour over black is the colour itself; alpha is dropped.
    std::vector<unsigned char> rgb(count * 3);
    auto q = [](float v) {
      if (!(v > 0.0f)) return static_cast<unsigned char>(0);  // also NaN
      if (v >= 1.0f) return static_cast<unsigned char>(255);
      return static_cast<unsigned char>(std::lround(v * 255.0f));
    };
    const std::vector<Rgba>& px = img.pixels();
    for (std::size_t i = 0; i < count; ++i) {
      rgb[3 * i + 0] = q(px[i].r);
      rgb[3 * i + 1] = q(px[i].g);
      rgb[3 * i + 2] = q(px[i].b);
    }
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
    ok = out->open(file.string(), spec) && out->write_image(OIIO::TypeDesc::UINT8, rgb.data()) &&
         out->close();
  } else {
    static_assert(sizeof(Rgba) == 4 * sizeof(float));
    OIIO::ImageSpec spec(w, h, 4,
                         format == Format::exr ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
    spec.alpha_channel = 3;
    spec.attribute("oiio:UnassociatedAlpha", 0);  // colour is premultiplied
    if (format == Format::tiff) spec.attribute("compression", "zip");
    ok = out->open(file.string(), spec) &&
         out->write_image(OIIO::TypeDesc::FLOAT, img.pixels().data()) && out->close();
  }
  if (ok) return "";
  std::string msg = out->geterror();
  return msg.empty() ? "OpenImageIO could not write the image" : msg;
}

void check_same_size(const Image& a, const Image& b, const char* what) {
  if (a.width() != b.width() || a.height() != b.height())
    throw ArgumentError(what, "image sizes differ: " + std::to_string(a.width()) + "x" +
                                  std::to_string(a.height()) + " vs " + std::to_string(b.width()) +
                                  "x" + std::to_string(b.height()));
}

}  // namespace

Image::Image(int width, int height) {
  if (width <= 0 || height <= 0)
    throw ArgumentError("image size", "width and height must be positive, got " +
                                          std::to_string(width) + "x" + std::to_string(height));
  w_ = width;
  h_ = height;
  px_.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), Rgba{});
}

void write_image(const Image& img, const fs::path& path) {
  const std::string ext = lower(path.extension().string());
  Format format;
  if (ext == ".png")
    format = Format::png;
  else if (ext == ".exr")
    format = Format::exr;
  else if (ext == ".tif" || ext == ".tiff")
    format = Format::tiff;
  else
    throw FileError(path, "unknown image extension '" + path.extension().string() +
                              "' (expected .png, .exr, .tif or .tiff)");
  if (img.width() <= 0 || img.height() <= 0 ||
      img.pixels().size() != static_cast<std::size_t>(img.width()) * img.height())
    throw FileError(path, "cannot write an empty image");

  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw FileError(path, "output directory '" + dir.string() + "' does not exist");

  const fs::path tmp = temp_path_for(path);
  std::string problem;
  try {
    problem = write_with_oiio(img, tmp, format);
  } catch (const std::exception& e) {
    problem = e.what();
  }
  if (problem.empty()) {
    fs::rename(tmp, path, ec);
    if (ec) problem = "cannot rename temporary file into place: " + ec.message();
  }
  if (!problem.empty()) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw FileError(path, problem);
  }
}

Image read_image(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw FileError(path, "no such image file");
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) {
    std::string msg = OIIO::geterror();
    throw FileError(path, msg.empty() ? "OpenImageIO cannot open it" : msg);
  }
  const OIIO::ImageSpec& spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (w <= 0 || h <= 0 || nch <= 0) throw FileError(path, "image has no pixels");
  if (spec.depth > 1) throw FileError(path, "3-D images are not supported");

  std::vector<float> buf(static_cast<std::size_t>(w) * h * nch);
  if (!in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, buf.data())) {
    std::string msg = in->geterror();
    throw FileError(path, msg.empty() ? "OpenImageIO could not read the pixels" : msg);
  }
  in->close();

  // 1 channel: grey; 2: grey + alpha; 3: RGB; 4 or more: RGBA (alpha where the
  // file says, else the fourth channel).
  const int alpha = nch == 2   ? 1
                    : nch >= 4 ? (spec.alpha_channel >= 0 ? spec.alpha_channel : 3)
                               : -1;
  Image img(w, h);
  std::vector<Rgba>& px = img.pixels();
  for (std::size_t i = 0; i < px.size(); ++i) {
    const float* p = &buf[i * nch];
    Rgba& o = px[i];
    if (nch >= 3) {
      o.r = p[0];
      o.g = p[1];
      o.b = p[2];
    } else {
      o.r = o.g = o.b = p[0];
    }
    o.a = alpha >= 0 ? p[alpha] : 1.0f;
  }
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

}  // namespace simdvol
