// Readers for volume files: NRRD, Levoy's .den, NIfTI-1, MetaImage, VTK image
// data, DICOM series and headerless raw.
//
// Every reader validates what it reads: a truncated file, a header whose sizes
// overflow or disagree with the data, an unknown type or encoding each give an
// InvalidArgument status whose message names the file and what is wrong. No
// reader reads past what it has checked. Volumes whose decoded size exceeds
// `ReadOptions::max_bytes` are refused with ResourceExhausted before any
// allocation of that size.
#ifndef TRANSTICK_VOLUME_IO_H_
#define TRANSTICK_VOLUME_IO_H_

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/volume.h"

namespace transtick {

struct ReadOptions {
  // Largest in-memory volume accepted (float samples, 4 bytes per voxel).
  uint64_t max_bytes = uint64_t{8} << 30;
  // Opens each file a reader needs (the volume; a detached data file named
  // relative to its header) read-only, returning a descriptor the reader
  // then owns, or an error naming the path. Null opens the path as given.
  // The root passes one that keeps every open inside its data directory.
  std::function<absl::StatusOr<int>(const std::string& path)> open;
  // Lists the names in a directory (a DICOM series), or an error naming it.
  // Null lists the path as given. The root passes one that stays inside its
  // data directory, as `open` does.
  std::function<absl::StatusOr<std::vector<std::string>>(const std::string& path)> list;
  // Seconds allowed to decode one DICOM file of compressed pixel data, plus
  // one per 4 MiB of its pixels; and to start the decoder process
  // (docs/formats.md, "DICOM decoder process"). Past them the decoder is
  // stopped and the file's read fails.
  double decode_seconds = 10;
};

enum class ByteOrder { kLittle, kBig };

// What a headerless raw file cannot say about itself.
struct RawSpec {
  std::array<int, 3> dims = {0, 0, 0};
  ScalarType type = ScalarType::kUint8;
  ByteOrder byte_order = ByteOrder::kLittle;
  std::array<double, 3> spacing = {1.0, 1.0, 1.0};
  uint64_t header_bytes = 0;  // bytes to skip at the start of the file
};

// Every reader of a format that says where its volume lies (NRRD, NIfTI-1,
// MetaImage, VTK image data, DICOM) sets Volume::origin and direction from it
// (orientation.h); the others leave the identity.

// NRRD: attached (.nrrd) and detached (.nhdr + data file) headers, encodings
// raw and gzip, types uint8/int8/uint16/int16/uint32/int32/float, both byte
// orders, "spacings" or "space directions" for the voxel size, space
// directions, space origin and space for the orientation. 3-D only.
absl::StatusOr<Volume> ReadNrrd(const std::string& path, const ReadOptions& options = {});

// Levoy's .den (VolPack): a 62-byte header of 16-bit fields (plus one 32-bit
// voxel count) in either byte order, detected from the version field, then
// 8-bit voxels x fastest.
absl::StatusOr<Volume> ReadDen(const std::string& path, const ReadOptions& options = {});

// NIfTI-1 single file (.nii, .nii.gz): 348-byte header, vox_offset, datatypes
// matching ScalarType, pixdim for spacing, scl_slope/scl_inter applied,
// sform or qform for the orientation. Given a .hdr or .img (either maybe
// .gz), the pair: NIfTI-1 ("ni1") or Analyze 7.5 (no orientation), samples
// from vox_offset of the .img.
absl::StatusOr<Volume> ReadNifti(const std::string& path, const ReadOptions& options = {});

// MetaImage (.mha attached, .mhd with a data file): 3-D scalar images, raw or
// zlib-compressed, TransformMatrix and Offset for the orientation.
absl::StatusOr<Volume> ReadMetaImage(const std::string& path, const ReadOptions& options = {});

// VTK XML image data (.vti): one piece, one scalar point-data array in
// appended raw encoding, uncompressed or vtkZLibDataCompressor; Origin,
// Spacing and Direction for the orientation.
absl::StatusOr<Volume> ReadVti(const std::string& path, const ReadOptions& options = {});

// A DICOM series of CT, MR or RT dose images in a directory, read with
// GDCM: single-frame slices, and multi-frame images whose frames become
// slices (placed by their functional groups, or an RT dose's frame
// offsets), sorted by position along the slice normal, rescaled by slope
// and intercept, spacing from PixelSpacing and the positions. Missing slices
// (gaps), duplicate positions, tilted gantries and slices of different
// sizes are refused. Subdirectories, files that are not DICOM and DICOM
// files without an image (reports, presentation states) are passed over
// and named in Volume::notes. A directory holding several series is read
// only when `path` names one, "DIR#UID" (SeriesPath); otherwise the error
// lists them. Every file goes through `options.open`, the directory
// through `options.list`.
absl::StatusOr<Volume> ReadDicomSeries(const std::string& path, const ReadOptions& options = {});

// A path that names one series of a DICOM directory: "DIR#UID", the UID of
// digits and dots (as every DICOM UID is), DIR the part before the last
// '#'. Whether `path` has that form; a path that names a file or a
// directory as it is (a name with a '#' in it) is read as that, and only
// one that does not is taken for a series (ReadVolume, the root).
struct SeriesPath {
  std::string dir;
  std::string series;
};
std::optional<SeriesPath> ParseSeriesPath(std::string_view path);

// One series of a DICOM directory, as its files' headers describe it.
struct DicomSeriesInfo {
  std::string uid;  // SeriesInstanceUID; "" when the files have none
  // The path that reads it: the directory when it is the only series,
  // else "DIR#UID"; "" when no path can name it (a UID that is not digits
  // and dots).
  std::string path;
  std::string modality, number, description;  // (0008,0060), (0020,0011), (0008,103E)
  std::string summary;  // "CT, series 2 'AX 5mm', 120 files" (each value shown printable)
  size_t files = 0;     // files of the series
  uint64_t bytes = 0;   // their sizes
  size_t frames = 0;    // slices: one per frame
  int columns = 0, rows = 0;
  // Why ReadDicomSeries would refuse it, as far as the headers tell (a
  // file's own problem, slices that differ, a gap, a tilt, the size): the
  // error it would give. "" when the headers raise none (the pixels may
  // still fail to decode).
  std::string problem;
};
// A DICOM file's header is read in prefixes: this many bytes first, then
// 4 times more each time while the header goes on (at least to the pixel
// data's value). Most headers take a few KiB. In a fuzzing build less, so
// that the fuzzers' inputs of at most 4 KiB are read in several looks.
#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
inline constexpr uint64_t kDicomFirstHeaderBytes = 256;
#else
inline constexpr uint64_t kDicomFirstHeaderBytes = 16 << 10;
#endif
// Bytes a listing may still read (ListDicomSeries); `exhausted` once a
// read would have gone past them.
struct DicomReadBudget {
  uint64_t bytes = 0;
  bool exhausted = false;
};
// The series of the DICOM directory `path`, in the order their first files
// come by name. Errors as ReadDicomSeries gives them for the directory (it
// cannot be listed, holds no DICOM image, a file starting as DICOM does
// cannot be read). Reads every file's header through `options`: its bytes
// up to the pixel data only, so a file damaged past that point is found
// when the series is read. With a `budget`, the bytes read are taken from
// it, and a read that would go past it gives ResourceExhausted (and sets
// budget->exhausted).
absl::StatusOr<std::vector<DicomSeriesInfo>> ListDicomSeries(const std::string& path,
                                                             const ReadOptions& options = {},
                                                             DicomReadBudget* budget = nullptr);

absl::StatusOr<Volume> ReadRaw(const std::string& path, const RawSpec& spec,
                               const ReadOptions& options = {});

// The file names ReadVolume reads, as extensions in lower case with the
// dot: ".nrrd", ".nhdr", ".den", ".nii", ".nii.gz", ".mha", ".mhd", ".vti".
// The one list: ReadVolume dispatches on it, the root lists the data
// directory's volumes by it. Of static storage.
std::span<const std::string_view> VolumeFileExtensions();
// Whether `path` ends in one of them, in any case.
bool IsVolumeFileName(std::string_view path);

// Chooses the reader by extension (VolumeFileExtensions); a directory, or
// a series of one (ParseSeriesPath), is read as a DICOM series.
absl::StatusOr<Volume> ReadVolume(const std::string& path, const ReadOptions& options = {});

// Parses "uint8", "int16", "float", ... (NRRD's names and their synonyms).
absl::StatusOr<ScalarType> ParseScalarType(const std::string& name);

}  // namespace transtick

#endif  // TRANSTICK_VOLUME_IO_H_
