// NIfTI-1 reader: single files (.nii, and .nii.gz: the same bytes gzipped)
// and pairs of a header and its samples (.hdr + .img, either gzipped), NIfTI-1
// ("ni1") or Analyze 7.5 (no magic; no orientation: the identity).
//
// The 348-byte header, fields used here (offsets in bytes; byte order is the
// file's, told by sizeof_hdr which must read 348):
//   offset  width        field
//        0  int32        sizeof_hdr   348
//       40  int16[8]     dim          dim[0] = number of axes, dim[1..] sizes
//       70  int16        datatype     2 uint8, 4 int16, 8 int32, 16 float32,
//                                     256 int8, 512 uint16, 768 uint32
//       76  float32[8]   pixdim       pixdim[1..3] = voxel size
//      108  float32      vox_offset   where the samples start
//      112  float32      scl_slope    value = stored * slope + inter,
//      116  float32      scl_inter      unless slope is 0 (no scaling)
//      252  int16        qform_code   > 0: the quaternion below is valid
//      254  int16        sform_code   > 0: the srow affine below is valid
//      256  float32[3]   quatern_b, quatern_c, quatern_d
//      268  float32[3]   qoffset_x, qoffset_y, qoffset_z
//      280  float32[12]  srow_x, srow_y, srow_z (4 each: i, j, k, offset)
//      344  char[4]      magic        "n+1\0" (single file), "ni1\0" (pair)
// Samples follow at vox_offset, x fastest (in a pair, at vox_offset of the
// .img, usually 0). Between byte 348 and vox_offset
// may sit extensions, which are skipped; bytes after the samples are ignored
// (in a .nii.gz, up to kMaxTrailingBytes of them).
//
// Accepted: dim[0] = 3, or up to 7 with every axis beyond the third of size
// 1 (a single time point). A nonpositive or non-finite pixdim is taken as 1,
// as many writers leave it unset; its sign is dropped.
//
// Orientation (world RAS in the file, converted to LPS by negating x and y):
// the sform when sform_code > 0 and its axes are orthogonal; else the qform
// when qform_code > 0 (a rotation by the quaternion, with pixdim[0] = -1
// reversing k); else the identity. A sheared sform with no qform is refused.
// The spacing stays pixdim's.
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "transtick/orientation.h"
#include "transtick/volume_io.h"
#include "volume_io_internal.h"

namespace transtick {
namespace {

namespace vi = volume_io_internal;

constexpr size_t kHeaderBytes = 348;
// Single-file NIfTI-1 puts a 4-byte extension flag after the header, so data
// start at 352 at the earliest; some writers leave vox_offset 0 to mean that.
constexpr uint64_t kDefaultVoxOffset = 352;
// vox_offset is a float: beyond 2^24 it cannot even name every byte.
constexpr double kMaxVoxOffset = double{1 << 24};
// Bytes after the samples are ignored, but a .nii.gz is read to its end so
// that the gzip CRC is checked; this bounds the work spent on a trailer.
constexpr uint64_t kMaxTrailingBytes = uint64_t{64} << 20;

class HeaderView {
 public:
  HeaderView(const unsigned char* bytes, bool big) : bytes_(bytes), big_(big) {}
  uint32_t U32(size_t offset) const {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) {
      v = v << 8 | bytes_[offset + (big_ ? i : 3 - i)];
    }
    return v;
  }
  int16_t I16(size_t offset) const {
    return static_cast<int16_t>(big_ ? (bytes_[offset] << 8 | bytes_[offset + 1])
                                     : (bytes_[offset + 1] << 8 | bytes_[offset]));
  }
  float F32(size_t offset) const {
    uint32_t bits = U32(offset);
    float f;
    std::memcpy(&f, &bits, sizeof(f));
    return f;
  }

