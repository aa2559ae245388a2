// Writes an enhanced multi-frame DICOM file byte by byte, for the tests
// (test_io, test_cli) and the fuzz seeds: no GDCM, no GoogleTest.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

namespace simdvol::testing {

/// One frame of an enhanced multi-frame file: its Image Position
/// (Patient) (none: the frame's Plane Position Sequence left out) and its
/// own Rescale Slope and Intercept (none: the shared ones apply).
struct EnhancedFrame {
  std::optional<std::array<double, 3>> position;
  std::optional<std::array<double, 2>> scale;  ///< slope, intercept
  std::vector<int16_t> pixels;
};

/// An Enhanced CT image file (explicit VR little-endian), its bytes written
/// here by hand, not by GDCM, so that the loader's reading of the
/// functional groups is checked against the standard's layout (PS3.3
/// C.7.6.16): the shared groups hold the plane's orientation, the pixel
/// measures (Pixel Spacing: rows' spacing, then columns') and, where given,
/// a shared scale; each frame's groups its position and, where given, its
/// own scale. `items` (where not -1) writes that many per-frame items.
inline void write_enhanced_dicom(const std::filesystem::path& p, int nx, int ny,
                                 const std::vector<EnhancedFrame>& frames,
                                 const std::array<double, 6>& cosines,
                                 const std::array<double, 2>& spacing,
                                 std::optional<std::array<double, 2>> shared_scale,
                                 int items = -1) {
  std::string out;
  auto u16 = [&](std::string& o, uint16_t v) {
    o.push_back(static_cast<char>(v & 0xff));
    o.push_back(static_cast<char>(v >> 8));
  };
  auto u32 = [&](std::string& o, uint32_t v) {
    for (int b = 0; b < 4; ++b) o.push_back(static_cast<char>(v >> (8 * b) & 0xff));
  };
  auto el = [&](std::string& o, uint16_t g, uint16_t e, const char* vr, std::string v) {
    if (v.size() % 2) v.push_back(vr[0] == 'U' && vr[1] == 'I' ? '\0' : ' ');
    u16(o, g);
    u16(o, e);
    o += vr;
    const std::string vrs(vr);
    if (vrs == "OB" || vrs == "OW" || vrs == "SQ") {
      u16(o, 0);
      u32(o, static_cast<uint32_t>(v.size()));
    } else {
      u16(o, static_cast<uint16_t>(v.size()));
    }
    o += v;
  };
  auto us = [&](uint16_t g, uint16_t e, uint16_t v) {
    std::string b;
    u16(b, v);
    el(out, g, e, "US", b);
  };
  auto ds = [](const double* v, int n) {
    std::string t;
    for (int i = 0; i < n; ++i) {
      char b[32];
      std::snprintf(b, sizeof b, "%.10g", v[i]);
      if (i) t += '\\';
      t += b;
    }
    return t;
  };
  auto begin_sq = [&](uint16_t g, uint16_t e) {
    u16(out, g);
    u16(out, e);
    out += "SQ";
    u16(out, 0);
    u32(out, 0xffffffffu);
  };
  auto item = [&](bool begin) {
    u16(out, 0xfffe);
    u16(out, begin ? 0xe000 : 0xe00d);
    u32(out, begin ? 0xffffffffu : 0u);
  };
  auto end_sq = [&] {
    u16(out, 0xfffe);
    u16(out, 0xe0dd);
    u32(out, 0);
  };
  auto scale = [&](const std::array<double, 2>& s) {
    begin_sq(0x0028, 0x9145);  // Pixel Value Transformation Sequence
    item(true);
    el(out, 0x0028, 0x1052, "DS", ds(&s[1], 1));
    el(out, 0x0028, 0x1053, "DS", ds(&s[0], 1));
    el(out, 0x0028, 0x1054, "LO", "HU");
    item(false);
    end_sq();
  };
  const std::string sop = "1.2.840.10008.5.1.4.1.1.2.1", instance = "1.2.826.0.1.3680043.10.1.9";
  std::string meta;
  el(meta, 0x0002, 0x0001, "OB", std::string("\0\1", 2));
  el(meta, 0x0002, 0x0002, "UI", sop);
  el(meta, 0x0002, 0x0003, "UI", instance);
  el(meta, 0x0002, 0x0010, "UI", "1.2.840.10008.1.2.1");
  out.assign(128, '\0');
  out += "DICM";
  std::string len;
  u32(len, static_cast<uint32_t>(meta.size()));
  el(out, 0x0002, 0x0000, "UL", len);
  out += meta;
  el(out, 0x0008, 0x0016, "UI", sop);
  el(out, 0x0008, 0x0018, "UI", instance);
  el(out, 0x0008, 0x0060, "CS", "CT");
  el(out, 0x0020, 0x000d, "UI", "1.2.826.0.1.3680043.10.1.7");
  el(out, 0x0020, 0x000e, "UI", "1.2.826.0.1.3680043.10.1.8");
  us(0x0028, 0x0002, 1);
  el(out, 0x0028, 0x0004, "CS", "MONOCHROME2");
  el(out, 0x0028, 0x0008, "IS", std::to_string(frames.size()));
  us(0x0028, 0x0010, static_cast<uint16_t>(ny));
  us(0x0028, 0x0011, static_cast<uint16_t>(nx));
  us(0x0028, 0x0100, 16);
  us(0x0028, 0x0101, 16);
  us(0x0028, 0x0102, 15);
  us(0x0028, 0x0103, 1);
  begin_sq(0x5200, 0x9229);  // Shared Functional Groups Sequence
  item(true);
  begin_sq(0x0020, 0x9116);  // Plane Orientation Sequence
  item(true);
  el(out, 0x0020, 0x0037, "DS", ds(cosines.data(), 6));
  item(false);
  end_sq();
  begin_sq(0x0028, 0x9110);  // Pixel Measures Sequence
  item(true);
  const double one = 1.0, rows_columns[2] = {spacing[1], spacing[0]};
  el(out, 0x0018, 0x0050, "DS", ds(&one, 1));
  el(out, 0x0028, 0x0030, "DS", ds(rows_columns, 2));
  item(false);
  end_sq();
  if (shared_scale) scale(*shared_scale);
  item(false);
  end_sq();
  begin_sq(0x5200, 0x9230);  // Per-frame Functional Groups Sequence
  const std::size_t n = items < 0 ? frames.size() : static_cast<std::size_t>(items);
  for (std::size_t k = 0; k < n; ++k) {
    const EnhancedFrame& f = frames[k % frames.size()];
    item(true);
    if (f.position) {
      begin_sq(0x0020, 0x9113);  // Plane Position Sequence
      item(true);
      el(out, 0x0020, 0x0032, "DS", ds(f.position->data(), 3));
      item(false);
      end_sq();
    }
    if (f.scale) scale(*f.scale);
    item(false);
  }
  end_sq();
  std::string px;
  for (const EnhancedFrame& f : frames)
    for (int16_t v : f.pixels) u16(px, static_cast<uint16_t>(v));
  el(out, 0x7fe0, 0x0010, "OW", px);
  std::ofstream(p, std::ios::binary).write(out.data(), static_cast<std::streamsize>(out.size()));
}

}  // namespace simdvol::testing
