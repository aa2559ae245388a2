// The shade kernel (kernels/shade.cl) against the serial reference
// (host/core/shade.cpp) on phantoms, an odd-sized anisotropic random volume
// and brainsmall.den, over several views and PE counts.
//
// Tolerances (absolute, per channel):
//   Id, Is:  1e-5. Id <= ka + kd and Is <= ks (cue <= 1/k1), so float
//            rounding in the kernel gives ~1e-7 for Id; Is = ks*cue*|N.H|^n
//            amplifies the ~3e-7 error of |N.H| by n (24 here): <= 3e-6.
//   |g|:     1e-6 * max(1, |g|), i.e. relative for large gradients (largest
//            seen: 2.3e-7). The
//            central differences of integer-valued data are exact in float,
//            but g.g and its square root round in float (a few ulp relative,
//            against the reference's double rounded once to float): CT
//            gradients reach ~1000 HU per voxel, where one float ulp is 6e-5.
//   v:       exact (the fourth channel copies the voxel's value).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "simdvol/io.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"
#include "stage_testing.hpp"
#include "testing.hpp"

namespace simdvol {
namespace {

using testing::run_shade;

constexpr double kTolLight = 1e-5;
constexpr double kTolGradRel = 1e-6;

struct Diff {
  double id = 0, is = 0, grad_rel = 0;
  bool value_exact = true;
};

Diff compare(const Volume& vol, const std::vector<ShadeSample>& ref,
             const std::vector<ShadeSample>& got) {
  Diff d;
  EXPECT_EQ(ref.size(), got.size());
  for (std::size_t i = 0; i < ref.size() && i < got.size(); ++i) {
    d.id = std::max(d.id, static_cast<double>(std::fabs(ref[i].diffuse - got[i].diffuse)));
    d.is = std::max(d.is, static_cast<double>(std::fabs(ref[i].specular - got[i].specular)));
    d.grad_rel = std::max(d.grad_rel, std::fabs(static_cast<double>(ref[i].gradient) -
                                                static_cast<double>(got[i].gradient)) /
                                          std::max(1.0, static_cast<double>(ref[i].gradient)));
    if (!(got[i].pad == vol.data()[i])) d.value_exact = false;
  }
  return d;
}

void check_case(const Volume& vol, ViewAngles angles, const ShadeParams& p, int64_t pes,
                const std::string& what) {
  SCOPED_TRACE(what + " pes=" + std::to_string(pes) + " view=(" + std::to_string(angles.theta) +
               "," + std::to_string(angles.phi) + "," + std::to_string(angles.varphi) + ")");
  Device* dev = testing::test_device();
  ASSERT_NE(dev, nullptr);
  const ViewGeometry view = make_view(vol, angles, 64, 64, Sampling::voxel);
  const std::vector<ShadeSample> ref = shade(vol, view, p);
  const sv_shade_params sp = shade_params(make_shade_frame(vol, view, p), p);
  const auto run = run_shade(*dev, vol, sp, pes);
  const Diff d = compare(vol, ref, run.flat);
  EXPECT_LE(d.id, kTolLight);
  EXPECT_LE(d.is, kTolLight);
  EXPECT_LE(d.grad_rel, kTolGradRel);
  EXPECT_TRUE(d.value_exact);
  // Block tails are zero.
  const VoxelLayout& L = run.layout;
  for (int64_t pe = 0; pe < L.pes(); ++pe)
    for (int64_t e = L.cell_voxels(); e < L.stride; ++e) {
      const ShadeSample& s = run.cells[static_cast<std::size_t>(pe * L.stride + e)];
      ASSERT_TRUE(s.diffuse == 0 && s.specular == 0 && s.gradient == 0 && s.pad == 0);
    }
}

const ViewAngles kViews[] = {{0, 0, 0}, {30, 45, 10}, {-70, 120, 200}};

TEST(ShadeKernel, SheppLoganAllPeCounts) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = shepp_logan(48);
  for (int64_t pes : {1, 8, 512, 8192})
    for (const ViewAngles& v : kViews) check_case(vol, v, ShadeParams{}, pes, "shepp_logan(48)");
}

TEST(ShadeKernel, MarschnerLobb) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = marschner_lobb(48);
  ShadeParams p;
  p.shininess = 10;
  p.light = {0.3, 0.3, 1.0};
  for (int64_t pes : {8, 512})
    for (const ViewAngles& v : kViews) check_case(vol, v, p, pes, "marschner_lobb(48)");
}

