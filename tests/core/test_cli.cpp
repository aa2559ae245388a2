// The simdvol program as a user meets it: exit codes, messages, files.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "dicom_testing.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "testing.hpp"

#include <nifti2_io.h>

namespace fs = std::filesystem;

namespace {

using simdvol::testing::write_dicom_slice;

/// Asserts that two rendered images are the same, red and alpha bit for
/// bit (the renders compared are grey: red stands for the colour).
void expect_same_pixels(const simdvol::Image& a, const simdvol::Image& b) {
  ASSERT_EQ(a.pixels().size(), b.pixels().size());
  for (std::size_t i = 0; i < a.pixels().size(); ++i) {
    ASSERT_EQ(a.pixels()[i].r, b.pixels()[i].r) << i;
    ASSERT_EQ(a.pixels()[i].a, b.pixels()[i].a) << i;
  }
}

/// The sum of an image's alpha: how much of it a render covers.
double alpha_sum(const simdvol::Image& img) {
  double sum = 0;
  for (const auto& p : img.pixels()) sum += p.a;
  return sum;
}

struct Result {
  int code = -1;
  std::string output;  // stdout and stderr together
};

// `env` ("NAME=value ..."), if any, is set for the program alone; `shell`,
// if any, is a shell command line the program's runs after ("ulimit -v N;
// exec").
Result run_once(const std::string& args, const std::string& env, const std::string& shell = "") {
  const std::string cmd = (shell.empty() ? "" : shell + " ") +
                          (env.empty() ? "" : "env " + env + " ") + std::string(SIMDVOL_CLI) + " " +
                          args + " 2>&1";
  Result r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Under the ASan build (scripts/test), LeakSanitizer's stop-the-world tracer
// now and then crashes at exit ("Tracer caught signal 11 ... LeakSanitizer
// has encountered a fatal error"; google/sanitizers#1353) after the program
// has done its work: seen twice in about 120 runs of a render here, with
// PoCL's worker threads alive. That is the sanitizer's own failure, not a
// finding, so the command runs again (twice at most); a leak report
// ("detected memory leaks") or any other failure is returned as it is.
Result run(const std::string& args, const std::string& env = "") {
  Result r = run_once(args, env);
  for (int retry = 0; retry < 2 && r.output.find("LeakSanitizer has encountered a fatal error") !=
                                       std::string::npos;
       ++retry)
    r = run_once(args, env);
  return r;
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() / ("simdvol-cli-" + std::to_string(rd()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

}  // namespace

TEST_F(Cli, HelpAndNoSubcommand) {
  const Result h = run("--help");
  EXPECT_EQ(h.code, 0);
  EXPECT_NE(h.output.find("render"), std::string::npos);
  EXPECT_NE(h.output.find("phantom"), std::string::npos);
  for (const char* sub : {"render", "info", "phantom", "devices"}) {
    const Result s = run(std::string(sub) + " --help");
    EXPECT_EQ(s.code, 0) << sub;
  }
  EXPECT_NE(run("").code, 0);
  // The phantoms' sizes give their range in the help, as the refusals do.
  EXPECT_NE(run("phantom --help").output.find("N (an N^3 grid), 2..1024"), std::string::npos);
  EXPECT_NE(run("render --help").output.find("N of an N^3 grid, 2..1024"), std::string::npos);
  const Result big = run("phantom shepp-logan --size 1025 -o " + path("big.nrrd"));
  EXPECT_NE(big.code, 0);
  EXPECT_NE(big.output.find("--size: 1025 is outside 2..1024"), std::string::npos) << big.output;
  EXPECT_FALSE(fs::exists(path("big.nrrd")));
}

TEST_F(Cli, PhantomRoundTripsThroughInfoAndLoader) {
  const Result r = run("phantom shepp-logan --size 24 -o " + path("p.nrrd"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("p.nrrd"), std::string::npos);
  const simdvol::Volume back = simdvol::load_volume(path("p.nrrd"));
  const simdvol::Volume orig = simdvol::shepp_logan(24, 4);  // the CLI default
  ASSERT_EQ(back.dims(), orig.dims());
  EXPECT_EQ(back.data(), orig.data());  // i16 values survive exactly
  const Result info = run("info " + path("p.nrrd"));
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("24 x 24 x 24"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("-1000"), std::string::npos) << info.output;
  EXPECT_EQ(run("phantom marschner-lobb --size 16 -o " + path("m.nrrd")).code, 0);
  EXPECT_EQ(simdvol::load_volume(path("m.nrrd")).nx(), 16);
}

// `info`'s figures on a volume whose answers are known: the values 0 .. 99
// in a scrambled order, a second 0 and three NaNs (a raw f32 file): mean
// 4950 / 101, the NaNs counted apart, 16 bins of 99 / 16 wide (8 values in
// the first: 0, 0, 1 .. 6), percentiles p1, p50, p99 at ranks 1, 50, 99 of
// the 101 finite values (0, 49, 98).
TEST_F(Cli, InfoFiguresOfAKnownVolume) {
  std::vector<float> v;
  for (int i = 0; i < 100; ++i) v.push_back(static_cast<float>((37 * i) % 100));
  v.insert(v.begin() + 10, 3, std::numeric_limits<float>::quiet_NaN());
  v.push_back(0.0f);  // (104 = 8 x 13 x 1 voxels)
  {
    std::ofstream out(path("known.raw"), std::ios::binary);
    out.write(reinterpret_cast<const char*>(v.data()),
              static_cast<std::streamsize>(v.size() * sizeof(float)));
  }
  const Result info = run("info " + path("known.raw") + " --raw-dims 8,13,1 --raw-type f32");
  ASSERT_EQ(info.code, 0) << info.output;
  for (const char* want : {"range:    0 .. 99\n", "mean:     49.0099\n", "nonfinite voxels: 3\n",
                           "            0          8 ", "percentiles: p1=0 p50=49 p99=98\n"})
    EXPECT_NE(info.output.find(want), std::string::npos) << want << "\n" << info.output;
}

TEST_F(Cli, RenderWritesTheImageItNames) {
  const Result r = run("render --phantom-size 32 --size 48x40 -o " + path("r.png"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find(path("r.png")), std::string::npos) << r.output;
  const simdvol::Image img = simdvol::read_image(path("r.png"));
  EXPECT_EQ(img.width(), 48);
  EXPECT_EQ(img.height(), 40);
  double sum = 0;
  for (const auto& p : img.pixels()) sum += p.r + p.g + p.b;
  EXPECT_GT(sum, 1.0);  // something was drawn
}

TEST_F(Cli, TurntableWritesNumberedFrames) {
  const Result r =
      run("render --phantom-size 16 --size 16x16 --frames 3 --step 5 -o " + path("t.png"));
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"t_0000.png", "t_0001.png", "t_0002.png"})
    EXPECT_TRUE(fs::exists(dir_ / f)) << f;
  EXPECT_EQ(r.output.find("note: --step"), std::string::npos) << r.output;
  // A step of whole turns renders one view in every frame: said, not refused.
  for (const char* step : {"0", "360", "-360"}) {
    const Result same =
        run(std::string("render --phantom-size 16 --size 16x16 --frames 2 --step ") + step +
            " -o " + path("s.png"));
    ASSERT_EQ(same.code, 0) << same.output;
    EXPECT_NE(same.output.find(std::string("simdvol: note: --step ") + step +
                               " turns the view a whole number of turns a frame: the 2 frames "
                               "show one view"),
              std::string::npos)
        << same.output;
  }
}

// Frame k of a turntable is the render of its view alone (--view THETA,
// PHI + k STEP, VARPHI), bit for bit in all four channels: the frames after
// the first keep the volume's cells and its mixture classification
// (RenderEngine's layout and classification kept), and Monte Carlo draws
// from the same seed in every frame. With --trace and --times: one times
// line and one traced frame per frame.
TEST_F(Cli, TurntableFramesEqualSingleRenders) {
  const std::string base =
      "render --phantom-size 32 --size 32x32 --classify mri --composite mc --samples 8 "
      "--mc-scope subray --allocate --seed 9 ";
  const Result t = run(base + "--view 20,35,10 --frames 3 --step 12.5 --times --trace " +
                       path("t.json") + " -o " + path("t.tif"));
  ASSERT_EQ(t.code, 0) << t.output;
  for (int f = 0; f < 3; ++f)
    EXPECT_NE(t.output.find("frame " + std::to_string(f) + " (opencl"), std::string::npos)
        << t.output;
  EXPECT_NE(t.output.find("classification kept"), std::string::npos) << t.output;
  std::ifstream trace(path("t.json"));
  const std::string json((std::istreambuf_iterator<char>(trace)), {});
  EXPECT_NE(json.find("\"args\": {\"frame\": 2}"), std::string::npos) << json.substr(0, 400);
  EXPECT_EQ(json.find("\"args\": {\"frame\": 3}"), std::string::npos);
  const char* phis[] = {"35", "47.5", "60"};
  for (int f = 0; f < 3; ++f) {
    const std::string one = path("one" + std::to_string(f) + ".tif");
    const Result r = run(base + "--view 20," + phis[f] + ",10 -o " + one);
    ASSERT_EQ(r.code, 0) << r.output;
    const simdvol::Image a = simdvol::read_image(path("t_000" + std::to_string(f) + ".tif"));
    const simdvol::Image b = simdvol::read_image(one);
    ASSERT_EQ(a.pixels().size(), b.pixels().size());
    EXPECT_GT(alpha_sum(a), 1.0);
    EXPECT_EQ(std::memcmp(a.pixels().data(), b.pixels().data(),
                          a.pixels().size() * sizeof(a.pixels()[0])),
              0)
        << "frame " << f;
  }
}

// Over 10,000 frames the numbers take five digits from the first frame on,
// so that the names sort in frame order (before: t_0000 ... t_9999, then
// t_10000, which sorts between t_1000 and t_1001). The reference engine on
// a 2^3 phantom at 1 x 1 pixel: about a second for the 10,001 files.
TEST_F(Cli, TurntableNamesSortInFrameOrderPastTenThousandFrames) {
  const Result r =
      run("render --engine reference --phantom-size 2 --size 1x1 --frames 10001 "
          "--step 0.01 -o " +
          path("t.png"));
  ASSERT_EQ(r.code, 0) << r.output;
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  ASSERT_EQ(names.size(), 10001u);
  for (int f = 0; f < 10001; ++f) {
    char want[32];
    std::snprintf(want, sizeof want, "t_%05d.png", f);
    ASSERT_EQ(names[static_cast<std::size_t>(f)], want);
  }
}

// One volume of a 4-D NIfTI (--volume-index; `info` too, which without the
// option describes volume 0 and says how many there are): the image equals
// the render of the same voxels as a 3-D file, from a .nii.gz and from a
// gzipped .hdr/.img pair named by its .img. Volume v of the file holds a
// phantom scaled by v + 1 and shifted, so each volume's image differs.
TEST_F(Cli, RendersOneVolumeOfAFourDNifti) {
  const simdvol::Volume ph = simdvol::shepp_logan(24, 2);
  const std::size_t n = ph.voxel_count();
  const int64_t dims[8] = {4, 24, 24, 24, 3, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, DT_FLOAT32, 1);
  ASSERT_NE(nim, nullptr);
  ASSERT_EQ(nim->nvox, 3 * n);
  auto* f = static_cast<float*>(nim->data);
  for (int v = 0; v < 3; ++v)
    for (std::size_t i = 0; i < n; ++i)
      f[static_cast<std::size_t>(v) * n + i] = static_cast<float>(v + 1) * ph.data()[i] + 100.0f;
  ASSERT_EQ(nifti_set_filenames(nim, path("series.nii.gz").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  // The same volumes as a gzipped .hdr/.img pair (named by its .img below).
  ASSERT_EQ(nifti_set_filenames(nim, path("pair.hdr.gz").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nifti_image_free(nim);
  ASSERT_TRUE(fs::exists(path("pair.img.gz")));
  simdvol::Volume one({24, 24, 24}, simdvol::VoxelType::f32);
  for (std::size_t i = 0; i < n; ++i) one.data()[i] = 2.0f * ph.data()[i] + 100.0f;  // volume 1
  simdvol::save_nrrd(one, path("one.nrrd"));

  const Result no_index = run("render " + path("series.nii.gz") + " -o " + path("x.png"));
  EXPECT_EQ(no_index.code, 1);
  EXPECT_NE(no_index.output.find("holds 3 3-D volumes"), std::string::npos) << no_index.output;
  EXPECT_NE(no_index.output.find("--volume-index"), std::string::npos) << no_index.output;
  const std::string common = " --size 32x32 --view 20,35,10 --classify mri -o ";
  ASSERT_EQ(
      run("render " + path("series.nii.gz") + " --volume-index 1" + common + path("a.tif")).code,
      0);
  ASSERT_EQ(run("render " + path("one.nrrd") + common + path("b.tif")).code, 0);
  ASSERT_EQ(
      run("render " + path("pair.img.gz") + " --volume-index 1" + common + path("c.tif")).code, 0);
  const simdvol::Image a = simdvol::read_image(path("a.tif")),
                       b = simdvol::read_image(path("b.tif")),
                       c = simdvol::read_image(path("c.tif"));
  expect_same_pixels(a, b);
  expect_same_pixels(c, b);
  EXPECT_GT(alpha_sum(a), 1.0);
  const Result info = run("info " + path("series.nii.gz") + " --volume-index 2");
  ASSERT_EQ(info.code, 0) << info.output;
  std::ostringstream range;  // volume 2: 3 x the phantom's range + 100
  range << "range:    " << 3.0f * ph.range().min + 100.0f << " .. "
        << 3.0f * ph.range().max + 100.0f << "\n";
  EXPECT_NE(info.output.find(range.str()), std::string::npos) << range.str() << info.output;
  EXPECT_NE(info.output.find("volumes:  3 in the file (4-D); the figures above are volume 2's"),
            std::string::npos)
      << info.output;
  // Without an index `info` describes volume 0 and says how many there are.
  const Result info0 = run("info " + path("series.nii.gz"));
  ASSERT_EQ(info0.code, 0) << info0.output;
  std::ostringstream range0;
  range0 << "range:    " << ph.range().min + 100.0f << " .. " << ph.range().max + 100.0f << "\n";
  EXPECT_NE(info0.output.find(range0.str()), std::string::npos) << range0.str() << info0.output;
  EXPECT_NE(info0.output.find("volumes:  3 in the file (4-D); the figures above are volume 0's"),
            std::string::npos)
      << info0.output;
}

// --orient turns the axes as the header says they lie: a NIfTI whose sform
// says LAS (x to the patient's left), rendered --orient RAS, equals the
// render of the same voxels reversed along x by hand and saved without an
// orientation; without the option the image differs (the volume is not
// symmetric). `info` names the axes. Refused: a code that is not one,
// a file whose header says nothing, and a file of another kind.
TEST_F(Cli, OrientTurnsTheAxesAsTheHeaderSays) {
  simdvol::Volume ph = simdvol::shepp_logan(24, 2);
  for (int64_t z = 2; z < 8; ++z)  // a block on one side: no mirror symmetry
    for (int64_t y = 4; y < 10; ++y)
      for (int64_t x = 2; x < 7; ++x) ph.at(x, y, z) = 0.9f;
  const int64_t dims[8] = {3, 24, 24, 24, 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, DT_FLOAT32, 1);
  ASSERT_NE(nim, nullptr);
  std::memcpy(nim->data, ph.data().data(), ph.voxel_count() * sizeof(float));
  nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
  nim->sto_xyz.m[0][0] = -1.0;
  nim->sto_xyz.m[1][1] = 1.0;
  nim->sto_xyz.m[2][2] = 1.0;
  ASSERT_EQ(nifti_set_filenames(nim, path("las.nii").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nim->sform_code = 0;  // the same voxels, saying nothing
  ASSERT_EQ(nifti_set_filenames(nim, path("plain.nii").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nifti_image_free(nim);
  simdvol::Volume flipped(ph.dims(), simdvol::VoxelType::f32);
  for (int64_t z = 0; z < 24; ++z)
    for (int64_t y = 0; y < 24; ++y)
      for (int64_t x = 0; x < 24; ++x) flipped.at(x, y, z) = ph.at(23 - x, y, z);
  simdvol::save_nrrd(flipped, path("flipped.nrrd"));

  const std::string common = " --size 32x32 --view 20,35,10 --classify mri -o ";
  ASSERT_EQ(run("render " + path("las.nii") + " --orient ras" + common + path("a.tif")).code, 0);
  ASSERT_EQ(run("render " + path("flipped.nrrd") + common + path("b.tif")).code, 0);
  ASSERT_EQ(run("render " + path("las.nii") + common + path("c.tif")).code, 0);
  const simdvol::Image a = simdvol::read_image(path("a.tif")),
                       b = simdvol::read_image(path("b.tif")),
                       c = simdvol::read_image(path("c.tif"));
  expect_same_pixels(a, b);
  ASSERT_EQ(c.pixels().size(), b.pixels().size());
  double differ = 0;
  for (std::size_t i = 0; i < c.pixels().size(); ++i)
    differ += std::fabs(c.pixels()[i].a - b.pixels()[i].a);
  EXPECT_GT(differ, 1.0);

  const Result las = run("info " + path("las.nii"));
  ASSERT_EQ(las.code, 0) << las.output;
  EXPECT_NE(las.output.find("axes:     LAS (x, y, z point to the patient's left, front, top)"),
            std::string::npos)
      << las.output;
  const Result ras = run("info " + path("las.nii") + " --orient RAS");
  EXPECT_NE(ras.output.find("axes:     RAS"), std::string::npos) << ras.output;
  for (const auto& [args, needle] : std::vector<std::pair<std::string, std::string>>{
           {"info " + path("las.nii") + " --orient RAX",
            "--orient: 'RAX' is not three letters, one each of R/L, A/P and S/I"},
           {"render " + path("plain.nii") + " --orient RAS -o " + path("x.png"),
            "--orient: " + path("plain.nii") + ": the file does not say where its axes point"},
           {"render " + path("flipped.nrrd") + " --orient RAS -o " + path("x.png"),
            "the file does not say where its axes point"},
           {"render --orient RAS -o " + path("x.png"),
            "--orient: applies only to NIfTI, NRRD, MetaImage, MGH, MINC and DICOM volumes"}}) {
    const Result r = run(args);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.output;  // simdvol's errors
    EXPECT_NE(r.output.find(needle), std::string::npos) << args << "\n" << r.output;
    EXPECT_FALSE(fs::exists(path("x.png")));
  }
}

// A DICOM CT series renders as the same Hounsfield values saved as a NRRD:
// its slices (files named against their order) sorted by position,
// Rescale Intercept applied, `auto` taking them for CT; from the directory
// and from one slice, bit for bit; so does the second time point of an
// enhanced multi-frame file by --volume-index, which without it is refused
// with how many volumes it holds. `info` describes the series.
TEST_F(Cli, RendersADicomSeries) {
  const simdvol::Volume ph = simdvol::shepp_logan(24, 2);
  const fs::path dir = dir_ / "series";
  fs::create_directories(dir);
  simdvol::Volume hu(ph.dims(), simdvol::VoxelType::f32, {0.5, 0.7, 1.25});
  // The same as the time point 1 of an enhanced multi-frame file whose
  // time point 0 is air, its frames stored from the top down.
  std::vector<simdvol::testing::EnhancedFrame> frames(48);
  for (int64_t z = 0; z < 24; ++z) {
    std::vector<int16_t> px(24 * 24);
    for (int64_t y = 0; y < 24; ++y)
      for (int64_t x = 0; x < 24; ++x) {
        px[static_cast<std::size_t>(y * 24 + x)] =
            static_cast<int16_t>(std::lround(ph.at(x, y, z)) + 1024);  // (HU -1000 .. 520)
        hu.at(x, y, z) = static_cast<float>(px[static_cast<std::size_t>(y * 24 + x)]) - 1024.0f;
      }
    simdvol::testing::DicomSlice s;
    s.position = {-20, 30, 7.5 + 1.25 * static_cast<double>(z)};
    s.intercept = -1024;
    write_dicom_slice(dir / ("IM" + std::to_string(1000 - z)), 24, 24, px, s);
    for (int t = 0; t < 2; ++t) {
      auto& f = frames[static_cast<std::size_t>(t * 24 + 23 - z)];
      f.position = s.position;
      f.pixels = t == 1 ? px : std::vector<int16_t>(px.size(), 24);
    }
  }
  simdvol::testing::write_enhanced_dicom(path("enhanced.dcm"), 24, 24, frames, {1, 0, 0, 0, 1, 0},
                                         {0.5, 0.7}, std::array<double, 2>{1.0, -1024.0});
  simdvol::save_nrrd(hu, path("hu.nrrd"));
  const std::string common = " --size 32x32 --view 20,35,10 -o ";
  ASSERT_EQ(run("render " + dir.string() + common + path("a.tif")).code, 0);
  ASSERT_EQ(run("render " + (dir / "IM990").string() + common + path("b.tif")).code, 0);
  ASSERT_EQ(run("render " + path("hu.nrrd") + common + path("c.tif")).code, 0);
  const simdvol::Image a = simdvol::read_image(path("a.tif")),
                       b = simdvol::read_image(path("b.tif")),
                       c = simdvol::read_image(path("c.tif"));
  expect_same_pixels(a, c);
  expect_same_pixels(b, c);
  EXPECT_GT(alpha_sum(a), 1.0);
  ASSERT_EQ(
      run("render " + path("enhanced.dcm") + " --volume-index 1" + common + path("d.tif")).code, 0);
  expect_same_pixels(simdvol::read_image(path("d.tif")), c);
  const Result four = run("render " + path("enhanced.dcm") + common + path("e.tif"));
  EXPECT_EQ(four.code, 1);
  EXPECT_NE(four.output.find("holds 2 3-D volumes (2 slices at each of 24 positions"),
            std::string::npos)
      << four.output;
  EXPECT_FALSE(fs::exists(path("e.tif")));
  const Result info4 = run("info " + path("enhanced.dcm"));
  ASSERT_EQ(info4.code, 0) << info4.output;
  EXPECT_NE(info4.output.find("volumes:  2 in the series (4-D); the figures above are volume 0's"),
            std::string::npos)
      << info4.output;
  EXPECT_NE(info4.output.find("range:    -1000 .. -1000"), std::string::npos) << info4.output;
  // A tilted copy of three slices: resampled, and the user told so.
  fs::create_directories(dir_ / "tilted");
  for (int64_t z = 0; z < 3; ++z) {
    simdvol::testing::DicomSlice s;
    s.position = {0, 2.0 * static_cast<double>(z), 5.0 * static_cast<double>(z)};
    write_dicom_slice(dir_ / "tilted" / ("T" + std::to_string(z + 10)), 24, 24,
                      std::vector<int16_t>(24 * 24, 7), s);
  }
  const std::string note = "its 3 slices were resampled in their plane to undo a gantry tilt";
  const Result tilted = run("info " + (dir_ / "tilted").string());
  EXPECT_NE(tilted.output.find("note:     " + note), std::string::npos) << tilted.output;
  const Result drawn = run("render " + (dir_ / "tilted").string() + common + path("t.tif"));
  EXPECT_EQ(drawn.code, 0) << drawn.output;
  EXPECT_NE(drawn.output.find("simdvol: note: " + note), std::string::npos) << drawn.output;
  const Result info = run("info " + dir.string());
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_EQ(info.output.find("note:"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("dims:     24 x 24 x 24"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("spacing:  0.5 x 0.7 x 1.25"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("axes:     LPS"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("range:    -1000 .. "), std::string::npos) << info.output;
}

TEST_F(Cli, RendersAMetaImage) {
  // The phantom in Hounsfield units as MET_SHORT, written by hand: a 4-D
  // .mha whose volume 0 is air (raw and compressed), and a .mhd whose
  // voxels lie in a .raw beside it. Each renders as the NRRD of the same
  // values.
  const simdvol::Volume ph = simdvol::shepp_logan(24, 2);
  simdvol::Volume hu(ph.dims(), simdvol::VoxelType::f32, {0.5, 0.7, 1.25});
  std::string air, body;
  for (std::size_t i = 0; i < ph.voxel_count(); ++i) {
    const auto v = static_cast<int16_t>(std::lround(ph.data()[i]));
    hu.data()[i] = static_cast<float>(v);
    const int16_t a = -1000;
    air.append(reinterpret_cast<const char*>(&a), 2);  // (little-endian, as the header says)
    body.append(reinterpret_cast<const char*>(&v), 2);
  }
  const std::string fields =
      "BinaryDataByteOrderMSB = False\nElementSpacing = 0.5 0.7 1.25\nElementType = MET_SHORT\n";
  std::ofstream(path("four.mha"), std::ios::binary)
      << "ObjectType = Image\nNDims = 4\nDimSize = 24 24 24 2\nElementSpacing = 0.5 0.7 1.25 1\n"
      << "ElementType = MET_SHORT\nElementDataFile = LOCAL\n"
      << air << body;
  std::ofstream(path("body.mhd")) << "ObjectType = Image\nNDims = 3\nDimSize = 24 24 24\n"
                                  << fields << "ElementDataFile = body.raw\n";
  std::ofstream(path("body.raw"), std::ios::binary) << body;
  simdvol::save_nrrd(hu, path("hu.nrrd"));
  const std::string common = " --size 32x32 --view 20,35,10 -o ";
  ASSERT_EQ(run("render " + path("hu.nrrd") + common + path("c.tif")).code, 0);
  ASSERT_EQ(run("render " + path("four.mha") + " --volume-index 1" + common + path("a.tif")).code,
            0);
  ASSERT_EQ(run("render " + path("body.mhd") + common + path("b.tif")).code, 0);
  const simdvol::Image c = simdvol::read_image(path("c.tif"));
  expect_same_pixels(simdvol::read_image(path("a.tif")), c);
  expect_same_pixels(simdvol::read_image(path("b.tif")), c);
  EXPECT_GT(alpha_sum(c), 1.0);
  const Result four = run("render " + path("four.mha") + common + path("e.tif"));
  EXPECT_EQ(four.code, 1);
  EXPECT_NE(four.output.find("holds 2 3-D volumes (a 4-D image): give the index of one, 0..1"),
            std::string::npos)
      << four.output;
  EXPECT_FALSE(fs::exists(path("e.tif")));
  const Result info = run("info " + path("body.mhd") + " --orient RAS");
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("axes:     RAS"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("spacing:  0.5 x 0.7 x 1.25"), std::string::npos) << info.output;
  // A data file cut short: one line, simdvol's, quoting MetaIO (which would
  // otherwise have written to stderr and read on), and no image.
  std::ofstream(path("body.raw"), std::ios::binary | std::ios::trunc) << body.substr(0, 100);
  std::ofstream(path("cut.mha"), std::ios::binary)
      << "ObjectType = Image\nNDims = 3\nDimSize = 24 24 24\n"
      << fields << "ElementDataFile = LOCAL\n"
      << body.substr(0, 1000);
  for (const char* name : {"body.mhd", "cut.mha"}) {
    const Result cut = run("render " + path(name) + common + path("f.tif"));
    EXPECT_EQ(cut.code, 1) << cut.output;
    EXPECT_EQ(std::count(cut.output.begin(), cut.output.end(), '\n'), 1) << cut.output;
    EXPECT_EQ(cut.output.rfind("simdvol: error: " + path(name) + ": ", 0), 0u) << cut.output;
    EXPECT_FALSE(fs::exists(path("f.tif")));
  }
}

TEST_F(Cli, RendersAnMghFrame) {
  // Frame 1 of a FreeSurfer .mgh written by hand (big-endian, conformed LIA
  // axes; frame 0 is air) renders as the NRRD of the same values.
  const simdvol::Volume ph = simdvol::shepp_logan(24, 2);
  simdvol::Volume hu(ph.dims(), simdvol::VoxelType::f32, {1.0, 1.0, 1.0});
  std::string header(284, '\0'), air, body;
  const auto big32 = [&](std::size_t at, uint32_t v) {
    for (int b = 0; b < 4; ++b) header[at + b] = static_cast<char>(v >> (24 - 8 * b));
  };
  big32(0, 1);  // version
  for (int i = 0; i < 3; ++i) big32(4 + 4 * i, 24);
  big32(16, 2);    // frames
  big32(20, 4);    // MRI_SHORT
  header[29] = 1;  // goodRASFlag
  const float one = 1.0f, minus = -1.0f;
  uint32_t b1, bm;
  std::memcpy(&b1, &one, 4);
  std::memcpy(&bm, &minus, 4);
  for (int i = 0; i < 3; ++i) big32(30 + 4 * i, b1);  // 1 mm voxels
  big32(42, bm);                                      // x to the left
  big32(42 + 20, bm);                                 // y down
  big32(42 + 28, b1);                                 // z to the front
  for (std::size_t i = 0; i < ph.voxel_count(); ++i) {
    const auto v = static_cast<int16_t>(std::lround(ph.data()[i]));
    hu.data()[i] = static_cast<float>(v);
    air += std::string("\xfc\x18", 2);  // -1000, big-endian
    body += static_cast<char>(static_cast<uint16_t>(v) >> 8);
    body += static_cast<char>(static_cast<uint16_t>(v) & 0xff);
  }
  std::ofstream(path("t1.mgh"), std::ios::binary) << header << air << body;
  simdvol::save_nrrd(hu, path("hu.nrrd"));
  const std::string common = " --size 32x32 --view 20,35,10 -o ";
  ASSERT_EQ(run("render " + path("hu.nrrd") + common + path("c.tif")).code, 0);
  ASSERT_EQ(run("render " + path("t1.mgh") + " --volume-index 1" + common + path("a.tif")).code, 0);
  expect_same_pixels(simdvol::read_image(path("a.tif")), simdvol::read_image(path("c.tif")));
  const Result info = run("info " + path("t1.mgh") + " --orient RAS");
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("axes:     RAS"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("volumes:  2 in the file (4-D)"), std::string::npos) << info.output;
}

TEST_F(Cli, ReadsMincFiles) {
  // nibabel's MINC files (scripts/fetch-data): info describes a 4-D MINC1
  // file's volume 0 and says how many; a MINC2 file renders, turned.
  const fs::path dir = simdvol::testing::data_dir() / "minc";
  SIMDVOL_REQUIRE_FILE(dir / "minc1_4d.mnc");
  SIMDVOL_REQUIRE_FILE(dir / "minc2_4d.mnc");
  const Result info = run("info " + (dir / "minc1_4d.mnc").string());
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("dims:     20 x 20 x 10"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("axes:     RAS"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("volumes:  2 in the file (4-D)"), std::string::npos) << info.output;
  const Result r = run("render " + (dir / "minc2_4d.mnc").string() +
                       " --volume-index 1 --orient LIP --size 32x32 -o " + path("m.tif"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_GT(alpha_sum(simdvol::read_image(path("m.tif"))), 1.0);
  const Result none = run("render " + (dir / "minc2_4d.mnc").string() + " -o " + path("n.tif"));
  EXPECT_EQ(none.code, 1);
  EXPECT_NE(none.output.find("holds 2 3-D volumes (time points: a 4-D image)"), std::string::npos)
      << none.output;
  EXPECT_FALSE(fs::exists(path("n.tif")));
}

// Every frame's name is checked before the first frame renders: a frame
// that cannot be written stops the turntable before any earlier frame
// replaces a file (it wrote frames 0 and 1 over what was there, then
// stopped), and -o's own name, which a turntable does not write, may be
// anything.
TEST_F(Cli, TurntableStopsAtAFrameItCannotWrite) {
  fs::create_directories(dir_ / "t_0002.png");
  std::ofstream(dir_ / "t_0000.png") << "kept";
  const Result r =
      run("render --phantom-size 16 --size 16x16 --frames 5 --step 5 -o " + path("t.png"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("-o: " + path("t_0002.png") + " is a directory"), std::string::npos)
      << r.output;
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"t_0000.png", "t_0002.png"}));
  EXPECT_TRUE(fs::is_directory(dir_ / "t_0002.png"));
  std::ifstream in(dir_ / "t_0000.png");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), {}), "kept");
  // -o names a directory, its numbered frames are free: written.
  fs::remove(dir_ / "t_0002.png");
  fs::remove(dir_ / "t_0000.png");
  fs::create_directories(dir_ / "t.png");
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 --frames 2 -o " + path("t.png")).code, 0);
  EXPECT_EQ(simdvol::read_image(path("t_0001.png")).width(), 16);
}

namespace {

/// Every file in `dir` by name, with its bytes.
std::map<std::string, std::string> files_of(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    files[e.path().filename().string()] = std::string(std::istreambuf_iterator<char>(in), {});
  }
  return files;
}

}  // namespace

// A turntable replaces its frames together, once the last has rendered and
// been written: a write or a render that fails part way (at frame 1 here)
// leaves an earlier run's frames byte for byte as they were, and no
// temporary file. Before, frame 0 had replaced its file by then and the
// later frames were the earlier run's: a mixed set, part of it lost. The
// write: frame 1 of these views (29,456 bytes, frame 0 26,022) past a
// file-size limit of 27,648 bytes; the render: frame 1's footprints (the
// allocation hook).
TEST_F(Cli, ATurntableThatFailsLeavesAnEarlierRunsFramesAsTheyWere) {
  const std::string tf = path("tf.txt");
  std::ofstream(tf) << "density 0 0 24 1 255 1\ngradient 0 0 5 0 20 1 221 1\ncolor 0 1 1 1\n";
  const std::string common = " --phantom-size 32 --size 256x256 --frames 4 -o " + path("t.png");
  // The earlier run: other views, so that every frame's bytes differ.
  ASSERT_EQ(run("render --engine reference --view 0,5,0 --step 10" + common).code, 0);
  const std::map<std::string, std::string> before = files_of(dir_);
  ASSERT_EQ(before.size(), 5u);
  // (sh's ulimit -f counts 512-byte blocks)
  const Result w = run_once("render --engine reference --step 45" + common, "", "ulimit -f 54;");
  EXPECT_EQ(w.code, 1) << w.output;
  EXPECT_NE(w.output.find("simdvol: error: " + path("t_0001.png") + ": "), std::string::npos)
      << w.output;
  EXPECT_NE(w.output.find("(the file-size limit, ulimit -f, is 27648 bytes)"), std::string::npos)
      << w.output;
  EXPECT_TRUE(files_of(dir_) == before) << "a failed write changed or left files";
  const Result r =
      run("render --step 45 --classify " + tf + common, "SIMDVOL_FAIL_ALLOCATION=footprints:2");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("clCreateBuffer(footprints, "), std::string::npos) << r.output;
  EXPECT_TRUE(files_of(dir_) == before) << "a failed render changed or left files";
  // Without a failure every frame is replaced.
  ASSERT_EQ(run("render --engine reference --step 45" + common).code, 0);
  const std::map<std::string, std::string> after = files_of(dir_);
  ASSERT_EQ(after.size(), 5u);
  for (const char* f : {"t_0000.png", "t_0001.png", "t_0002.png", "t_0003.png"})
    EXPECT_TRUE(after.at(f) != before.at(f)) << f << " not replaced";
}

// A turntable ended by a signal (SIGTERM after frame 1 is written, frames
// 2 to 4 still to render) leaves an earlier run's frames as they were and
// no temporary file: the handlers remove the batch's temporary files
// (ImageBatch), and no frame has replaced its file yet. Before, frames 0
// and 1 had replaced theirs. Started directly (no shell between), so that
// the signal reaches it.
TEST_F(Cli, ATurntableEndedBySignalLeavesAnEarlierRunsFramesAsTheyWere) {
  const std::string out = path("t.png");
  ASSERT_EQ(run("render --engine reference --phantom-size 32 --size 256x256 --frames 5 --view "
                "0,5,0 --step 10 -o " +
                out)
                .code,
            0);
  const std::map<std::string, std::string> before = files_of(dir_);
  ASSERT_EQ(before.size(), 5u);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Slow frames: pixel sampling of the reference engine (about 1 s each).
    ::execl(SIMDVOL_CLI, SIMDVOL_CLI, "render", "--engine", "reference", "--phantom-size", "64",
            "--sampling", "pixel", "--size", "256x256", "--frames", "5", "--step", "45", "-o",
            out.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  // Frame 1 written: two temporary files (frames 0 and 1), or, as before,
  // frame 1 in place.
  bool written = false;
  for (int i = 0; i < 24000 && !written; ++i) {
    ::usleep(5000);
    int temps = 0;
    for (const auto& e : fs::directory_iterator(dir_))
      temps += e.path().filename().string().find(".tmp-") != std::string::npos;
    std::ifstream in(path("t_0001.png"), std::ios::binary);
    written = temps >= 2 ||
              std::string(std::istreambuf_iterator<char>(in), {}) != before.at("t_0001.png");
  }
  EXPECT_TRUE(written) << "frame 1 was not written within 120 s";
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << status;
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  const std::map<std::string, std::string> after = files_of(dir_);
  EXPECT_EQ(after.size(), before.size());
  for (const auto& [name, bytes] : after) {
    const auto was = before.find(name);
    EXPECT_TRUE(was != before.end() && was->second == bytes) << name << " changed or left";
  }
}

// A file-size limit (ulimit -f) that cuts the image short: before, SIGXFSZ
// ended the program (exit 153) with the temporary file left beside the
// output; now each format's write fails with a message naming the output
// and the limit, exit 1, the old file kept and nothing left beside it.
TEST_F(Cli, FileSizeLimitFailsTheWriteAndKeepsTheOldFile) {
  for (const char* name : {"out.png", "out.exr", "out.tif"}) {
    SCOPED_TRACE(name);
    std::ofstream(path(name)) << "kept";
    // sh's ulimit -f counts 512-byte blocks: 10,240 bytes.
    const Result r =
        run_once("render --engine reference --phantom-size 32 --size 256x256 -o " + path(name), "",
                 "ulimit -f 20;");
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_NE(r.output.find("simdvol: error: " + path(name) + ": "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("(the file-size limit, ulimit -f, is 10240 bytes)"), std::string::npos)
        << r.output;
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.insert(e.path().filename().string());
    EXPECT_EQ(names, (std::set<std::string>{name}));
    std::ifstream in(path(name));
    EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), {}), "kept");
    fs::remove(path(name));
  }
  // libpng's own message ("Write Error") does not say why: ours does.
  const Result r =
      run_once("render --engine reference --phantom-size 32 --size 256x256 -o " + path("out.png"),
               "", "ulimit -f 20;");
  EXPECT_NE(r.output.find("cannot write it: File too large"), std::string::npos) << r.output;
}

// The program installs remove_temporary_files_on_signals()'s handlers
// (IoTest.EndingSignalsRemoveTheTemporaryFiles tests what they do): its
// /proc status shows SIGINT, SIGTERM, SIGHUP and SIGQUIT caught and SIGXFSZ
// ignored, and SIGTERM still ends it by that signal, leaving no temporary
// file. Started directly (no shell between), so that the signal reaches it.
TEST_F(Cli, ProgramCatchesTheEndingSignals) {
  const std::string out = path("long.png");
  const pid_t pid = ::fork();
  if (pid == 0) {
    // A long render: pixel sampling of the reference engine at 1024^2.
    ::execl(SIMDVOL_CLI, SIMDVOL_CLI, "render", "--engine", "reference", "--phantom-size", "64",
            "--sampling", "pixel", "--size", "1024x1024", "--frames", "1000", "-o", out.c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  // The masks in hex, bit n - 1 for signal n.
  const auto mask = [&](const std::string& field) -> unsigned long long {
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(in, line))
      if (line.rfind(field + ":", 0) == 0)
        return std::stoull(line.substr(field.size() + 1), nullptr, 16);
    return 0;
  };
  const auto bit = [](int sig) { return 1ull << (sig - 1); };
  const unsigned long long want = bit(SIGINT) | bit(SIGTERM) | bit(SIGHUP) | bit(SIGQUIT);
  unsigned long long caught = 0;
  for (int i = 0; i < 500 && (caught & want) != want; ++i) {
    ::usleep(10000);
    caught = mask("SigCgt");
  }
  EXPECT_EQ(caught & want, want) << std::hex << caught;
  EXPECT_NE(mask("SigIgn") & bit(SIGXFSZ), 0u);
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << status;
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST_F(Cli, SkipPesLeavesPesOutWithTheSameImage) {
  // --times reports the PEs that got samples: fewer by default (the PEs with
  // nothing in reach take no part) than with --no-skip-pes, and without
  // balancing the images are the same.
  auto busy = [](const std::string& out) {
    const std::size_t at = out.find(" samples on ");
    EXPECT_NE(at, std::string::npos) << out;
    return at == std::string::npos ? -1 : std::stol(out.substr(at + 12));
  };
  const std::string common =
      "render --phantom-size 32 --size 40x40 --pe 64 --view 20,35,10 "
      "--balance-sweeps 0 --times -o ";
  const Result a = run(common + path("a.png"));
  const Result b = run(common + path("b.png") + " --no-skip-pes");
  ASSERT_EQ(a.code, 0) << a.output;
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_GT(busy(a.output), 0);
  EXPECT_LT(busy(a.output), busy(b.output));
  const simdvol::Image ia = simdvol::read_image(path("a.png"));
  const simdvol::Image ib = simdvol::read_image(path("b.png"));
  ASSERT_EQ(ia.pixels().size(), ib.pixels().size());
  double sum = 0;
  for (std::size_t k = 0; k < ia.pixels().size(); ++k) {
    EXPECT_EQ(ia.pixels()[k].r, ib.pixels()[k].r);
    EXPECT_EQ(ia.pixels()[k].a, ib.pixels()[k].a);
    sum += ia.pixels()[k].r;
  }
  EXPECT_GT(sum, 1.0);
}

// The reference engine renders per sub-ray Monte Carlo at the PE cells and
// balancing that --pe and --balance-sweeps give, as the OpenCL engine: the
// two frames agree within 1e-5 (float TIFF, every channel), and another PE
// count gives another frame (the sub-rays are cut elsewhere).
TEST_F(Cli, ReferenceRendersPerSubRayMonteCarlo) {
  const std::string common =
      "render --phantom-size 24 --size 32x32 --view 20,35,10 --composite mc --samples 4 "
      "--mc-scope subray ";
  for (const std::string extra : {"--pe 64", "--pe 8 --balance-sweeps 0 --allocate",
                                  "--pe 4x2 --exact-opacity --streams shared"}) {
    const Result a = run(common + extra + " -o " + path("a.tif"));
    const Result b = run(common + extra + " --engine reference -o " + path("b.tif"));
    ASSERT_EQ(a.code, 0) << a.output;
    ASSERT_EQ(b.code, 0) << b.output;
    const simdvol::Image ia = simdvol::read_image(path("a.tif"));
    const simdvol::Image ib = simdvol::read_image(path("b.tif"));
    EXPECT_LE(simdvol::max_abs_diff(ia, ib), 1e-5f) << extra;
    double sum = 0;
    for (const simdvol::Rgba& p : ib.pixels()) sum += p.a;
    EXPECT_GT(sum, 10.0) << extra;
  }
  ASSERT_EQ(run(common + "--pe 64 --engine reference -o " + path("a.tif")).code, 0);
  ASSERT_EQ(run(common + "--pe 8 --engine reference -o " + path("b.tif")).code, 0);
  EXPECT_GT(
      simdvol::max_abs_diff(simdvol::read_image(path("a.tif")), simdvol::read_image(path("b.tif"))),
      1e-3f);
}

// --times names the PEs a frame's shade left out: none in a turntable's
// first frame (every cell shaded), the kept volume's transparent cells in
// the next ones (RenderEngine's live mask), never every PE.
TEST_F(Cli, TimesNameThePesTheShadeLeftOut) {
  const Result r =
      run("render --phantom-size 32 --size 40x40 --pe 64 --view 20,35,10 --frames 3 --step 10 "
          "--times -o " +
          path("t.png"));
  ASSERT_EQ(r.code, 0) << r.output;
  std::vector<long> left;
  std::istringstream lines(r.output);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("frame ", 0) != 0) continue;
    const std::size_t at = line.find(", shade left out ");
    left.push_back(at == std::string::npos ? 0 : std::stol(line.substr(at + 17)));
    if (at != std::string::npos) {
      EXPECT_NE(line.find(" PEs", at + 17), std::string::npos) << line;
    }
  }
  ASSERT_EQ(left.size(), 3u) << r.output;
  EXPECT_EQ(left[0], 0);
  EXPECT_GT(left[1], 0);
  EXPECT_LT(left[1], 64);
  EXPECT_EQ(left[2], left[1]);
}

namespace {

// The frames of a --times run, one line each: whether the line says
// "classification kept" and "classification let go".
struct FrameNote {
  bool kept = false, let_go = false;
};
std::vector<FrameNote> frame_notes(const std::string& out) {
  std::vector<FrameNote> notes;
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("frame ", 0) != 0) continue;
    notes.push_back({line.find(", classification kept") != std::string::npos,
                     line.find(", classification let go (memory ran out)") != std::string::npos});
  }
  return notes;
}

// How many pixels of two images differ in any channel (-1: other sizes);
// `alpha` receives the first one's alpha sum.
long differing_pixels(const std::string& a, const std::string& b, double* alpha) {
  const simdvol::Image ia = simdvol::read_image(a);
  const simdvol::Image ib = simdvol::read_image(b);
  if (ia.pixels().size() != ib.pixels().size()) return -1;
  long differ = 0;
  *alpha = 0;
  for (std::size_t k = 0; k < ia.pixels().size(); ++k) {
    const simdvol::Rgba& x = ia.pixels()[k];
    const simdvol::Rgba& y = ib.pixels()[k];
    differ += x.r != y.r || x.g != y.g || x.b != y.b || x.a != y.a;
    *alpha += x.a;
  }
  return differ;
}

// How many frames of a --times run say "classification kept".
int kept_frames(const std::string& out) {
  int n = 0;
  for (const FrameNote& f : frame_notes(out)) n += f.kept;
  return n;
}

// Frames `frames` (suffixes such as "_0001.exr") of the runs written as
// a + suffix and b + suffix are the same bit for bit and not empty (alpha
// sum above 1).
void expect_same_frames(const std::string& a, const std::string& b,
                        std::initializer_list<const char*> frames, const std::string& what = "") {
  for (const char* frame : frames) {
    double alpha = 0;
    EXPECT_EQ(differing_pixels(a + frame, b + frame, &alpha), 0) << what << frame;
    EXPECT_GT(alpha, 1.0) << what << frame;
  }
}

}  // namespace

// The kept classification is kept only where it fits one allocation
// (engine.cpp): a 200^3 phantom at 8,192 PEs has cells 13 voxels wide, so
// its kept planes hold the gradient too (7 / 4 of the 148 MiB of RGBA
// cells, 259 MiB). With PoCL's device memory limited to 1 GiB (its largest
// allocation then 256 MiB) the frames classify every time instead, and
// their images are the same as the kept ones bit for bit.
TEST_F(Cli, KeptClassificationLeftOutWhereItDoesNotFit) {
  const std::string limit = "POCL_MEMORY_LIMIT=1";
  const Result dev = run("devices", limit);
  if (dev.output.find("max allocation 256 MiB") == std::string::npos)
    GTEST_SKIP() << "the device does not take POCL_MEMORY_LIMIT: " << dev.output;
  const std::string common =
      "render --phantom-size 200 --size 64x64 --view 20,35,10 --frames 3 --step 0 --times -o ";
  const Result a = run(common + path("a.exr"));
  const Result b = run(common + path("b.exr"), limit);
  ASSERT_EQ(a.code, 0) << a.output;
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_EQ(kept_frames(a.output), 2) << a.output;  // frames 1 and 2
  EXPECT_EQ(kept_frames(b.output), 0) << b.output;
  expect_same_frames(path("a"), path("b"), {"_0000.exr", "_0002.exr"});
}

// The fused shade + classify stores voxel cells of 64 MiB or more
// non-temporally where they were stored before (a turntable's later frames;
// chunk_ranges.hpp, nt_out): a 168^3 phantom's cells (76 MB at 8,192 PEs),
// the kept classification lit from other views in frames 1 and 2. The same
// frames bit for bit as with ordinary stores (SIMDVOL_NT_STORES=0).
TEST_F(Cli, NonTemporalStoresGiveTheSameFrames) {
  const std::string common =
      "render --phantom-size 168 --size 64x64 --view 20,35,10 --frames 3 --step 10 --times -o ";
  const Result a = run(common + path("a.exr"));
  const Result b = run(common + path("b.exr"), "SIMDVOL_NT_STORES=0");
  ASSERT_EQ(a.code, 0) << a.output;
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_EQ(kept_frames(a.output), 2) << a.output;  // frames 1 and 2 light the kept classification
  expect_same_frames(path("a"), path("b"), {"_0001.exr", "_0002.exr"});
}

// Where memory runs out for the kept classification, the frames classify
// as where it never fit, with the same images bit for bit: its buffer's
// allocation failing (the engine's catch), or a later allocation of a frame
// that holds it (RenderEngine::render lets it go and renders the frame
// again). SIMDVOL_FAIL_ALLOCATION=WHAT[:N] makes the N-th request for the
// buffer named WHAT fail as a device out of memory would (a test hook of
// Device): the kept planes in frame 0, the footprints in frame 1 (its
// second request for them; the kept planes were made in frame 0).
TEST_F(Cli, KeptClassificationLetGoWhereMemoryRunsOut) {
  const std::string common =
      "render --phantom-size 64 --size 48x48 --pe 512 --view 20,35,10 --frames 3 --step 0 "
      "--times -o ";
  const Result a = run(common + path("a.exr"));
  ASSERT_EQ(a.code, 0) << a.output;
  const std::vector<FrameNote> na = frame_notes(a.output);
  ASSERT_EQ(na.size(), 3u) << a.output;
  EXPECT_TRUE(!na[0].kept && na[1].kept && na[2].kept) << a.output;
  for (const FrameNote& n : na) EXPECT_FALSE(n.let_go) << a.output;
  struct Case {
    const char* fail;
    const char* out;
    int let_go_frame;
  };
  for (const Case c : {Case{"kept classification", "b", 0}, Case{"footprints:2", "c", 1}}) {
    const Result r = run(common + path(std::string(c.out) + ".exr"),
                         std::string("SIMDVOL_FAIL_ALLOCATION='") + c.fail + "'");
    ASSERT_EQ(r.code, 0) << c.fail << "\n" << r.output;
    const std::vector<FrameNote> n = frame_notes(r.output);
    ASSERT_EQ(n.size(), 3u) << r.output;
    for (int f = 0; f < 3; ++f) {
      EXPECT_EQ(n[f].let_go, f == c.let_go_frame) << c.fail << ", frame " << f << "\n" << r.output;
      // kept before the frame that let it go (frame 0 never reads it), not after
      EXPECT_EQ(n[f].kept, f > 0 && f < c.let_go_frame) << c.fail << ", frame " << f;
    }
    expect_same_frames(path("a"), path(c.out), {"_0000.exr", "_0001.exr", "_0002.exr"}, c.fail);
  }
}

// --trace of a turntable that fails part way: the frames rendered before
// the error are in the trace (before, it was written only after the last
// frame, and a failure lost it all), with a note saying so; the error is
// still the exit status.
TEST_F(Cli, TraceKeepsTheFramesBeforeAnError) {
  const std::string tf = path("tf.txt");
  std::ofstream(tf) << "density 0 0 24 1 255 1\ngradient 0 0 5 0 20 1 221 1\ncolor 0 1 1 1\n";
  // The footprints' second request: frame 1 (a transfer function keeps no
  // classification, so frame 0 asks for them once).
  const Result r =
      run("render --phantom-size 32 --size 32x32 --classify " + tf +
              " --frames 4 --step 30 --trace " + path("t.json") + " -o " + path("t.png"),
          "SIMDVOL_FAIL_ALLOCATION=footprints:2");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("clCreateBuffer(footprints, "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("simdvol: note: --trace " + path("t.json") +
                          " holds the frame rendered before the error"),
            std::string::npos)
      << r.output;
  std::ifstream in(path("t.json"));
  const std::string json((std::istreambuf_iterator<char>(in)), {});
  EXPECT_NE(json.find("\"name\": \"simdvol_layout\""), std::string::npos) << json.substr(0, 400);
  EXPECT_NE(json.find("\"frame\": 0"), std::string::npos);
  EXPECT_EQ(json.find("\"frame\": 1"), std::string::npos);
  // No frame is written (they replace their files together, after the last
  // frame), and no temporary file is left.
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"tf.txt", "t.json"}));
  // Without the failure all four frames are in it.
  const Result ok = run("render --phantom-size 32 --size 32x32 --classify " + tf +
                        " --frames 4 --step 30 --trace " + path("t.json") + " -o " + path("t.png"));
  ASSERT_EQ(ok.code, 0) << ok.output;
  std::ifstream in2(path("t.json"));
  const std::string all((std::istreambuf_iterator<char>(in2)), {});
  EXPECT_NE(all.find("\"frame\": 3"), std::string::npos);
}

// A single frame keeps no classification (it would only write it, and hold
// as much memory as the RGBA voxel cells): it never asks for the kept
// planes, so a failure injected there changes nothing.
TEST_F(Cli, SingleFrameKeepsNoClassification) {
  const Result r = run("render --phantom-size 64 --size 48x48 --pe 512 --times -o " + path("s.png"),
                       "SIMDVOL_FAIL_ALLOCATION='kept classification'");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<FrameNote> n = frame_notes(r.output);
  ASSERT_EQ(n.size(), 1u) << r.output;
  EXPECT_FALSE(n[0].kept || n[0].let_go) << r.output;
  // The engine fuses shade and classify: one figure, not "shade 0 ms"; a
  // direct frame lists its swap's launches.
  EXPECT_NE(r.output.find("shade + classify (one kernel) "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("shade 0 ms"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" ms ("), std::string::npos) << r.output;
}

// Out of memory is an error naming the buffer, with exit code 1 and no
// output file: injected for the footprints of a frame that keeps no
// classification (a transfer function's), and for real under an address
// space limit (ulimit -v) that leaves the 256^3 phantom's 268 MB of RGBA
// voxel cells no room. PoCL 3.1 allocates a buffer only when a command
// first uses it and aborts the process where that fails; the Device asks
// for host memory (CL_MEM_ALLOC_HOST_PTR) on a CPU device, so that the
// failure comes from clCreateBuffer instead.
TEST_F(Cli, OutOfMemoryIsAnErrorNamingTheBuffer) {
  const std::string tf = path("tf.txt");
  std::ofstream(tf) << "density 0 0 24 1 255 1\ngradient 0 0 5 0 20 1 221 1\ncolor 0 1 1 1\n";
  const Result inj =
      run("render --phantom-size 32 --size 32x32 --classify " + tf + " -o " + path("i.png"),
          "SIMDVOL_FAIL_ALLOCATION=footprints");
  EXPECT_EQ(inj.code, 1) << inj.output;
  EXPECT_NE(inj.output.find("clCreateBuffer(footprints, "), std::string::npos) << inj.output;
  EXPECT_NE(inj.output.find("CL_MEM_OBJECT_ALLOCATION_FAILURE"), std::string::npos) << inj.output;
  EXPECT_FALSE(fs::exists(path("i.png")));
  const Result bad =
      run("render --phantom-size 16 -o " + path("j.png"), "SIMDVOL_FAIL_ALLOCATION=footprints:0");
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("SIMDVOL_FAIL_ALLOCATION"), std::string::npos) << bad.output;

  if (simdvol::testing::kUnderAsan)
    GTEST_SKIP() << "an address space limit and AddressSanitizer's shadow memory do not mix";
  const Result dev = run("devices");
  if (dev.output.find("CPU") == std::string::npos)
    GTEST_SKIP() << "the default device is not a CPU device: " << dev.output;
  // The same render first without the limit (it builds the kernels into
  // PoCL's cache: under the limit no compiler runs), then under it.
  const std::string args = "render --size 64x64 -o ";
  ASSERT_EQ(run(args + path("w.png")).code, 0);
  const Result r = run_once(args + path("o.png"), "", "ulimit -v 700000; exec");
  EXPECT_EQ(r.code, 1) << r.output;  // not an abort (134) inside PoCL
  EXPECT_NE(r.output.find("memory"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("o.png")));
}

// --trace: every frame's kernels as a Chrome trace, one event per line;
// within a frame each kernel starts after the one before ended (one
// in-order queue), the second frame after the first, and the frames hold
// the stages' kernels; --times sums them up.
TEST_F(Cli, TraceHoldsEveryFramesKernelsInOrder) {
  const Result r =
      run("render --phantom-size 32 --size 40x40 --pe 64 --frames 2 --step 5 "
          "--times --trace " +
          path("t.json") + " -o " + path("t.png"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find(" ms span"), std::string::npos) << r.output;
  std::ifstream in(path("t.json"));
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line, "{\"displayTimeUnit\": \"ms\", \"traceEvents\": [");
  const std::regex ev(
      R"re(\{"name": "(simdvol_[a-z0-9_]+)", "cat": "kernel", "ph": "X", "ts": ([0-9]+\.[0-9]{3}), "dur": ([0-9]+\.[0-9]{3}), "pid": 1, "tid": 1, "args": \{"frame": ([01])\}\},?)re");
  std::vector<std::set<std::string>> names(2);
  double end = -1;
  int events = 0, frame = 0;
  bool closed = false;
  while (std::getline(in, line)) {
    if (line == "]}") {
      closed = true;
      break;
    }
    std::smatch m;
    ASSERT_TRUE(std::regex_match(line, m, ev)) << line;
    const double ts = std::stod(m[2]), dur = std::stod(m[3]);
    const int f = std::stoi(m[4]);
    EXPECT_GE(f, frame) << line;
    frame = f;
    EXPECT_GE(ts + 0.0015, end) << line;  // (each figure rounded to 1 ns)
    end = ts + dur;
    names[static_cast<std::size_t>(f)].insert(m[1]);
    ++events;
  }
  EXPECT_TRUE(closed);
  EXPECT_GE(events, 20);
  for (const auto& n : names)
    for (const char* want :
         {"simdvol_shade_classify16_il", "simdvol_match_fill", "simdvol_display", "simdvol_warp"})
      EXPECT_EQ(n.count(want), 1u) << want;
  EXPECT_EQ(names[0].count("simdvol_layout"), 1u);  // the second frame keeps the layout
  EXPECT_EQ(names[1].count("simdvol_layout"), 0u);
}

// --light, --phong and --depth-cue reach the shading of both engines: each
// engine's PNG equals the reference rendered here with those ShadeParams
// set field by field (to the PNG's 8-bit rounding), and differs from the
// default lighting's image.
TEST_F(Cli, LightingOptionsReachBothEngines) {
  const std::string common =
      "render --phantom-size 24 --size 32x32 --view 20,35,10 --light 0.3,-0.2,-1 "
      "--phong 0.1,0.8,0.5,8 --depth-cue 1,0.3 -o ";
  const Result a = run(common + path("cl.png"));
  const Result b = run(common + path("ref.png") + " --engine reference");
  const Result d =
      run("render --phantom-size 24 --size 32x32 --view 20,35,10 -o " + path("default.png"));
  ASSERT_EQ(a.code, 0) << a.output;
  ASSERT_EQ(b.code, 0) << b.output;
  ASSERT_EQ(d.code, 0) << d.output;
  simdvol::RenderOptions opt;
  opt.view = {20, 35, 10};
  opt.width = opt.height = 32;
  opt.classifier = simdvol::classifier_preset("ct");  // auto: Hounsfield data
  opt.shade.light = {0.3, -0.2, -1.0};
  opt.shade.ka = 0.1;
  opt.shade.kd = 0.8;
  opt.shade.ks = 0.5;
  opt.shade.shininess = 8;
  opt.shade.k1 = 1.0;
  opt.shade.k2 = 0.3;
  const simdvol::Image want = simdvol::render_reference(simdvol::shepp_logan(24, 4), opt);
  const simdvol::Image dflt = simdvol::read_image(path("default.png"));
  for (const char* f : {"cl.png", "ref.png"}) {
    SCOPED_TRACE(f);
    const simdvol::Image got = simdvol::read_image(path(f));
    ASSERT_EQ(got.pixels().size(), want.pixels().size());
    double worst = 0, changed = 0;
    for (std::size_t k = 0; k < got.pixels().size(); ++k) {
      const auto& g = got.pixels()[k];
      const auto& w = want.pixels()[k];
      const float gc[3] = {g.r, g.g, g.b}, wc[3] = {w.r, w.g, w.b};
      const float dc[3] = {dflt.pixels()[k].r, dflt.pixels()[k].g, dflt.pixels()[k].b};
      for (int c = 0; c < 3; ++c) {
        worst = std::max(worst, std::fabs(double(gc[c]) - std::clamp(double(wc[c]), 0.0, 1.0)));
        changed = std::max(changed, std::fabs(double(gc[c]) - double(dc[c])));
      }
    }
    EXPECT_LE(worst, 0.5 / 255 + 1e-5);
    EXPECT_GT(changed, 0.05);
  }
}

// --seed reaches the Monte Carlo render: on each engine the same seed
// gives the same bytes, another seed another image, and each image is the
// library's reference Monte Carlo render with its seed (float TIFF, within
// 1e-5; the two seeds' reference images differ by far more). An ignored
// --seed had been caught only by the slow independent check: the other
// Cli tests render every Monte Carlo frame with one seed.
TEST_F(Cli, SeedReachesTheMonteCarloRender) {
  const std::string common =
      "render --phantom-size 24 --size 32x32 --view 20,35,10 --composite mc --samples 4 ";
  const auto bytes = [](const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  simdvol::RenderOptions opt;
  opt.view = {20, 35, 10};
  opt.width = opt.height = 32;
  opt.classifier = simdvol::classifier_preset("ct");  // auto: Hounsfield data
  opt.composite.mode = simdvol::CompositeMode::mc;
  opt.composite.samples = 4;
  const simdvol::Volume vol = simdvol::shepp_logan(24, 4);
  opt.composite.seed = 7;
  const simdvol::Image want7 = simdvol::render_reference(vol, opt);
  opt.composite.seed = 12345;
  const simdvol::Image want12345 = simdvol::render_reference(vol, opt);
  ASSERT_GT(simdvol::max_abs_diff(want7, want12345), 0.05f);
  for (const char* engine : {"opencl", "reference"}) {
    SCOPED_TRACE(engine);
    const std::string e = std::string("--engine ") + engine + " ";
    using Run = std::pair<const char*, const char*>;  // --seed, -o
    for (const auto& [seed, out] : {Run{"7", "a.tif"}, Run{"7", "b.tif"}, Run{"12345", "c.tif"}}) {
      const std::string args = common + e + "--seed " + seed + " -o " + path(out);
      const Result r = run(args);
      ASSERT_EQ(r.code, 0) << args << "\n" << r.output;
    }
    EXPECT_EQ(bytes(path("a.tif")), bytes(path("b.tif")));
    const simdvol::Image a = simdvol::read_image(path("a.tif"));
    const simdvol::Image c = simdvol::read_image(path("c.tif"));
    EXPECT_LE(simdvol::max_abs_diff(a, want7), 1e-5f);
    EXPECT_LE(simdvol::max_abs_diff(c, want12345), 1e-5f);
    EXPECT_GT(simdvol::max_abs_diff(a, c), 0.05f);
  }
}

TEST_F(Cli, BadArgumentsFailClearly) {
  struct Case {
    std::string args, needle;
  };
  const Case cases[] = {
      {"render --order 4 -o " + path("x.png"), "--order"},
      {"render --view 1,2 -o " + path("x.png"), "--view"},
      {"render --size 0x10 -o " + path("x.png"), "--size"},
      {"render --size abc -o " + path("x.png"), "--size"},
      {"render --sampling warp -o " + path("x.png"), "--sampling"},
      {"render --fit tight -o " + path("x.png"), "--fit"},
      {"render --composite fancy -o " + path("x.png"), "--composite"},
      {"render --classify nosuchpreset -o " + path("x.png"), "nosuchpreset"},
      {"render --engine gpu -o " + path("x.png"), "--engine"},
      {"render --mc-scope half -o " + path("x.png"), "--mc-scope"},
      {"render --layout spiral -o " + path("x.png"), "--layout"},
      {"render --balance-sweeps 65 -o " + path("x.png"), "--balance-sweeps"},
      {"render --balance-sweeps -1 -o " + path("x.png"), "--balance-sweeps"},
      {"render --composite mc --seed -1 -o " + path("x.png"), "--seed"},
      {"render " + path("vol.raw") + " --raw-dims 2,2,2 --raw-header -5 -o " + path("x.png"),
       "--raw-header"},
      {"render --composite mc --allocate -o " + path("x.png"), "--allocate"},
      {"render --trace " + path("t.txt") + " -o " + path("x.png"), ".json"},
      {"render --trace " + path("x.png") + " -o " + path("x.png"), "--trace"},
      {"render --engine reference --trace " + path("t.json") + " -o " + path("x.png"), "--trace"},
      {"render --trace " + path("no/t.json") + " -o " + path("x.png"), "--trace"},
      {"render --composite mc --mc-stratified -o " + path("x.png"), "--mc-stratified"},
      // (with direct or adaptive compositing it was taken and did nothing)
      {"render --exact-opacity --mc-stratified -o " + path("x.png"),
       "--exact-opacity: applies only to --composite mc"},
      {"render --composite adaptive --mc-stratified -o " + path("x.png"),
       "--mc-stratified: applies only to --composite mc"},
      {"render --composite direct --allocate -o " + path("x.png"),
       "--allocate: needs --composite mc"},
      {"render --engine reference --composite mc --mc-scope subray --layout hierarchical -o " +
           path("x.png"),
       "--layout: applies only to --engine opencl"},
      {"render --engine reference --composite mc --mc-scope subray --pe 12 -o " + path("x.png"),
       "--pe"},
      {"render --phantom-size 16 -o " + path("nodir/x.png"), "nodir"},
      {"render --phantom-size 16 -o " + path("x.bmpx"), "x.bmpx"},
      {"render " + path("missing.nrrd") + " -o " + path("x.png"), "missing.nrrd"},
      {"render " + path("vol.xyz") + " -o " + path("x.png"), "vol.xyz"},
      {"info " + path("missing.den"), "missing.den"},
      {"info " + path("adir"), "adir: holds no DICOM image"},  // (a directory is a DICOM series)
      {"render --classify " + path("adir") + " -o " + path("x.png"), "adir: is a directory"},
      {"compare " + path("adir") + " " + path("adir"), "adir: is a directory"},
      {"render " + path("adir.nrrd") + " -o " + path("x.png"), "adir.nrrd: is a directory"},
      {"render --light 0,0,0 -o " + path("x.png"), "--light"},
      {"render --light 1,2 -o " + path("x.png"), "--light"},
      {"render --light 1,2,3, -o " + path("x.png"), "--light"},
      {"render --phong 0.2,0.7,0.3 -o " + path("x.png"), "--phong"},
      {"render --phong 0.2,-0.7,0.3,8 -o " + path("x.png"), "--phong"},
      {"render --phong 0.2,0.7,0.3,nan -o " + path("x.png"), "--phong"},
      {"render --depth-cue 0,1 -o " + path("x.png"), "--depth-cue"},
      {"render --depth-cue 1,-1 -o " + path("x.png"), "--depth-cue"},
      {"render --view 1,2,3, -o " + path("x.png"), "--view"},
      {"phantom cube --size 8 -o " + path("c.nrrd"), "cube"},
      {"phantom shepp-logan --size 0 -o " + path("c.nrrd"), "--size"},
      // The phantom is NRRD whatever the name said (a .png of NRRD bytes).
      {"phantom shepp-logan --size 8 -o " + path("x.png"), "give a name ending in .nrrd"},
      // Numbers reported as given (a single --size was clamped to -1x-1).
      {"render --size -5 -o " + path("x.png"), "--size: -5 is outside 1 .. 16384"},
      {"render --size 3000000000 -o " + path("x.png"), "3000000000 is outside"},
      {"render --device -1 -o " + path("x.png"), "--device: -1 is negative"},
      // Whole numbers past a 64-bit option's range (taken as its largest).
      {"render --composite mc --seed 18446744073709551616 -o " + path("x.png"),
       "--seed: 18446744073709551616 is outside 0 .. 18446744073709551615"},
      {"render --volume-index 99999999999999999999 " + path("vol.raw") + " -o " + path("x.png"),
       "--volume-index: 99999999999999999999 is outside"},
      {"render " + path("vol.raw") + " --raw-dims 2,2,2 --raw-header 18446744073709551616 -o " +
           path("x.png"),
       "--raw-header: 18446744073709551616 is outside"},
      // "32x" was taken as 32x32.
      {"render --size 32x -o " + path("x.png"), "--size: expected WxH, e.g. 256x256, not '32x'"},
      // An empty name rendered the phantom (render "$VOL", VOL unset).
      {"render '' -o " + path("x.png"), "volume: empty name"},
      {"render --step 5 -o " + path("x.png"),
       "--step: applies only to turntables (--frames 2 or more)"},
      // Checked before the first frame (it said --view after two frames).
      {"render --phantom-size 16 --frames 3 --step 1e308 -o " + path("t.png"), "--step"},
      {"render --phantom-size 16 --frames 2 -o " + path("noext"), "unknown image extension"},
      {"mismatch --size 8 --size3 4 --plot " + path("x.jpg"), "unknown image extension"},
      {"mismatch --size 8 --size3 4 --plot " + path("m.png") + " --csv " + path("m.png"),
       "--plot and --csv: both name"},
      // A FIFO blocked the read, /dev/zero filled the memory.
      {"render --classify " + path("fifo.tf") + " -o " + path("x.png"),
       "fifo.tf: is not a regular file"},
      {"render --classify /dev/zero -o " + path("x.png"), "/dev/zero: is not a regular file"},
      {"render --classify " + path("sigma.tf") + " -o " + path("x.png"),
       "sigma.tf: line 2: sigma 1e-39 of 'a' is too small"},
      {"render --classify " + path("wide.tf") + " -o " + path("x.png"),
       "wide.tf: line 1: density x values -1e+38 and 3e+38 are too far apart"},
      // Voxel sampling at the smallest spacing: a 1.6e8^2 intermediate image
      // (the engine grew to 5 GB and ran on; the reference threw bad_alloc).
      {"render " + path("v16.raw") + " --raw-dims 16,16,16 --raw-spacing 1,1,1e7 -o " +
           path("x.png"),
       "use --sampling pixel"},
      {"render " + path("v16.raw") +
           " --raw-dims 16,16,16 --raw-spacing 1,1,1e4 --engine "
           "reference -o " +
           path("x.png"),
       "16x16x16 voxels of spacing 1,1,10000 need a viewing grid of 160002 x 160002"},
      {"render " + path("v16.raw") +
           " --raw-dims 16,16,16 --raw-spacing 1e300,1,1e-300 --sampling pixel -o " + path("x.png"),
       "its largest over its smallest is too large"},
      // Whole numbers in decimal only: CLI11 read "010" in base 0, as octal
      // (8 frames, volume 8, a 52^3 phantom), and "0x10" as 16.
      {"render --phantom-size 16 --frames 010 -o " + path("t.png"),
       "--frames: '010' has a leading zero"},
      {"render --order 01 -o " + path("x.png"), "--order: '01' has a leading zero"},
      {"render --composite mc --seed 0x10 -o " + path("x.png"),
       "--seed: expected a whole number in decimal, not '0x10'"},
      {"render --composite mc --samples 032 -o " + path("x.png"), "--samples: '032'"},
      {"render --balance-sweeps 08 -o " + path("x.png"), "--balance-sweeps: '08'"},
      {"render --phantom-size 016 -o " + path("x.png"), "--phantom-size: '016'"},
      {"render --device 00 -o " + path("x.png"), "--device: '00'"},
      {"info " + path("vol.raw") + " --raw-dims 2,2,2 --raw-header 010", "--raw-header: '010'"},
      {"info " + path("vol.raw") + " --volume-index 010", "--volume-index: '010'"},
      {"phantom shepp-logan --size 064 -o " + path("c.nrrd"), "--size: '064' has a leading zero"},
      {"phantom shepp-logan --size 8 --supersample 04 -o " + path("c.nrrd"), "--supersample: '04'"},
      {"mismatch --size 010 --size3 4", "--size: '010'"},
      // The same rule inside lists (010x64 was a 10x64 image, 0512 PEs 512).
      {"render --size 010x64 -o " + path("x.png"), "--size: '010' has a leading zero"},
      {"render --size 1e2 -o " + path("x.png"),
       "--size: expected a whole number in decimal, not '1e2'"},
      {"render --pe 0512 -o " + path("x.png"), "--pe: \"0512\" is not a PE count"},
      {"render --pe 032x16 -o " + path("x.png"), "--pe: \"032x16\" is not a PE count"},
      {"info " + path("vol.raw") + " --raw-dims 02,2,2", "--raw-dims: '02' has a leading zero"},
      // --no-skip-pes where every PE is matched already.
      {"render --composite mc --mc-scope subray --no-skip-pes -o " + path("x.png"),
       "--no-skip-pes: applies only to direct, adaptive, whole-ray Monte Carlo, and per sub-ray "
       "Monte Carlo with --balance-sweeps 0"},
      {"render --no-skip-empty --no-skip-pes -o " + path("x.png"),
       "--no-skip-pes: applies only to renders that skip the empty samples"},
      // Angles in -360 .. 360 degrees, as the bench tools take them (1e300
      // was taken); lists without a trailing comma, as render's others.
      {"render --view 1e300,0,0 -o " + path("x.png"),
       "--view: '1e300,0,0': each angle must be in -360 .. 360 degrees"},
      {"mismatch --size 8 --size3 4 --view 30,20,10,",
       "--view: expected THETA,PHI,VARPHI in degrees, not '30,20,10,'"},
      {"mismatch --size 8 --size3 4 --view 400,0,0", "--view: '400,0,0': each angle must be in"},
      {"mismatch --size 8 --size3 4 --theta 1e300", "--theta: must be in -360 .. 360 degrees"},
      {"info " + path("vol.raw") + " --raw-dims 2,2,2,",
       "--raw-dims: expected NX,NY,NZ, not '2,2,2,'"},
      {"info ''", "volume: empty name"},
      // It made the same file as without it.
      {"phantom marschner-lobb --size 8 --supersample 2 -o " + path("c.nrrd"),
       "--supersample: applies only to shepp-logan"},
      {"phantom shepp-logan --size 8 -o " + path(".nrrd"), "give a name ending in .nrrd"},
      // -o: a file where its directory should be (said "does not exist"), a
      // FIFO (replaced by a file), a link into a missing directory (found
      // only after the render).
      {"render --phantom-size 16 -o " + path("afile/x.png"),
       path("afile") + ", the directory of " + path("afile/x.png") + ", is not a directory"},
      {"render --phantom-size 16 -o " + path("fifo.png"), "fifo.png is not a regular file"},
      {"render --phantom-size 16 -o " + path("dangling.png"),
       "directory " + path("nodir2") + " of " + path("dangling.png") + " does not exist"},
      // A name that cannot be looked up (it was "unknown volume file
      // extension ''", and as --classify "no such classifier file").
      {"info " + path("loopA"), path("loopA") + ": Too many levels of symbolic links"},
      {"render --classify " + path("loopA") + " -o " + path("x.png"),
       path("loopA") + ": Too many levels of symbolic links"},
      {"info " + path("missing"), path("missing") + ": no such file"},
      // Lighting beyond float: the device's image was 42-52 dB from the
      // reference's (an infinite cue times 0), or it refused with
      // "shade.k1" where the reference rendered.
      {"render --light 1,0,0 --depth-cue 1e-40,0 -o " + path("x.png"),
       "--phong and --depth-cue: a voxel's light could reach"},
      {"render --engine reference --phong 0,0,3e38,1 -o " + path("x.png"),
       "--phong: coefficients and the exponent must be at most 1e30 (got 3e+38)"},
      {"render --light 1e400,0,0 -o " + path("x.png"),
       "--light: '1e400' is beyond the largest number"},
      {"render --view 0x1p3,0,0 -o " + path("x.png"), "--view: '0x1p3' is not a number"},
      {"render --frames 2 --step 1e300 -o " + path("t.png"),
       "--step: must be in -360 .. 360 degrees per frame"},
      // The engine's own shape of 8192 PEs is 128x64: 1x8192 was taken as
      // its count alone.
      {"render --pe 1x8192 -o " + path("x.png"),
       "--pe: 1x8192: the engine arranges 8192 PEs as 128x64"},
      {"mismatch --size 8 --size3 4 --csv ''", "--csv: empty output path"},
      {"mismatch --size 8 --size3 4 --plot ''", "--plot: empty output path"},
      // Options that do nothing in the chosen mode are refused, not ignored.
      {"render --samples 8 -o " + path("x.png"), "--samples: applies only to --composite mc"},
      {"render --exact-opacity -o " + path("x.png"),
       "--exact-opacity: applies only to --composite mc"},
      {"render --composite adaptive --mc-scope subray -o " + path("x.png"),
       "--mc-scope: applies only to --composite mc"},
      {"render --composite mc --threshold 0.9 -o " + path("x.png"),
       "--threshold: applies only to --composite adaptive"},
      {"render --engine reference --pe 64 -o " + path("x.png"),
       "--pe: applies only to --engine opencl"},
      {"render --engine reference --balance-sweeps 0 -o " + path("x.png"),
       "--balance-sweeps: applies only to --engine opencl"},
      {"render --engine reference --no-skip-pes -o " + path("x.png"),
       "--no-skip-pes: applies only to --engine opencl"},
      {"render --raw-dims 2,2,2 -o " + path("x.png"),
       "--raw-dims: applies only to .raw volumes (no volume given)"},
      {"render --volume-index 1 -o " + path("x.png"),
       "--volume-index: applies only to NIfTI, NRRD, MetaImage, MGH, MINC and DICOM volumes "
       "(.nii, .nii.gz, .hdr/.img, .nrrd, .nhdr, .mha, .mhd, .mgh, .mgz, .mnc, DICOM) (no volume "
       "given)"},
      {"info " + path("vol.raw") + " --raw-dims 2,2,2 --volume-index 0",
       "--volume-index: applies only to NIfTI, NRRD, MetaImage, MGH, MINC and DICOM volumes "
       "(.nii, .nii.gz, .hdr/.img, .nrrd, .nhdr, .mha, .mhd, .mgh, .mgz, .mnc, DICOM) (" +
           path("vol.raw") + " is not one)"},
      {"render --no-shade --light 1,0,0 -o " + path("x.png"),
       "--light: applies only to lit renders (not with --no-shade)"},
      {"render --no-shade --phong 0.1,0.9,0,1 -o " + path("x.png"),
       "--phong: applies only to lit renders (not with --no-shade)"},
      {"render --no-shade --depth-cue 1,0 -o " + path("x.png"),
       "--depth-cue: applies only to lit renders (not with --no-shade)"},
      {"render " + path("v16.raw") + " --raw-dims 16,16,16 --phantom-size 32 -o " + path("x.png"),
       "--phantom-size: applies only to the built-in phantom (a volume file is given)"},
      {"info " + path("vol.xyz") + " --raw-type u16",
       "--raw-type: applies only to .raw volumes (" + path("vol.xyz") + " is not one)"},
      // Too long for the file system: an error, not a filesystem_error.
      {"render --phantom-size 16 -o " + path(std::string(300, 'y') + ".png"),
       "-o: " + path(std::string(300, 'y') + ".png") + ": File name too long"},
      {"mismatch --size 8 --size3 4 --csv " + path(std::string(300, 'y') + ".csv"),
       "--csv: " + path(std::string(300, 'y') + ".csv") + ": File name too long"},
  };
  std::ofstream(dir_ / "vol.xyz") << "junk";
  std::ofstream(dir_ / "vol.raw") << "12345678";
  std::ofstream(dir_ / "v16.raw") << std::string(4096, '\x40');
  std::ofstream(dir_ / "sigma.tf") << "material b 100 10 1 1 1 0.5\nmaterial a 0 1e-39 1 1 1 0.5\n";
  std::ofstream(dir_ / "wide.tf") << "density -1e38 0 3e38 1\n";
  ASSERT_EQ(mkfifo(path("fifo.tf").c_str(), 0600), 0);
  ASSERT_EQ(mkfifo(path("fifo.png").c_str(), 0600), 0);
  std::ofstream(dir_ / "afile") << "keep";
  fs::create_symlink("nodir2/x.png", dir_ / "dangling.png");
  fs::create_symlink("loopB", dir_ / "loopA");
  fs::create_symlink("loopA", dir_ / "loopB");
  fs::create_directories(dir_ / "adir");
  fs::create_directories(dir_ / "adir.nrrd");
  for (const Case& c : cases) {
    const Result r = run(c.args);
    // 1: simdvol's errors; 105: CLI11's parse errors; never 2 (an exception
    // main() did not expect) or a signal (-1).
    EXPECT_TRUE(r.code == 1 || r.code == 105) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.needle), std::string::npos) << c.args << "\n" << r.output;
    // CLI11's refusals too say whose error it is.
    EXPECT_NE(r.output.find("simdvol: error: "), std::string::npos) << c.args << "\n" << r.output;
    EXPECT_EQ(r.output.find("unexpected error"), std::string::npos) << c.args << "\n" << r.output;
  }
  EXPECT_FALSE(fs::exists(dir_ / "x.png"));
  EXPECT_FALSE(fs::exists(dir_ / "t_0000.png"));
  EXPECT_FALSE(fs::exists(dir_ / "noext_0000"));
  EXPECT_FALSE(fs::exists(dir_ / "m.png"));
  EXPECT_FALSE(fs::exists(dir_ / "c.nrrd"));
  EXPECT_TRUE(fs::is_fifo(dir_ / "fifo.png"));
}

// No output replaces a file the render reads (each was replaced before):
// the volume through a symbolic link named as the image, a DICOM slice
// named .tif (told by its contents), a DICOM slice beside the one asked
// for or in the directory asked for, the --classify file, and the trace
// through a link. A new name in the series' directory is fine.
TEST_F(Cli, OutputNeverReplacesAnInput) {
  ASSERT_EQ(run("phantom shepp-logan --size 8 -o " + path("v.nrrd")).code, 0);
  const fs::path ser = dir_ / "ser";
  fs::create_directories(ser);
  for (int z = 0; z < 4; ++z) {
    simdvol::testing::DicomSlice sl;
    sl.position = {0, 0, 1.0 * z};
    write_dicom_slice(ser / ("s" + std::to_string(z) + ".tif"), 8, 8,
                      std::vector<int16_t>(64, static_cast<int16_t>(100 * z)), sl);
  }
  std::ofstream(dir_ / "c.tf") << "density 0 0 100 1\n";
  fs::create_symlink("v.nrrd", dir_ / "link.png");
  fs::create_symlink("v.nrrd", dir_ / "link.json");
  fs::create_symlink("c.tf", dir_ / "tf.png");
  const auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  std::vector<std::pair<fs::path, std::string>> kept;
  for (const fs::path& p : {dir_ / "v.nrrd", dir_ / "c.tf", ser / "s0.tif", ser / "s1.tif"})
    kept.emplace_back(p, bytes(p));
  struct Case {
    std::string args, needle;
  };
  const std::string vol = path("v.nrrd"), s0 = (ser / "s0.tif").string(),
                    s1 = (ser / "s1.tif").string();
  const Case cases[] = {
      {"render " + vol + " --size 8 -o " + path("link.png"),
       "-o: writing " + path("link.png") + " would replace " + vol + ", which this command reads"},
      {"render " + s0 + " --size 8 -o " + s0,
       "-o: writing " + s0 + " would replace " + s0 + ", which this command reads"},
      {"render " + s0 + " --size 8 -o " + s1,
       "-o: writing " + s1 + " would replace " + s1 + ", which this command reads"},
      {"render " + ser.string() + " --size 8 -o " + s1,
       "-o: writing " + s1 + " would replace " + s1 + ", which this command reads"},
      {"render " + vol + " --size 8 --classify " + path("c.tf") + " -o " + path("tf.png"),
       "would replace " + path("c.tf")},
      {"render " + vol + " --size 8 --trace " + path("link.json") + " -o " + path("ok.png"),
       "--trace: writing " + path("link.json") + " would replace " + vol},
  };
  for (const Case& c : cases) {
    const Result r = run(c.args);
    EXPECT_EQ(r.code, 1) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.needle), std::string::npos) << c.args << "\n" << r.output;
  }
  for (const auto& [p, b] : kept) EXPECT_EQ(bytes(p), b) << p;
  EXPECT_FALSE(fs::exists(dir_ / "ok.png"));
  const Result r = run("render " + s0 + " --size 8 -o " + (ser / "new.png").string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(ser / "new.png"));
  // A DICOM file below the series' directory that the read left alone (of
  // another series) is not replaced either.
  fs::create_directories(ser / "sub");
  simdvol::testing::DicomSlice other;
  other.series = "1.2.826.0.1.3680043.10.1.7";
  const fs::path o = ser / "sub" / "other.tif";
  write_dicom_slice(o, 8, 8, std::vector<int16_t>(64, 5), other);
  const std::string before = bytes(o);
  const Result again = run("render " + s0 + " --size 8 -o " + o.string());
  EXPECT_EQ(again.code, 1) << again.output;
  EXPECT_NE(again.output.find("-o: writing " + o.string() +
                              " would replace a DICOM file of the series being read"),
            std::string::npos)
      << again.output;
  EXPECT_EQ(bytes(o), before);
}

// A series' slice without DICOM's preamble (a bare data set, as old
// ACR-NEMA files and some exporters write them; GDCM reads them) is not
// told as DICOM by its contents, so an output that named it (through a
// symbolic link, or as IM3.tif) replaced it with exit 0: "wrote
// .../o.png", the slice an image and the series one slice short. The
// series' slices are now the volume's companion files, refused as any
// file the command reads (the directory named, or a DICOMDIR beside it).
TEST_F(Cli, OutputNeverReplacesASliceOfTheSeries) {
  const fs::path ser = dir_ / "ser";
  fs::create_directories(ser);
  const auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  const char* names[4] = {"IM0", "IM1", "IM2", "IM3.tif"};
  for (int z = 0; z < 4; ++z) {
    simdvol::testing::DicomSlice sl;
    sl.position = {0, 0, 1.0 * z};
    write_dicom_slice(ser / names[z], 8, 8, std::vector<int16_t>(64, static_cast<int16_t>(100 * z)),
                      sl);
    // The preamble, "DICM" and the file meta group (its length at 140) cut off.
    const std::string b = bytes(ser / names[z]);
    ASSERT_EQ(b.compare(128, 4, "DICM"), 0);
    uint32_t meta = 0;
    std::memcpy(&meta, b.data() + 140, 4);
    std::ofstream(ser / names[z], std::ios::binary | std::ios::trunc) << b.substr(144 + meta);
  }
  std::ofstream(ser / "DICOMDIR") << std::string(200, '\0');  // (only its name counts)
  ASSERT_EQ(simdvol::volume_file_kind(ser / "IM1"), simdvol::VolumeFileKind::unknown);
  ASSERT_EQ(simdvol::load_volume(ser).dims()[2], 4);  // (read as a series of four)
  fs::create_symlink(ser / "IM1", dir_ / "o.png");
  std::vector<std::pair<fs::path, std::string>> kept;
  for (const char* n : names) kept.emplace_back(ser / n, bytes(ser / n));
  struct Case {
    std::string volume, out, replaced;
  };
  const Case cases[] = {
      {ser.string(), path("o.png"), (ser / "IM1").string()},
      {ser.string(), (ser / "IM3.tif").string(), (ser / "IM3.tif").string()},
      {(ser / "DICOMDIR").string(), path("o.png"), (ser / "IM1").string()},
  };
  for (const Case& c : cases) {
    const Result r = run("render " + c.volume + " --size 8 -o " + c.out);
    EXPECT_EQ(r.code, 1) << c.volume << " -o " << c.out << "\n" << r.output;
    EXPECT_NE(r.output.find("-o: writing " + c.out + " would replace " + c.replaced +
                            ", which this command reads"),
              std::string::npos)
        << c.volume << " -o " << c.out << "\n"
        << r.output;
  }
  for (const auto& [p, b] : kept) EXPECT_EQ(bytes(p), b) << p;
  // Beside the slices, under a name of its own, it renders.
  const Result ok = run("render " + ser.string() + " --size 8 -o " + (ser / "new.png").string());
  EXPECT_EQ(ok.code, 0) << ok.output;
  EXPECT_TRUE(fs::is_regular_file(ser / "new.png"));
}

// `mismatch --plot P --csv C` writes both or neither: a CSV that failed on
// a full disk (a file size limit here: the plot's 6 KB fit, the CSV's 11
// KB do not) had left a new plot over the old. A plot that fails is named
// as given, not by its temporary name.
TEST_F(Cli, MismatchWritesBothOutputsOrNeither) {
  std::ofstream(dir_ / "keep.png") << "old";
  std::ofstream(dir_ / "keep.csv") << "old";
  const Result r = run_once(
      "mismatch --size 8 --size3 4 --plot " + path("keep.png") + " --csv " + path("keep.csv"), "",
      "trap '' XFSZ; ulimit -f 16;");  // 8 KiB (sh counts 512 bytes)
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("keep.csv: write failed: File too large"), std::string::npos) << r.output;
  for (const char* f : {"keep.png", "keep.csv"}) {
    std::ifstream in(dir_ / f);
    EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), {}), "old") << f;
  }
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir_)) files += e.is_regular_file();
  EXPECT_EQ(files, 2);  // no temporary left
  const Result small = run_once("mismatch --size 8 --size3 4 --plot " + path("keep.png"), "",
                                "trap '' XFSZ; ulimit -f 2;");
  EXPECT_EQ(small.code, 1) << small.output;
  EXPECT_NE(small.output.find("simdvol: error: " + path("keep.png") + ": "), std::string::npos)
      << small.output;
  // Without the limit both are written.
  ASSERT_EQ(
      run("mismatch --size 8 --size3 4 --plot " + path("keep.png") + " --csv " + path("keep.csv"))
          .code,
      0);
  EXPECT_GT(fs::file_size(dir_ / "keep.png"), 3u);
  EXPECT_GT(fs::file_size(dir_ / "keep.csv"), 3u);
}

