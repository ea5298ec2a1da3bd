// Readers for volume files: NRRD, Levoy's .den, NIfTI-1 and headerless raw.
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
#include <string>

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

// NRRD: attached (.nrrd) and detached (.nhdr + data file) headers, encodings
// raw and gzip, types uint8/int8/uint16/int16/uint32/int32/float, both byte
// orders, "spacings" or "space directions" for the voxel size. 3-D only.
absl::StatusOr<Volume> ReadNrrd(const std::string& path, const ReadOptions& options = {});

// Levoy's .den (VolPack): a 62-byte header of 16-bit fields (plus one 32-bit
// voxel count) in either byte order, detected from the version field, then
// 8-bit voxels x fastest.
absl::StatusOr<Volume> ReadDen(const std::string& path, const ReadOptions& options = {});

// NIfTI-1 single file (.nii, .nii.gz): 348-byte header, vox_offset, datatypes
// matching ScalarType, pixdim for spacing, scl_slope/scl_inter applied.
absl::StatusOr<Volume> ReadNifti(const std::string& path, const ReadOptions& options = {});

absl::StatusOr<Volume> ReadRaw(const std::string& path, const RawSpec& spec,
                               const ReadOptions& options = {});

// Chooses the reader by extension: .nrrd/.nhdr, .den, .nii/.nii.gz.
absl::StatusOr<Volume> ReadVolume(const std::string& path, const ReadOptions& options = {});

// Parses "uint8", "int16", "float", ... (NRRD's names and their synonyms).
absl::StatusOr<ScalarType> ParseScalarType(const std::string& name);

}  // namespace transtick

#endif  // TRANSTICK_VOLUME_IO_H_
