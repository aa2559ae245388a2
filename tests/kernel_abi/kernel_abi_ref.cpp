// kernel-abi-ref: the library's side of the kernel ABI check
// (tests/kernel_abi/kernel_abi_check.py, run by scripts/embed-check against
// an installed prefix). For a handful of cases it writes what a host of the
// kernels starts from and what the serial references make of it, one
// directory per case (meta.txt: "key value" lines; binary files raw,
// little-endian):
//   swap-*: a view (sv_view), the k-d split's bit_axis, the matching's
//     rectangles, random footprints on them, and per layout plan_swap's
//     tables (bits, front, held, offset, xpe, ype) with swap_reference's last
//     level and display_reference's image;
//   mc-*: a view, the (balanced) matching's segments and rectangles,
//     resample_reference's samples, and the references: sample_offsets,
//     ray_segments, mc_whole_reference and mc_sub_reference (with and without
//     allocation_reference) in several variants with their McStats,
//     segment_alphas, composite_adaptive per ray at two thresholds and, with
//     voxel sampling, the warp tables of output_to_intermediate and
//     warp_to_output's image;
//   direct-*: a phantom, its view, kd_split's bit_axis, the library's cell
//     geometry (CellLayout, VoxelLayout), origins and pe_of_cell,
//     layout_reference's cells, the raw sv_shade_params and
//     sv_classify_params with their defines, shade() and classify(), the
//     voxels in voxel cells (voxels_to_cells), resample_address_table
//     (planar, interleaved), resample_pair_table, resample_cell_bits, the
//     matching's candidates, segments, offsets and rectangles, the balanced
//     segments, and per order 0-3 resample_reference's samples and
//     footprints_reference(local_reference)'s footprints;
//   match-*: a view, match_candidates, (with a PE mask) a brick reach and
//     match_active_reference's mask, match_reference's segments, offsets,
//     rectangles and loads, balance_links, and (with sweeps) the balanced
//     segments and loads with, per sweep, whether it changed the bounds.
// Nothing here runs a kernel: the Python host does, from KERNELS.md.
//
// Usage: kernel-abi-ref DIR. Exit status 0, or 2 on an error.
#include <simdvol/simdvol.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace simdvol;
namespace fs = std::filesystem;

template <class T>
void put(const fs::path& file, const std::vector<T>& v) {
  std::ofstream f(file, std::ios::binary);
  f.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
  if (!f) throw std::runtime_error("cannot write " + file.string());
}

std::vector<int32_t> to32(const std::vector<int64_t>& v) {
  std::vector<int32_t> out;
  for (int64_t x : v) out.push_back(static_cast<int32_t>(x));
  return out;
}

// meta.txt: one "key value" line each.
struct Meta {
  std::ofstream out;
  explicit Meta(const fs::path& dir) : out(dir / "meta.txt") {}
  template <class T>
  void operator()(const char* key, const T& value) {
    out << key << " " << value << "\n";
  }
};

template <class T>
std::string words(const std::array<T, 3>& v) {
  std::ostringstream o;
  o << v[0] << " " << v[1] << " " << v[2];
  return o.str();
}

// ---------------------------------------------------------------- swap
struct SwapCase {
  const char* name;
  Dims3 dims;
  int64_t pes;
  ViewAngles angles;
  int width, height;  // pixel sampling: the intermediate image is the output's size
};

