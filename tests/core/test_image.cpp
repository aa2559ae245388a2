// Images: construction, PSNR and differences, and atomic output (.png
// through libpng, .exr and .tif/.tiff through the OpenImageIO module; every
// read through OpenImageIO, so the PNG round trip checks libpng's file with
// another library).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

#include "simdvol/error.hpp"
#include "simdvol/image.hpp"

namespace simdvol {
namespace {

namespace fs = std::filesystem;

Image constant(int w, int h, Rgba c) {
  Image img(w, h);
  std::fill(img.pixels().begin(), img.pixels().end(), c);
  return img;
}

// A premultiplied test pattern with every channel varying.
Image pattern(int w, int h) {
  Image img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = static_cast<float>(x + 1) / static_cast<float>(w);
      const float u = static_cast<float>(y) / static_cast<float>(h - 1);
      img.at(x, y) = {a * u, a * (1.0f - u),
                      a * 0.5f * static_cast<float>((x * 7 + y * 3) % 11) / 10.0f, a};
    }
  return img;
}

std::string read_bytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

std::set<std::string> listing(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

class ImageFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("simdvol_test_image_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
};

TEST(Image, ConstructsZeroedAndRejectsBadSizes) {
  Image img(3, 2);
  EXPECT_EQ(img.width(), 3);
  EXPECT_EQ(img.height(), 2);
  ASSERT_EQ(img.pixels().size(), 6u);
  for (const Rgba& p : img.pixels()) EXPECT_TRUE(p.r == 0 && p.g == 0 && p.b == 0 && p.a == 0);
  img.at(2, 1).g = 0.5f;
  EXPECT_EQ(img.pixels()[5].g, 0.5f);
  EXPECT_THROW(Image(0, 5), ArgumentError);
  EXPECT_THROW(Image(5, 0), ArgumentError);
  EXPECT_THROW(Image(-1, 5), ArgumentError);
}

TEST(Image, TakesOverPixelsOfItsSize) {
  std::vector<Rgba> px(6);
  for (std::size_t i = 0; i < px.size(); ++i) px[i].r = float(i);
  const Image img(3, 2, px);
  EXPECT_EQ(img.width(), 3);
  EXPECT_EQ(img.height(), 2);
  EXPECT_EQ(img.at(0, 1).r, 3.0f);
  EXPECT_EQ(img.at(2, 1).r, 5.0f);
  EXPECT_THROW(Image(3, 2, std::vector<Rgba>(5)), ArgumentError);
  EXPECT_THROW(Image(2, 3, std::vector<Rgba>(7)), ArgumentError);
  EXPECT_THROW(Image(0, 2, std::vector<Rgba>()), ArgumentError);
}

TEST(Psnr, KnownValues) {
  // Offset 0.125 (exact in float): MSE = 1/64, PSNR = 10 log10(64).
  const Image a = constant(8, 5, {0.25f, 0.5f, 0.75f, 1.0f});
  const Image b = constant(8, 5, {0.375f, 0.625f, 0.875f, 1.0f});
  EXPECT_NEAR(psnr(a, b), 10.0 * std::log10(64.0), 1e-9);
  EXPECT_NEAR(psnr(b, a), 10.0 * std::log10(64.0), 1e-9);

  // Offset 0.1 (as close as float gets): 20 dB.
  const Image c = constant(4, 4, {0.5f, 0.5f, 0.5f, 1.0f});
  const Image d = constant(4, 4, {0.6f, 0.6f, 0.6f, 1.0f});
  const double off = static_cast<double>(0.6f) - static_cast<double>(0.5f);
  EXPECT_NEAR(psnr(c, d), -20.0 * std::log10(off), 1e-9);
  EXPECT_NEAR(psnr(c, d), 20.0, 1e-5);

  // One channel of one pixel off by 0.5 in a 4x4 image: MSE = 0.25 / 48.
  Image e = c;
  e.at(1, 2).g += 0.5f;
  EXPECT_NEAR(psnr(c, e), 10.0 * std::log10(48.0 / 0.25), 1e-9);

  // Identical (alpha is not part of PSNR).
  EXPECT_EQ(psnr(c, c), std::numeric_limits<double>::infinity());
  Image f = c;
  f.at(0, 0).a = 0.0f;
  EXPECT_EQ(psnr(c, f), std::numeric_limits<double>::infinity());
}

TEST(Psnr, SizeMismatchThrows) {
  EXPECT_THROW(psnr(Image(4, 4), Image(4, 5)), ArgumentError);
  EXPECT_THROW(psnr(Image(3, 4), Image(4, 4)), ArgumentError);
  EXPECT_THROW(max_abs_diff(Image(4, 4), Image(5, 4)), ArgumentError);
}

TEST(MaxAbsDiff, CoversAllFourChannels) {
  const Image a = constant(3, 3, {0.1f, 0.2f, 0.3f, 0.4f});
  EXPECT_EQ(max_abs_diff(a, a), 0.0f);
  Image b = a;
  b.at(2, 2).a = 0.9f;
  EXPECT_NEAR(max_abs_diff(a, b), 0.5f, 1e-7f);
  b.at(0, 1).r = -0.7f;
  EXPECT_NEAR(max_abs_diff(a, b), 0.8f, 1e-7f);
  b.at(1, 1).b = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(std::isnan(max_abs_diff(a, b)));
}

TEST(PixelsOver, CountsPixelsNotChannelsAndFindsTheWorst) {
  const Image a = constant(4, 3, {0.1f, 0.2f, 0.3f, 0.4f});
  PixelsOver o = pixels_over(a, a, 0.0f);
  EXPECT_EQ(o.count, 0u);
  EXPECT_EQ(o.alpha_count, 0u);
  EXPECT_EQ(o.worst_x, 0);
  EXPECT_EQ(o.worst_y, 0);
  Image b = a;
  b.at(1, 0).r += 0.25f;  // colour only
  b.at(1, 0).g += 0.25f;  // the same pixel: counted once
  b.at(3, 2).a -= 0.5f;   // alpha, the largest
  b.at(2, 1).b += 1e-6f;  // within the tolerance below
  o = pixels_over(a, b, 1e-5f);
  EXPECT_EQ(o.count, 2u);
  EXPECT_EQ(o.alpha_count, 1u);
  EXPECT_EQ(o.worst_x, 3);
  EXPECT_EQ(o.worst_y, 2);
  EXPECT_EQ(pixels_over(a, b, 0.0f).count, 3u);  // strictly more than the tolerance
  EXPECT_EQ(pixels_over(a, b, 0.3f).count, 1u);
  EXPECT_EQ(pixels_over(a, b, 0.5f).count, 0u);
  b.at(0, 2).g = std::numeric_limits<float>::quiet_NaN();  // a NaN counts at any tolerance
  o = pixels_over(a, b, 1e30f);
  EXPECT_EQ(o.count, 1u);
  EXPECT_EQ(o.worst_x, 0);
  EXPECT_EQ(o.worst_y, 2);
  EXPECT_THROW(pixels_over(a, b, -1.0f), ArgumentError);
  EXPECT_THROW(pixels_over(a, b, std::numeric_limits<float>::quiet_NaN()), ArgumentError);
  EXPECT_THROW(pixels_over(a, Image(4, 4), 0.0f), ArgumentError);
}

TEST(InvalidPremultiplied, AlphaInZeroOneAndColoursInZeroAlpha) {
  Image img = constant(5, 2, {0.2f, 0.3f, 0.5f, 0.5f});
  EXPECT_EQ(invalid_premultiplied(img), 0u);
  img.at(0, 0) = {0.0f, 0.0f, 0.0f, 0.0f};            // transparent black: valid
  img.at(1, 0) = {1.0f, 1.0f, 1.0f, 1.0f};            // opaque white: valid
  img.at(2, 0) = {0.5f + 5e-7f, 0.0f, 0.0f, 0.5f};    // within the slack: valid
  img.at(3, 0) = {0.0f, -5e-7f, 0.0f, 1.0f + 5e-7f};  // within the slack: valid
  EXPECT_EQ(invalid_premultiplied(img), 0u);
  img.at(4, 0) = {0.6f, 0.0f, 0.0f, 0.5f};                   // colour above alpha
  img.at(0, 1) = {0.0f, 0.0f, 0.0f, -0.01f};                 // alpha below 0
  img.at(1, 1) = {0.0f, 0.0f, -0.01f, 0.5f};                 // colour below 0
  img.at(2, 1) = {0.0f, 0.0f, 0.0f, 1.01f};                  // alpha above 1
  img.at(3, 1).a = std::numeric_limits<float>::quiet_NaN();  // NaN
  EXPECT_EQ(invalid_premultiplied(img), 5u);
}

TEST_F(ImageFiles, PngRoundTripQuantisesOverBlack) {
  Image img = pattern(37, 23);
  img.at(0, 0) = {1.7f, -0.3f, 0.5f, 1.0f};  // clamped to [0, 1]
  const fs::path p = dir_ / "out.png";
  write_image(img, p);
  const Image back = read_image(p);
  ASSERT_EQ(back.width(), 37);
  ASSERT_EQ(back.height(), 23);
  for (int y = 0; y < 23; ++y)
    for (int x = 0; x < 37; ++x) {
      const Rgba& o = img.at(x, y);
      const Rgba& r = back.at(x, y);
      auto q = [](float v) { return std::round(std::clamp(v, 0.0f, 1.0f) * 255.0f) / 255.0f; };
      ASSERT_NEAR(r.r, q(o.r), 1e-6f) << x << "," << y;
      ASSERT_NEAR(r.g, q(o.g), 1e-6f) << x << "," << y;
      ASSERT_NEAR(r.b, q(o.b), 1e-6f) << x << "," << y;
      ASSERT_EQ(r.a, 1.0f);  // no alpha in the file
    }
  EXPECT_EQ(back.at(0, 0).r, 1.0f);
  EXPECT_EQ(back.at(0, 0).g, 0.0f);
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.png"}));
}

TEST_F(ImageFiles, ExrRoundTripIsHalfPrecision) {
  Image img = pattern(31, 17);
  img.at(3, 4) = {2.5f, 0.001f, 0.0f, 1.0f};  // outside [0, 1] survives in EXR
  const fs::path p = dir_ / "out.exr";
  write_image(img, p);
  const Image back = read_image(p);
  ASSERT_EQ(back.width(), 31);
  ASSERT_EQ(back.height(), 17);
  for (std::size_t i = 0; i < img.pixels().size(); ++i) {
    const Rgba& o = img.pixels()[i];
    const Rgba& r = back.pixels()[i];
    // half: 11 significant bits, relative error <= 2^-11.
    ASSERT_NEAR(r.r, o.r, 1e-3f * std::fabs(o.r) + 1e-7f) << i;
    ASSERT_NEAR(r.g, o.g, 1e-3f * std::fabs(o.g) + 1e-7f) << i;
    ASSERT_NEAR(r.b, o.b, 1e-3f * std::fabs(o.b) + 1e-7f) << i;
    ASSERT_NEAR(r.a, o.a, 1e-3f * std::fabs(o.a) + 1e-7f) << i;
  }
  EXPECT_NEAR(back.at(3, 4).r, 2.5f, 1e-6f);  // exactly representable
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.exr"}));
}

TEST_F(ImageFiles, TiffRoundTripIsExact) {
  Image img = pattern(29, 13);
  img.at(5, 6) = {-0.25f, 3.0f, 1e-20f, 0.123456789f};
  for (const char* name : {"out.tif", "out.tiff"}) {
    const fs::path p = dir_ / name;
    write_image(img, p);
    const Image back = read_image(p);
    ASSERT_EQ(back.width(), 29);
    ASSERT_EQ(back.height(), 13);
    EXPECT_EQ(max_abs_diff(img, back), 0.0f) << name;
    EXPECT_EQ(back.at(5, 6).a, 0.123456789f);
  }
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.tif", "out.tiff"}));
}

// The same image written at two times is the same bytes: OpenImageIO
// stamped an EXR's capDate and a TIFF's DateTime with the time of writing,
// so that one render run twice (or at two thread counts, on two machines)
// gave files that cmp and checksums told apart. The second writes wait for
// the clock's second to turn (the stamp's unit): at most a second.
TEST_F(ImageFiles, SameImageIsSameBytesWhenWrittenLater) {
  const Image img = pattern(16, 8);
  const std::vector<std::string> exts = {".png", ".exr", ".tif"};
  for (const std::string& ext : exts) write_image(img, dir_ / ("a" + ext));
  const std::time_t first = std::time(nullptr);
  while (std::time(nullptr) == first) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  for (const std::string& ext : exts) {
    write_image(img, dir_ / ("b" + ext));
    const std::string a = read_bytes(dir_ / ("a" + ext)), b = read_bytes(dir_ / ("b" + ext));
    EXPECT_FALSE(a.empty()) << ext;
    const auto diff = std::mismatch(a.begin(), a.end(), b.begin(), b.end());
    EXPECT_TRUE(a == b) << ext << ": two writes of one image differ from byte "
                        << (diff.first - a.begin()) << " (" << a.size() << " and " << b.size()
                        << " bytes)";
  }
}

TEST_F(ImageFiles, OverwriteReplacesTheFile) {
  const fs::path p = dir_ / "out.tif";
  write_image(constant(4, 4, {0.1f, 0.2f, 0.3f, 0.4f}), p);
  const Image second = constant(6, 2, {0.5f, 0.6f, 0.7f, 0.8f});
  write_image(second, p);
  const Image back = read_image(p);
  ASSERT_EQ(back.width(), 6);
  ASSERT_EQ(back.height(), 2);
  EXPECT_EQ(max_abs_diff(second, back), 0.0f);
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.tif"}));
}

// An ImageBatch (a turntable's frames) replaces its files together: until
// commit() every existing file keeps its bytes and the images wait in
// temporary files beside them; a batch dropped before commit() (a render
// or write that failed) removes them and leaves the files as they were.
TEST_F(ImageFiles, ImageBatchReplacesItsFilesOnlyAtCommit) {
  const std::vector<fs::path> paths = {dir_ / "f_0.tif", dir_ / "f_1.png", dir_ / "f_2.tif"};
  for (const fs::path& p : paths) std::ofstream(p) << "old " << p.filename().string();
  const Image a = pattern(8, 6), b = constant(5, 3, {0.5f, 0.25f, 0.0f, 1.0f});
  {
    ImageBatch batch(3);
    batch.write(a, paths[0]);
    batch.write(b, paths[1]);
    for (const fs::path& p : paths)
      EXPECT_EQ(read_bytes(p), "old " + p.filename().string()) << "replaced before commit()";
    EXPECT_EQ(listing(dir_).size(), 5u);  // the two temporary files beside them
  }                                       // dropped: the temporary files removed, nothing replaced
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"f_0.tif", "f_1.png", "f_2.tif"}));
  for (const fs::path& p : paths) EXPECT_EQ(read_bytes(p), "old " + p.filename().string());

  // A write that fails (a name with no image extension) keeps the others'
  // temporary files for the batch, and the files as they were.
  {
    ImageBatch batch(3);
    batch.write(a, paths[0]);
    EXPECT_THROW(batch.write(b, dir_ / "f_1.bmp"), FileError);
  }
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"f_0.tif", "f_1.png", "f_2.tif"}));
  EXPECT_EQ(read_bytes(paths[0]), "old f_0.tif");

  ImageBatch batch(3);
  batch.write(a, paths[0]);
  batch.write(b, paths[1]);
  batch.write(a, paths[2]);
  EXPECT_THROW(batch.write(a, dir_ / "f_3.tif"), ArgumentError);  // past its 3
  batch.commit();
  EXPECT_EQ(max_abs_diff(read_image(paths[0]), a), 0.0f);
  EXPECT_EQ(read_image(paths[1]).width(), 5);
  EXPECT_EQ(max_abs_diff(read_image(paths[2]), a), 0.0f);
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"f_0.tif", "f_1.png", "f_2.tif"}));
}

