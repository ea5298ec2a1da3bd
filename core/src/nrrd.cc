// NRRD reader (http://teem.sourceforge.net/nrrd/format.html), the subset a
// volume renderer needs.
//
// Layout of a file:
//   "NRRD000N"                magic line, N = format version (1..5)
//   "# anything"              comment lines, anywhere in the header
//   "field: value"            fields, in any order, each at most once
//   "key:=value"              key/value pairs, ignored
//   ""                        a blank line ends an attached header; the data
//                             follows immediately. A detached header (.nhdr)
//                             names its data with "data file:" and may simply
//                             end at end of file.
// Fields read: type, dimension (must be 3), sizes, encoding (raw, gzip/gz,
// bzip2/bz2, ascii/text/txt: numbers separated by white space), endian
// (needed for binary samples wider than a byte), spacings or space directions
// (the length of each direction vector is the spacing), byte skip (>= 0, or
// -1 for raw data: "the data are the last bytes of the file"), line skip, data
// file (a single file, relative to the header's directory), and for the
// orientation space (or space dimension: 3), space directions (three 3-vectors:
// each index axis's step in space) and space origin. Other fields (kinds,
// labels, ...) are accepted and ignored.
//
// Orientation: with three 3-component space directions, the volume's
// direction and origin are set from them (orientation.h). The space is
// converted to LPS: right-anterior-superior (RAS) negates x and y,
// left-anterior-superior (LAS) y, right-posterior-superior (RPS) x; LPS,
// scanner-xyz, 3D-right-handed and a bare space dimension are taken as LPS
// already. Left-handed spaces (3D-left-handed, ...-time) are refused. Without
// space directions (spacings only) the direction is the identity.
//
// Line skip counts lines of the data file before decompression; byte skip
// counts bytes after decompression, as teem does.
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
#include "absl/strings/string_view.h"
#include "transtick/orientation.h"
#include "transtick/volume_io.h"
#include "volume_io_internal.h"