// --classify ct is the preset even where a file ./ct lies beside: said in
// a note (nothing said for ./ct, the file, or without --classify).
TEST_F(Cli, PresetNameBesideAFileOfThatNameIsSaid) {
  std::ofstream(dir_ / "ct") << "density 0 0 100 1\n";
  const std::string in_dir = "cd " + dir_.string() + " &&";
  Result r = run_once("render --phantom-size 16 --size 8 --classify ct -o x.png", "", in_dir);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("note: --classify ct is the preset; for the file ct here, give ./ct"),
            std::string::npos)
      << r.output;
  r = run_once("render --phantom-size 16 --size 8 --classify ./ct -o y.png", "", in_dir);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("note: --classify"), std::string::npos) << r.output;
  r = run_once("render --phantom-size 16 --size 8 -o z.png", "", in_dir);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("note: --classify"), std::string::npos) << r.output;
}

// An output linked to the other file of a two-file volume replaced it
// with exit 0: the .hdr of an .img named (plain or gzipped pair, either
// half named), a detached NRRD's data file, a MetaImage's ElementDataFile.
// Refused once the volume is read, before any frame.
TEST_F(Cli, OutputNeverReplacesAVolumesOtherFile) {
  const int64_t dims[8] = {3, 8, 8, 8, 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, DT_FLOAT32, 1);
  ASSERT_NE(nim, nullptr);
  auto* f = static_cast<float*>(nim->data);
  for (std::size_t i = 0; i < 512; ++i) f[i] = static_cast<float>(i % 61);
  ASSERT_EQ(nifti_set_filenames(nim, path("p.hdr").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  ASSERT_EQ(nifti_set_filenames(nim, path("g.hdr.gz").c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nifti_image_free(nim);
  std::string raw(512 * 4, '\0');
  for (std::size_t i = 0; i < 512; ++i) {
    const float v = static_cast<float>(i % 61);
    std::memcpy(&raw[i * 4], &v, 4);
  }
  std::ofstream(dir_ / "n.raw", std::ios::binary) << raw;
  std::ofstream(dir_ / "m.raw", std::ios::binary) << raw;
  std::ofstream(dir_ / "n.nhdr") << "NRRD0004\ntype: float\ndimension: 3\nsizes: 8 8 8\n"
                                    "endian: little\nencoding: raw\ndata file: n.raw\n\n";
  std::ofstream(dir_ / "m.mhd") << "ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\n"
                                   "ElementType = MET_FLOAT\nElementByteOrderMSB = False\n"
                                   "ElementDataFile = m.raw\n";
  struct Case {
    std::string volume, other;
  };
  const Case cases[] = {{"p.img", "p.hdr"},       {"p.hdr", "p.img"},  {"g.img.gz", "g.hdr.gz"},
                        {"g.hdr.gz", "g.img.gz"}, {"n.nhdr", "n.raw"}, {"m.mhd", "m.raw"}};
  const auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  for (const Case& c : cases) {
    const std::string before = bytes(dir_ / c.other);
    fs::remove(dir_ / "o.png");
    fs::create_symlink(c.other, dir_ / "o.png");
    const Result r = run("render " + path(c.volume) + " --size 16 -o " + path("o.png"));
    EXPECT_EQ(r.code, 1) << c.volume << "\n" << r.output;
    EXPECT_NE(r.output.find("-o: writing " + path("o.png") + " would replace"), std::string::npos)
        << c.volume << "\n"
        << r.output;
    EXPECT_EQ(bytes(dir_ / c.other), before) << c.other;
    // Under another name it renders.
    const Result ok = run("render " + path(c.volume) + " --size 16 -o " + path("ok.png"));
    EXPECT_EQ(ok.code, 0) << c.volume << "\n" << ok.output;
  }
}

// PoCL 3.1 stops the process on some values of its variables (an empty
// POCL_CACHE_DIR fails an assertion, POCL_MAX_PTHREAD_COUNT=-1 is a
// segmentation fault): refused first, naming the variable. A cache
// directory PoCL cannot make is named where the build then fails.
TEST_F(Cli, PoclVariablesThatStopPoclAreRefused) {
  const std::string args = "render --phantom-size 16 --size 8 -o " + path("x.png");
  Result r = run("devices", "POCL_CACHE_DIR=");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("POCL_CACHE_DIR: is set but empty"), std::string::npos) << r.output;
  for (const char* bad : {"-1", "2147483647", "garbage"}) {
    r = run(args, std::string("POCL_MAX_PTHREAD_COUNT=") + bad);
    EXPECT_EQ(r.code, 1) << bad << "\n" << r.output;
    EXPECT_NE(
        r.output.find(std::string("POCL_MAX_PTHREAD_COUNT: \"") + bad + "\" is not a thread count"),
        std::string::npos)
        << r.output;
  }
  EXPECT_EQ(run(args, "POCL_MAX_PTHREAD_COUNT=2").code, 0);
  // A file where the cache should be: PoCL's build fails without a compiler
  // message, and the message says where the cache was looked for.
  std::ofstream(dir_ / "cachefile") << "x";
  r = run("render --phantom-size 16 --size 8 -o " + path("y.png"),
          "POCL_CACHE_DIR=" + path("cachefile") + " SIMDVOL_CACHE_DIR=off");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot write its cache directory, POCL_CACHE_DIR=" + path("cachefile")),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "y.png"));
}

// The image does not depend on how many threads PoCL runs the work-groups
// on: every kernel's work-group size is fixed (reqd_work_group_size), the
// only atomics count or claim slots that are sorted afterwards
// (simdvol_mc_ray_fill) or set a flag (SV_MARK), and no reduction runs in
// the order work-groups finish. Checked bit for bit, all four channels of
// the float TIFF, at 1 and 3 threads (3: an odd split, and on a machine of
// 2 cores more threads than cores), over the stages whose
// results could depend on an order: Monte Carlo walks per sub-ray with the
// walks allocated, whole rays (the ray lists built by atomics), adaptive
// termination with balancing and the hierarchical layout, pixel sampling
// at 65,536 PEs. The --times line's counts (samples, PEs, utilisation)
// must agree too.
TEST_F(Cli, SameImageAtEveryThreadCount) {
  const std::string base = "render --phantom-size 32 --size 32x32 --view 20,35,10 --times ";
  const std::vector<std::string> cases = {
      "--composite mc --samples 8 --mc-scope subray --allocate --exact-opacity --seed 3",
      "--composite mc --samples 8 --pe 64",
      "--composite adaptive --layout hierarchical --order 3",
      "--sampling pixel --pe 65536 --balance-sweeps 0",
  };
  const auto counts = [](const std::string& out) {  // "N samples on P of Q PEs, utilisation U"
    const std::size_t at = out.find(" samples on ");
    if (at == std::string::npos) return std::string();
    const std::size_t begin = out.rfind("; ", at) + 2, end = out.find('\n', at);
    return out.substr(begin, end - begin);
  };
  for (std::size_t c = 0; c < cases.size(); ++c) {
    std::vector<simdvol::Image> images;
    std::string first_counts;
    for (const char* threads : {"1", "3"}) {
      const std::string out = path("c" + std::to_string(c) + "_t" + threads + ".tif");
      const Result r =
          run(base + cases[c] + " -o " + out, std::string("POCL_MAX_PTHREAD_COUNT=") + threads);
      ASSERT_EQ(r.code, 0) << cases[c] << "\n" << r.output;
      const std::string n = counts(r.output);
      EXPECT_FALSE(n.empty()) << r.output;
      if (images.empty())
        first_counts = n;
      else
        EXPECT_EQ(n, first_counts) << cases[c] << " at " << threads << " threads";
      images.push_back(simdvol::read_image(out));
    }
    EXPECT_GT(alpha_sum(images[0]), 1.0) << cases[c];
    for (std::size_t t = 1; t < images.size(); ++t) {
      ASSERT_EQ(images[t].pixels().size(), images[0].pixels().size());
      EXPECT_EQ(std::memcmp(images[t].pixels().data(), images[0].pixels().data(),
                            images[0].pixels().size() * sizeof(simdvol::Rgba)),
                0)
          << cases[c] << ": 3 threads against 1";
    }
  }
}

// SIMDVOL_CACHE_DIR that cannot keep programs: the render goes on (built
// from source, only slower), and says so; it said nothing before.
TEST_F(Cli, ProgramCacheThatCannotBeWrittenIsNoted) {
  std::ofstream(dir_ / "afile") << "x";
  const std::string args = "render --phantom-size 16 --size 8 -o ";
  Result r = run(args + path("a.png"), "SIMDVOL_CACHE_DIR=" + path("afile"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("simdvol: note: SIMDVOL_CACHE_DIR=" + path("afile") +
                          " is not a directory: programs are built from source"),
            std::string::npos)
      << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "a.png"));
  r = run(args + path("b.png"), "SIMDVOL_CACHE_DIR=" + path("afile") + "/sub");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("SIMDVOL_CACHE_DIR=" + path("afile") + "/sub cannot be made ("),
            std::string::npos)
      << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "b.png"));
  // A directory that can be made and written: no note, and it is made.
  r = run(args + path("c.png"), "SIMDVOL_CACHE_DIR=" + path("cache/programs"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("SIMDVOL_CACHE_DIR"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::is_directory(dir_ / "cache/programs"));
}

// The benchmarking switches take only their values: anything else was read
// as unset (SIMDVOL_HUGE_PAGES=true, SIMDVOL_VOXEL_WGS=100 as 256) and the
// run measured the default without a word.
TEST_F(Cli, BenchmarkSwitchesTakeOnlyTheirValues) {
  const std::string args = "render --phantom-size 128 --size 16 -o " + path("x.png");
  for (const char* bad : {"SIMDVOL_HUGE_PAGES=true", "SIMDVOL_NT_STORES=on",
                          "SIMDVOL_MATCH_SAVED=false", "SIMDVOL_VOXEL_WGS=100"}) {
    const Result r = run(args, bad);
    const std::string name(bad, std::strchr(bad, '=') - bad);
    EXPECT_EQ(r.code, 1) << bad << "\n" << r.output;
    EXPECT_NE(
        r.output.find("simdvol: error: " + name + ": \"" + std::string(std::strchr(bad, '=') + 1)),
        std::string::npos)
        << r.output;
  }
  EXPECT_FALSE(fs::exists(dir_ / "x.png"));
  for (const char* good : {"SIMDVOL_HUGE_PAGES=1", "SIMDVOL_NT_STORES=0", "SIMDVOL_VOXEL_WGS=128"})
    EXPECT_EQ(run(args, good).code, 0) << good;
}

// `simdvol devices` is where a bad SIMDVOL_DEVICE's error points: it lists
// the devices all the same (it failed with that error), then says what is
// wrong, exit 1. A number past long's range is named as given (it was
// "device 9223372036854775807").
TEST_F(Cli, DevicesListedWhateverSimdvolDeviceSays) {
  Result r = run("devices", "SIMDVOL_DEVICE=4096");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("  0: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.rfind("  0: ", 0), std::string::npos) << r.output;  // none chosen
  EXPECT_EQ(r.output.find("\n* "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("SIMDVOL_DEVICE: no OpenCL device 4096"), std::string::npos) << r.output;
  r = run("render --phantom-size 16 --size 8 -o " + path("x.png"),
          "SIMDVOL_DEVICE=99999999999999999999");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("SIMDVOL_DEVICE: \"99999999999999999999\" is not a device index"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "x.png"));
  r = run("devices");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(r.output.rfind("* ", 0) == 0 || r.output.find("\n* ") != std::string::npos)
      << r.output;
}

// Legal names up to the file system's 255 bytes: the temporary file beside
// each output has a short name of its own (image, NRRD and CSV writers; the
// suffix pushed a 251-byte name over the limit), and a file that happens to
// have the CSV's old fixed temporary name is left alone.
TEST_F(Cli, OutputNamesNearTheFileSystemLimitWork) {
  const std::string stem(246, 'z');
  Result r = run("render --phantom-size 16 --size 16x16 -o " + path(stem + ".png"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / (stem + ".png")));
  r = run("phantom shepp-logan --size 8 -o " + path(stem + ".nrrd"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(simdvol::load_volume(dir_ / (stem + ".nrrd")).nx(), 8);
  std::ofstream(dir_ / "m.csv.tmp") << "someone's file";
  r = run("mismatch --size 8 --size3 4 --csv " + path(stem + ".csv") + " --plot " +
          path(stem + ".tif"));
  EXPECT_EQ(r.code, 0) << r.output;
  r = run("mismatch --size 8 --size3 4 --csv " + path("m.csv"));
  EXPECT_EQ(r.code, 0) << r.output;
  std::ifstream csv(dir_ / (stem + ".csv"));
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header, "dims,method,measure,bin_lo,bin_hi,count,fraction");
  // A TIFF (its byte order and 42), not read in this process: under the
  // CI's ASan build, a process that had read a TIFF here crashed in
  // LeakSanitizer's tracer at exit on a Zen 3 machine (a bogus dynamic-TLS
  // range of a module the image read loads; 8 of 8 runs) after the test
  // had passed; the image's contents are the writers' tests' business.
  {
    std::ifstream tif(dir_ / (stem + ".tif"), std::ios::binary);
    char magic[4] = {};
    tif.read(magic, 4);
    const std::string m(magic, 4);
    EXPECT_TRUE(m == std::string("II*\0", 4) || m == std::string("MM\0*", 4));
  }
  std::ifstream kept(dir_ / "m.csv.tmp");
  const std::string k((std::istreambuf_iterator<char>(kept)), {});
  EXPECT_EQ(k, "someone's file");
  // Nothing else: no temporary file left behind.
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{stem + ".png", stem + ".nrrd", stem + ".csv",
                                          stem + ".tif", "m.csv", "m.csv.tmp"}));
  // Paths of Linux's 4,095 bytes, in directories 250 bytes a name: a
  // turntable's frames and a NRRD (the temporary's suffix took the path over
  // the limit where the output's own fitted).
  fs::path deep = dir_;
  while (deep.string().size() + 251 < 4070) deep /= std::string(250, 'd');
  deep /= std::string(4070 - deep.string().size() - 1, 'e');  // 4,070 bytes: 24 left for a name
  fs::create_directories(deep);
  const std::size_t left = 4095 - deep.string().size() - 1;
  const std::string frame_stem(left - std::strlen("_0000.png"), 'f');
  r = run("render --phantom-size 16 --size 16x16 --frames 2 -o " +
          (deep / (frame_stem + ".png")).string());
  EXPECT_EQ(r.code, 0) << r.output.substr(0, 300);
  EXPECT_TRUE(fs::exists(deep / (frame_stem + "_0001.png")));
  const std::string nrrd_stem(left - std::strlen(".nrrd"), 'n');
  r = run("phantom shepp-logan --size 8 -o " + (deep / (nrrd_stem + ".nrrd")).string());
  EXPECT_EQ(r.code, 0) << r.output.substr(0, 300);
  EXPECT_EQ(std::distance(fs::directory_iterator(deep), fs::directory_iterator{}), 3);
}

// A light direction is a direction at any length: |light| by hypot (the
// squares of 1e200 overflowed to inf, the light became 0: a 25 dB image).
TEST_F(Cli, LightOfAnyLengthIsTheSameDirection) {
  for (const char* engine : {"reference", "opencl"}) {
    const std::string base = std::string("render --engine ") + engine +
                             " --phantom-size 16 --size 16x16 --view 20,35,10 --light ";
    ASSERT_EQ(run(base + "1,-2,3 -o " + path("a.tif")).code, 0);
    for (const char* l : {"1e200,-2e200,3e200", "1e-200,-2e-200,3e-200"}) {
      const Result r = run(base + l + " -o " + path("b.tif"));
      ASSERT_EQ(r.code, 0) << r.output;
      EXPECT_GT(
          simdvol::psnr(simdvol::read_image(dir_ / "a.tif"), simdvol::read_image(dir_ / "b.tif")),
          100.0)
          << engine << " " << l;
    }
  }
}

// compare: images of other sizes fail with both files named and nothing on
// stdout before the error (no half-printed "psnr_db"); the same image
// compares as identical.
TEST_F(Cli, CompareNamesBothImagesOfOtherSizes) {
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("a.png")).code, 0);
  ASSERT_EQ(run("render --phantom-size 16 --size 24x16 -o " + path("b.png")).code, 0);
  Result r = run("compare " + path("a.png") + " " + path("b.png"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find(path("a.png") + " and " + path("b.png")), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("16x16 against 24x16"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("psnr_db"), std::string::npos) << r.output;
  r = run("compare " + path("a.png") + " " + path("a.png"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("psnr_db inf"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("max_abs_diff 0"), std::string::npos) << r.output;
}

// compare --tolerance / --check-rgba: the counts for two renders that differ
// (shading on and off), against a count made here from the images read
// back; bad tolerances refused naming the option, before any output.
namespace {

// A baseline TIFF of `pages` pages, each w x h pixels of 8-bit grey (the
// pixel data: one byte per page, the header need not match it for the
// size check), written by hand: no TIFF writer makes several pages here.
std::string tiny_tiff(uint32_t w, uint32_t h, int pages) {
  std::string t("II*\0", 4);
  const auto put16 = [&t](uint32_t v) {
    t += static_cast<char>(v & 0xff), t += static_cast<char>(v >> 8);
  };
  const auto put32 = [&](uint32_t v) { put16(v & 0xffff), put16(v >> 16); };
  const uint32_t ifd_bytes = 2 + 8 * 12 + 4;
  put32(8);
  const uint32_t data = 8 + static_cast<uint32_t>(pages) * ifd_bytes;
  for (int p = 0; p < pages; ++p) {
    put16(8);
    const auto entry = [&](uint32_t tag, uint32_t type, uint32_t value) {
      put16(tag), put16(type), put32(1), put32(value);  // (a SHORT sits in the low half)
    };
    entry(256, 4, w);  // ImageWidth
    entry(257, 4, h);  // ImageLength
    entry(258, 3, 8);  // BitsPerSample
    entry(259, 3, 1);  // Compression: none
    entry(262, 3, 1);  // PhotometricInterpretation: black is zero
    entry(273, 4, data + static_cast<uint32_t>(p) * w * h);  // StripOffsets
    entry(278, 4, h);                                        // RowsPerStrip
    entry(279, 4, w * h);                                    // StripByteCounts
    put32(p + 1 < pages ? 8 + static_cast<uint32_t>(p + 1) * ifd_bytes : 0);
  }
  for (int p = 0; p < pages && uint64_t{w} * h <= 64; ++p)
    t += std::string(w * h, static_cast<char>(40 * (p + 1)));
  return t;
}

}  // namespace

// `compare` takes one whole image from each file. Refused now, each was
// compared before: a TIFF cut short (its missing strips read as black,
// exit 0), a second page (the first alone compared), OpenImageIO's "null"
// reader (any *.null file a black 1024 x 1024), a header claiming 20000 x
// 20000 pixels (4.8 GB and 15 s before it failed).
TEST_F(Cli, CompareTakesOneWholeImage) {
  std::ofstream(dir_ / "one.tif", std::ios::binary) << tiny_tiff(2, 2, 1);
  std::ofstream(dir_ / "two.tif", std::ios::binary) << tiny_tiff(2, 2, 2);
  std::ofstream(dir_ / "big.tif", std::ios::binary) << tiny_tiff(20000, 20000, 1);
  std::ofstream(dir_ / "z.null") << "";
  std::ofstream(dir_ / "j.null") << "junk\n";
  Result r = run("compare " + path("one.tif") + " " + path("one.tif"));
  ASSERT_EQ(r.code, 0) << r.output;  // the hand-made file is a good TIFF
  EXPECT_NE(r.output.find("psnr_db inf"), std::string::npos) << r.output;
  simdvol::Image img(48, 40);
  for (std::size_t i = 0; i < img.pixels().size(); ++i) {
    const float v = static_cast<float>(i % 97) / 97.0f;
    img.pixels()[i] = {v, v * 0.5f, 1.0f - v, 1.0f};
  }
  simdvol::write_image(img, path("r.tif"));
  const std::uintmax_t size = fs::file_size(path("r.tif"));
  std::ifstream in(path("r.tif"), std::ios::binary);
  const std::string whole((std::istreambuf_iterator<char>(in)), {});
  struct Case {
    std::string b, needle;
  };
  std::vector<Case> cases = {
      {path("two.tif"), "two.tif: it holds several images (pages or parts)"},
      {path("big.tif"), "big.tif: its header says 20000x20000 pixels, 1 channels: more than"},
      {path("j.null"), "j.null: not an image file"},
  };
  for (const std::uintmax_t cut : {size / 4, size / 2, size * 3 / 4, size - 1}) {
    const std::string name = "cut" + std::to_string(cut) + ".tif";
    std::ofstream(dir_ / name, std::ios::binary) << whole.substr(0, cut);
    cases.push_back({path(name), name + ": "});
  }
  for (const Case& c : cases) {
    r = run("compare " + path("r.tif") + " " + c.b);
    EXPECT_EQ(r.code, 1) << c.b << "\n" << r.output;
    EXPECT_NE(r.output.find(c.needle), std::string::npos) << c.b << "\n" << r.output;
    EXPECT_EQ(r.output.find("psnr_db"), std::string::npos) << c.b << "\n" << r.output;
  }
  r = run("compare " + path("z.null") + " " + path("j.null"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("z.null: not an image file"), std::string::npos) << r.output;
}

TEST_F(Cli, CompareCountsPixelsOverATolerance) {
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("a.png")).code, 0);
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 --no-shade -o " + path("b.png")).code, 0);
  Result r = run("compare " + path("a.png") + " " + path("a.png") + " --tolerance 0 --check-rgba");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("\npixels_over_tolerance 0\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\nalpha_pixels_over_tolerance 0\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\ninvalid_rgba_a 0\ninvalid_rgba_b 0\n"), std::string::npos) << r.output;
  r = run("compare " + path("a.png") + " " + path("b.png") + " --tolerance 0.01");
  EXPECT_EQ(r.code, 0) << r.output;
  const simdvol::Image a = simdvol::read_image(path("a.png")),
                       b = simdvol::read_image(path("b.png"));
  std::size_t want = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i) {
    const simdvol::Rgba p = a.pixels()[i], q = b.pixels()[i];
    want += std::fabs(p.r - q.r) > 0.01f || std::fabs(p.g - q.g) > 0.01f ||
            std::fabs(p.b - q.b) > 0.01f;
  }
  ASSERT_GT(want, 0u);
  EXPECT_NE(r.output.find("\npixels_over_tolerance " + std::to_string(want) + "\n"),
            std::string::npos)
      << r.output << " want " << want;
  EXPECT_NE(r.output.find("\nalpha_pixels_over_tolerance 0\n"), std::string::npos)
      << r.output;  // PNG: alpha 1 in both
  EXPECT_EQ(r.output.find("invalid_rgba"), std::string::npos) << r.output;
  for (const char* bad : {"-1", "nan", "abc"}) {
    r = run("compare " + path("a.png") + " " + path("b.png") + " --tolerance " + bad);
    EXPECT_NE(r.code, 0) << bad;
    EXPECT_NE(r.output.find("--tolerance"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("psnr_db"), std::string::npos) << r.output;
  }
}

// A PNG (RGB over black, no alpha) against the same frame as TIFF (float
// premultiplied RGBA): the PNG's alpha reads as 1, so max_abs_diff is the
// alpha's difference (1 where the TIFF is transparent). compare says so on
// stderr, with the largest difference over RGB alone (8-bit rounding
// here), and stdout is as before.
TEST_F(Cli, CompareSaysWhenOneImageHasNoAlpha) {
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("a.png")).code, 0);
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("a.tif")).code, 0);
  bool png_alpha = true, tif_alpha = false;
  const simdvol::Image png = simdvol::read_image_with_alpha(path("a.png"), &png_alpha),
                       tif = simdvol::read_image_with_alpha(path("a.tif"), &tif_alpha);
  EXPECT_FALSE(png_alpha);
  EXPECT_TRUE(tif_alpha);
  float rgb = 0;
  for (std::size_t i = 0; i < png.pixels().size(); ++i) {
    const simdvol::Rgba p = png.pixels()[i], q = tif.pixels()[i];
    rgb = std::max({rgb, std::fabs(p.r - q.r), std::fabs(p.g - q.g), std::fabs(p.b - q.b)});
  }
  ASSERT_GT(rgb, 0.0f);
  ASSERT_LE(rgb, 0.5f / 255.0f + 1e-6f);  // the PNG's rounding
  for (const bool png_first : {true, false}) {
    const std::string a = path(png_first ? "a.png" : "a.tif"),
                      b = path(png_first ? "a.tif" : "a.png");
    const Result r = run("compare " + a + " " + b);
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("max_abs_diff 1\n"), std::string::npos) << r.output;
    std::ostringstream want;
    want << "note: " << path("a.png")
         << " has no alpha channel (it reads as opaque, alpha 1) where " << path("a.tif")
         << " has one";
    EXPECT_NE(r.output.find(want.str()), std::string::npos) << r.output;
    std::ostringstream largest;
    largest << "over RGB alone the largest difference is " << rgb << " ";
    EXPECT_NE(r.output.find(largest.str()), std::string::npos) << r.output << " want " << rgb;
  }
  // Both with alpha, or both without: no note.
  for (const char* same : {"a.png", "a.tif"}) {
    const Result r = run(std::string("compare ") + path(same) + " " + path(same));
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output.find("note:"), std::string::npos) << r.output;
  }
}