// The renames are the one window in which a batch can end half done: a
// name taken by a directory after the images were written fails its
// rename, and the error names it and says which files were replaced
// before it; the ones after it keep their bytes, and no temporary file is
// left.
TEST_F(ImageFiles, ImageBatchSaysWhichFilesARenameThatFailedLeftReplaced) {
  std::vector<fs::path> paths;
  for (int i = 0; i < 5; ++i) {
    paths.push_back(dir_ / ("f_" + std::to_string(i) + ".tif"));
    std::ofstream(paths.back()) << "old " << i;
  }
  const Image img = pattern(8, 6);
  {
    ImageBatch batch(5);
    for (const fs::path& p : paths) batch.write(img, p);
    fs::remove(paths[2]);
    fs::create_directory(paths[2]);
    try {
      batch.commit();
      ADD_FAILURE() << "the rename over a directory did not fail";
    } catch (const FileError& e) {
      EXPECT_EQ(e.path(), paths[2]);
      const std::string what = e.what();
      EXPECT_EQ(
          what.rfind(paths[2].string() + ": cannot rename the temporary file into place: ", 0), 0u)
          << what;
      EXPECT_NE(what.find("; the 2 files before it, " + paths[0].string() +
                          " .. f_1.tif, were replaced already; it and the 2 after it keep their "
                          "files"),
                std::string::npos)
          << what;
    }
  }
  EXPECT_EQ(max_abs_diff(read_image(paths[0]), img), 0.0f);
  EXPECT_EQ(max_abs_diff(read_image(paths[1]), img), 0.0f);
  EXPECT_TRUE(fs::is_directory(paths[2]));
  EXPECT_EQ(read_bytes(paths[3]), "old 3");
  EXPECT_EQ(read_bytes(paths[4]), "old 4");
  EXPECT_EQ(listing(dir_),
            (std::set<std::string>{"f_0.tif", "f_1.tif", "f_2.tif", "f_3.tif", "f_4.tif"}));
}

