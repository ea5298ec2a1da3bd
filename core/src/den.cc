// Levoy's .den density files, as read and written by VolPack's
// examples/denfile.c.
//
// Header, 62 bytes, fields back to back with no padding, all in the file's
// byte order:
//   offset  width  field
//        0  int16  map_version   1 (the magic: its byte order is the file's)
//        2  int16  orig_min[3]   original data set: min, max, length per axis
//        8  int16  orig_max[3]
//       14  int16  orig_len[3]
//       20  int16  extr_min[3]   extracted part of the original
//       26  int16  extr_max[3]
//       32  int16  extr_len[3]
//       38  int16  map_min[3]    this map
//       44  int16  map_max[3]
//       50  int16  map_len[3]    the volume's size x, y, z
//       56  int16  map_warps
//       58  int32  map_length    voxel count; must equal the product of map_len
// Then map_length uint8 voxels, x fastest, and nothing else.
//
// denfile.c writes with the host's byte order, so files from big-endian
// workstations and from PCs both exist; map_version tells them apart.
// The format records no voxel size, so spacing is 1, 1, 1.
#include <array>
#include <cstdint>
#include <string>

#include "absl/strings/str_cat.h"
#include "transtick/volume_io.h"
#include "volume_io_internal.h"

namespace transtick {
namespace {

namespace vi = volume_io_internal;

constexpr size_t kHeaderBytes = 62;
constexpr size_t kMapLenOffset = 50;
constexpr size_t kMapLengthOffset = 58;

uint16_t Load16(const unsigned char* p, bool big) {
  return big ? static_cast<uint16_t>(p[0] << 8 | p[1]) : static_cast<uint16_t>(p[1] << 8 | p[0]);
}

uint32_t Load32(const unsigned char* p, bool big) {
  return big ? (uint32_t{p[0]} << 24 | uint32_t{p[1]} << 16 | uint32_t{p[2]} << 8 | p[3])
             : (uint32_t{p[3]} << 24 | uint32_t{p[2]} << 16 | uint32_t{p[1]} << 8 | p[0]);
}

}  // namespace

absl::StatusOr<Volume> ReadDen(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<std::string> header = vi::ReadPrefix(path, kHeaderBytes, options);
  if (!header.ok()) return header.status();
  if (header->size() < kHeaderBytes) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": file holds ", header->size(),
                                                   " bytes, less than the ", kHeaderBytes,
                                                   "-byte .den header (truncated header)"));
  }
  const auto* h = reinterpret_cast<const unsigned char*>(header->data());

  bool big = false;
  const uint16_t version = Load16(h, /*big=*/true);
  if (version == 0x0001) {
    big = true;
  } else if (version == 0x0100) {
    big = false;
  } else {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a .den file (map_version is 0x",
                                                   absl::Hex(version, absl::kZeroPad4),
                                                   ", expected 1 in either byte order)"));
  }

  std::array<int64_t, 3> dims;
  for (int i = 0; i < 3; ++i) {
    dims[i] = static_cast<int16_t>(Load16(h + kMapLenOffset + 2 * i, big));
  }
  // The 32-bit count is read as signed, like denfile.c's int.
  const int64_t map_length = static_cast<int32_t>(Load32(h + kMapLengthOffset, big));

  absl::StatusOr<uint64_t> data_bytes =
      vi::CheckedDataBytes(path, dims, ScalarType::kUint8, options);
  if (!data_bytes.ok()) return data_bytes.status();
  if (map_length < 0 || static_cast<uint64_t>(map_length) != *data_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": inconsistent header: map_length ", map_length, " but map_len ",
                     dims[0], "x", dims[1], "x", dims[2], " = ", *data_bytes, " voxels"));
  }
  absl::StatusOr<uint64_t> file_size = vi::FileSize(path, options);
  if (!file_size.ok()) return file_size.status();
  const uint64_t available = *file_size > kHeaderBytes ? *file_size - kHeaderBytes : 0;
  if (available != *data_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": header says ", vi::DescribeLayout(dims, ScalarType::kUint8),
                     ", file holds ", available, " after the ", kHeaderBytes, "-byte header"));
  }

  Volume volume;
  volume.dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};
  volume.spacing = {1.0, 1.0, 1.0};
  volume.source_type = ScalarType::kUint8;
  absl::Status status = vi::ReadRawSamples(path, kHeaderBytes, volume.VoxelCount(),
                                           ScalarType::kUint8, ByteOrder::kLittle, &volume.values, options);
  if (!status.ok()) return status;
  return volume;
}

}  // namespace transtick