void write_swap_case(const fs::path& dir, const SwapCase& c, std::mt19937& rng) {
  fs::create_directories(dir);
  const ViewGeometry view =
      make_view(c.dims, {1, 1, 1}, c.angles, c.width, c.height, Sampling::pixel);
  if (view.width() != c.width || view.height() != c.height)
    throw std::runtime_error(std::string(c.name) + ": unexpected intermediate size");
  const KdSplit split = kd_split(c.dims, c.pes);
  const Matching m = match_reference(view, split);
  // Random footprints on the matching's rectangles: some pixels 0 (no
  // segment), some opaque, the rest premultiplied colours of random alpha.
  Footprints f;
  f.rect_offset = rect_offsets(m);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int64_t e = 0; e < f.rect_offset.back(); ++e) {
    const float r = u(rng), a = r < 0.2f ? 0.f : r < 0.25f ? 1.f : u(rng);
    f.pixels.push_back({a * u(rng), a * u(rng), a * u(rng), a});
  }
  Meta meta(dir);
  meta("kind", "swap");
  meta("pes", c.pes);
  meta("width", c.width);
  meta("height", c.height);
  meta("dims", words(c.dims));
  put(dir / "view.bin", std::vector<sv_view>{view.grid});
  put(dir / "bit_axis.i32", split.bit_axis);
  put(dir / "rects.bin", m.rects);
  put(dir / "foot.f32", f.pixels);
  for (SwapLayout layout : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
    const SwapPlan plan = plan_swap(m.rects, split, view, pe_grid(c.pes), layout);
    const std::string p = swap_layout_name(layout);
    std::vector<int32_t> bits;
    for (const PixelBit& b : plan.bits) bits.insert(bits.end(), {b.axis, b.level});
    std::vector<SwapRect> held;
    std::vector<int64_t> offset;
    for (int level = 0; level <= plan.stages(); ++level) {
      held.insert(held.end(), plan.held[level].begin(), plan.held[level].end());
      offset.insert(offset.end(), plan.offset[level].begin(), plan.offset[level].end());
    }
    const std::vector<Rgba> last = swap_reference(plan, f);
    put(dir / (p + ".bits.i32"), bits);
    put(dir / (p + ".front.i32"), plan.front);
    put(dir / (p + ".held.i32"), held);
    put(dir / (p + ".off.i64"), offset);
    put(dir / (p + ".xpe.i64"), plan.xpe);
    put(dir / (p + ".ype.i64"), plan.ype);
    put(dir / (p + ".last.f32"), last);
    put(dir / (p + ".image.f32"), display_reference(plan, last).pixels());
  }
}

// ---------------------------------------------------------------- Monte Carlo, adaptive, warp
struct McCase {
  const char* name;
  struct {
    Dims3 dims;  // shepp_logan(n), n the largest of them, cropped to them
    std::array<double, 3> spacing;
  } volume;
  struct {
    ViewAngles angles;
    int out_width, out_height;
    Sampling sampling;
    Framing framing;
  } view;
  struct {
    int64_t pes;
    int sweeps, order, walks;
    uint64_t seed;
    bool tiny;  // some transparent samples made denormal or tiny instead
  } run;
};

struct McVariant {
  const char* name;
  bool exact, stratified;
  RandomStreams streams;
  bool sub;  // also per sub-ray
};
constexpr McVariant kVariants[] = {
    {"plain_ray", false, false, RandomStreams::per_ray, true},
    {"plain_shared", false, false, RandomStreams::shared, false},
    {"exact_ray", true, false, RandomStreams::per_ray, false},
    {"exact_shared", true, false, RandomStreams::shared, true},
    {"strat_ray", true, true, RandomStreams::per_ray, true},
    {"strat_shared", true, true, RandomStreams::shared, false},
};
constexpr float kThresholds[] = {0.95f, 0.5f};

std::vector<int64_t> stats_words(const McStats& s) {
  return {s.walks, s.draws, s.skipped, s.fallbacks};
}

// shepp_logan(n), n the largest of dims, cropped to dims.
Volume phantom(const Dims3& dims, const std::array<double, 3>& spacing) {
  const Volume full = shepp_logan(static_cast<int>(std::max({dims[0], dims[1], dims[2]})));
  Volume vol(dims, VoxelType::f32, spacing);
  for (int64_t z = 0; z < dims[2]; ++z)
    for (int64_t y = 0; y < dims[1]; ++y)
      for (int64_t x = 0; x < dims[0]; ++x) vol.at(x, y, z) = full.at(x, y, z);
  return vol;
}

