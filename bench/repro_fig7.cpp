// simdvol-repro-fig7: thesis fig 7.2 (whole-ray Monte Carlo) and fig 7.3
// (per sub-ray Monte Carlo) reproduced: PSNR of the Monte Carlo intermediate
// image against direct compositing, versus the number of samples (walks)
// 1, 2, 4, ..., 128, for every variant, on the 256^3 CT phantom
// (shepp_logan(256, 4), preset ct) and on brainsmall.den (preset volpack).
//
//   simdvol-repro-fig7 --out DIR [--brain PATH] [--pes P] [--size N]
//                      [--view theta,phi,varphi] [--seed S] [--order K]
//
// Writes DIR/fig7.csv and DIR/fig7.png (2 x 2 panels: rows CT phantom,
// brainsmall; columns whole ray (fig 7.2), per sub-ray (fig 7.3); x = log2 n
// from 0 to 7, y = PSNR 10 .. 70 dB, grid every 10 dB, the 38 dB line in
// grey; the legend of colours is printed).
//
// Everything runs on the device (PoCL): shade + classify, match + balance
// on P PEs (default 8,192), resample into the samples buffer, then the
// Monte Carlo kernels of mc.cl; the direct image is the device's local
// (direct) compositing of the same segments, composited in depth order on
// the host (composite_footprints), as are the per-sub-ray footprints (until
// the swap stage does it on the device). PSNR is over RGB, peak 1, on the
// intermediate image (voxel sampling, before the 2-D warp, which would blur
// the noise).
//
// Variants: plain (thesis), exact opacity (ch. 7.5 (a)), allocation by
// opacity (ch. 7.5 (b)), and beyond the thesis stratified picks with exact
// opacity (strat, strat-alloc; CompositeParams::stratified).
// n is the walks per ray (whole ray), per sub-ray (plain and exact per
// sub-ray, as the thesis's fig 7.3), or the per-ray budget (allocated); the
// CSV also gives the walks and random draws actually spent per ray.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "bench_args.hpp"
#include "bench_common.hpp"
#include "simdvol/classify.hpp"
#include "simdvol/device.hpp"
#include "simdvol/io.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/mc.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/view.hpp"

using namespace simdvol;
using simdvol::bench::Args;
using simdvol::bench::argument_error;
using simdvol::bench::check_output_dir;
using simdvol::bench::check_output_file;
using simdvol::bench::make_output_dir;