TEST(ShadeKernel, SpecularExponents) {
  // sv_pow16 takes whole exponents 1..64 by repeated squaring and the others
  // by exp(y log x): both within the light tolerance of the reference's
  // std::pow, for the float16 kernel (the frame's) and the scalar one.
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = marschner_lobb(40);
  for (const double n : {0.0, 1.0, 2.0, 5.0, 10.0, 24.0, 37.0, 64.0, 7.5, 100.0})
    for (const ShadeKernel k : {ShadeKernel::vec16, ShadeKernel::rows}) {
      SCOPED_TRACE("shininess " + std::to_string(n) +
                   (k == ShadeKernel::vec16 ? " vec16" : " rows"));
      ShadeParams p;
      p.shininess = n;
      const ViewGeometry view = make_view(vol, kViews[1], 64, 64, Sampling::voxel);
      const auto sp = shade_params(make_shade_frame(vol, view, p), p);
      const auto run = run_shade(dev, vol, sp, 512, k);
      const Diff d = compare(vol, shade(vol, view, p), run.flat);
      EXPECT_LE(d.id, kTolLight);
      EXPECT_LE(d.is, kTolLight);
      double lit = 0;
      for (const ShadeSample& x : run.flat) lit = std::max(lit, static_cast<double>(x.specular));
      EXPECT_GT(lit, 0.05);  // highlights to compare
      // No denormal specular term (specular_floor: |N.H| below it counts as
      // 0, so the power's multiplications stay normal), though most voxels'
      // |N.H|^n would be one at the larger n.
      std::size_t denormal = 0, below_floor = 0;
      for (const ShadeSample& x : run.flat) denormal += std::fpclassify(x.specular) == FP_SUBNORMAL;
      const std::vector<ShadeSample> ref = shade(vol, view, p);
      for (const ShadeSample& x : ref) {
        denormal += std::fpclassify(x.specular) == FP_SUBNORMAL;
        below_floor += x.specular == 0.0f;
      }
      EXPECT_EQ(denormal, 0u);
      if (n >= 24) {
        EXPECT_GT(below_floor, ref.size() / 50) << "cases the floor takes";
      }
    }
}

// The floor of |N.H| under which the specular power counts as 0: where the
// power would fall below 2^-100, never below FLT_MIN, none for n = 0.
TEST(ShadeKernel, SpecularFloor) {
  EXPECT_EQ(specular_floor(0.0), 0.0f);
  EXPECT_EQ(specular_floor(0.5), std::numeric_limits<float>::min());
  EXPECT_EQ(specular_floor(1.0), static_cast<float>(std::exp2(-100.0)));
  for (const double n : {1.0, 2.0, 7.5, 10.0, 24.0, 64.0, 100.0, 1000.0}) {
    const double t = specular_floor(n);
    EXPECT_NEAR(std::log2(std::pow(t, n)), -100.0, 1e-3 * n) << n;
  }
}

TEST(ShadeKernel, OddAnisotropicVolume) {
  SIMDVOL_TEST_DEVICE(dev);
  // 37 x 29 x 23 with unequal spacing (grad_scale != 1), values in HU range.
  const Volume vol = testing::random_volume({37, 29, 23}, -1000.0f, 2000.0f, {1.0, 0.8, 2.5}, 7);
  for (int64_t pes : {1, 8, 512, 8192})
    for (const ViewAngles& v : kViews) check_case(vol, v, ShadeParams{}, pes, "random 37x29x23");
}

TEST(ShadeKernel, UnlitAndAxisOfLengthOne) {
  SIMDVOL_TEST_DEVICE(dev);
  ShadeParams p;
  p.enabled = false;
  check_case(testing::random_volume({19, 1, 6}, 0.0f, 255.0f, {1, 1, 1}, 3), kViews[1], p, 8,
             "unlit 19x1x6");
  check_case(testing::random_volume({19, 1, 6}, 0.0f, 255.0f, {1, 1, 1}, 3), kViews[1],
             ShadeParams{}, 8, "lit 19x1x6");
  // Single-voxel slabs: every gradient is 0 (ambient only).
  check_case(Volume({1, 1, 1}, VoxelType::f32), kViews[0], ShadeParams{}, 1, "1x1x1");
}

