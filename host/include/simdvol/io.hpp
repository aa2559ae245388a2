// Volume loaders and writers. Every malformed input throws FileError naming
// the file and the problem: missing file, directory, truncated data, header
// dims that disagree with the data size, overflowing dims, unknown type,
// non-positive dimension.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string_view>

#include "simdvol/volume.hpp"

namespace simdvol {

enum class Endian { little, big };

/// What a raw file cannot say about itself.
struct RawLayout {
  std::array<int64_t, 3> dims{0, 0, 0};
  VoxelType type = VoxelType::u8;
  Endian endian = Endian::little;
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  uint64_t header_bytes = 0;  ///< bytes to skip before the voxels
};

/// Raw voxels, x fastest. The file must hold exactly header_bytes + voxels.
Volume load_raw(const std::filesystem::path& path, const RawLayout& layout);
/// VolPack's .den format (brainsmall.den, from examples/denfile.c): a 62-byte
/// header in the writer's byte order (int16 version 1, whose byte order gives
/// the file's; 27 int16 min/max/len fields, the dims being map_len at byte 50;
/// int16 map_warps; int32 map_length = voxel count), then 8-bit voxels.
Volume load_den(const std::filesystem::path& path);
/// NRRD through teem: attached and detached headers (.nrrd, .nhdr), raw and
/// gzip encodings, 3-D scalar data (or one volume of 4-D data, below). uint8,
/// uint16, int16 and float keep their type; int8 loads as i16; int32, uint32,
/// int64, uint64 and double load as f32. Spacing from "spacings" or the norms
/// of "space directions", else 1. Not thread-safe (teem's biff is global).
/// A 4-D nrrd of several 3-D volumes loads the one at `volume_index`, as
/// load_nifti; its volume axis is its one axis of a non-spatial kind (a
/// list or vector: a diffusion series), else an axis of size 1, else the
/// last axis (a time series). Where the data are one raw or gzip stream
/// (attached, or one detached file) that volume is read alone from it, the
/// others skipped; otherwise (ASCII or hex, several data files, a line
/// skip) teem reads every volume and one is kept.
Volume load_nrrd(const std::filesystem::path& path,
                 std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);
/// NIfTI through niftilib: NIfTI-1 and NIfTI-2, each as a single file
/// (.nii, .nii.gz) or a .hdr/.img pair (either half may be named, each
/// plain or gzipped: .hdr.gz, .img.gz), and Analyze 7.5 pairs (a .hdr with
/// no NIfTI magic). 3-D scalar, scl_slope/scl_inter applied; an Analyze
/// header's scale is SPM's (bytes 112 and 116, which niftilib ignores),
/// applied by the same rule. The type follows the datatype as for NRRD, but
/// a volume with a non-identity scaling loads as f32. A file of several 3-D
/// volumes (dim[4] and up above 1: a time series, a diffusion series) loads
/// the one at `volume_index` (0-based, volumes in file order; only its
/// bytes are read); without an index such a file is a FileError that says
/// how many it holds. An index outside the file's volumes is a FileError.
/// `volumes`, if given, receives how many 3-D volumes the file holds (1 for
/// a 3-D file; so for load_nrrd and load_volume). The volume's orientation
/// is its sform's where sform_code > 0, else its qform's where qform_code
/// > 0, else none (and none for Analyze); load_nrrd gives that of an
/// anatomical space (RAS, LAS, LPS) and its space directions.
Volume load_nifti(const std::filesystem::path& path,
                  std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);

/// DICOM through GDCM: `path` names a directory holding one series' slices
/// (in it or in the directories below it, as on a CD; a DICOMDIR stands for
/// the tree beside it), one slice of a series (the series' other slices are
/// found beside it by their Series Instance UID), or one multi-frame file: an enhanced one
/// (Enhanced CT, MR, PET) places each frame by its functional groups (a
/// frame's own, else the shared ones: position, plane, Pixel Spacing,
/// scale), an RT dose grid by its Grid Frame Offset Vector; other
/// multi-frame files keep their frames as stored. A Siemens mosaic (Image
/// Type MOSAIC) is unpacked: its tiles, left to right and top to bottom,
/// are slices (their count and size from its CSA header, through GDCM's
/// SplitMosaicFilter) placed from its Image Position (Patient) along the
/// normal, as nibabel and SPM place them. Slices and placed frames
/// are sorted by their position along the normal of their plane and must
/// lie evenly spaced in one plane orientation, of one size, Pixel Spacing
/// and pixel format (slices whose origins lie off the line along the normal,
/// as a CT gantry tilt leaves them, are resampled in their plane, bilinearly,
/// so that the grid is orthogonal; f32 then, with a Volume::notes entry
/// saying so); grey scale only (any transfer syntax GDCM decodes:
/// JPEG, JPEG 2000, JPEG-LS, RLE). Rescale Slope and Intercept are applied
/// per slice or frame (Hounsfield units for CT), the type following the
/// pixels as for NIfTI (f32 where any is scaled). The spacing: Pixel
/// Spacing, and the mean gap (an unplaced multi-frame file's from GDCM).
/// The orientation: Image Orientation (Patient) and the slice order, in
/// DICOM's LPS space (none for unplaced frames). Where every position
/// holds K images (time points, echoes), the series holds K volumes:
/// `volume_index` picks one (volume v: the v-th at each position in
/// acquisition order: Temporal Position Identifier, Echo Numbers,
/// Acquisition Number, Instance Number; a frame's place in its file), and
/// is needed where K > 1; `volumes` receives K. A directory of several
/// series is a FileError that lists them (modality, description, a file).
Volume load_dicom(const std::filesystem::path& path,
                  std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);

/// MetaImage through MetaIO (ITK's copy): a header with the voxels after
/// it (.mha, ElementDataFile = LOCAL) or in another file (.mhd; raw or
/// zlib/gzip-compressed, inflated by simdvol with zlib), binary or ASCII,
/// either byte order; a LIST of slice files or a printf pattern of them is
/// refused. NDims 3, or 4 (a series: `volume_index` picks one volume, as
/// for load_nifti; only it is kept). One channel of a scalar ElementType
/// (u8, u16 and i16 kept, int8 as i16, wider types as f32). ElementSpacing
/// (else 1). The orientation: the closest axes of TransformMatrix (its row
/// i the direction of axis i, as ITK reads it) in MetaImage's LPS space; a
/// header without one is LPS. ElementToIntensityFunctionSlope and Offset
/// are not applied (ITK, Slicer and elastix do not apply them either). The
/// header's lines are checked before MetaIO parses them (its parser
/// overflows its buffers on long names and values). MetaIO's messages on
/// std::cerr and std::cout are caught while it reads (one load at a time),
/// so that they can be quoted in the FileError: another thread's writes to
/// them in that time land there too.
Volume load_metaimage(const std::filesystem::path& path,
                      std::optional<int64_t> volume_index = std::nullopt,
                      int64_t* volumes = nullptr);

/// FreeSurfer's MGH: .mgh, or .mgz (.mgh.gz) gzipped, read by simdvol from
/// its fixed big-endian header (no library for it is packaged): uchar,
/// short, int and float voxels (u8 and i16 kept, the others as f32), the
/// voxel sizes, and where goodRASFlag says they are valid the direction
/// cosines (the closest axes, in RAS; none otherwise). A file of several
/// frames is a 4-D series: `volume_index` picks one, and only the bytes up
/// to it are read. The tags after the voxels (TR, flip angle) are not.
Volume load_mgh(const std::filesystem::path& path,
                std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);

/// MINC (.mnc: MINC1 on netCDF, MINC2 on HDF5) through libminc's C++
/// reader, in a child process as load_dicom reads (HDF5 and netCDF are not
/// safe on hostile files; SIMDVOL_MINC_IN_PROCESS=1 reads in this process).
/// Real values (the slices' scaling applied), as f32, the file's order
/// kept (its fastest dimension is x). 3 dimensions, or 4 with time the
/// slowest (a series: `volume_index` picks one time point); a vector
/// dimension (colour) is refused. Spacing: |step|. Orientation: the
/// closest axes of the dimensions' direction cosines (else the world axis
/// each dimension is named for) times the step's sign, in MINC's RAS world.
Volume load_minc(const std::filesystem::path& path,
                 std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);

/// The kinds of volume file load_volume reads, told by the name's ending
/// (whatever its case; a DICOMDIR is DICOM), else by being a directory
/// (DICOM) or by "DICM" at byte 128 (a DICOM file of any name).
enum class VolumeFileKind { unknown, den, nrrd, nifti, raw, dicom, metaimage, mgh, minc };
VolumeFileKind volume_file_kind(const std::filesystem::path& path);
/// The endings volume_file_kind knows, for messages.
inline constexpr std::string_view kVolumeFileNames =
    ".den, .nrrd, .nhdr, .nii, .nii.gz, .hdr/.img (NIfTI or Analyze pairs, plain or .gz), "
    ".mha, .mhd (MetaImage), .mgh, .mgz (FreeSurfer), .mnc (MINC), "
    "DICOM (.dcm, a file of any name, or a directory of one series) or .raw";
/// The files that may hold several 3-D volumes (NIfTI, NRRD, MetaImage,
/// MGH, MINC, DICOM).
inline constexpr std::string_view kSeriesFileNames =
    ".nii, .nii.gz, .hdr/.img, .nrrd, .nhdr, .mha, .mhd, .mgh, .mgz, .mnc, DICOM";

/// Chooses the loader by volume_file_kind (.raw needs `raw`). Throws
/// FileError for an unknown extension, and for a `volume_index` given with
/// a file other than NIfTI, NRRD, MetaImage, MGH, MINC or DICOM. Every
/// file the read meets is watched: `path`, and the files read beside it (a
/// detached header's data files, a pair's other half, a DICOM series'
/// slices), each looked up (one stat) when first met and again after the
/// read. Where one was replaced (or changed) meanwhile, the volume is read
/// again, so that it is what the files held at one moment (up to three
/// reads, the later ones 10 ms, then 100 ms, after a change beside `path`,
/// where a writer of several files may still be at work; then a FileError
/// naming the file that changed while being read). A directory (a DICOM
/// series) is watched as which directory it is, not by its times: files
/// made or removed beside a series' own are not changes.
Volume load_volume(const std::filesystem::path& path,
                   const std::optional<RawLayout>& raw = std::nullopt,
                   std::optional<int64_t> volume_index = std::nullopt, int64_t* volumes = nullptr);

/// Writes `parts`, one after another, to a new temporary file in `path`'s
/// directory (named after at most the first 64 bytes of path's name, so any
/// legal path has room for it), then renames it over `path`: a failure
/// leaves an existing file at `path` untouched and no temporary file behind.
/// Throws FileError naming `path`.
void write_file_atomically(const std::filesystem::path& path,
                           std::initializer_list<std::string_view> parts);

/// For programs (the library installs no handler unless asked): SIGINT,
/// SIGTERM, SIGHUP and SIGQUIT first remove the temporary files of the
/// writes in progress (write_file_atomically, write_image, an ImageBatch's
/// images not yet renamed into place, save_nrrd, the program cache), then
/// end the process as before; and a write past the
/// file-size limit (ulimit -f) fails as a FileError ("File too large")
/// instead of SIGXFSZ ending the process. A signal the program already
/// ignores or handles keeps its disposition. The simdvol program and the
/// bench programs call it first.
void remove_temporary_files_on_signals();

/// Writes an attached-header NRRD (raw encoding) in the volume's own type,
/// atomically: a temporary file beside `path`, then rename. A volume with
/// an orientation is written in RAS space, its axes' directions scaled by
/// the spacing (so load_nrrd gives both back); others with "spacings".
void save_nrrd(const Volume& vol, const std::filesystem::path& path);

}  // namespace simdvol