namespace transtick {
namespace {

namespace vi = volume_io_internal;

// A header longer than this is not a header we want to parse; it also bounds
// how much a file without a blank line costs to reject.
constexpr uint64_t kMaxHeaderBytes = uint64_t{1} << 20;

enum class Encoding { kRaw, kGzip, kBzip2, kAscii };

struct Field {
  std::string value;
  int line = 0;
};

absl::Status Error(const std::string& path, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

// Keeps the code of `status` and adds context to its message.
absl::Status Annotate(const absl::Status& status, absl::string_view context) {
  return absl::Status(status.code(), absl::StrCat(status.message(), "; ", context));
}

std::string CanonicalKey(absl::string_view raw) {
  std::string key = absl::AsciiStrToLower(absl::StripAsciiWhitespace(raw));
  if (key == "datafile") return "data file";
  if (key == "byteskip") return "byte skip";
  if (key == "lineskip") return "line skip";
  return key;
}

std::vector<absl::string_view> Tokens(absl::string_view value) {
  return absl::StrSplit(value, absl::ByAnyChar(" \t\r\n\v\f"), absl::SkipEmpty());
}

// NaN means "unknown" in NRRD: use 1. The sign only says which way an axis
// runs, which a renderer of index-aligned volumes does not track.
absl::StatusOr<double> CleanSpacing(const std::string& path, absl::string_view field, double s) {
  if (std::isnan(s)) return 1.0;
  s = std::fabs(s);
  if (!(s > 0.0) || !std::isfinite(s)) {
    return Error(path, absl::StrCat(field, ": spacing ", s, " is not a positive finite number"));
  }
  return s;
}

struct SpaceDirections {
  std::array<double, 3> lengths;
  // Each axis's vector when all three have three components.
  std::optional<std::array<std::array<double, 3>, 3>> vectors;
};

// "(x,y,z)" of space origin.
absl::StatusOr<std::array<double, 3>> ParseVector(const std::string& path, absl::string_view field,
                                                  absl::string_view value) {
  value = absl::StripAsciiWhitespace(value);
  if (value.size() < 2 || value.front() != '(' || value.back() != ')') {
    return Error(path, absl::StrCat(field, ": '", value, "' is not an (x,y,z) vector"));
  }
  std::vector<absl::string_view> parts = absl::StrSplit(value.substr(1, value.size() - 2), ',');
  if (parts.size() != 3) {
    return Error(path, absl::StrCat(field, ": vector with ", parts.size(),
                                    " components, expected 3"));
  }
  std::array<double, 3> v;
  for (int i = 0; i < 3; ++i) {
    if (!absl::SimpleAtod(absl::StripAsciiWhitespace(parts[i]), &v[i]) || !std::isfinite(v[i])) {
      return Error(path, absl::StrCat(field, ": '", parts[i], "' is not a finite number"));
    }
  }
  return v;
}

// The signs that take a NRRD space's coordinates to LPS, or an error.
absl::StatusOr<std::array<double, 3>> ToLps(const std::string& path, absl::string_view space) {
  const std::string s = absl::AsciiStrToLower(absl::StripAsciiWhitespace(space));
  if (s == "left-posterior-superior" || s == "lps" || s == "scanner-xyz" ||
      s == "3d-right-handed") {
    return std::array<double, 3>{1, 1, 1};
  }
  if (s == "right-anterior-superior" || s == "ras") return std::array<double, 3>{-1, -1, 1};
  if (s == "left-anterior-superior" || s == "las") return std::array<double, 3>{1, -1, 1};
  if (s == "right-posterior-superior" || s == "rps") return std::array<double, 3>{-1, 1, 1};
  return Error(path, absl::StrCat("space '", space,
                                  "' is not supported (supported: left-posterior-superior, "
                                  "right-anterior-superior, left-anterior-superior, "
                                  "right-posterior-superior, scanner-xyz, 3D-right-handed)"));
}

// "(1,0,0) (0,1,0) (0,0,2)" or with "none" for non-spatial axes.
absl::StatusOr<SpaceDirections> ParseSpaceDirections(const std::string& path,
                                                     absl::string_view value) {
  std::vector<double> lengths;
  std::vector<std::array<double, 3>> vectors;
  size_t i = 0;
  while (i < value.size()) {
    if (absl::ascii_isspace(static_cast<unsigned char>(value[i]))) {
      ++i;
    } else if (absl::StartsWith(value.substr(i), "none")) {
      lengths.push_back(1.0);
      i += 4;
    } else if (value[i] == '(') {
      size_t close = value.find(')', i);
      if (close == absl::string_view::npos) {
        return Error(path, "space directions: '(' without ')'");
      }
      double sum = 0.0;
      int components = 0;
      std::array<double, 3> vector = {0, 0, 0};
      for (absl::string_view part : absl::StrSplit(value.substr(i + 1, close - i - 1), ',')) {
        double c = 0.0;
        if (!absl::SimpleAtod(absl::StripAsciiWhitespace(part), &c)) {
          return Error(path, absl::StrCat("space directions: '", part, "' is not a number"));
        }
        sum += c * c;
        if (components < 3) vector[components] = c;
        ++components;
      }
      if (components == 3) vectors.push_back(vector);
      if (components < 1 || components > 3) {
        return Error(path, absl::StrCat("space directions: vector with ", components,
                                        " components, expected 1 to 3"));
      }
      absl::StatusOr<double> s = CleanSpacing(path, "space directions", std::sqrt(sum));
      if (!s.ok()) return s.status();
      lengths.push_back(*s);
      i = close + 1;
    } else {
      return Error(path, absl::StrCat("space directions: unexpected text '", value.substr(i),
                                      "', expected (x,y,z) vectors or none"));
    }
  }
  if (lengths.size() != 3) {
    return Error(path, absl::StrCat("space directions: expected 3 vectors, got ", lengths.size()));
  }
  SpaceDirections out;
  out.lengths = {lengths[0], lengths[1], lengths[2]};
  if (vectors.size() == 3) out.vectors = {vectors[0], vectors[1], vectors[2]};
  return out;
}

absl::StatusOr<int64_t> ParseInteger(const std::string& path, absl::string_view field,
                                     absl::string_view text) {
  int64_t v = 0;
  if (!absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &v)) {
    return Error(path, absl::StrCat(field, ": '", text, "' is not an integer"));
  }
  return v;
}

}  // namespace

absl::StatusOr<Volume> ReadNrrd(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<std::string> prefix = vi::ReadPrefix(path, kMaxHeaderBytes, options);
  if (!prefix.ok()) return prefix.status();
  absl::StatusOr<uint64_t> file_size = vi::FileSize(path, options);
  if (!file_size.ok()) return file_size.status();
  const std::string& text = *prefix;

  if (!absl::StartsWith(text, "NRRD000") || text.size() < 8 ||
      !absl::ascii_isdigit(static_cast<unsigned char>(text[7]))) {
    return Error(path, "not a NRRD file (does not start with NRRD000N)");
  }

  // Split the header into fields, remembering where the data begins.
  std::map<std::string, Field> fields;
  std::optional<uint64_t> data_offset;  // set when a blank line ends the header
  size_t pos = 0;
  int line_number = 0;
  while (pos < text.size()) {
    size_t newline = text.find('\n', pos);
    const bool complete = newline != std::string::npos;
    size_t end = complete ? newline : text.size();
    absl::string_view line(text.data() + pos, end - pos);
    pos = complete ? newline + 1 : text.size();
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_number == 1) continue;  // the magic
    if (line.empty() && complete) {
      data_offset = pos;
      break;
    }
    if (!complete && text.size() == kMaxHeaderBytes && *file_size > kMaxHeaderBytes) {
      return Error(path, absl::StrCat("header longer than ", kMaxHeaderBytes,
                                      " bytes (or the blank line ending it is missing)"));
    }
    if (line.empty() || line.front() == '#') continue;
    size_t colon = line.find(':');
    if (colon == absl::string_view::npos) {
      return Error(path,
                   absl::StrCat("header line ", line_number, " '", line, "' is not 'field: value'",
                                complete ? "" : " (header truncated?)"));
    }
    if (colon + 1 < line.size() && line[colon + 1] == '=') continue;  // key:=value
    std::string key = CanonicalKey(line.substr(0, colon));
    Field field{std::string(absl::StripAsciiWhitespace(line.substr(colon + 1))), line_number};
    auto [it, inserted] = fields.emplace(key, field);
    if (!inserted) {
      return Error(path, absl::StrCat("field '", key, "' appears twice (lines ", it->second.line,
                                      " and ", line_number, ")"));
    }
  }