TEST(ShadeKernel, NonFiniteNeighboursMeanNoSurface) {
  SIMDVOL_TEST_DEVICE(dev);
  Volume vol = testing::random_volume({12, 10, 9}, 0.0f, 100.0f, {1, 1, 1}, 11);
  vol.at(4, 4, 4) = std::nanf("");
  vol.at(7, 3, 2) = INFINITY;
  const ViewGeometry view = make_view(vol, kViews[1], 32, 32, Sampling::voxel);
  const auto ref = shade(vol, view, ShadeParams{});
  const auto run = run_shade(
      dev, vol, shade_params(make_shade_frame(vol, view, ShadeParams{}), ShadeParams{}), 8);
  for (std::size_t i = 0; i < ref.size(); ++i) {
    ASSERT_NEAR(ref[i].diffuse, run.flat[i].diffuse, kTolLight) << i;
    ASSERT_NEAR(ref[i].specular, run.flat[i].specular, kTolLight) << i;
    ASSERT_NEAR(ref[i].gradient, run.flat[i].gradient,
                kTolGradRel * std::max(1.0f, ref[i].gradient))
        << i;
  }
  EXPECT_EQ(run.flat[vol.index(5, 4, 4)].gradient, 0.0f);        // next to the NaN
  EXPECT_FLOAT_EQ(run.flat[vol.index(5, 4, 4)].diffuse, 0.25f);  // ka
}

// Values far beyond float's square root: a random volume times 1e25 (the
// gradients' squares overflow float; before, the kernels took every such
// voxel as no surface, |g| = 0, where the reference lit it), times 1e-25
// (the squares underflow: no surface on both sides, |g| to 1e-6 relative),
// and neighbours 3e38 and -3e38 apart (their float difference overflows:
// no surface on both sides).
TEST(ShadeKernel, HugeAndTinyValues) {
  SIMDVOL_TEST_DEVICE(dev);
  for (const float k : {1e25f, 1e-25f, 1e35f}) {
    Volume vol = testing::random_volume({21, 13, 10}, -100.0f, 100.0f, {1, 1, 1}, 17);
    for (float& v : vol.data()) v *= k;
    for (const ViewAngles& v : kViews)
      for (int64_t pes : {1, 8, 512})
        check_case(vol, v, ShadeParams{}, pes, "random x " + std::to_string(k));
  }
  Volume vol = testing::random_volume({12, 10, 9}, 0.0f, 100.0f, {1, 1, 1}, 11);
  vol.at(4, 4, 4) = 3e38f;
  vol.at(6, 4, 4) = -3e38f;
  check_case(vol, kViews[1], ShadeParams{}, 8, "neighbours 3e38 and -3e38");
  const ViewGeometry view = make_view(vol, kViews[1], 32, 32, Sampling::voxel);
  const auto ref = shade(vol, view, ShadeParams{});
  EXPECT_EQ(ref[vol.index(5, 4, 4)].gradient, 0.0f);        // between them
  EXPECT_FLOAT_EQ(ref[vol.index(5, 4, 4)].diffuse, 0.25f);  // ka
  // A huge gradient is a surface with its length.
  Volume big({3, 1, 1}, VoxelType::f32);
  big.data() = {0.0f, 0.0f, 1e30f};
  const auto rb = shade(big, make_view(big, kViews[0], 8, 8, Sampling::voxel), ShadeParams{});
  EXPECT_FLOAT_EQ(rb[1].gradient, 5e29f);
  EXPECT_GT(rb[1].diffuse, 0.25f);
}

