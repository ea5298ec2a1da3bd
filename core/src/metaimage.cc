// MetaImage reader (ITK's MetaIO: .mha with the data attached, .mhd with the
// data in another file), written by hand: the header is a few text lines, and
// the one library that reads it (ITK) is far too heavy to bring in for them.
//
// Layout: "Key = Value" lines, in any order, ending with ElementDataFile
// (the last line of the header); with "ElementDataFile = LOCAL" the samples
// follow that line at once. Keys read (case as MetaIO writes them; others
// are ignored):
//   ObjectType = Image           optional; anything else is refused
//   NDims = 3                    3, or 4 with a last DimSize of 1
//   DimSize = nx ny nz
//   ElementType = MET_UCHAR | MET_CHAR | MET_USHORT | MET_SHORT | MET_UINT |
//                 MET_INT | MET_FLOAT
//   ElementNumberOfChannels = 1  optional
//   ElementSpacing = sx sy sz    (or ElementSize); default 1 1 1
//   BinaryData = True            ASCII data is refused
//   BinaryDataByteOrderMSB = False (or ElementByteOrderMSB); default False
//   CompressedData = True|False  True: a zlib stream (CompressedDataSize is
//                                then not needed: the stream says where it ends)
//   HeaderSize = n               bytes to skip in the data file; -1: the data
//                                are the file's last bytes
//   TransformMatrix = 9 numbers  (or Rotation, Orientation) each index
//                                axis's direction, x axis first, in LPS
//   Offset = x y z               (or Position, Origin) sample (0,0,0), LPS
//   ElementDataFile = LOCAL | a single file, relative to the header
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "transtick/orientation.h"
#include "transtick/volume_io.h"
#include "volume_io_internal.h"