 private:
  const unsigned char* bytes_;
  bool big_;
};

const char* UnsupportedDatatypeName(int datatype) {
  switch (datatype) {
    case 1:
      return "binary";
    case 32:
      return "complex64";
    case 128:
      return "rgb24";
    case 1024:
      return "int64";
    case 1280:
      return "uint64";
    case 1536:
      return "float128";
    case 1792:
      return "complex128";
    case 2048:
      return "complex256";
    case 2304:
      return "rgba32";
    default:
      return "unknown";
  }
}

absl::Status Error(const std::string& path, const std::string& message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

struct Header {
  std::array<int64_t, 3> dims;
  ScalarType type;
  ByteOrder order;
  std::array<double, 3> spacing;
  uint64_t vox_offset;
  float slope;
  float inter;
  // The index axes and origin in RAS, from the sform or the qform; unset
  // when the file gives neither.
  std::optional<std::array<std::array<double, 3>, 3>> axes;
  std::optional<std::array<std::array<double, 3>, 3>> qform_axes;  // a fallback for a sheared sform
  std::array<double, 3> origin = {0, 0, 0};
  std::array<double, 3> qform_origin = {0, 0, 0};
};

// The qform's axes (columns of the rotation, the k axis times qfac).
std::array<std::array<double, 3>, 3> QformAxes(const HeaderView& h) {
  const double b = h.F32(256), c = h.F32(260), d = h.F32(264);
  const double aa = 1.0 - (b * b + c * c + d * d);
  const double a = aa > 0 ? std::sqrt(aa) : 0.0;
  const double qfac = h.F32(76) < 0 ? -1.0 : 1.0;
  const double r[3][3] = {{a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)},
                          {2 * (b * c + a * d), a * a + c * c - b * b - d * d, 2 * (c * d - a * b)},
                          {2 * (b * d - a * c), 2 * (c * d + a * b), a * a + d * d - c * c - b * b}};
  std::array<std::array<double, 3>, 3> axes;
  for (int j = 0; j < 3; ++j) {
    for (int w = 0; w < 3; ++w) axes[j][w] = r[w][j] * (j == 2 ? qfac : 1.0);
  }
  return axes;
}

// `pair`: the header of a .hdr/.img pair, NIfTI-1 or Analyze 7.5.
absl::StatusOr<Header> ParseHeader(const std::string& path, const unsigned char* bytes, bool pair) {
  Header header;
  bool big;
  if (HeaderView(bytes, false).U32(0) == kHeaderBytes) {
    big = false;
  } else if (HeaderView(bytes, true).U32(0) == kHeaderBytes) {
    big = true;
  } else if (HeaderView(bytes, false).U32(0) == 540 || HeaderView(bytes, true).U32(0) == 540) {
    return Error(path, "NIfTI-2 files are not supported, only NIfTI-1");
  } else {
    return Error(path, "not a NIfTI-1 file (sizeof_hdr is not 348 in either byte order)");
  }
  header.order = big ? ByteOrder::kBig : ByteOrder::kLittle;
  HeaderView h(bytes, big);

  // Analyze 7.5 has no magic there; its bytes 252-347 mean other things
  // (orient, originator, ...), so no orientation is read from them.
  bool analyze = false;
  if (!pair) {
    if (std::memcmp(bytes + 344, "ni1\0", 4) == 0) {
      return Error(path, "is the header of a .hdr/.img pair: open it as the .hdr file");
    }
    if (std::memcmp(bytes + 344, "n+1\0", 4) != 0) {
      return Error(path, "bad NIfTI-1 magic (expected \"n+1\")");
    }
  } else if (std::memcmp(bytes + 344, "n+1\0", 4) == 0) {
    return Error(path, "magic \"n+1\": a single-file NIfTI-1 header; name the file .nii");
  } else {
    analyze = std::memcmp(bytes + 344, "ni1\0", 4) != 0;
  }

  const int rank = h.I16(40);
  if (rank < 3 || rank > 7) {
    return Error(path, absl::StrCat("dim[0] is ", rank, ": only 3-D volumes are supported"));
  }
  for (int i = 4; i <= rank; ++i) {
    if (h.I16(40 + 2 * i) != 1) {
      return Error(path, absl::StrCat("dim[", i, "] is ", h.I16(40 + 2 * i),
                                      ": only 3-D volumes (a single time point) are supported"));
    }
  }
  for (int i = 0; i < 3; ++i) header.dims[i] = h.I16(40 + 2 * (i + 1));

  const int datatype = h.I16(70);
  switch (datatype) {
    case 2:
      header.type = ScalarType::kUint8;
      break;
    case 4:
      header.type = ScalarType::kInt16;
      break;
    case 8:
      header.type = ScalarType::kInt32;
      break;
    case 16:
      header.type = ScalarType::kFloat32;
      break;
    case 64:
      header.type = ScalarType::kFloat64;
      break;
    case 256:
      header.type = ScalarType::kInt8;
      break;
    case 512:
      header.type = ScalarType::kUint16;
      break;
    case 768:
      header.type = ScalarType::kUint32;
      break;
    default:
      return Error(path, absl::StrCat("unsupported datatype ", datatype, " (",
                                      UnsupportedDatatypeName(datatype),
                                      "); supported: uint8, int8, uint16, int16, uint32, "
                                      "int32, float32, float64"));
  }

  for (int i = 0; i < 3; ++i) {
    double s = std::fabs(h.F32(76 + 4 * (i + 1)));
    header.spacing[i] = (s > 0.0 && std::isfinite(s)) ? s : 1.0;
  }

  const float vox_offset = h.F32(108);
  if (pair) {
    // Into the .img: from 0.
    if (!(vox_offset >= 0) || !(vox_offset <= kMaxVoxOffset) ||
        vox_offset != std::floor(vox_offset)) {
      return Error(path, absl::StrCat("vox_offset ", vox_offset,
                                      " is not a whole number of bytes into the .img"));
    }
    header.vox_offset = static_cast<uint64_t>(vox_offset);
  } else if (vox_offset == 0.0f) {
    header.vox_offset = kDefaultVoxOffset;
  } else if (!(vox_offset >= kHeaderBytes) || !(vox_offset <= kMaxVoxOffset) ||
             vox_offset != std::floor(vox_offset)) {
    return Error(path, absl::StrCat("vox_offset ", vox_offset,
                                    " is not a whole number of bytes at or after the header"));
  } else {
    header.vox_offset = static_cast<uint64_t>(vox_offset);
  }

  header.slope = h.F32(112);
  header.inter = h.F32(116);
  if (analyze) return header;
  const int qform_code = h.I16(252), sform_code = h.I16(254);
  if (qform_code > 0) {
    header.qform_axes = QformAxes(h);
    header.qform_origin = {h.F32(268), h.F32(272), h.F32(276)};
  }
  if (sform_code > 0) {
    std::array<std::array<double, 3>, 3> axes;
    for (int j = 0; j < 3; ++j) {
      for (int w = 0; w < 3; ++w) axes[j][w] = h.F32(280 + 16 * w + 4 * j);
    }
    header.axes = axes;
    header.origin = {h.F32(280 + 12), h.F32(296 + 12), h.F32(312 + 12)};
  } else if (header.qform_axes) {
    header.axes = header.qform_axes;
    header.origin = header.qform_origin;
  }
  return header;
}

void ApplyScaling(float slope, float inter, std::vector<float>* values) {
  // Slope 0 (or not a number) means "no scaling" in NIfTI-1; skip the
  // identity too, so unscaled files cost nothing.
  if (!std::isfinite(slope) || slope == 0.0f) return;
  if (!std::isfinite(inter)) inter = 0.0f;
  if (slope == 1.0f && inter == 0.0f) return;
  for (float& v : *values) v = v * slope + inter;
}

// The name with its 3-letter extension swapped between hdr and img, letter
// case kept ("a.HDR" and "a.IMG").
std::string Swapped(std::string name, size_t ext_at) {
  static constexpr char kFrom[] = "hdrimgHDRIMG", kTo[] = "imghdrIMGHDR";
  for (size_t i = ext_at; i < ext_at + 3; ++i) {
    for (size_t k = 0; k < 12; ++k) {
      if (name[i] == kFrom[k] && (k % 3) == i - ext_at) {
        name[i] = kTo[k];
        break;
      }
    }
  }
  return name;
}

// For a .hdr or .img (either possibly .gz): the header's file and the
// samples' file, the other of which may or may not be gzipped, whichever
// exists.
absl::StatusOr<std::pair<std::string, std::string>> PairFiles(const std::string& path,
                                                              const ReadOptions& options) {
  const bool gz = absl::EndsWith(absl::AsciiStrToLower(path), ".gz");
  const std::string plain = gz ? path.substr(0, path.size() - 3) : path;
  const size_t ext_at = plain.size() - 3;
  const std::string other = Swapped(plain, ext_at);
  std::string found;
  for (const std::string& candidate : {other + (gz ? ".gz" : ""), other + (gz ? "" : ".gz")}) {
    if (vi::FileSize(candidate, options).ok()) {
      found = candidate;
      break;
    }
  }
  if (found.empty()) {
    return absl::NotFoundError(
        absl::StrCat(path, ": its pair ", other, " (or ", other, ".gz) is not there"));
  }
  const bool is_header = absl::AsciiStrToLower(plain.substr(ext_at)) == "hdr";
  return is_header ? std::pair{path, found} : std::pair{found, path};
}

}  // namespace