// psnr_db is over RGB and max_abs_diff over RGBA: two images that differ in
// alpha alone printed "psnr_db inf" beside a difference, with no word.
TEST_F(Cli, CompareSaysWhenOnlyAlphaDiffers) {
  simdvol::Image a(4, 3), b(4, 3);
  for (simdvol::Rgba& p : a.pixels()) p = {0.2f, 0.1f, 0.05f, 0.5f};
  b = a;
  b.pixels()[5].a = 0.75f;
  simdvol::write_image(a, path("c.tif"));
  simdvol::write_image(b, path("d.tif"));
  const Result r = run("compare " + path("c.tif") + " " + path("d.tif"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("psnr_db inf\nmax_abs_diff 0.25\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("note: the colours are equal (psnr_db, over RGB, is inf); the images "
                          "differ in alpha alone, by up to 0.25"),
            std::string::npos)
      << r.output;
  const Result same = run("compare " + path("c.tif") + " " + path("c.tif"));
  EXPECT_EQ(same.output.find("note:"), std::string::npos) << same.output;
}

// --sampling pixel at an image much larger than the volume: a note before
// the first frame with the samples a frame takes (the grid's points inside
// the volume: 64^3 voxels at 32 samples a voxel length, 2^33), and voxel
// sampling's. The device asked for does not exist, so the run stops after
// the note, before the 18 s frame.
TEST_F(Cli, PixelSamplingOfALargeImageIsNoted) {
  const std::string args = "render --phantom-size 64 -o " + path("p.png");
  Result r = run(args + " --sampling pixel --size 2048x2048", "SIMDVOL_DEVICE=4096");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("note: --sampling pixel at 2048x2048 takes about 8.6e+09 samples a "
                          "frame (--sampling voxel: about 2.6e+05)"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("SIMDVOL_DEVICE: no OpenCL device 4096"), std::string::npos) << r.output;
  for (const char* quiet :
       {" --sampling pixel --size 512x512", " --sampling voxel --size 2048x2048"}) {
    r = run(args + quiet, "SIMDVOL_DEVICE=4096");
    EXPECT_NE(r.output.find("SIMDVOL_DEVICE: no OpenCL device 4096"), std::string::npos)
        << quiet << "\n"
        << r.output;
    EXPECT_EQ(r.output.find("note: --sampling"), std::string::npos) << quiet << "\n" << r.output;
  }
  EXPECT_FALSE(fs::exists(path("p.png")));
}

TEST_F(Cli, FailedRenderLeavesExistingOutputUntouched) {
  ASSERT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("keep.png")).code, 0);
  std::ifstream in(path("keep.png"), std::ios::binary);
  const std::string before((std::istreambuf_iterator<char>(in)), {});
  // A bad volume fails after argument parsing; the old image must survive.
  std::ofstream(dir_ / "bad.nrrd") << "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\n"
                                      "encoding: raw\n\n12";
  const Result r = run("render " + path("bad.nrrd") + " -o " + path("keep.png"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("bad.nrrd"), std::string::npos) << r.output;
  std::ifstream again(path("keep.png"), std::ios::binary);
  const std::string after((std::istreambuf_iterator<char>(again)), {});
  EXPECT_EQ(before, after);
  // No temporary files left behind.
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir_)) files += e.is_regular_file();
  EXPECT_EQ(files, 2);
}