namespace transtick {
namespace {

namespace vi = volume_io_internal;

constexpr uint64_t kMaxHeaderBytes = uint64_t{1} << 20;

absl::Status Error(const std::string& path, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

absl::StatusOr<bool> Boolean(const std::string& path, const std::string& key,
                             const std::string& value) {
  const std::string v = absl::AsciiStrToLower(value);
  if (v == "true" || v == "1") return true;
  if (v == "false" || v == "0") return false;
  return Error(path, absl::StrCat(key, ": '", value, "' is neither True nor False"));
}

absl::StatusOr<ScalarType> ElementType(const std::string& path, const std::string& value) {
  static const std::map<std::string, ScalarType> kTypes = {
      {"MET_UCHAR", ScalarType::kUint8},   {"MET_CHAR", ScalarType::kInt8},
      {"MET_USHORT", ScalarType::kUint16}, {"MET_SHORT", ScalarType::kInt16},
      {"MET_UINT", ScalarType::kUint32},   {"MET_INT", ScalarType::kInt32},
      {"MET_FLOAT", ScalarType::kFloat32}, {"MET_DOUBLE", ScalarType::kFloat64}};
  auto it = kTypes.find(value);
  if (it == kTypes.end()) {
    return Error(path,
                 absl::StrCat("ElementType '", value,
                              "' is not supported (supported: MET_UCHAR, MET_CHAR, "
                              "MET_USHORT, MET_SHORT, MET_UINT, MET_INT, MET_FLOAT, MET_DOUBLE)"));
  }
  return it->second;
}

}  // namespace

absl::StatusOr<Volume> ReadMetaImage(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<std::string> prefix = vi::ReadPrefix(path, kMaxHeaderBytes, options);
  if (!prefix.ok()) return prefix.status();
  const std::string& text = *prefix;

  // Header lines up to and including ElementDataFile.
  std::map<std::string, std::string> fields;
  std::optional<uint64_t> data_offset;
  size_t pos = 0;
  int line_number = 0;
  while (pos < text.size() && !data_offset) {
    size_t newline = text.find('\n', pos);
    if (newline == std::string::npos) break;
    absl::string_view line(text.data() + pos, newline - pos);
    pos = newline + 1;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (absl::StripAsciiWhitespace(line).empty()) continue;
    size_t eq = line.find('=');
    if (eq == absl::string_view::npos) {
      return Error(path, absl::StrCat("header line ", line_number, " '",
                                      line.substr(0, std::min<size_t>(line.size(), 80)),
                                      "' is not 'Key = Value'",
                                      line_number == 1 ? " (not a MetaImage file?)" : ""));
    }
    std::string key(absl::StripAsciiWhitespace(line.substr(0, eq)));
    std::string value(absl::StripAsciiWhitespace(line.substr(eq + 1)));
    if (!fields.emplace(key, value).second) {
      return Error(path, absl::StrCat("key '", key, "' appears twice"));
    }
    if (key == "ElementDataFile") data_offset = pos;
  }
  if (!data_offset) {
    return Error(path, "header has no ElementDataFile line (not a MetaImage file, or truncated)");
  }
  auto find = [&](std::initializer_list<const char*> keys) -> const std::string* {
    for (const char* k : keys) {
      auto it = fields.find(k);
      if (it != fields.end()) return &it->second;
    }
    return nullptr;
  };
  auto missing = [&](const char* key) {
    return Error(path, absl::StrCat("header has no '", key, "' key"));
  };

  if (const std::string* t = find({"ObjectType"}); t && absl::AsciiStrToLower(*t) != "image") {
    return Error(path, absl::StrCat("ObjectType '", *t, "' is not Image"));
  }
  const std::string* ndims_text = find({"NDims"});
  if (!ndims_text) return missing("NDims");
  int ndims = 0;
  if (!absl::SimpleAtoi(*ndims_text, &ndims) || (ndims != 3 && ndims != 4)) {
    return Error(path, absl::StrCat("NDims '", *ndims_text, "': only 3-D images are supported"));
  }
  const std::string* dim_text = find({"DimSize"});
  if (!dim_text) return missing("DimSize");
  std::array<int64_t, 3> dims;
  {
    std::vector<absl::string_view> t = absl::StrSplit(*dim_text, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    if (t.size() != static_cast<size_t>(ndims)) {
      return Error(path, absl::StrCat("DimSize: expected ", ndims, " sizes, got ", t.size()));
    }
    for (size_t i = 0; i < t.size(); ++i) {
      int64_t v = 0;
      if (!absl::SimpleAtoi(t[i], &v)) {
        return Error(path, absl::StrCat("DimSize: '", t[i], "' is not an integer"));
      }
      if (i < 3) {
        dims[i] = v;
      } else if (v != 1) {
        return Error(path, absl::StrCat("DimSize: a 4th size of ", v,
                                        ": only 3-D images (one time point) are supported"));
      }
    }
  }
  const std::string* type_text = find({"ElementType"});
  if (!type_text) return missing("ElementType");
  absl::StatusOr<ScalarType> type = ElementType(path, *type_text);
  if (!type.ok()) return type.status();
  if (const std::string* c = find({"ElementNumberOfChannels"}); c && *c != "1") {
    return Error(path, absl::StrCat("ElementNumberOfChannels ", *c,
                                    ": only scalar images (1 channel) are supported"));
  }
  if (const std::string* b = find({"BinaryData"})) {
    absl::StatusOr<bool> binary = Boolean(path, "BinaryData", *b);
    if (!binary.ok()) return binary.status();
    if (!*binary) return Error(path, "BinaryData False (ASCII samples) is not supported");
  }
  ByteOrder order = ByteOrder::kLittle;
  if (const std::string* m = find({"BinaryDataByteOrderMSB", "ElementByteOrderMSB"})) {
    absl::StatusOr<bool> msb = Boolean(path, "BinaryDataByteOrderMSB", *m);
    if (!msb.ok()) return msb.status();
    order = *msb ? ByteOrder::kBig : ByteOrder::kLittle;
  }
  bool compressed = false;
  if (const std::string* c = find({"CompressedData"})) {
    absl::StatusOr<bool> v = Boolean(path, "CompressedData", *c);
    if (!v.ok()) return v.status();
    compressed = *v;
  }
  std::array<double, 3> spacing = {1, 1, 1};
  if (const std::string* s = find({"ElementSpacing", "ElementSize"})) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "ElementSpacing", *s, ndims);
    if (!v.ok()) return v.status();
    for (int i = 0; i < 3; ++i) {
      if (!((*v)[i] > 0)) {
        return Error(path, absl::StrCat("ElementSpacing: spacing ", (*v)[i],
                                        " is not a positive number"));
      }
      spacing[i] = (*v)[i];
    }
  }
  std::optional<std::array<std::array<double, 3>, 3>> axes;
  if (const std::string* m = find({"TransformMatrix", "Rotation", "Orientation"})) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "TransformMatrix", *m, ndims * ndims);
    if (!v.ok()) return v.status();
    std::array<std::array<double, 3>, 3> a;
    for (int i = 0; i < 3; ++i) {
      for (int w = 0; w < 3; ++w) a[i][w] = (*v)[i * ndims + w];
    }
    axes = a;
  }
  std::array<double, 3> origin = {0, 0, 0};
  if (const std::string* o = find({"Offset", "Position", "Origin"})) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "Offset", *o, ndims);
    if (!v.ok()) return v.status();
    origin = {(*v)[0], (*v)[1], (*v)[2]};
  }
  int64_t header_size = 0;
  if (const std::string* h = find({"HeaderSize"})) {
    if (!absl::SimpleAtoi(*h, &header_size) || header_size < -1) {
      return Error(path, absl::StrCat("HeaderSize '", *h, "' is not a byte count or -1"));
    }
    if (header_size == -1 && compressed) {
      return Error(path, "HeaderSize -1 is only allowed for uncompressed data");
    }
  }

  const std::string& data_file = fields["ElementDataFile"];
  std::string data_path = path;
  uint64_t offset = *data_offset;
  if (data_file != "LOCAL" && data_file != "Local" && data_file != "local") {
    if (data_file.empty() || absl::StartsWith(data_file, "LIST") ||
        absl::StrContains(data_file, '%') || absl::StrContains(data_file, ' ')) {
      return Error(path, absl::StrCat("ElementDataFile '", data_file,
                                      "': only LOCAL or a single data file is supported"));
    }
    data_path = data_file.front() == '/' ? data_file : absl::StrCat(vi::DirectoryOf(path), data_file);
    offset = 0;
  }

  absl::StatusOr<uint64_t> data_bytes = vi::CheckedDataBytes(path, dims, *type, options);
  if (!data_bytes.ok()) return data_bytes.status();
  const std::string layout = vi::DescribeLayout(dims, *type);
  const std::string where = data_path == path ? "file" : absl::StrCat("data file ", data_path);

  Volume volume;
  volume.dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};
  volume.spacing = spacing;
  volume.source_type = *type;
  const uint64_t count = volume.VoxelCount();

  if (!compressed) {
    absl::StatusOr<uint64_t> size = vi::FileSize(data_path, options);
    if (!size.ok()) return size.status();
    uint64_t start = 0;
    if (header_size == -1) {
      if (*size < offset || *size - offset < *data_bytes) {
        return Error(path, absl::StrCat("header says ", layout, ", ", where, " holds ",
                                        *size < offset ? 0 : *size - offset));
      }
      start = *size - *data_bytes;
    } else if (!vi::CheckedAdd(offset, static_cast<uint64_t>(header_size), &start)) {
      return Error(path, "HeaderSize is too large");
    }
    const uint64_t available = *size > start ? *size - start : 0;
    if (available != *data_bytes) {
      return Error(path, absl::StrCat("header says ", layout, ", ", where, " holds ", available));
    }
    absl::Status s = vi::ReadRawSamples(data_path, start, count, *type, order, &volume.values, options);
    if (!s.ok()) return s;
  } else {
    uint64_t start = 0;
    if (!vi::CheckedAdd(offset, static_cast<uint64_t>(header_size), &start)) {
      return Error(path, "HeaderSize is too large");
    }
    absl::StatusOr<std::unique_ptr<vi::CompressedFileReader>> reader =
        vi::CompressedFileReader::Open(data_path, start, options);
    if (!reader.ok()) return reader.status();
    vi::CompressedFileReader& gz = **reader;
    absl::Status s = vi::ReadSamples([&gz](unsigned char* dst, size_t n) { return gz.Read(dst, n); },
                                     count, *type, order, &volume.values);
    absl::StatusOr<bool> at_end = s.ok() ? gz.AtEnd() : absl::StatusOr<bool>(s);
    if (!at_end.ok()) {
      return absl::Status(at_end.status().code(),
                          absl::StrCat(at_end.status().message(), "; header says ", layout));
    }
    if (!*at_end) {
      return Error(path, absl::StrCat("header says ", layout, ", compressed data in ", where,
                                      " holds more"));
    }
  }
  if (axes) {
    if (absl::Status s = SetOrientation(path, *axes, origin, &volume); !s.ok()) return s;
  } else {
    volume.origin = origin;
  }
  return volume;
}

}  // namespace transtick
