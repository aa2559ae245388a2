// A scalar volume: dims, voxel spacing, the type it was stored as, and its
// values as float (x fastest, then y, then z).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace simdvol {

enum class VoxelType { u8, u16, i16, f32 };

std::string_view to_string(VoxelType t);
/// Parses "u8", "u16", "i16", "f32" (also "uint8", "uint16", "int16", "float").
/// Throws ArgumentError naming `argument` otherwise.
VoxelType parse_voxel_type(std::string_view s, const std::string& argument = "type");
std::size_t voxel_bytes(VoxelType t);

struct ValueRange {
  float min = 0.0f;
  float max = 0.0f;
};

class Volume {
 public:
  Volume() = default;
  /// Allocates a zero-filled volume. Throws ArgumentError for a non-positive
  /// dimension or a voxel count that overflows.
  Volume(std::array<int64_t, 3> dims, VoxelType type,
         std::array<double, 3> spacing = {1.0, 1.0, 1.0});

  const std::array<int64_t, 3>& dims() const { return dims_; }
  int64_t nx() const { return dims_[0]; }
  int64_t ny() const { return dims_[1]; }
  int64_t nz() const { return dims_[2]; }
  std::size_t voxel_count() const { return data_.size(); }

  const std::array<double, 3>& spacing() const { return spacing_; }
  void set_spacing(std::array<double, 3> s);  // throws ArgumentError if not > 0 and finite
  VoxelType type() const { return type_; }

  std::size_t index(int64_t x, int64_t y, int64_t z) const {
    return static_cast<std::size_t>((z * dims_[1] + y) * dims_[0] + x);
  }
  float at(int64_t x, int64_t y, int64_t z) const { return data_[index(x, y, z)]; }
  float& at(int64_t x, int64_t y, int64_t z) { return data_[index(x, y, z)]; }
  /// Value at (x, y, z) with each coordinate clamped into the volume.
  float at_clamped(int64_t x, int64_t y, int64_t z) const;

  const std::vector<float>& data() const { return data_; }
  std::vector<float>& data() { return data_; }
  /// Throws ArgumentError (naming `argument`: "holds 1000 voxels, but its
  /// dims 64 x 64 x 64 need 262144") where data() no longer holds
  /// nx * ny * nz values: a vector resized by its caller was read past its
  /// end. The renderers (make_view, render_reference, RenderEngine), shade,
  /// classify, the layout and save_nrrd check it.
  void check_voxel_count(const std::string& argument = "volume") const;

  /// The volume's identity for the kept layout of a RenderEngine
  /// (EngineOptions::reuse_layout): a number no other volume of the process
  /// has had, new for every volume made or copied (a copy may be changed
  /// apart from its original) and for one assigned a copy; a volume moved
  /// from keeps it in its new place and takes a new one. A volume made
  /// where an earlier one was destroyed (at its address, its voxels in the
  /// same storage) is thus not taken for it.
  std::uint64_t serial() const { return serial_.value(); }

  /// Smallest and largest finite value (computed on demand).
  ValueRange range() const;

  /// Where each index axis (x, y, z) points in the patient, as the file's
  /// header says: three letters, one of R/L, one of A/P, one of S/I ("LAS":
  /// x runs to the patient's left, y to the front, z up), the closest axes
  /// of an oblique scan; empty where the file says nothing (a raw or .den
  /// file, Analyze, NIfTI without a qform or sform, NRRD without an
  /// anatomical space). The voxels keep the file's order: see reorient.
  const std::string& orientation() const { return orientation_; }
  /// Throws ArgumentError unless `code` is empty or valid_orientation.
  void set_orientation(std::string code);

  /// What the loader did to the voxels beyond reading them, one sentence
  /// each, for the user to be told (a DICOM series' slices resampled for
  /// a gantry tilt); empty for most files.
  const std::vector<std::string>& notes() const { return notes_; }
  void add_note(std::string note) { notes_.push_back(std::move(note)); }

  /// The files the loader read beside the one named, where a format keeps
  /// the voxels apart from the header (an Analyze or NIfTI .hdr's .img and
  /// the other way round, a detached NRRD's or MetaImage's data files):
  /// what an output must not replace. Empty for one-file formats.
  const std::vector<std::filesystem::path>& companion_files() const { return companions_; }
  void add_companion_file(std::filesystem::path p) { companions_.push_back(std::move(p)); }

 private:
  // serial(): new on every construction and copy, carried by a move.
  class Serial {
   public:
    Serial() noexcept : value_(next()) {}
    Serial(const Serial&) noexcept : value_(next()) {}
    Serial(Serial&& o) noexcept : value_(o.value_) { o.value_ = next(); }
    Serial& operator=(const Serial&) noexcept {
      value_ = next();
      return *this;
    }
    Serial& operator=(Serial&& o) noexcept {
      if (this != &o) {
        value_ = o.value_;
        o.value_ = next();
      }
      return *this;
    }
    std::uint64_t value() const noexcept { return value_; }

   private:
    static std::uint64_t next() noexcept;
    std::uint64_t value_;
  };

  std::array<int64_t, 3> dims_{0, 0, 0};
  std::array<double, 3> spacing_{1.0, 1.0, 1.0};
  VoxelType type_ = VoxelType::f32;
  std::vector<float> data_;
  std::string orientation_;
  std::vector<std::string> notes_;
  std::vector<std::filesystem::path> companions_;
  Serial serial_;
};

/// Whether `code` names each of the axes R/L, A/P, S/I once, in upper case
/// ("RAS", "LPS", "PIR", ...).
bool valid_orientation(std::string_view code);

/// The orientation code of three index axes whose directions (x, y, z) are
/// given in a world whose +x, +y, +z point to `world` ("RAS" for NIfTI,
/// "LPS" for DICOM): each axis takes the world axis it lies closest to (the
/// permutation of the three with the largest sum of |cos|), with the sign
/// of that component. Empty if a direction is 0 or not finite, or `world`
/// is not a valid_orientation.
std::string closest_orientation(const std::array<std::array<double, 3>, 3>& dirs,
                                std::string_view world);

/// `v` with its axes permuted and reversed so that its orientation is `to`
/// (a valid_orientation code, such as "RAS"): voxels, spacing and
/// orientation follow, the type is kept, and no value is resampled. Throws
/// ArgumentError (naming `argument`) if `to` is not a code or `v` has no
/// orientation.
Volume reorient(const Volume& v, std::string_view to, const std::string& argument = "orientation");

/// Multiplies the three dims, throwing ArgumentError (naming `what`) if any is
/// non-positive or the product (times `bytes_per_voxel`) overflows size_t.
std::size_t checked_voxel_count(const std::array<int64_t, 3>& dims, const std::string& what,
                                std::size_t bytes_per_voxel = sizeof(float));

}  // namespace simdvol