TEST_F(ImageFiles, WritesThroughASymbolicLink) {
  // The link's target is replaced (the temporary beside it), the link kept.
  fs::create_directory(dir_ / "real");
  write_image(constant(4, 4, {0.1f, 0.2f, 0.3f, 0.4f}), dir_ / "real" / "out.tif");
  fs::create_symlink("real/out.tif", dir_ / "link.tif");
  const Image second = constant(6, 2, {0.5f, 0.6f, 0.7f, 0.8f});
  write_image(second, dir_ / "link.tif");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "link.tif")));
  EXPECT_EQ(max_abs_diff(second, read_image(dir_ / "real" / "out.tif")), 0.0f);
  EXPECT_EQ(listing(dir_ / "real"), (std::set<std::string>{"out.tif"}));
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"real", "link.tif"}));
}

TEST_F(ImageFiles, UnknownExtensionThrowsNamingThePath) {
  for (const char* name : {"out.bmp", "out.jpg", "out", "out.png.txt"}) {
    const fs::path p = dir_ / name;
    try {
      write_image(pattern(4, 4), p);
      ADD_FAILURE() << "no error for " << p;
    } catch (const FileError& e) {
      EXPECT_EQ(e.path(), p);
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
      EXPECT_NE(e.problem().find("unknown image extension"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(listing(dir_).empty());
}

TEST_F(ImageFiles, MissingDirectoryThrows) {
  const fs::path p = dir_ / "no_such_dir" / "out.png";
  try {
    write_image(pattern(4, 4), p);
    ADD_FAILURE() << "no error";
  } catch (const FileError& e) {
    EXPECT_EQ(e.path(), p);
  }
  EXPECT_FALSE(fs::exists(dir_ / "no_such_dir"));
  EXPECT_TRUE(listing(dir_).empty());
}

// The temporary file is written completely, then the rename onto `path`
// fails because `path` is a directory: the temporary must be removed and the
// directory left as it was.
TEST_F(ImageFiles, FailedRenameLeavesTargetAndNoTemporary) {
  const fs::path p = dir_ / "out.png";
  fs::create_directory(p);
  { std::ofstream(p / "inside.txt") << "keep me"; }
  for (const char* ext : {".png", ".exr", ".tif"}) {
    const fs::path target = fs::path(p).replace_extension(ext);
    if (ext != std::string(".png")) fs::create_directory(target);
    EXPECT_THROW(write_image(pattern(8, 8), target), FileError) << target;
  }
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.png", "out.exr", "out.tif"}));
  EXPECT_TRUE(fs::is_directory(p));
  EXPECT_EQ(listing(p), (std::set<std::string>{"inside.txt"}));
  EXPECT_EQ(read_bytes(p / "inside.txt"), "keep me");
}

// libpng refuses widths over 1,000,000 once the temporary file is already
// open, so this fails in the middle of writing: the existing file must stay
// byte-identical and the temporary must be gone.
TEST_F(ImageFiles, FailedWriteLeavesExistingFileUntouched) {
  const fs::path p = dir_ / "out.png";
  write_image(pattern(16, 9), p);
  const std::string before = read_bytes(p);
  ASSERT_FALSE(before.empty());
  try {
    write_image(Image(1000001, 1), p);
    ADD_FAILURE() << "no error";
  } catch (const FileError& e) {
    EXPECT_EQ(e.path(), p);
  }
  EXPECT_EQ(read_bytes(p), before);
  EXPECT_EQ(listing(dir_), (std::set<std::string>{"out.png"}));
  // And it still reads as the first image.
  EXPECT_EQ(read_image(p).width(), 16);
}

TEST_F(ImageFiles, ReadErrorsAreFileErrors) {
  EXPECT_THROW(read_image(dir_ / "missing.png"), FileError);
  const fs::path junk = dir_ / "junk.png";
  { std::ofstream(junk) << "this is not a png"; }
  EXPECT_THROW(read_image(junk), FileError);
  EXPECT_THROW(read_image(dir_), FileError);
  // A FIFO is refused before anything opens it (opening would block).
  const fs::path fifo = dir_ / "fifo.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  try {
    read_image(fifo);
    ADD_FAILURE() << "no FileError for a FIFO";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("is not a regular file"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace simdvol