// Values in small units (a random volume times 1e-9, as a diffusion map in
// m^2/s, and times 2^-40): lit as the reference lights them, which is as the
// same volume in larger units (surface_threshold); before, the kernels and
// the reference alike took |g|^2 < 1e-12 as no surface and left every voxel
// ambient only. Each kernel variant, with a flat run of voxels (no surface)
// among them.
TEST(ShadeKernel, TinyValuesAreLit) {
  SIMDVOL_TEST_DEVICE(dev);
  for (const float k : {1e-9f, std::ldexp(1.0f, -40)}) {
    Volume vol = testing::random_volume({37, 29, 23}, 0.0f, 100.0f, {1, 0.8, 2.5}, 23);
    for (int64_t x = 0; x < 37; ++x)
      for (int64_t y = 0; y < 29; ++y) vol.at(x, y, 4) = vol.at(x, y, 5) = vol.at(x, y, 6) = 50.0f;
    for (float& v : vol.data()) v *= k;
    for (const ViewAngles& v : kViews)
      for (int64_t pes : {1, 8, 512})
        check_case(vol, v, ShadeParams{}, pes, "random x " + std::to_string(k));
    const ViewGeometry view = make_view(vol, kViews[1], 32, 32, Sampling::voxel);
    const auto sp = shade_params(make_shade_frame(vol, view, ShadeParams{}), ShadeParams{});
    EXPECT_GT(sp.surface_g2, 0.0f);
    EXPECT_LT(sp.surface_g2, 1e-24f);
    const auto ref = shade(vol, view, ShadeParams{});
    for (ShadeKernel kv :
         {ShadeKernel::range3d, ShadeKernel::voxel, ShadeKernel::rows, ShadeKernel::vec16}) {
      const auto run = run_shade(dev, vol, sp, 64, kv);
      std::size_t lit = 0, ambient = 0;
      for (std::size_t i = 0; i < ref.size(); ++i) {
        ASSERT_NEAR(ref[i].diffuse, run.flat[i].diffuse, kTolLight) << i;
        lit += run.flat[i].diffuse > 0.25f;
        ambient += run.flat[i].diffuse == 0.25f;
      }
      EXPECT_GT(lit, ref.size() / 2) << "k " << k;
      EXPECT_GE(ambient, 37u * 29u) << "k " << k;  // the flat run's middle slice
    }
  }
}

TEST(ShadeKernel, BrainSmall) {
  const auto path = testing::data_dir() / "brainsmall.den";
  SIMDVOL_REQUIRE_FILE(path);
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = load_den(path);
  ShadeParams p;  // VolPack's rendervolume.c lighting
  p.ka = 0.18;
  p.kd = 0.35;
  p.ks = 0.39;
  p.shininess = 10;
  p.light = {0.3, 0.3, 1.0};
  p.k1 = 1.0;
  p.k2 = 0.5;
  for (int64_t pes : {512, 8192}) check_case(vol, kViews[1], p, pes, "brainsmall.den");
  check_case(vol, kViews[2], p, 8, "brainsmall.den");
}

TEST(ShadeKernel, DecompositionsAgree) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = testing::random_volume({37, 29, 23}, -1000.0f, 2000.0f, {1, 1, 1}, 5);
  const ViewGeometry view = make_view(vol, kViews[1], 32, 32, Sampling::voxel);
  const auto sp = shade_params(make_shade_frame(vol, view, ShadeParams{}), ShadeParams{});
  for (int64_t pes : {1, 512}) {
    const auto a = run_shade(dev, vol, sp, pes, ShadeKernel::range3d);
    for (ShadeKernel k : {ShadeKernel::voxel, ShadeKernel::rows, ShadeKernel::vec16}) {
      const auto b = run_shade(dev, vol, sp, pes, k);
      ASSERT_EQ(a.cells.size(), b.cells.size());
      double worst = 0;
      for (std::size_t i = 0; i < a.cells.size(); ++i) {
        worst = std::max(worst,
                         static_cast<double>(std::fabs(a.cells[i].diffuse - b.cells[i].diffuse)));
        worst = std::max(worst,
                         static_cast<double>(std::fabs(a.cells[i].specular - b.cells[i].specular)));
        worst = std::max(worst,
                         std::fabs(static_cast<double>(a.cells[i].gradient - b.cells[i].gradient)) /
                             std::max(1.0f, a.cells[i].gradient));
      }
      EXPECT_LE(worst, 1e-6) << "pes " << pes;
    }
  }
}