void write_mc_case(const fs::path& dir, const McCase& c) {
  fs::create_directories(dir);
  const Dims3& dims = c.volume.dims;
  const Volume vol = phantom(dims, c.volume.spacing);
  const ViewGeometry view = make_view(vol, c.view.angles, c.view.out_width, c.view.out_height,
                                      c.view.sampling, c.view.framing);
  const std::vector<Rgba> voxels =
      classify(vol, shade(vol, view, ShadeParams{}), classifier_preset("ct"), view.step);
  const KdSplit split = kd_split(dims, c.run.pes);
  Matching m = match_reference(view, split);
  if (c.run.sweeps > 0) m = balance_reference(m, view, split, c.run.sweeps);
  std::vector<Rgba> s = resample_reference(m, voxels, dims, view, c.run.order);
  if (c.run.tiny) {  // the kernels' tests of alpha > 0 on denormal and tiny alphas
    for (std::size_t e = 0; e < s.size(); e += 5) {
      if (s[e].a > 0) continue;
      const Rgba tiny[] = {
          {5e-40f, 2e-40f, 0, 1e-39f}, {1e-38f, 0, 5e-39f, 2e-38f}, {0, 0, 0, 1.4e-45f}};
      s[e] = tiny[e / 5 % 3];
    }
  }
  const int W = view.width(), H = view.height();
  const RaySegments rays = ray_segments(m, W, H);
  Meta meta(dir);
  meta("kind", "mc");
  meta("width", W);
  meta("height", H);
  meta("pes", c.run.pes);
  meta("nseg", m.segments.size());
  meta("ow", view.out_width);
  meta("oh", view.out_height);
  meta("seed", c.run.seed);
  meta("walks", c.run.walks);
  meta("sampling", c.view.sampling == Sampling::voxel ? "voxel" : "pixel");
  meta("framing", c.view.framing == Framing::longest ? "longest" : "diagonal");
  meta("dims", words(dims));
  meta("spacing", words(c.volume.spacing));
  put(dir / "segs.bin", m.segments);
  put(dir / "seg_offset.i32", to32(m.seg_offset));
  put(dir / "rects.bin", m.rects);
  put(dir / "rect_off.i32", to32(rect_offsets(m)));
  put(dir / "samples.f32", s);
  put(dir / "sample_off.i32", to32(sample_offsets(m)));
  put(dir / "ray_off.i32", to32(rays.offset));
  put(dir / "ray_items.i32", to32(rays.items));
  const std::vector<int32_t> alloc = allocation_reference(m, s, rays, c.run.walks);
  put(dir / "alloc.i32", alloc);
  put(dir / "seg_alpha.f32", segment_alphas(m, s));
  for (const McVariant& v : kVariants) {
    CompositeParams p;
    p.mode = CompositeMode::mc;
    p.samples = c.run.walks;
    p.seed = c.run.seed;
    p.streams = v.streams;
    p.exact_opacity = v.exact;
    p.stratified = v.stratified;
    McStats st;
    put(dir / (std::string("whole_") + v.name + ".f32"),
        mc_whole_reference(m, s, rays, p, &st).pixels());
    put(dir / (std::string("whole_") + v.name + ".stats"), stats_words(st));
    for (int with_alloc = 0; with_alloc < 2 && v.sub; ++with_alloc) {
      McStats sub_st;
      const std::vector<Rgba> sub =
          mc_sub_reference(m, s, rays, p, with_alloc ? alloc : std::vector<int32_t>{}, &sub_st);
      const std::string base = std::string("sub_") + v.name + (with_alloc ? "_alloc" : "");
      put(dir / (base + ".foot.f32"), footprints_reference(m, sub).pixels);
      put(dir / (base + ".stats"), stats_words(sub_st));
    }
  }
  // Adaptive: composite_adaptive on each ray's samples, its segments in
  // increasing k0 (ray_segments), from the first segment's depth.
  const std::vector<int64_t> so = sample_offsets(m);
  for (float threshold : kThresholds) {
    Image img(W, H);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        const int64_t px = int64_t(j) * W + i;
        if (rays.offset[px] == rays.offset[px + 1]) continue;
        std::vector<Rgba> ray;
        for (int64_t q = rays.offset[px]; q < rays.offset[px + 1]; ++q)
          ray.insert(ray.end(), s.begin() + so[rays.items[q]], s.begin() + so[rays.items[q] + 1]);
        img.at(i, j) = composite_adaptive(
            RaySamples{ray, m.segments[rays.items[rays.offset[px]]].k0}, threshold);
      }
    char name[32];
    std::snprintf(name, sizeof name, "adaptive_%g.f32", double(threshold));
    put(dir / name, img.pixels());
    if (threshold == kThresholds[0] && c.view.sampling == Sampling::voxel) {
      // The warp of that image, and the library's tables: floor and
      // fraction of output_to_intermediate, column x from (x, 0), row y from (0, y).
      std::vector<int32_t> ix, iy;
      std::vector<float> tx, ty;
      for (int x = 0; x < view.out_width; ++x) {
        const double f = view.output_to_intermediate(x, 0)[0], fl = std::floor(f);
        ix.push_back(static_cast<int32_t>(fl));
        tx.push_back(static_cast<float>(f - fl));
      }
      for (int y = 0; y < view.out_height; ++y) {
        const double f = view.output_to_intermediate(0, y)[1], fl = std::floor(f);
        iy.push_back(static_cast<int32_t>(fl));
        ty.push_back(static_cast<float>(f - fl));
      }
      put(dir / "warp_ix.i32", ix);
      put(dir / "warp_tx.f32", tx);
      put(dir / "warp_iy.i32", iy);
      put(dir / "warp_ty.f32", ty);
      put(dir / "warp_in.f32", img.pixels());
      put(dir / "warp_ref.f32", warp_to_output(img, view).pixels());
    }
  }
}