// OpenImageIO lives in a module loaded on first use (host/core/oiio_module.hpp):
// a PNG render never loads it, and without it .exr fails clearly.
TEST_F(Cli, PngNeedsNoOpenImageIoAndExrWithoutItFailsClearly) {
  // The dynamic loader's own list of what it loads.
  Result r = run("render --phantom-size 16 --size 16x16 -o " + path("a.png"), "LD_DEBUG=files");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("libpng"), std::string::npos) << "LD_DEBUG printed nothing?";
  EXPECT_EQ(r.output.find("libOpenImageIO"), std::string::npos) << r.output;
  r = run("render --phantom-size 16 --size 16x16 -o " + path("a.exr"), "LD_DEBUG=files");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("libOpenImageIO"), std::string::npos);
  // The module elsewhere: PNG still works, EXR names the file and the module.
  const std::string missing = "SIMDVOL_OIIO_MODULE=" + path("nowhere.so");
  EXPECT_EQ(run("render --phantom-size 16 --size 16x16 -o " + path("b.png"), missing).code, 0);
  EXPECT_TRUE(fs::exists(dir_ / "b.png"));
  r = run("render --phantom-size 16 --size 16x16 -o " + path("b.exr"), missing);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("b.exr"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("OpenImageIO module"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("nowhere.so: not there"), std::string::npos) << r.output;
  // A file that is not a module: dlopen's reason.
  std::ofstream(dir_ / "junk.so") << "not a library";
  r = run("compare " + path("a.png") + " " + path("b.png"),
          "SIMDVOL_OIIO_MODULE=" + path("junk.so"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("a.png"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("junk.so: "), std::string::npos) << r.output;
  // A shared library without the module's functions.
  r = run("render --phantom-size 16 --size 16x16 -o " + path("c.tif"),
          "SIMDVOL_OIIO_MODULE=libz.so.1");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("not a simdvol OpenImageIO module"), std::string::npos) << r.output;
  // Nothing half-written: the two PNGs, the EXR and the junk.
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"a.exr", "a.png", "b.png", "junk.so"}));
  // And the two PNGs hold the same image, read through OpenImageIO.
  r = run("compare " + path("a.png") + " " + path("b.png"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("max_abs_diff 0"), std::string::npos) << r.output;
}