// The float16 kernel (the default) for each row width it has: cells whose x
// extent is a multiple of 16, 8 or 4 (with plane tails for 8 and 4), and any
// other width (SV_RW 1: lanes from float estimates for cells up to 2^22
// positions, stepped lane by lane above), against the reference and the
// scalar rows kernel.
TEST(ShadeKernel, Float16RowWidths) {
  SIMDVOL_TEST_DEVICE(dev);
  struct Shape {
    Dims3 dims;
    int64_t pes, cx, cvox;
  };
  const Shape shapes[] = {{{48, 7, 5}, 1, 48, 1680},
                          {{64, 64, 64}, 8, 32, 32768},
                          {{16, 3, 5}, 2, 8, 120},
                          {{64, 64, 64}, 512, 8, 512},
                          {{8, 3, 3}, 2, 4, 36},
                          {{32, 32, 32}, 512, 4, 64},
                          {{24, 5, 3}, 2, 12, 180},
                          // SV_RW 1 (per-lane positions): chunks across rows and planes
                          {{22, 9, 7}, 1, 22, 1386},
                          {{5, 7, 3}, 1, 5, 105},
                          // (lx, ly, lz) from float estimates of q / cx and row / cy
                          // that are one short from the first row (plane) on for cx
                          // (cy) = 41, 47, 61: the correction by the remainder
                          {{41, 41, 5}, 1, 41, 8405},
                          {{47, 23, 3}, 1, 47, 3243},
                          {{61, 5, 41}, 1, 61, 12505},
                          // a cell over 2^22 positions: the lane-by-lane steps
                          {{131, 127, 253}, 1, 131, 4209161}};
  for (const Shape& sh : shapes) {
    SCOPED_TRACE("dims " + std::to_string(sh.dims[0]) + "x" + std::to_string(sh.dims[1]) + "x" +
                 std::to_string(sh.dims[2]) + " pes " + std::to_string(sh.pes));
    const Volume vol = testing::random_volume(sh.dims, -1000.0f, 2000.0f, {1, 1.25, 0.8}, 9);
    const ViewGeometry view = make_view(vol, kViews[2], 32, 32, Sampling::voxel);
    ShadeParams p;
    p.shininess = 24;
    const auto sp = shade_params(make_shade_frame(vol, view, p), p);
    const auto v = run_shade(dev, vol, sp, sh.pes, ShadeKernel::vec16);
    ASSERT_EQ(v.layout.cell()[0], sh.cx);
    ASSERT_EQ(v.layout.cell_voxels(), sh.cvox);
    const Diff d = compare(vol, shade(vol, view, p), v.flat);
    EXPECT_LE(d.id, kTolLight);
    EXPECT_LE(d.is, kTolLight);
    EXPECT_LE(d.grad_rel, kTolGradRel);
    EXPECT_TRUE(d.value_exact);
    const auto r = run_shade(dev, vol, sp, sh.pes, ShadeKernel::rows);
    ASSERT_EQ(v.cells.size(), r.cells.size());
    double worst = 0;
    for (std::size_t i = 0; i < v.cells.size(); ++i) {
      worst =
          std::max(worst, static_cast<double>(std::fabs(v.cells[i].diffuse - r.cells[i].diffuse)));
      worst = std::max(worst,
                       static_cast<double>(std::fabs(v.cells[i].specular - r.cells[i].specular)));
      worst = std::max(worst,
                       std::fabs(static_cast<double>(v.cells[i].gradient - r.cells[i].gradient)) /
                           std::max(1.0f, r.cells[i].gradient));
      ASSERT_EQ(v.cells[i].pad, r.cells[i].pad) << "element " << i;  // values and zero tails
    }
    EXPECT_LE(worst, 1e-6);
  }
}

TEST(ShadeKernel, RejectsBadArguments) {
  SIMDVOL_TEST_DEVICE(dev);
  const Volume vol = testing::random_volume({16, 16, 16}, 0, 1, {1, 1, 1}, 1);
  PeArray array(dev, pe_grid(8));
  CellBuffer no_halo = array.layout(vol, 0);
  CellBuffer cells = array.layout(vol, 1);
  VoxelBuffer out(dev, make_voxel_layout(cells.layout()));
  const ViewGeometry view = make_view(vol, kViews[0], 16, 16, Sampling::voxel);
  const auto sp = shade_params(make_shade_frame(vol, view, ShadeParams{}), ShadeParams{});
  EXPECT_THROW(enqueue_shade(dev, no_halo, sp, out), ArgumentError);
  PeArray other(dev, pe_grid(64));
  CellBuffer cells64 = other.layout(vol, 1);
  EXPECT_THROW(enqueue_shade(dev, cells64, sp, out), ArgumentError);
  ShadeFrame f = make_shade_frame(vol, view, ShadeParams{});
  f.depth_offset = NAN;
  EXPECT_THROW(shade_params(f, ShadeParams{}), ArgumentError);
}

}  // namespace
}  // namespace simdvol