// ---------------------------------------------------------------- direct frame
struct DirectCase {
  const char* name;
  struct {
    Dims3 dims;  // phantom(dims, spacing) times scale
    std::array<double, 3> spacing;
    float scale;
  } volume;
  struct {
    ViewAngles angles;
    int out_width, out_height;
    Sampling sampling;
  } view;
  struct {
    int64_t pes;
    const char* classifier;  // classifier_preset
    int sweeps;              // balance_reference's (0: the matching itself)
  } run;
};

void put_defines(Meta& meta, const char* key, const Defines& defines) {
  for (const auto& [name, value] : defines) meta(key, name + " " + value);
}

void write_direct_case(const fs::path& dir, const DirectCase& c) {
  fs::create_directories(dir);
  const Dims3& dims = c.volume.dims;
  const int64_t pes = c.run.pes;
  Volume vol = phantom(dims, c.volume.spacing);
  for (float& v : vol.data()) v *= c.volume.scale;
  const ViewGeometry view = make_view(vol, c.view.angles, c.view.out_width, c.view.out_height,
                                      c.view.sampling, Framing::longest);
  const KdSplit split = kd_split(dims, pes);
  const CellLayout cells = make_cell_layout(dims, pes, 1);
  const VoxelLayout planar = make_voxel_layout(cells), il = make_voxel_layout(cells, true);
  const ShadeParams sp{};
  const sv_shade_params shade_p = shade_params(make_shade_frame(vol, view, sp), sp);
  const Classifier classifier = classifier_preset(c.run.classifier);
  const ValueRange range = vol.range();  // (the shading's; the mixture's below)
  const sv_classify_params classify_p =
      classify_params(classifier, mixture_range(vol, classifier.mixture, range), view.step);
  const std::vector<ShadeSample> shading = shade(vol, view, sp);
  const std::vector<Rgba> rgba = classify(vol, shading, classifier, view.step);
  cl_int cs = 0, cs_il = 0;
  const std::vector<cl_int> table = resample_address_table(planar, &cs);
  const std::vector<cl_int> table_il = resample_address_table(il, &cs_il);
  const Matching m = match_reference(view, split);
  const Matching b = c.run.sweeps > 0 ? balance_reference(m, view, split, c.run.sweeps) : m;
  Meta meta(dir);
  meta("kind", "direct");
  meta("pes", pes);
  meta("dims", words(dims));
  meta("spacing", words(c.volume.spacing));
  meta("width", view.width());
  meta("height", view.height());
  meta("nseg", m.segments.size());
  meta("range", std::to_string(range.min) + " " + std::to_string(range.max));
  meta("shininess", sp.shininess);
  meta("ka_kd_ks",
       std::to_string(sp.ka) + " " + std::to_string(sp.kd) + " " + std::to_string(sp.ks));
  meta("k1_k2", std::to_string(sp.k1) + " " + std::to_string(sp.k2));
  meta("opacity_step", view.step);
  meta("cell", words(cells.cell()));  // the library's CellLayout / VoxelLayout
  meta("block", words(cells.block));
  meta("halo", cells.halo);
  meta("cell_stride", cells.cell_stride);
  meta("vstride", planar.stride);
  meta("cs", cs);
  meta("cs_il", cs_il);
  put_defines(meta, "shade_define", shade_defines(shade_p));
  put_defines(meta, "classify_define", classify_defines(classify_p));
  put(dir / "volume.f32", vol.data());
  put(dir / "view.bin", std::vector<sv_view>{view.grid});
  put(dir / "bit_axis.i32", split.bit_axis);
  put(dir / "origins.i32", cell_origin_table(split));
  std::vector<int32_t> pe_of_cell;
  const Dims3 s = split.splits();
  for (int64_t iz = 0; iz < s[2]; ++iz)
    for (int64_t iy = 0; iy < s[1]; ++iy)
      for (int64_t ix = 0; ix < s[0]; ++ix)
        pe_of_cell.push_back(static_cast<int32_t>(split.pe_of_cell({ix, iy, iz})));
  put(dir / "pe_of_cell.i32", pe_of_cell);
  put(dir / "cells.f32", layout_reference(vol.data(), cells));
  put(dir / "shade_params.bin", std::vector<sv_shade_params>{shade_p});
  put(dir / "classify_params.bin", std::vector<sv_classify_params>{classify_p});
  put(dir / "shade.f32", shading);
  put(dir / "rgba.f32", rgba);
  put(dir / "rgba_cells.f32", voxels_to_cells(rgba, planar));  // (PE, position) elements
  put(dir / "table.i32", table);
  put(dir / "table_il.i32", table_il);
  put(dir / "pairs_il.i64", resample_pair_table(table_il, dims));
  put(dir / "cell_bits_il.i32", resample_cell_bits(table_il, dims));
  put(dir / "cand.bin", match_candidates(view, split));
  put(dir / "segs.bin", m.segments);
  put(dir / "bal_segs.bin", b.segments);
  put(dir / "seg_offset.i32", to32(m.seg_offset));
  put(dir / "rects.bin", m.rects);
  put(dir / "rect_off.i64", rect_offsets(m));
  put(dir / "sample_off.i64", sample_offsets(b));
  for (int order = 0; order <= 3; ++order) {
    const std::string o = std::to_string(order);
    put(dir / ("samples_o" + o + ".f32"), resample_reference(b, rgba, dims, view, order));
    put(dir / ("foot_o" + o + ".f32"),
        footprints_reference(b, local_reference(b, rgba, dims, view, order)).pixels);
  }
}