namespace {

struct Variant {
  const char* scope;  // "whole" or "sub"
  const char* name;   // plain, exact, alloc, strat (exact + stratified), strat-alloc
  RandomStreams streams;
  Rgba colour;
};

const Variant kVariants[] = {
    {"whole", "plain", RandomStreams::per_ray, {0.90f, 0.10f, 0.10f, 1}},
    {"whole", "plain", RandomStreams::shared, {1.00f, 0.60f, 0.00f, 1}},
    {"whole", "exact", RandomStreams::per_ray, {0.15f, 0.30f, 1.00f, 1}},
    {"whole", "exact", RandomStreams::shared, {0.00f, 0.85f, 0.95f, 1}},
    {"sub", "plain", RandomStreams::per_ray, {0.90f, 0.10f, 0.10f, 1}},
    {"sub", "plain", RandomStreams::shared, {1.00f, 0.60f, 0.00f, 1}},
    {"sub", "exact", RandomStreams::per_ray, {0.15f, 0.30f, 1.00f, 1}},
    {"sub", "exact", RandomStreams::shared, {0.00f, 0.85f, 0.95f, 1}},
    {"sub", "alloc", RandomStreams::per_ray, {0.10f, 0.75f, 0.10f, 1}},
    {"sub", "alloc", RandomStreams::shared, {0.70f, 1.00f, 0.30f, 1}},
    {"whole", "strat", RandomStreams::per_ray, {0.75f, 0.20f, 0.90f, 1}},
    {"sub", "strat", RandomStreams::per_ray, {0.75f, 0.20f, 0.90f, 1}},
    {"sub", "strat-alloc", RandomStreams::per_ray, {0.45f, 0.25f, 0.10f, 1}},
};
const char* streams_name(RandomStreams s) {
  return s == RandomStreams::shared ? "shared" : "per-ray";
}

struct Row {
  std::string dataset;
  const Variant* v;
  int n;
  double psnr;
  double walks_per_ray, draws_per_ray;
  int64_t fallbacks;
};

Image read_image(Device& dev, const cl::Buffer& b, int w, int h) {
  Image im(w, h);
  cl_check(
      dev.queue().enqueueReadBuffer(b, CL_TRUE, 0, im.pixels().size() * 16, im.pixels().data()),
      "clEnqueueReadBuffer(image)");
  return im;
}

// ---- plot ----
void put(Image& im, int x, int y, const Rgba& c) {
  if (x >= 0 && y >= 0 && x < im.width() && y < im.height()) im.at(x, y) = c;
}
void line(Image& im, int x0, int y0, int x1, int y1, const Rgba& c, int thick = 1) {
  const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0);
  const int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
  int err = dx + dy;
  for (;;) {
    for (int a = -(thick / 2); a <= thick / 2; ++a)
      for (int b = -(thick / 2); b <= thick / 2; ++b) put(im, x0 + a, y0 + b, c);
    if (x0 == x1 && y0 == y1) break;
    const int e2 = 2 * err;
    if (e2 >= dy) {
      err += dy;
      x0 += sx;
    }
    if (e2 <= dx) {
      err += dx;
      y0 += sy;
    }
  }
}

void plot(const std::vector<Row>& rows, const std::vector<std::string>& datasets,
          const std::filesystem::path& path) {
  const int PW = 420, PH = 320, M = 30;
  Image im(2 * PW, static_cast<int>(datasets.size()) * PH);
  for (Rgba& p : im.pixels()) p = {1, 1, 1, 1};
  const double ylo = 10, yhi = 70;
  for (std::size_t d = 0; d < datasets.size(); ++d)
    for (int col = 0; col < 2; ++col) {
      const int ox = col * PW + M, oy = static_cast<int>(d) * PH + M;
      const int w = PW - 2 * M, h = PH - 2 * M;
      auto X = [&](int n) { return ox + static_cast<int>(std::lround(std::log2(n) / 7.0 * w)); };
      auto Y = [&](double db) {
        db = std::clamp(db, ylo, yhi);
        return oy + h - static_cast<int>(std::lround((db - ylo) / (yhi - ylo) * h));
      };
      for (double db = ylo; db <= yhi; db += 10)
        line(im, ox, Y(db), ox + w, Y(db), {0.88f, 0.88f, 0.88f, 1});
      for (int n = 1; n <= 128; n *= 2) line(im, X(n), oy + h, X(n), oy + h + 5, {0, 0, 0, 1});
      for (int x = ox; x <= ox + w; x += 6)
        line(im, x, Y(38), std::min(x + 3, ox + w), Y(38), {0.45f, 0.45f, 0.45f, 1}, 1);
      line(im, ox, oy, ox, oy + h, {0, 0, 0, 1});
      line(im, ox, oy + h, ox + w, oy + h, {0, 0, 0, 1});
      const char* scope = col == 0 ? "whole" : "sub";
      for (const Variant& v : kVariants) {
        if (std::strcmp(v.scope, scope) != 0) continue;
        int px = -1, py = -1;
        for (const Row& r : rows) {
          if (r.dataset != datasets[d] || r.v != &v) continue;
          const int x = X(r.n), y = Y(std::isfinite(r.psnr) ? r.psnr : yhi);
          if (px >= 0) line(im, px, py, x, y, v.colour, v.streams == RandomStreams::shared ? 1 : 3);
          for (int a = -3; a <= 3; ++a)
            for (int b = -3; b <= 3; ++b) put(im, x + a, y + b, v.colour);
          px = x;
          py = y;
        }
      }
    }
  write_image(im, path);
}

