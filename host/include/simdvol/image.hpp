// Float RGBA images (premultiplied, i.e. associative colour over black) and
// their files: PNG written through libpng, EXR and TIFF written and every
// format read through OpenImageIO, in a module loaded on first use
// (libsimdvol_oiio.so, found beside the program, in <libdir>/simdvol, or
// at $SIMDVOL_OIIO_MODULE).
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <vector>

namespace simdvol {

struct Rgba {
  float r = 0, g = 0, b = 0, a = 0;
};

/// Pixels of a width x height image; ArgumentError naming the size unless
/// both are positive.
std::size_t image_pixels(int width, int height);

class Image {
 public:
  Image() = default;
  Image(int width, int height);  // throws ArgumentError if not positive
  /// An image of these pixels (row-major, width * height of them; else
  /// ArgumentError), taken over without zeroing the storage first.
  Image(int width, int height, std::vector<Rgba> pixels);
  int width() const { return w_; }
  int height() const { return h_; }
  Rgba& at(int x, int y) { return px_[index(x, y)]; }
  const Rgba& at(int x, int y) const { return px_[index(x, y)]; }
  std::vector<Rgba>& pixels() { return px_; }
  const std::vector<Rgba>& pixels() const { return px_; }

 private:
  std::size_t index(int x, int y) const {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
  }
  int w_ = 0, h_ = 0;
  std::vector<Rgba> px_;
};

/// Writes by extension: .png (8-bit RGB over black, alpha dropped), .exr
/// (half-float RGBA, premultiplied), .tif/.tiff (32-bit float RGBA). Written
/// to a temporary file beside `path` and renamed, so a failure never leaves a
/// partial or clobbered file. Throws FileError on any problem (unknown
/// extension, missing directory, libpng or OpenImageIO error, the OpenImageIO
/// module not found for .exr/.tif).
void write_image(const Image& img, const std::filesystem::path& path);

/// Images that replace their files together (a turntable's frames): write()
/// puts each in a temporary file beside its path, as write_image does (to
/// disk, closed), and commit(), once every one is written, renames them
/// into place in the order written. Until commit(), and where the batch
/// ends without it (a write that failed, a render that failed, a signal
/// that remove_temporary_files_on_signals() handles), every file at the
/// paths keeps its bytes and the temporary files are removed. All the
/// temporary files exist at once: the disk needs room for every image
/// beside the files they replace. One write() at a time (from any thread,
/// each after the one before has returned).
class ImageBatch {
 public:
  /// A batch of at most `count` images.
  explicit ImageBatch(std::size_t count);
  ~ImageBatch();
  ImageBatch(const ImageBatch&) = delete;
  ImageBatch& operator=(const ImageBatch&) = delete;

  /// Writes `img` for `path`; FileError as write_image's (that image's
  /// temporary file removed, the others kept for commit() or the end), and
  /// ArgumentError past `count` images or after commit().
  void write(const Image& img, const std::filesystem::path& path);
  /// Renames every image written into place, in order. The renames are the
  /// one window in which the batch can end half done: a rename that fails
  /// (the name taken by a directory since, say) is a FileError naming its
  /// path and saying which of the batch's paths were replaced before it,
  /// the rest keeping their files (their temporary files removed).
  void commit();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Throws FileError (as write_image would) unless `path` ends in an extension
/// write_image writes: for checking an output name before the work.
void check_image_extension(const std::filesystem::path& path);

/// Reads an image written by write_image (any format OpenImageIO reads) as
/// float RGBA; a missing alpha becomes 1. Throws FileError (also when the
/// OpenImageIO module cannot be loaded).
Image read_image(const std::filesystem::path& path);
/// The same, and whether the file has an alpha channel (a PNG that
/// write_image wrote, RGB over black, has none: its alpha reads as 1).
Image read_image_with_alpha(const std::filesystem::path& path, bool* has_alpha);

/// Peak signal-to-noise ratio in dB over the RGB channels, peak 1.0.
/// Returns +infinity for identical images. Throws ArgumentError on size mismatch.
double psnr(const Image& a, const Image& b);

/// Largest absolute difference over all four channels.
float max_abs_diff(const Image& a, const Image& b);

/// Where two images differ beyond a tolerance: `count` pixels have some
/// channel (RGBA) that differs by more than it (a NaN in either counts),
/// `alpha_count` of them in alpha, and (`worst_x`, `worst_y`) is the pixel of
/// the largest difference (a NaN first; the first pixel if none differs).
/// Throws ArgumentError on size mismatch or a negative or NaN tolerance.
struct PixelsOver {
  std::size_t count = 0, alpha_count = 0;
  int worst_x = 0, worst_y = 0;
};
PixelsOver pixels_over(const Image& a, const Image& b, float tolerance);

/// Pixels that are not premultiplied RGBA: alpha outside [0, 1] or a colour
/// outside [0, alpha], beyond `kPremultipliedSlack` (float rounding of the
/// compositing), or any NaN. A render's every pixel must pass.
inline constexpr float kPremultipliedSlack = 1e-6f;
std::size_t invalid_premultiplied(const Image& img);

}  // namespace simdvol