  // An attached header cut short is the likeliest cause of what would
  // otherwise surface as a missing or malformed field: say so first.
  if (!data_offset.has_value() && fields.find("data file") == fields.end()) {
    return Error(path, "header does not end with a blank line and names no data file (truncated?)");
  }

  auto find = [&](const char* key) -> const std::string* {
    auto it = fields.find(key);
    return it == fields.end() ? nullptr : &it->second.value;
  };
  auto missing = [&](const char* key) {
    return Error(path, absl::StrCat("header has no '", key, "' field"));
  };

  // type
  const std::string* type_text = find("type");
  if (type_text == nullptr) return missing("type");
  absl::StatusOr<ScalarType> type = ParseScalarType(*type_text);
  if (!type.ok()) return Error(path, type.status().message());

  // dimension and sizes
  const std::string* dimension_text = find("dimension");
  if (dimension_text == nullptr) return missing("dimension");
  absl::StatusOr<int64_t> dimension = ParseInteger(path, "dimension", *dimension_text);
  if (!dimension.ok()) return dimension.status();
  if (*dimension != 3) {
    return Error(path, absl::StrCat("dimension ", *dimension,
                                    ": only 3-D volumes (dimension 3) are supported"));
  }
  const std::string* sizes_text = find("sizes");
  if (sizes_text == nullptr) return missing("sizes");
  std::vector<absl::string_view> size_tokens = Tokens(*sizes_text);
  if (size_tokens.size() != 3) {
    return Error(
        path, absl::StrCat("sizes: expected 3 values for dimension 3, got ", size_tokens.size()));
  }
  std::array<int64_t, 3> dims;
  for (int i = 0; i < 3; ++i) {
    absl::StatusOr<int64_t> v = ParseInteger(path, "sizes", size_tokens[i]);
    if (!v.ok()) return v.status();
    dims[i] = *v;
  }