constexpr const char* kUsage =
    "usage: simdvol-repro-fig7 --out DIR [--brain PATH] [--pes P] [--size N]\n"
    "                          [--view theta,phi,varphi] [--seed S] [--order K]\n"
    "  P: a power of two in 1..1048576; N: 8..1024 (the N^3 phantom); view: three angles\n"
    "  in -360..360 (degrees); S: 0..18446744073709551615; K: 0..3; PATH: brainsmall.den\n"
    "  (default: in $SIMDVOL_DATA_DIR where set, else in the source tree's data/)\n";

}  // namespace

int main(int argc, char** argv) try {
  simdvol::remove_temporary_files_on_signals();
  std::filesystem::path out, brain = simdvol::bench::data_dir() / "brainsmall.den";
  int64_t pes = 8192;
  int size = 256, order = 1;
  uint64_t seed = 1;
  ViewAngles angles{20, 30, 0};
  try {
    Args args(argc, argv);
    while (args.next()) {
      if (args.help()) {
        std::fputs(kUsage, stdout);
        return 0;
      } else if (args.is("--out")) {
        out = args.name();
      } else if (args.is("--brain")) {
        brain = args.existing_file();
      } else if (args.is("--pes")) {
        pes = args.pes();
      } else if (args.is("--size")) {
        size = static_cast<int>(args.integer(8, 1024));
      } else if (args.is("--order")) {
        order = static_cast<int>(args.integer(0, 3));
      } else if (args.is("--seed")) {
        seed = args.uint64();
      } else if (args.is("--view")) {
        angles = args.view();
      } else {
        args.unknown();
      }
    }
    if (out.empty())
      throw ArgumentError("--out", "the output directory (for fig7.csv and fig7.png) is required");
    // Checked before any work: a fig7.png that could not be written had
    // left a fresh fig7.csv over the old one.
    check_output_dir(out, "--out");
    if (std::filesystem::is_directory(out))
      for (const char* f : {"fig7.csv", "fig7.png"}) check_output_file(out / f, "--out");
    make_output_dir(out, "--out");
  } catch (const ArgumentError& e) {
    return argument_error("simdvol-repro-fig7", e, kUsage);
  }

  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // progress lines when redirected
  Device device;
  std::printf(
      "device: %s (%u compute units); every stage and every Monte Carlo estimate runs "
      "on the device\n",
      device.info().name.c_str(), device.info().compute_units);
  std::printf("view (%g, %g, %g), order %d, %lld PEs, seed %llu, voxel sampling\n\n", angles.theta,
              angles.phi, angles.varphi, order, static_cast<long long>(pes),
              static_cast<unsigned long long>(seed));

  struct Data {
    std::string name;
    Volume vol;
    Classifier cls;
  };
  std::vector<Data> data;
  data.push_back(
      {"ct-phantom-" + std::to_string(size), shepp_logan(size, 4), classifier_preset("ct")});
  if (std::filesystem::exists(brain))
    data.push_back({"brainsmall", load_volume(brain), classifier_preset("volpack")});
  else
    std::printf("(%s not found: the brain is skipped)\n", brain.string().c_str());

  std::vector<Row> rows;
  std::vector<std::string> names;
  const int ns[] = {1, 2, 4, 8, 16, 32, 64, 128};
  for (Data& d : data) {
    names.push_back(d.name);
    const Volume& vol = d.vol;
    const ViewGeometry view = make_view(vol, angles, size, size, Sampling::voxel);
    const int W = view.width(), H = view.height();
    PeArray array(device, pe_grid(pes));
    CellBuffer cells = array.layout(vol, 1);
    const VoxelLayout L = make_voxel_layout(cells.layout());
    VoxelBuffer rgba(device, L);
    const ShadeParams shp{};
    enqueue_shade_classify(device, cells, shade_params(make_shade_frame(vol, view, shp), shp),
                           classify_params(d.cls, classify_range(vol, d.cls), view.step), rgba);
    const KdSplit& split = cells.layout().split;
    DeviceMatching dm = enqueue_match(device, view, split);
    enqueue_balance(device, dm, view, split);
    const LocalSegments segs = device_segments(device, dm);
    const Matching m = dm.read(device);
    const ResampleTables tables = make_resample_tables(device, L, view);
    const cl::Buffer soff = upload_sample_offsets(device, m);
    const int64_t nsamples = sample_offsets(m).back();
    cl::Buffer samples = device.buffer(
        CL_MEM_READ_WRITE, static_cast<std::size_t>(std::max<int64_t>(nsamples, 1)) * 16, nullptr,
        "samples");
    enqueue_resample(device, segs, soff, tables, rgba, order, samples);
    DeviceFootprints fp = make_footprints(device, m.rects);
    enqueue_zero_footprints(device, fp);
    enqueue_local(device, segs, soff, samples, fp);
    const Image direct = composite_footprints(m, read_footprints(device, fp), W, H);
    DeviceRayLists rays = enqueue_ray_lists(device, segs, view);
    const RaySegments host_rays = read_ray_lists(device, rays);
    int64_t live_rays = 0;
    for (std::size_t q = 0; q + 1 < host_rays.offset.size(); ++q)
      live_rays += host_rays.offset[q + 1] > host_rays.offset[q];
    std::printf(
        "%s: %dx%dx%d, %dx%d rays (%lld through the volume), %lld samples, %lld segments "
        "(%.1f non-empty per ray), utilisation %.3f\n",
        d.name.c_str(), static_cast<int>(vol.dims()[0]), static_cast<int>(vol.dims()[1]),
        static_cast<int>(vol.dims()[2]), W, H, static_cast<long long>(live_rays),
        static_cast<long long>(nsamples), static_cast<long long>(m.segments.size()),
        static_cast<double>(host_rays.items.size()) / std::max<int64_t>(live_rays, 1),
        m.utilisation());
    cl::Buffer image =
        device.buffer(CL_MEM_READ_WRITE, static_cast<std::size_t>(W) * H * 16, nullptr, "image");
    DeviceFootprints mcfp = make_footprints(device, m.rects);
    for (const Variant& v : kVariants) {
      for (int n : ns) {
        CompositeParams p;
        p.mode = CompositeMode::mc;
        p.samples = n;
        p.seed = seed;
        p.streams = v.streams;
        p.exact_opacity = std::strcmp(v.name, "plain") != 0;
        p.stratified = std::strncmp(v.name, "strat", 5) == 0;
        DeviceMcStats st;
        Image im;
        if (!std::strcmp(v.scope, "whole")) {
          enqueue_mc_whole(device, segs, soff, samples, rays, p, image, &st);
          im = read_image(device, image, W, H);
        } else {
          std::optional<DeviceAllocation> alloc;
          if (!std::strcmp(v.name, "alloc") || !std::strcmp(v.name, "strat-alloc"))
            alloc = enqueue_mc_allocation(device, segs, soff, samples, rays, n);
          enqueue_zero_footprints(device, mcfp);
          enqueue_mc_local(device, segs, soff, samples, W, p, alloc ? &*alloc : nullptr, mcfp, &st);
          im = composite_footprints(m, read_footprints(device, mcfp), W, H);
        }
        const McStats s = st.read(device);
        // Per pixel: whole-ray Monte Carlo starts its n walks on every ray,
        // those that miss the volume too (over the rays through the volume
        // it read 8.26 at n = 8).
        const double rays_all = static_cast<double>(W) * H;
        rows.push_back({d.name, &v, n, psnr(im, direct), static_cast<double>(s.walks) / rays_all,
                        static_cast<double>(s.draws) / rays_all, s.fallbacks});
      }
    }
    // Ch. 7.5 (c): transparent samples dropped before sampling: same image,
    // fewer draws (n = 8, per-ray streams).
    for (const char* scope : {"whole", "sub"}) {
      CompositeParams p;
      p.samples = 8;
      p.seed = seed;
      Image a, b;
      McStats sa, sb;
      for (bool drop : {false, true}) {
        p.drop_transparent = drop;
        DeviceMcStats st;
        Image im;
        if (!std::strcmp(scope, "whole")) {
          enqueue_mc_whole(device, segs, soff, samples, rays, p, image, &st);
          im = read_image(device, image, W, H);
        } else {
          enqueue_zero_footprints(device, mcfp);
          enqueue_mc_local(device, segs, soff, samples, W, p, nullptr, mcfp, &st);
          im = composite_footprints(m, read_footprints(device, mcfp), W, H);
        }
        (drop ? b : a) = im;
        (drop ? sb : sa) = st.read(device);
      }
      std::printf(
          "  drop transparent (%s ray, n = 8): draws %lld -> %lld (%.1f%% saved), image %s\n",
          scope, static_cast<long long>(sa.draws), static_cast<long long>(sb.draws),
          100.0 * static_cast<double>(sa.draws - sb.draws) / std::max<int64_t>(sa.draws, 1),
          a.pixels().size() == b.pixels().size() &&
                  std::equal(a.pixels().begin(), a.pixels().end(), b.pixels().begin(),
                             [](const Rgba& x, const Rgba& y) {
                               return x.r == y.r && x.g == y.g && x.b == y.b && x.a == y.a;
                             })
              ? "bitwise identical"
              : "DIFFERENT");
    }
  }

  // CSV and table.
  std::ostringstream csv;
  csv << "dataset,scope,variant,streams,n,psnr_db,walks_per_ray,draws_per_ray,fallbacks\n";
  for (const Row& r : rows)
    csv << r.dataset << ',' << r.v->scope << ',' << r.v->name << ',' << streams_name(r.v->streams)
        << ',' << r.n << ',' << r.psnr << ',' << r.walks_per_ray << ',' << r.draws_per_ray << ','
        << r.fallbacks << '\n';
  for (const std::string& dn : names) {
    std::printf("\n%s: PSNR (dB) vs n  [walks per ray at n = 8]\n%-6s %-11s %-8s", dn.c_str(),
                "scope", "variant", "streams");
    for (int n : ns) std::printf(" %6d", n);
    std::printf("  w/ray@8\n");
    for (const Variant& v : kVariants) {
      std::printf("%-6s %-11s %-8s", v.scope, v.name, streams_name(v.streams));
      double w8 = 0;
      for (const Row& r : rows)
        if (r.dataset == dn && r.v == &v) {
          std::printf(" %6.2f", r.psnr);
          if (r.n == 8) w8 = r.walks_per_ray;
        }
      std::printf("  %7.1f\n", w8);
    }
  }
  // The tables first: a CSV that could not be written took them with it.
  write_file_atomically(out / "fig7.csv", {csv.str()});
  plot(rows, names, out / "fig7.png");
  std::printf(
      "\nn: walks per ray (whole), per sub-ray (sub plain/exact, as fig 7.3), per-ray budget "
      "(sub alloc, strat-alloc). strat: exact opacity with stratified picks "
      "(CompositeParams::stratified, beyond the thesis). w/ray: walks started per ray, over "
      "all W x H rays (whole-ray Monte Carlo starts n on each, also those that miss the "
      "volume).\n"
      "plot %s (rows: datasets; columns: whole ray = fig 7.2, per sub-ray = fig 7.3; x = log2 n "
      "0..7; y = 10..70 dB, grey grid every 10 dB, dashed grey line 38 dB; thick lines per-ray "
      "streams, thin shared)\nlegend: red plain, orange plain shared, blue exact opacity, cyan "
      "exact shared, green exact + opacity allocation, light green allocation shared, purple "
      "stratified, brown stratified + allocation\n"
      "csv %s\n",
      (out / "fig7.png").string().c_str(), (out / "fig7.csv").string().c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "simdvol-repro-fig7: %s\n", e.what());
  return 1;
}