absl::StatusOr<Volume> ReadNifti(const std::string& given, const ReadOptions& options) {
  const std::string lower = absl::AsciiStrToLower(given);
  const bool pair = absl::EndsWith(lower, ".hdr") || absl::EndsWith(lower, ".hdr.gz") ||
                    absl::EndsWith(lower, ".img") || absl::EndsWith(lower, ".img.gz");
  // The header's file, and the samples' (the same file unless a pair).
  std::string path = given, data_path = given;
  if (pair) {
    auto files = PairFiles(given, options);
    if (!files.ok()) return files.status();
    std::tie(path, data_path) = *files;
  }
  absl::StatusOr<bool> gzipped = vi::IsGzipFile(path, options);
  if (!gzipped.ok()) return gzipped.status();

  unsigned char bytes[kHeaderBytes];
  std::unique_ptr<vi::CompressedFileReader> gz;
  if (*gzipped) {
    absl::StatusOr<std::unique_ptr<vi::CompressedFileReader>> reader =
        vi::CompressedFileReader::Open(path, 0, options);
    if (!reader.ok()) return reader.status();
    gz = *std::move(reader);
    absl::Status status = gz->Read(bytes, kHeaderBytes);
    if (!status.ok()) {
      return absl::Status(status.code(), absl::StrCat(status.message(), "; expected a ",
                                                      kHeaderBytes, "-byte NIfTI-1 header"));
    }
  } else {
    absl::StatusOr<std::string> prefix = vi::ReadPrefix(path, kHeaderBytes, options);
    if (!prefix.ok()) return prefix.status();
    if (prefix->size() < kHeaderBytes) {
      return Error(path, absl::StrCat("file holds ", prefix->size(), " bytes, less than the ",
                                      kHeaderBytes, "-byte NIfTI-1 header (truncated header)"));
    }
    std::memcpy(bytes, prefix->data(), kHeaderBytes);
  }

  absl::StatusOr<Header> header = ParseHeader(path, bytes, pair);
  if (!header.ok()) return header.status();
  absl::StatusOr<uint64_t> data_bytes =
      vi::CheckedDataBytes(path, header->dims, header->type, options);
  if (!data_bytes.ok()) return data_bytes.status();
  const std::string layout = vi::DescribeLayout(header->dims, header->type);

  Volume volume;
  volume.dims = {static_cast<int>(header->dims[0]), static_cast<int>(header->dims[1]),
                 static_cast<int>(header->dims[2])};
  volume.spacing = header->spacing;
  volume.source_type = header->type;
  const uint64_t count = volume.VoxelCount();

  // A pair's samples are in a file of their own, from vox_offset.
  const uint64_t skip = pair ? header->vox_offset : header->vox_offset - kHeaderBytes;
  if (pair) {
    gz.reset();
    absl::StatusOr<bool> data_gzipped = vi::IsGzipFile(data_path, options);
    if (!data_gzipped.ok()) return data_gzipped.status();
    if (*data_gzipped) {
      auto reader = vi::CompressedFileReader::Open(data_path, 0, options);
      if (!reader.ok()) return reader.status();
      gz = *std::move(reader);
    }
  }
  if (gz != nullptr) {
    absl::Status status = gz->Skip(skip);
    if (status.ok()) {
      status = vi::ReadSamples([&](unsigned char* dst, size_t n) { return gz->Read(dst, n); },
                               count, header->type, header->order, &volume.values);
    }
    if (status.ok()) status = gz->SkipToEnd(kMaxTrailingBytes).status();
    if (!status.ok()) {
      return absl::Status(status.code(), absl::StrCat(status.message(), "; header says ", layout,
                                                      " at offset ", header->vox_offset));
    }
  } else {
    absl::StatusOr<uint64_t> file_size = vi::FileSize(data_path, options);
    if (!file_size.ok()) return file_size.status();
    const uint64_t available =
        *file_size > header->vox_offset ? *file_size - header->vox_offset : 0;
    if (available < *data_bytes) {
      return Error(data_path, absl::StrCat("header says ", layout, " at offset ",
                                           header->vox_offset, ", file holds ", available));
    }
    absl::Status status = vi::ReadRawSamples(data_path, header->vox_offset, count, header->type,
                                             header->order, &volume.values, options);
    if (!status.ok()) return status;
  }
  ApplyScaling(header->slope, header->inter, &volume.values);
  if (header->axes) {
    // RAS to LPS.
    auto to_lps = [](std::array<std::array<double, 3>, 3> axes, std::array<double, 3>* origin) {
      for (auto& axis : axes) {
        axis[0] = -axis[0];
        axis[1] = -axis[1];
      }
      (*origin)[0] = -(*origin)[0];
      (*origin)[1] = -(*origin)[1];
      return axes;
    };
    std::array<double, 3> origin = header->origin;
    absl::Status s = SetOrientation(path, to_lps(*header->axes, &origin), origin, &volume);
    if (!s.ok() && header->qform_axes && header->axes != header->qform_axes) {
      // A sheared sform: the qform is the scanner's rigid placement.
      origin = header->qform_origin;
      s = SetOrientation(path, to_lps(*header->qform_axes, &origin), origin, &volume);
    }
    if (!s.ok()) return s;
  }
  return volume;
}

}  // namespace transtick