  // encoding and endian
  const std::string* encoding_text = find("encoding");
  if (encoding_text == nullptr) return missing("encoding");
  Encoding encoding;
  std::string encoding_name = absl::AsciiStrToLower(*encoding_text);
  if (encoding_name == "raw") {
    encoding = Encoding::kRaw;
  } else if (encoding_name == "gzip" || encoding_name == "gz") {
    encoding = Encoding::kGzip;
  } else if (encoding_name == "bzip2" || encoding_name == "bz2") {
    encoding = Encoding::kBzip2;
  } else if (encoding_name == "ascii" || encoding_name == "text" || encoding_name == "txt") {
    encoding = Encoding::kAscii;
  } else {
    return Error(path, absl::StrCat("unsupported encoding '", *encoding_text,
                                    "' (supported: raw, gzip, bzip2, ascii)"));
  }
  ByteOrder order = ByteOrder::kLittle;
  if (ScalarTypeSize(*type) > 1 && encoding != Encoding::kAscii) {
    const std::string* endian_text = find("endian");
    if (endian_text == nullptr) return missing("endian");
    std::string endian = absl::AsciiStrToLower(*endian_text);
    if (endian == "little") {
      order = ByteOrder::kLittle;
    } else if (endian == "big") {
      order = ByteOrder::kBig;
    } else {
      return Error(path, absl::StrCat("endian '", *endian_text, "' is neither 'little' nor 'big'"));
    }
  }

  // spacing: space directions win over spacings, as they carry more.
  std::array<double, 3> spacing = {1.0, 1.0, 1.0};
  std::optional<std::array<std::array<double, 3>, 3>> axes;
  std::array<double, 3> origin = {0, 0, 0};
  if (const std::string* directions = find("space directions")) {
    absl::StatusOr<SpaceDirections> parsed = ParseSpaceDirections(path, *directions);
    if (!parsed.ok()) return parsed.status();
    spacing = parsed->lengths;
    axes = parsed->vectors;
    std::array<double, 3> to_lps = {1, 1, 1};
    if (const std::string* space = find("space")) {
      absl::StatusOr<std::array<double, 3>> signs = ToLps(path, *space);
      if (!signs.ok()) return signs.status();
      to_lps = *signs;
    }
    if (const std::string* o = find("space origin")) {
      absl::StatusOr<std::array<double, 3>> parsed_origin = ParseVector(path, "space origin", *o);
      if (!parsed_origin.ok()) return parsed_origin.status();
      origin = *parsed_origin;
    }
    for (int w = 0; w < 3; ++w) {
      origin[w] *= to_lps[w];
      if (axes) {
        for (auto& axis : *axes) axis[w] *= to_lps[w];
      }
    }
  } else if (const std::string* spacings = find("spacings")) {
    std::vector<absl::string_view> tokens = Tokens(*spacings);
    if (tokens.size() != 3) {
      return Error(path, absl::StrCat("spacings: expected 3 values, got ", tokens.size()));
    }
    for (int i = 0; i < 3; ++i) {
      double s = 0.0;
      if (!absl::SimpleAtod(tokens[i], &s)) {
        return Error(path, absl::StrCat("spacings: '", tokens[i], "' is not a number"));
      }
      absl::StatusOr<double> clean = CleanSpacing(path, "spacings", s);
      if (!clean.ok()) return clean.status();
      spacing[i] = *clean;
    }
  }

  // skips
  int64_t byte_skip = 0;
  if (const std::string* t = find("byte skip")) {
    absl::StatusOr<int64_t> v = ParseInteger(path, "byte skip", *t);
    if (!v.ok()) return v.status();
    byte_skip = *v;
    if (byte_skip < -1) {
      return Error(path,
                   absl::StrCat("byte skip ", byte_skip, " is negative (only -1 is allowed)"));
    }
    if (byte_skip == -1 && encoding != Encoding::kRaw) {
      return Error(path, "byte skip -1 is only allowed with raw encoding");
    }
    if (byte_skip != 0 && encoding == Encoding::kAscii) {
      return Error(path, "byte skip is not allowed with ascii encoding (line skip is)");
    }
  }
  int64_t line_skip = 0;
  if (const std::string* t = find("line skip")) {
    absl::StatusOr<int64_t> v = ParseInteger(path, "line skip", *t);
    if (!v.ok()) return v.status();
    line_skip = *v;
    if (line_skip < 0) {
      return Error(path, absl::StrCat("line skip ", line_skip, " is negative"));
    }
  }

  // Where the data is: another file, or after the blank line of this one.
  std::string data_path = path;
  uint64_t offset = 0;
  if (const std::string* data_file = find("data file")) {
    if (data_file->empty() || *data_file == "LIST" || absl::StrContains(*data_file, '%')) {
      return Error(
          path, absl::StrCat("data file '", *data_file, "': only a single data file is supported"));
    }
    data_path =
        data_file->front() == '/' ? *data_file : absl::StrCat(vi::DirectoryOf(path), *data_file);
  } else {
    offset = *data_offset;  // present: checked above
  }