// ---------------------------------------------------------------- match, balance
struct MatchCase {
  const char* name;
  struct {
    Dims3 dims;
    std::array<double, 3> spacing;
  } volume;
  struct {
    ViewAngles angles;
    int out_width, out_height;
    Sampling sampling;
  } view;
  struct {
    int64_t pes;
    int sweeps;  // balance_reference's (0: the matching alone, as --balance-sweeps 0)
    bool skip;   // a PE mask from a brick reach (skip_pes)
  } run;
};

void write_match_case(const fs::path& dir, const MatchCase& c) {
  fs::create_directories(dir);
  const Dims3& dims = c.volume.dims;
  const ViewGeometry view = make_view(dims, c.volume.spacing, c.view.angles, c.view.out_width,
                                      c.view.out_height, c.view.sampling);
  const KdSplit split = kd_split(dims, c.run.pes);
  Meta meta(dir);
  meta("kind", "match");
  meta("pes", c.run.pes);
  meta("dims", words(dims));
  meta("sweeps", c.run.sweeps);
  meta("skip", int(c.run.skip));
  meta("sampling", c.view.sampling == Sampling::voxel ? "voxel" : "pixel");
  put(dir / "view.bin", std::vector<sv_view>{view.grid});
  put(dir / "cand.bin", match_candidates(view, split));
  std::vector<uint8_t> active;
  if (c.run.skip) {
    // A brick reach (a byte per brick of 2^SV_BRICK_LOG2 voxels, x fastest): a ball of
    // bricks off centre, so that some PEs meet none, every 211th brick, and the far corner's
    // (past the volume where a dim is not a multiple of 4, and there meeting cells that lie
    // wholly past the volume: match-P16-pad).
    const int64_t b = int64_t(1) << SV_BRICK_LOG2;
    const Dims3 nb{(dims[0] + b - 1) / b, (dims[1] + b - 1) / b, (dims[2] + b - 1) / b};
    std::vector<uint8_t> reach;
    for (int64_t z = 0; z < nb[2]; ++z)
      for (int64_t y = 0; y < nb[1]; ++y)
        for (int64_t x = 0; x < nb[0]; ++x) {
          const double dx = (x + 0.5) / nb[0] - 0.25, dy = (y + 0.5) / nb[1] - 0.72,
                       dz = (z + 0.5) / nb[2] - 0.3;
          const int64_t e = (z * nb[1] + y) * nb[0] + x;
          const bool last = x == nb[0] - 1 && y == nb[1] - 1 && z == nb[2] - 1;
          reach.push_back(dx * dx + dy * dy + dz * dz < 0.04 || e % 211 == 5 || last ? 1 : 0);
        }
    active = match_active_reference(split, reach);
    meta("bricks", words(nb));
    put(dir / "reach.u8", reach);
    put(dir / "active.u8", active);
  }
  const Matching m = match_reference(view, split, active);
  meta("nseg", m.segments.size());
  meta("active_pes", active.empty() ? c.run.pes : std::count(active.begin(), active.end(), 1));
  put(dir / "segs.bin", m.segments);
  put(dir / "seg_offset.i32", to32(m.seg_offset));
  put(dir / "rects.bin", m.rects);
  put(dir / "loads.i64", m.loads);
  put(dir / "links.i32", balance_links(m, view, split));
  if (c.run.sweeps > 0) {
    // The balanced matching, and per sweep s whether it changed the bounds (the rounds'
    // `moves` flag of sweep s: some pair moved samples; a sweep whose moves all cancelled
    // would set its flag and read 0 here, which none of these cases has). Each from the
    // matching: its links are the matching's, not a balanced one's.
    const Matching b = balance_reference(m, view, split, c.run.sweeps);
    std::vector<int32_t> changed;
    Matching before = m;
    for (int s = 1; s <= c.run.sweeps; ++s) {
      const Matching after = balance_reference(m, view, split, s);
      bool differ = false;
      for (std::size_t e = 0; e < after.segments.size(); ++e)
        differ = differ || after.segments[e].k0 != before.segments[e].k0 ||
                 after.segments[e].k1 != before.segments[e].k1;
      changed.push_back(differ ? 1 : 0);
      before = after;
    }
    put(dir / "bal_segs.bin", b.segments);
    put(dir / "bal_loads.i64", b.loads);
    put(dir / "sweep_changed.i32", changed);
  }
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc != 2) {
    std::fprintf(stderr, "usage: kernel-abi-ref DIR\n");
    return 2;
  }
  const fs::path out = argv[1];
  // Swap: P = 1, 8, 512, 8192; odd image sizes, images of fewer pixels than
  // P and narrower than the PE grid; views with negative depth steps (front 1).
  const SwapCase swaps[] = {
      {"swap-P1-5x3", {20, 24, 16}, 1, {30, 20, 10}, 5, 3},
      {"swap-P1-64x64", {24, 20, 28}, 1, {-40, 130, 75}, 64, 64},
      {"swap-P8-1x1", {16, 16, 16}, 8, {10, 200, 30}, 1, 1},
      {"swap-P8-7x13", {30, 18, 25}, 8, {0, 180, 90}, 7, 13},
      {"swap-P8-31x17", {32, 24, 40}, 8, {30, 20, 10}, 31, 17},
      {"swap-P512-5x3", {40, 33, 17}, 512, {200, -35, 120}, 5, 3},
      {"swap-P512-7x13", {24, 24, 24}, 512, {95, 275, 185}, 7, 13},
      {"swap-P512-100x37", {40, 33, 17}, 512, {-60, 45, 10}, 100, 37},
      {"swap-P8192-1x1", {32, 32, 32}, 8192, {45, 135, 60}, 1, 1},
      {"swap-P8192-31x17", {64, 48, 80}, 8192, {-100, 250, 10}, 31, 17},
      {"swap-P8192-100x37", {64, 64, 64}, 8192, {45, 135, 60}, 100, 37},
      {"swap-P8192-129x130", {48, 40, 56}, 8192, {170, -20, 300}, 129, 130},
  };
  std::mt19937 rng(20261207);
  for (const SwapCase& c : swaps) write_swap_case(out / c.name, c, rng);
  const McCase mcs[] = {
      {"mc-P8-voxel",
       {{32, 32, 32}, {1, 1, 1}},
       {{30, 20, 10}, 48, 48, Sampling::voxel, Framing::longest},
       {8, 0, 1, 32, 0x123456789abcdefULL, false}},
      {"mc-P512-voxel-diagonal",
       {{40, 28, 36}, {1, 1.25, 0.8}},
       {{-50, 110, 35}, 61, 45, Sampling::voxel, Framing::diagonal},
       {512, 8, 1, 13, 7, true}},
      {"mc-P8192-pixel",
       {{30, 32, 26}, {1, 1, 1}},
       {{75, -20, 140}, 37, 53, Sampling::pixel, Framing::longest},
       {8192, 3, 3, 33, 0xfedcba9876543210ULL, false}},
  };
  for (const McCase& c : mcs) write_mc_case(out / c.name, c);
  // Direct frame: cells of 16 (P 8), 4 (P 512), 7 (odd dims) and 8 (P 64)
  // in x, so SV_RW 16, 4, 1 and 8; two views of one volume; voxel and pixel
  // sampling; mixtures (one relative) and a transfer function; balanced and
  // not; values spanning 2e20 (SV_GRAD_OVER).
  const DirectCase directs[] = {
      {"direct-P8-v1",
       {{32, 32, 32}, {1, 1, 1}, 1},
       {{30, 20, 10}, 40, 40, Sampling::voxel},
       {8, "ct", 8}},
      {"direct-P8-v2",
       {{32, 32, 32}, {1, 1, 1}, 1},
       {{-50, 200, 35}, 36, 44, Sampling::pixel},
       {8, "ct", 0}},
      {"direct-P512",
       {{32, 32, 32}, {1, 1, 1}, 1},
       {{75, -20, 140}, 40, 40, Sampling::voxel},
       {512, "ct-bone", 4}},
      {"direct-P8-odd",
       {{27, 19, 13}, {1, 1.25, 0.8}, 1},
       {{10, 110, 300}, 33, 29, Sampling::voxel},
       {8, "volpack", 3}},
      {"direct-P64-huge",
       {{32, 24, 20}, {1, 1, 1}, 1e17f},
       {{-100, 250, 10}, 31, 37, Sampling::pixel},
       {64, "mri", 2}},
  };
  for (const DirectCase& c : directs) write_direct_case(out / c.name, c);
  // Match and balance: P 1 .. 8192 (16: cells wholly past the volume, x 26 = 13 cells of 2);
  // axis-aligned, 30 deg, 45 deg and oblique views (negative
  // depth steps among them); voxel and pixel sampling; a PE mask or none; balance sweeps 0
  // (the matching alone) and 8 (the default).
  const MatchCase matches[] = {
      {"match-P1",
       {{20, 17, 9}, {1, 1, 1}},
       {{30, 20, 10}, 24, 20, Sampling::voxel},
       {1, 8, false}},
      {"match-P16-pad-skip",
       {{26, 4, 4}, {1, 1, 1}},
       {{20, 35, 10}, 30, 30, Sampling::pixel},
       {16, 8, true}},
      {"match-P8-axis",
       {{32, 30, 27}, {1, 1, 1}},
       {{0, 0, 0}, 40, 40, Sampling::voxel},
       {8, 8, false}},
      {"match-P8-oblique-skip",
       {{32, 28, 24}, {1, 1, 1}},
       {{-50, 200, 35}, 36, 44, Sampling::pixel},
       {8, 8, true}},
      {"match-P64-30",
       {{40, 32, 36}, {1, 1.25, 0.8}},
       {{0, 30, 0}, 48, 40, Sampling::voxel},
       {64, 8, false}},
      {"match-P64-axis-skip",
       {{27, 19, 13}, {1, 1, 1}},
       {{0, 0, 90}, 33, 29, Sampling::pixel},
       {64, 0, true}},
      {"match-P512-45-skip",
       {{48, 48, 48}, {1, 1, 1}},
       {{0, 45, 0}, 64, 64, Sampling::voxel},
       {512, 8, true}},
      {"match-P512-oblique",
       {{40, 33, 17}, {1, 1, 1}},
       {{30, 20, 10}, 61, 45, Sampling::pixel},
       {512, 0, false}},
      {"match-P8192-45",
       {{64, 64, 64}, {1, 1, 1}},
       {{45, 45, 0}, 64, 64, Sampling::voxel},
       {8192, 8, false}},
      {"match-P8192-oblique-skip",
       {{64, 48, 80}, {1, 1, 1}},
       {{-100, 250, 10}, 72, 56, Sampling::pixel},
       {8192, 8, true}},
      {"match-P8192-30",
       {{64, 64, 64}, {1, 1, 1}},
       {{30, 0, 0}, 64, 64, Sampling::pixel},
       {8192, 0, false}},
  };
  for (const MatchCase& c : matches) write_match_case(out / c.name, c);
  std::printf(
      "kernel-abi-ref: %zu swap, %zu Monte Carlo, %zu direct-frame and %zu match cases written "
      "to %s\n",
      std::size(swaps), std::size(mcs), std::size(directs), std::size(matches), out.c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "kernel-abi-ref: %s\n", e.what());
  return 2;
}
