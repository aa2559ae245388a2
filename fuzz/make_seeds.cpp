// Writes the seed corpora of the loader fuzz targets from the real volumes
// (data/brainsmall.den, data/ch2.nii.gz; a synthetic volume stands in for a
// missing one): small crops written with save_nrrd, teem and niftilib, and
// truncated and malformed variants, each framed as its fuzz target expects.
//   make_seeds <data dir> <corpus root>
//     -> <root>/{raw,den,nrrd,nifti,dicom,metaimage,mgh,minc,classifier}/
// Nothing it writes is committed: scripts/fuzz regenerates the corpora.
#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "dicom_enhanced.hpp"
#include "simdvol/error.hpp"
#include "simdvol/io.hpp"
#include "simdvol/volume.hpp"

extern "C" {
#include <nifti2_io.h>
#include <teem/nrrd.h>
}

namespace fs = std::filesystem;
using Bytes = std::vector<uint8_t>;
using simdvol::Volume;
using simdvol::VoxelType;

namespace {

Bytes read_bytes(const fs::path& p, std::size_t limit = SIZE_MAX) {
  std::ifstream in(p, std::ios::binary);
  Bytes b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (b.size() > limit) b.resize(limit);
  return b;
}

void write_seed(const fs::path& dir, const std::string& name, const Bytes& b) {
  std::ofstream out(dir / name, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

Bytes framed(uint8_t mode, const Bytes& body) {
  Bytes b{mode};
  b.insert(b.end(), body.begin(), body.end());
  return b;
}

/// The crop [x0, x0+nx) x [y0, y0+ny) x [z0, z0+nz) of `v` (clamped).
Volume crop(const Volume& v, std::array<int64_t, 3> o, std::array<int64_t, 3> n, VoxelType t) {
  Volume c(n, t, v.spacing());
  for (int64_t z = 0; z < n[2]; ++z)
    for (int64_t y = 0; y < n[1]; ++y)
      for (int64_t x = 0; x < n[0]; ++x) c.at(x, y, z) = v.at_clamped(o[0] + x, o[1] + y, o[2] + z);
  return c;
}

Volume synthetic(std::array<int64_t, 3> d) {
  Volume v(d, VoxelType::u8);
  for (int64_t z = 0; z < d[2]; ++z)
    for (int64_t y = 0; y < d[1]; ++y)
      for (int64_t x = 0; x < d[0]; ++x)
        v.at(x, y, z) = static_cast<float>((x * 7 + y * 3 + z) % 256);
  return v;
}

template <typename T>
void put(Bytes& b, T v, bool big = false) {
  uint8_t t[sizeof(T)];
  std::memcpy(t, &v, sizeof(T));
  if (big) std::reverse(t, t + sizeof(T));
  b.insert(b.end(), t, t + sizeof(T));
}

/// Voxel bytes of `v` in its type (little- or big-endian).
Bytes voxel_bytes_of(const Volume& v, bool big = false) {
  Bytes b;
  for (float f : v.data()) switch (v.type()) {
      case VoxelType::u8:
        b.push_back(static_cast<uint8_t>(f));
        break;
      case VoxelType::u16:
        put(b, static_cast<uint16_t>(f), big);
        break;
      case VoxelType::i16:
        put(b, static_cast<int16_t>(f), big);
        break;
      case VoxelType::f32:
        put(b, f, big);
        break;
    }
  return b;
}

Bytes den_file(const Volume& v, bool big) {
  Bytes b;
  put<int16_t>(b, 1, big);
  for (int i = 0; i < 24; ++i) put<int16_t>(b, 0, big);
  for (int a = 0; a < 3; ++a) put<int16_t>(b, static_cast<int16_t>(v.dims()[a]), big);
  put<int16_t>(b, 0, big);
  put<int32_t>(b, static_cast<int32_t>(v.voxel_count()), big);
  const Bytes d = voxel_bytes_of(v);
  b.insert(b.end(), d.begin(), d.end());
  return b;
}

Bytes raw_prefix(VoxelType t, bool big, const std::array<int64_t, 3>& d, uint16_t header) {
  Bytes b{static_cast<uint8_t>(t), static_cast<uint8_t>(big)};
  for (int a = 0; a < 3; ++a) put<int16_t>(b, static_cast<int16_t>(d[a]));
  put<uint16_t>(b, header);
  for (int a = 0; a < 3; ++a) {
    b.push_back(7);
    b.push_back(12);  // spacing 1.0
  }
  return b;
}

Bytes nrrd_via_teem(const Volume& v, const char* encoding, const fs::path& tmp) {
  Nrrd* n = nrrdNew();
  std::vector<float> data = v.data();
  nrrdWrap_va(n, data.data(), nrrdTypeFloat, 3, static_cast<size_t>(v.nx()),
              static_cast<size_t>(v.ny()), static_cast<size_t>(v.nz()));
  NrrdIoState* nio = nrrdIoStateNew();
  nrrdIoStateEncodingSet(nio,
                         std::string(encoding) == "gzip" ? nrrdEncodingGzip : nrrdEncodingAscii);
  Bytes out;
  if (nrrdSave(tmp.c_str(), n, nio) == 0) out = read_bytes(tmp);
  nrrdIoStateNix(nio);
  nrrdNix(n);
  fs::remove(tmp);
  return out;
}

Bytes nifti_via_niftilib(const Volume& v, int datatype, float slope, const fs::path& tmp) {
  const int64_t dims[8] = {3, v.nx(), v.ny(), v.nz(), 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, datatype, 1);
  if (!nim) return {};
  for (std::size_t i = 0; i < v.voxel_count(); ++i) {
    const float f = v.data()[i];
    switch (datatype) {
      case DT_UINT8:
        static_cast<uint8_t*>(nim->data)[i] = static_cast<uint8_t>(f);
        break;
      case DT_INT16:
        static_cast<int16_t*>(nim->data)[i] = static_cast<int16_t>(f);
        break;
      default:
        static_cast<float*>(nim->data)[i] = f;
        break;
    }
  }
  nim->scl_slope = slope;
  nim->scl_inter = slope != 1.0f ? 1.5f : 0.0f;
  nifti_set_filenames(nim, tmp.c_str(), 0, 1);
  nifti_image_write(nim);
  nifti_image_free(nim);
  Bytes out = read_bytes(tmp);
  fs::remove(tmp);
  return out;
}

/// A header by niftilib's own conversion (nifti_convert_nim2n1hdr or
/// nim2n2hdr; its writer leaves a single NIfTI-2 file headerless) and the
/// voxels: `version` 2 NIfTI-2, 1 NIfTI-1, 0 Analyze 7.5 (no magic, SPM's
/// scale 2 at byte 112); a single file (4 bytes of "no extensions" between)
/// or, with `pair`, the header then the .img's bytes, as the target's pair
/// form splits them. Byte-swapped when `big`.
Bytes nifti_by_hand(const Volume& v, int version, bool pair, bool big) {
  const int64_t dims[8] = {3, v.nx(), v.ny(), v.nz(), 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, DT_INT16, 0);
  if (!nim) return {};
  nim->nifti_type = version == 0   ? NIFTI_FTYPE_ANALYZE
                    : version == 2 ? (pair ? NIFTI_FTYPE_NIFTI2_2 : NIFTI_FTYPE_NIFTI2_1)
                                   : (pair ? NIFTI_FTYPE_NIFTI1_2 : NIFTI_FTYPE_NIFTI1_1);
  const std::size_t header = version == 2 ? 540 : 348;
  nim->iname_offset = pair ? 0 : static_cast<int64_t>(header + 4);
  Bytes out(header);
  if (version == 2) {
    nifti_2_header h{};
    nifti_convert_nim2n2hdr(nim, &h);
    if (big) swap_nifti_header(&h, 2);
    std::memcpy(out.data(), &h, header);
  } else {
    nifti_1_header h{};
    nifti_convert_nim2n1hdr(nim, &h);
    if (version == 0) {
      std::memset(h.magic, 0, sizeof h.magic);
      h.scl_slope = 2.0f;
    }
    if (big) swap_nifti_header(&h, version);
    std::memcpy(out.data(), &h, header);
  }
  nifti_image_free(nim);
  if (!pair) out.resize(header + 4, 0);
  std::vector<int16_t> vox(v.voxel_count());
  for (std::size_t i = 0; i < vox.size(); ++i) vox[i] = static_cast<int16_t>(v.data()[i]);
  if (big) nifti_swap_Nbytes(static_cast<int64_t>(vox.size()), 2, vox.data());
  const auto* p = reinterpret_cast<const unsigned char*>(vox.data());
  out.insert(out.end(), p, p + vox.size() * 2);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: make_seeds <data dir> <corpus root>\n";
    return 2;
  }
  const fs::path data(argv[1]), root(argv[2]);
  for (const char* t :
       {"raw", "den", "nrrd", "nifti", "dicom", "metaimage", "mgh", "minc", "classifier"})
    fs::create_directories(root / t);
  const fs::path tmpdir = root / "tmp";
  fs::create_directories(tmpdir);
  nifti_set_debug_level(0);

  Volume brain, ch2;
  try {
    brain = simdvol::load_den(data / "brainsmall.den");
  } catch (const simdvol::Error& e) {
    std::cerr << "make_seeds: " << e.what() << " (using a synthetic volume)\n";
    brain = synthetic({128, 128, 84});
  }
  try {
    ch2 = simdvol::load_nifti(data / "ch2.nii.gz");
  } catch (const simdvol::Error& e) {
    std::cerr << "make_seeds: " << e.what() << " (using a synthetic volume)\n";
    ch2 = synthetic({181, 217, 181});
  }
  const Volume b8 = crop(brain, {56, 56, 40}, {16, 16, 8}, VoxelType::u8);
  const Volume b16 = crop(brain, {56, 56, 40}, {16, 16, 8}, VoxelType::u16);
  const Volume c8 = crop(ch2, {82, 100, 82}, {16, 16, 8}, VoxelType::u8);
  const Volume c16 = crop(ch2, {82, 100, 82}, {16, 16, 8}, VoxelType::i16);
  const Volume cf = crop(ch2, {82, 100, 82}, {16, 16, 8}, VoxelType::f32);
  const Volume tiny = crop(brain, {60, 60, 40}, {3, 2, 2}, VoxelType::f32);

  // .den: little- and big-endian crops, the header alone, the real file's start.
  const fs::path den = root / "den";
  const Bytes den_le = den_file(b8, false);
  write_seed(den, "crop_le", den_le);
  write_seed(den, "crop_be", den_file(b8, true));
  write_seed(den, "header_only", Bytes(den_le.begin(), den_le.begin() + 62));
  write_seed(den, "real_start", read_bytes(data / "brainsmall.den", 4096));

  // raw: layout prefix + voxels, each type and byte order, with a header.
  const fs::path raw = root / "raw";
  auto raw_seed = [&](const std::string& name, const Volume& v, bool big, uint16_t header) {
    Bytes b = raw_prefix(v.type(), big, v.dims(), header);
    b.insert(b.end(), header, 0xAB);
    const Bytes d = voxel_bytes_of(v, big);
    b.insert(b.end(), d.begin(), d.end());
    write_seed(raw, name, b);
  };
  raw_seed("u8", b8, false, 0);
  raw_seed("u16_be", b16, true, 0);
  raw_seed("i16_header", c16, false, 4);
  raw_seed("f32_be", cf, true, 0);
  raw_seed("f32_tiny", tiny, false, 2);

  // NRRD: byte 0 even = attached, odd = detached (header, blank line, data).
  const fs::path nrrd = root / "nrrd";
  for (const auto& [name, v] :
       {std::pair<std::string, const Volume*>{"u8", &b8}, {"i16", &c16}, {"f32", &cf}}) {
    const fs::path p = tmpdir / "s.nrrd";
    simdvol::save_nrrd(*v, p);
    write_seed(nrrd, "attached_" + name, framed(0, read_bytes(p)));
    fs::remove(p);
  }
  write_seed(nrrd, "attached_gzip", framed(0, nrrd_via_teem(cf, "gzip", tmpdir / "g.nrrd")));
  write_seed(nrrd, "attached_ascii", framed(0, nrrd_via_teem(tiny, "ascii", tmpdir / "a.nrrd")));
  auto detached = [&](const std::string& name, const std::string& header, const Bytes& d) {
    Bytes b(header.begin(), header.end());
    b.insert(b.end(), d.begin(), d.end());
    write_seed(nrrd, name, framed(1, b));
  };
  const Bytes c16_le = voxel_bytes_of(c16);
  detached("detached_i16",
           "NRRD0004\ntype: short\ndimension: 3\nsizes: 16 16 8\nspacings: 1 1 2\n"
           "endian: little\nencoding: raw\ndata file: data.raw\n\n",
           c16_le);
  detached("detached_4d",
           "NRRD0005\ntype: uint8\ndimension: 4\nsizes: 1 16 16 8\n"
           "space directions: none (1,0,0) (0,1,0) (0,0,1.5)\nencoding: raw\n"
           "byte skip: 0\ndata file: data.raw\n\n",
           voxel_bytes_of(b8));
  // 4-D files whose one volume is read alone from the data stream
  // (io.cpp, nrrd_read_volume): the volume axis first, big-endian, volume
  // 1; gzip with the volume axis last; a detached file with a byte skip,
  // volume 2.
  Bytes series(2 * 3 * 6 * 5 * 4);
  for (std::size_t i = 0; i < series.size(); ++i) series[i] = static_cast<unsigned char>(i * 7);
  auto gzip_bytes = [](const Bytes& in) {
    z_stream z{};
    Bytes out(compressBound(static_cast<uLong>(in.size())) + 32);
    if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) return Bytes{};
    z.next_in = const_cast<unsigned char*>(in.data());
    z.avail_in = static_cast<uInt>(in.size());
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    const int r = deflate(&z, Z_FINISH);
    out.resize(out.size() - z.avail_out);
    deflateEnd(&z);
    return r == Z_STREAM_END ? out : Bytes{};
  };
  auto attached4 = [&](const std::string& name, uint8_t mode, const std::string& header,
                       const Bytes& d) {
    Bytes b(header.begin(), header.end());
    b.insert(b.end(), d.begin(), d.end());
    write_seed(nrrd, name, framed(mode, b));
  };
  attached4("attached_4d_list", 4,
            "NRRD0004\ntype: short\ndimension: 4\nsizes: 3 6 5 4\n"
            "kinds: list domain domain domain\nendian: big\nencoding: raw\n\n",
            series);
  attached4("attached_4d_gzip", 4,
            "NRRD0004\ntype: short\ndimension: 4\nsizes: 6 5 4 3\n"
            "kinds: domain domain domain list\nendian: little\nencoding: gzip\n\n",
            gzip_bytes(series));
  {
    Bytes skipped(5, 0xAB);
    skipped.insert(skipped.end(), series.begin(), series.end());
    const std::string h =
        "NRRD0004\ntype: short\ndimension: 4\nsizes: 6 5 4 3\n"
        "kinds: domain domain domain list\nendian: little\nencoding: raw\nbyte skip: 5\n"
        "data file: data.raw\n\n";
    Bytes b(h.begin(), h.end());
    b.insert(b.end(), skipped.begin(), skipped.end());
    write_seed(nrrd, "detached_4d_skip", framed(7, b));
  }
  detached("detached_format",
           "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 2\nencoding: raw\n"
           "data file: data%d.raw 1 2 1 2\n\n",
           Bytes(32, 7));
  detached("detached_list",
           "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 2\nencoding: raw\n"
           "data file: LIST\ndata.raw\n\n",
           Bytes(32, 9));

  // NIfTI: byte 0 mod 4: 0 plain .nii, 1 compressed by the target, 2 .nii.gz
  // as is, 3 a .hdr/.img pair (16 added: loaded by its .img).
  const fs::path nifti = root / "nifti";
  const Bytes nii_u8 = nifti_via_niftilib(c8, DT_UINT8, 1.0f, tmpdir / "a.nii");
  const Bytes nii_i16 = nifti_via_niftilib(c16, DT_INT16, 1.0f, tmpdir / "b.nii");
  const Bytes nii_scaled = nifti_via_niftilib(cf, DT_FLOAT32, 0.5f, tmpdir / "c.nii");
  const Bytes niigz = nifti_via_niftilib(c8, DT_UINT8, 1.0f, tmpdir / "d.nii.gz");
  write_seed(nifti, "nii_u8", framed(0, nii_u8));
  write_seed(nifti, "nii_i16", framed(0, nii_i16));
  write_seed(nifti, "nii_scaled", framed(0, nii_scaled));
  write_seed(nifti, "gz_u8", framed(1, nii_u8));
  write_seed(nifti, "gz_i16", framed(1, nii_i16));
  write_seed(nifti, "niigz_raw", framed(2, niigz));
  write_seed(nifti, "real_start", framed(2, read_bytes(data / "ch2.nii.gz", 4096)));
  write_seed(nifti, "nifti2", framed(0, nifti_by_hand(c16, 2, false, false)));
  write_seed(nifti, "nifti2_be_gz", framed(1, nifti_by_hand(c16, 2, false, true)));
  write_seed(nifti, "pair_nifti1", framed(3, nifti_by_hand(c16, 1, true, false)));
  write_seed(nifti, "pair_nifti2_be", framed(3, nifti_by_hand(c16, 2, true, true)));
  write_seed(nifti, "pair_analyze_be", framed(3, nifti_by_hand(c16, 0, true, true)));
  write_seed(nifti, "pair_analyze_by_img", framed(3 + 16, nifti_by_hand(c16, 0, true, false)));
  // DICOM: the real files scripts/fetch-data brings (pydicom's: MR in five
  // transfer syntaxes, an RT dose grid, a CT slice), whole.
  std::error_code ec;
  for (fs::recursive_directory_iterator it(data / "dicom", ec), end; !ec && it != end;
       it.increment(ec))
    if (it->is_regular_file() && it->file_size() < (1u << 20))  // (not the 23 MB MPRAGE)
      write_seed(root / "dicom", it->path().filename().string(), read_bytes(it->path()));
  // An enhanced multi-frame file (as the tests write it): two time points of
  // three frames, one frame with its own scale.
  std::vector<simdvol::testing::EnhancedFrame> frames(6);
  for (int k = 0; k < 6; ++k) {
    frames[k].position = std::array<double, 3>{0, 0, 2.5 * (k % 3)};
    if (k == 4) frames[k].scale = std::array<double, 2>{2.0, -1024.0};
    frames[k].pixels.assign(12, static_cast<int16_t>(100 * k));
  }
  simdvol::testing::write_enhanced_dicom(tmpdir / "enhanced.dcm", 4, 3, frames, {1, 0, 0, 0, 1, 0},
                                         {0.5, 0.7}, std::array<double, 2>{1.0, -1024.0});
  write_seed(root / "dicom", "enhanced.dcm", read_bytes(tmpdir / "enhanced.dcm"));
  // MetaImage: byte 0 even = the voxels after the header (.mha), odd = a
  // header apart (.mhd, blank line, data.raw); (byte 0 / 2) % 4 = 1 asks
  // for volume 0 of a 4-D file.
  const fs::path mha = root / "metaimage";
  auto mha_seed = [&](const std::string& name, uint8_t form, const std::string& header,
                      const Bytes& d) {
    Bytes b(header.begin(), header.end());
    b.insert(b.end(), d.begin(), d.end());
    write_seed(mha, name, framed(form, b));
  };
  const std::string mha_u8 =
      "ObjectType = Image\nNDims = 3\nDimSize = 16 16 8\nElementType = MET_UCHAR\n";
  mha_seed("local_u8", 0, mha_u8 + "ElementDataFile = LOCAL\n", voxel_bytes_of(b8));
  mha_seed("local_i16_be", 0,
           "ObjectType = Image\nNDims = 3\nBinaryDataByteOrderMSB = True\n"
           "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nElementSpacing = 1 1 2\nDimSize = 16 16 8\n"
           "ElementType = MET_SHORT\nElementDataFile = LOCAL\n",
           voxel_bytes_of(c16, true));
  {
    const Bytes f = voxel_bytes_of(cf);
    uLongf len = compressBound(static_cast<uLong>(f.size()));
    Bytes z(len);
    if (compress2(z.data(), &len, f.data(), static_cast<uLong>(f.size()), 6) == Z_OK) {
      z.resize(len);
      mha_seed("local_f32_zlib", 0,
               "ObjectType = Image\nNDims = 3\nCompressedData = True\nCompressedDataSize = " +
                   std::to_string(len) +
                   "\nDimSize = 16 16 8\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n",
               z);
      mha_seed("apart_f32_zlib", 1,
               "ObjectType = Image\nNDims = 3\nCompressedData = True\nDimSize = 16 16 8\n"
               "ElementType = MET_FLOAT\nElementDataFile = data.raw\n\n",
               z);
    }
  }
  mha_seed("apart_u8", 1, mha_u8 + "ElementDataFile = data.raw\n\n", voxel_bytes_of(b8));
  mha_seed("four_d", 0 + 2,
           "ObjectType = Image\nNDims = 4\nDimSize = 16 16 4 2\nElementSpacing = 1 1 1 1\n"
           "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
           voxel_bytes_of(b8));
  mha_seed("ascii", 0,
           "ObjectType = Image\nNDims = 3\nBinaryData = False\nDimSize = 3 2 2\n"
           "ElementType = MET_FLOAT\nElementDataFile = LOCAL\n",
           [&] {
             std::string t;
             for (float x : tiny.data()) t += std::to_string(x) + " ";
             return Bytes(t.begin(), t.end());
           }());
  mha_seed("list_2d", 1,
           "ObjectType = Image\nNDims = 3\nDimSize = 4 4 2\nElementType = MET_UCHAR\n"
           "ElementDataFile = LIST 2D\ndata.raw\ndata.raw\n\n",
           Bytes(16, 5));
  if (fs::exists(data / "metaimage" / "BrainProtonDensity3Slices.mha")) {
    Bytes h = read_bytes(data / "metaimage" / "BrainProtonDensity3Slices.mha");
    std::string t(h.begin(), h.end());
    const std::size_t at = t.find("BrainProtonDensity3Slices.raw");
    if (at != std::string::npos) t.replace(at, 29, "data.raw");
    mha_seed("real_itk_example", 1, t + "\n",
             read_bytes(data / "metaimage" / "BrainProtonDensity3Slices.raw", 16384));
  }
  // MGH: byte 0 % 3: 0 plain .mgh, 1 gzipped by the target, 2 .mgz as is;
  // (byte 0 / 3) % 4 = 2 asks for frame 1.
  auto mgh_file = [](const Volume& v, int32_t type, int32_t frames) {
    Bytes b;
    auto be32 = [&b](uint32_t x) {
      for (int s = 24; s >= 0; s -= 8) b.push_back(static_cast<uint8_t>(x >> s));
    };
    be32(1);
    for (int i = 0; i < 3; ++i) be32(static_cast<uint32_t>(v.dims()[i]));
    be32(static_cast<uint32_t>(frames));
    be32(static_cast<uint32_t>(type));
    be32(0);
    b.push_back(0);
    b.push_back(1);                                                // goodRASFlag
    const float cos[12] = {1, 1, 2, -1, 0, 0, 0, 0, -1, 0, 1, 0};  // sizes, then LIA
    for (float c : cos) {
      uint32_t u;
      std::memcpy(&u, &c, 4);
      be32(u);
    }
    b.resize(284, 0);
    for (int f = 0; f < frames; ++f)
      for (float x : v.data()) {
        if (type == 0) {
          b.push_back(static_cast<uint8_t>(x));
        } else if (type == 4) {
          const auto s = static_cast<uint16_t>(static_cast<int16_t>(x));
          b.push_back(static_cast<uint8_t>(s >> 8));
          b.push_back(static_cast<uint8_t>(s));
        } else {
          uint32_t u;
          std::memcpy(&u, &x, 4);
          be32(u);
        }
      }
    return b;
  };
  write_seed(root / "mgh", "u8", framed(0, mgh_file(b8, 0, 1)));
  write_seed(root / "mgh", "i16_gz", framed(1, mgh_file(c16, 4, 1)));
  write_seed(root / "mgh", "f32_frames", framed(0 + 2 * 3, mgh_file(tiny, 3, 2)));
  if (fs::exists(data / "mgh" / "test.mgz"))
    write_seed(root / "mgh", "real_test_mgz", framed(2, read_bytes(data / "mgh" / "test.mgz")));
  // MINC: nibabel's files (MINC1 and MINC2), byte 0 = 1 asks for volume 0.
  for (fs::directory_iterator it(data / "minc", ec), end; !ec && it != end; it.increment(ec))
    if (it->is_regular_file() && it->file_size() < (1u << 20))
      write_seed(root / "minc", it->path().filename().string(), framed(1, read_bytes(it->path())));
  // Classifier files: the README's two forms, a relative mixture, and the
  // "ct" preset's materials written out, with comments and CRLF endings.
  const auto text = [](const std::string& t) { return Bytes(t.begin(), t.end()); };
  const fs::path tf = root / "classifier";
  write_seed(tf, "volpack",
             text("# VolPack's example\ndensity  0 0   24 1   255 1\ngradient 0 0   5 0   20 1   "
                  "221 1\ncolor    0 1 1 1\n"));
  write_seed(tf, "mixture",
             text("material air   -1000 120  0 0 0        0\nmaterial soft     40  60  0.85 0.45 "
                  "0.4 0.005\nmaterial bone   1000 250  1 0.97 0.9   0.12\n"));
  write_seed(tf, "relative",
             text("relative\r\nmaterial csf 0.1 0.05 0.3 0.3 1 0.01\r\nmaterial grey 0.45 0.1 "
                  "0.9 0.6 0.5 0.05\r\nmaterial white 0.8 0.1 1 1 0.9 0.2\r\n"));
  write_seed(tf, "far", text("material a -1e18 1 1 0 0 0.5\nmaterial b 3e18 3 0 1 0 0.8\n"));
  fs::remove_all(tmpdir);
  std::cout << "make_seeds: corpora written under " << root.string() << "\n";
  return 0;
}