  // Sizes are checked (and max_bytes enforced) before anything is allocated.
  absl::StatusOr<uint64_t> data_bytes = vi::CheckedDataBytes(path, dims, *type, options);
  if (!data_bytes.ok()) return data_bytes.status();
  const std::string layout = vi::DescribeLayout(dims, *type);
  const std::string where = data_path == path ? "file" : absl::StrCat("data file ", data_path);

  absl::StatusOr<uint64_t> after_lines =
      vi::SkipLines(data_path, offset, static_cast<uint64_t>(line_skip), options);
  if (!after_lines.ok()) return after_lines.status();
  offset = *after_lines;

  Volume volume;
  volume.dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};
  volume.spacing = spacing;
  volume.source_type = *type;
  const uint64_t count = volume.VoxelCount();

  if (encoding == Encoding::kRaw) {
    absl::StatusOr<uint64_t> data_size = vi::FileSize(data_path, options);
    if (!data_size.ok()) return data_size.status();
    uint64_t start = 0;
    if (byte_skip == -1) {
      if (*data_size < offset || *data_size - offset < *data_bytes) {
        return Error(path, absl::StrCat("header says ", layout, ", ", where, " holds ",
                                        *data_size < offset ? 0 : *data_size - offset));
      }
      start = *data_size - *data_bytes;
    } else if (!vi::CheckedAdd(offset, static_cast<uint64_t>(byte_skip), &start)) {
      return Error(path, absl::StrCat("byte skip ", byte_skip, " is too large"));
    }
    const uint64_t available = *data_size > start ? *data_size - start : 0;
    if (available != *data_bytes) {
      return Error(path, absl::StrCat("header says ", layout, ", ", where, " holds ", available));
    }
    absl::Status status = vi::ReadRawSamples(data_path, start, count, *type, order, &volume.values, options);
    if (!status.ok()) return status;
    if (axes) {
      if (absl::Status s = SetOrientation(path, *axes, origin, &volume); !s.ok()) return s;
    }
    return volume;
  }

  if (encoding == Encoding::kAscii) {
    absl::StatusOr<vi::FilePtr> file = vi::OpenFile(data_path, options);
    if (!file.ok()) return file.status();
    if (::fseeko(file->get(), static_cast<off_t>(offset), SEEK_SET) != 0) {
      return Error(path, absl::StrCat("seek in ", where, " failed"));
    }
    if (absl::Status s = vi::ReadAsciiSamples(data_path, file->get(), count, false, &volume.values);
        !s.ok()) {
      return s;
    }
    if (axes) {
      if (absl::Status s = SetOrientation(path, *axes, origin, &volume); !s.ok()) return s;
    }
    return volume;
  }

  const bool bzip2 = encoding == Encoding::kBzip2;
  absl::StatusOr<std::unique_ptr<vi::CompressedFileReader>> reader = vi::CompressedFileReader::Open(
      data_path, offset, options,
      bzip2 ? vi::CompressedFileReader::Codec::kBzip2 : vi::CompressedFileReader::Codec::kGzip);
  if (!reader.ok()) return reader.status();
  vi::CompressedFileReader& gz = **reader;
  const std::string context = absl::StrCat(
      "header says ", layout,
      byte_skip > 0 ? absl::StrCat(" after a byte skip of ", byte_skip) : std::string());
  absl::Status status = gz.Skip(static_cast<uint64_t>(byte_skip));
  if (status.ok()) {
    status = vi::ReadSamples([&gz](unsigned char* dst, size_t n) { return gz.Read(dst, n); }, count,
                             *type, order, &volume.values);
  }
  if (!status.ok()) return Annotate(status, context);
  absl::StatusOr<bool> at_end = gz.AtEnd();
  if (!at_end.ok()) return Annotate(at_end.status(), context);
  if (!*at_end) {
    return Error(path, absl::StrCat(context, bzip2 ? ", bzip2" : ", gzip", " data in ", where,
                                    " holds more"));
  }
  if (axes) {
    if (absl::Status s = SetOrientation(path, *axes, origin, &volume); !s.ok()) return s;
  }
  return volume;
}

}  // namespace transtick
