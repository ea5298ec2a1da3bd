// VTK XML image data reader (.vti), written by hand for the subset VTK and
// ParaView write for one scalar volume. VTK itself (libvtk9) would bring a
// large library into the image for one file format; the XML here is a few
// tags before the data.
//
// Accepted:
//   <VTKFile type="ImageData" byte_order="LittleEndian|BigEndian"
//            header_type="UInt32|UInt64"
//            compressor="vtkZLibDataCompressor|vtkLZ4DataCompressor|vtkLZMADataCompressor"?>
//     <ImageData WholeExtent="x0 x1 y0 y1 z0 z1" Origin="x y z"
//                Spacing="sx sy sz" Direction="9 numbers, row-major"?>
//       <Piece Extent="the whole extent">          exactly one piece
//         <PointData Scalars="name"?>
//           <DataArray type="Int8|UInt8|Int16|UInt16|Int32|UInt32|Float32|Float64"
//                      Name="..." NumberOfComponents="1"?
//                      format="appended" offset="n"/>       or
//                      format="binary"> base64 </DataArray>  or
//                      format="ascii"> numbers </DataArray>
//     <AppendedData encoding="raw|base64"> _ then the arrays' bytes
// The array used is the one PointData's Scalars names, else the first.
// Point data: the volume has x1-x0+1 samples along x (likewise y, z).
// Direction's columns are the index axes in world space; world is LPS, as
// VTK does not say otherwise.
//
// An array without compression is a header_type byte count, then the
// bytes. Compressed (vtkZLibDataCompressor, vtkLZ4DataCompressor or
// vtkLZMADataCompressor), it is a header of header_type integers: the
// number of blocks n, the uncompressed block size, the size of the last
// block (0: a full block), and n compressed sizes; then the n compressed
// blocks (a zlib stream, a raw LZ4 block, an .xz stream). In base64
// (appended with encoding="base64", where offsets count characters after
// the '_', or inline with format="binary") the same bytes are encoded; VTK
// encodes the header and the data as separate base64 runs, each with its
// own padding, so the decoder starts afresh after a padded group. ASCII
// arrays are the samples' numbers, separated by white space. Other
// compressors, several pieces and Int64 are refused, each with a clear
// error, and an inline array's tag must lie in the file's first MiB (where
// the tags are read).
#include <lz4.h>
#include <lzma.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
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
// A compressed block larger than this is not one VTK writes (its blocks are
// 32 KiB by default); refusing it bounds the buffer a header can ask for.
constexpr uint64_t kMaxBlockBytes = uint64_t{64} << 20;

absl::Status Error(const std::string& path, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

struct Tag {
  std::string name;
  std::map<std::string, std::string> attributes;
  size_t end = 0;      // just past its '>' in the text it was read from
  bool empty = false;  // <tag ... />: no content
};

// The tags of the XML before the appended data, in order; closing tags and
// the <?xml ?> declaration are left out. Comments are skipped.
absl::StatusOr<std::vector<Tag>> ParseTags(const std::string& path, absl::string_view xml) {
  std::vector<Tag> tags;
  size_t i = 0;
  while ((i = xml.find('<', i)) != absl::string_view::npos) {
    if (absl::StartsWith(xml.substr(i), "<!--")) {
      size_t end = xml.find("-->", i);
      if (end == absl::string_view::npos) return Error(path, "XML comment without its end");
      i = end + 3;
      continue;
    }
    size_t end = xml.find('>', i);
    if (end == absl::string_view::npos) return Error(path, "XML tag without '>' (truncated?)");
    absl::string_view body = xml.substr(i + 1, end - i - 1);
    i = end + 1;
    if (body.empty() || body[0] == '/' || body[0] == '?' || body[0] == '!') continue;
    Tag tag;
    tag.end = i;
    if (body.back() == '/') {
      body.remove_suffix(1);
      tag.empty = true;
    }
    size_t p = 0;
    while (p < body.size() && !absl::ascii_isspace(static_cast<unsigned char>(body[p]))) ++p;
    tag.name = std::string(body.substr(0, p));
    while (p < body.size()) {
      while (p < body.size() && absl::ascii_isspace(static_cast<unsigned char>(body[p]))) ++p;
      if (p >= body.size()) break;
      size_t eq = body.find('=', p);
      if (eq == absl::string_view::npos || eq + 1 >= body.size() ||
          (body[eq + 1] != '"' && body[eq + 1] != '\'')) {
        return Error(path, absl::StrCat("XML tag <", tag.name, ">: malformed attribute"));
      }
      const char quote = body[eq + 1];
      size_t close = body.find(quote, eq + 2);
      if (close == absl::string_view::npos) {
        return Error(path, absl::StrCat("XML tag <", tag.name, ">: unterminated attribute value"));
      }
      tag.attributes[std::string(absl::StripAsciiWhitespace(body.substr(p, eq - p)))] =
          std::string(body.substr(eq + 2, close - eq - 2));
      p = close + 1;
    }
    tags.push_back(std::move(tag));
  }
  return tags;
}

absl::StatusOr<ScalarType> ArrayType(const std::string& path, const std::string& name) {
  static const std::map<std::string, ScalarType> kTypes = {
      {"Int8", ScalarType::kInt8},       {"UInt8", ScalarType::kUint8},
      {"Int16", ScalarType::kInt16},     {"UInt16", ScalarType::kUint16},
      {"Int32", ScalarType::kInt32},     {"UInt32", ScalarType::kUint32},
      {"Float32", ScalarType::kFloat32}, {"Float64", ScalarType::kFloat64}};
  auto it = kTypes.find(name);
  if (it == kTypes.end()) {
    return Error(path, absl::StrCat("DataArray type '", name,
                                    "' is not supported (supported: Int8, UInt8, Int16, UInt16, "
                                    "Int32, UInt32, Float32, Float64)"));
  }
  return it->second;
}

// The bytes of an array, from where they begin in the file: raw, or
// decoded from base64 as they are read.
class ByteSource {
 public:
  ByteSource(const std::string& path, std::FILE* f, bool base64)
      : path_(path), f_(f), base64_(base64) {}

  // Exactly n bytes, or an error naming `what` was cut short.
  absl::Status Read(unsigned char* dst, size_t n, const char* what) {
    if (!base64_) {
      if (std::fread(dst, 1, n, f_) != n) return Short(what);
      return absl::OkStatus();
    }
    while (n > 0) {
      if (out_pos_ == out_len_) {
        if (absl::Status s = DecodeGroup(what); !s.ok()) return s;
        continue;
      }
      const size_t take = std::min(n, out_len_ - out_pos_);
      std::copy_n(out_ + out_pos_, take, dst);
      dst += take;
      out_pos_ += take;
      n -= take;
    }
    return absl::OkStatus();
  }

 private:
  absl::Status Short(const char* what) const {
    return Error(path_, absl::StrCat(base64_ ? "base64 data" : "file", " ends inside the ", what,
                                     " (truncated?)"));
  }

  // The next group of four base64 characters, white space skipped, into
  // one to three bytes; '=' pads a group short, and the next run begins
  // after it. The data ends at '<' (the element's end) or the file's.
  absl::Status DecodeGroup(const char* what) {
    uint32_t bits = 0;
    int chars = 0, pad = 0;
    while (chars + pad < 4) {
      const int c = getc_unlocked(f_);
      if (c == EOF || c == '<') return Short(what);
      if (absl::ascii_isspace(static_cast<unsigned char>(c))) continue;
      if (c == '=') {
        // Padding: at least two characters in the group before it, and
        // nothing but padding after it.
        if (chars < 2) {
          if (chars == 0) continue;  // a stray '=' between runs
          return Error(path_,
                       absl::StrCat("base64 data of the ", what, ": '=' after one character"));
        }
        ++pad;
        continue;
      }
      const int v = Value(c);
      if (v < 0 || pad > 0) {
        return Error(path_, absl::StrCat("base64 data of the ", what, ": character '",
                                         absl::CEscape(std::string(1, static_cast<char>(c))),
                                         "' is not base64"));
      }
      bits = bits << 6 | static_cast<uint32_t>(v);
      ++chars;
    }
    bits <<= 6 * pad;
    out_[0] = static_cast<unsigned char>(bits >> 16);
    out_[1] = static_cast<unsigned char>(bits >> 8);
    out_[2] = static_cast<unsigned char>(bits);
    out_pos_ = 0;
    out_len_ = static_cast<size_t>(chars - 1);  // 4 characters: 3 bytes, 3: 2, 2: 1
    return absl::OkStatus();
  }

  static int Value(int c) {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  }

  const std::string& path_;
  std::FILE* const f_;
  const bool base64_;
  unsigned char out_[3] = {0, 0, 0};
  size_t out_pos_ = 0, out_len_ = 0;
};

enum class Compressor { kNone, kZlib, kLz4, kLzma };

// One compressed block into exactly `want` bytes at `out`: false when it is
// corrupt or holds another number of bytes. zlib: a zlib stream; LZ4: a raw
// LZ4 block (LZ4_compress_fast); LZMA: an .xz stream
// (lzma_easy_buffer_encode), as VTK's compressors write them.
bool Inflate(Compressor compressor, const std::vector<unsigned char>& in, uint64_t want,
             unsigned char* out) {
  switch (compressor) {
    case Compressor::kZlib: {
      uLongf got = static_cast<uLongf>(want);
      return uncompress(out, &got, in.data(), static_cast<uLong>(in.size())) == Z_OK && got == want;
    }
    case Compressor::kLz4: {
      if (in.size() > static_cast<size_t>(INT32_MAX)) return false;  // want <= kMaxBlockBytes
      const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(in.data()),
                                          reinterpret_cast<char*>(out), static_cast<int>(in.size()),
                                          static_cast<int>(want));
      return got >= 0 && static_cast<uint64_t>(got) == want;
    }
    case Compressor::kLzma: {
      // The decoder may use at most this much memory: a stream that asks
      // for more (a dictionary no block of kMaxBlockBytes needs) fails.
      uint64_t memlimit = uint64_t{256} << 20;
      size_t in_pos = 0, out_pos = 0;
      const lzma_ret r = lzma_stream_buffer_decode(&memlimit, 0, nullptr, in.data(), &in_pos,
                                                   in.size(), out, &out_pos, want);
      // All of the block read, and exactly `want` bytes made of it.
      return r == LZMA_OK && in_pos == in.size() && out_pos == want;
    }
    case Compressor::kNone:
      break;
  }
  return false;
}

// The volume placed as the file says.
absl::StatusOr<Volume> Finish(const std::string& path, bool oriented,
                              const std::array<std::array<double, 3>, 3>& axes,
                              const std::array<double, 3>& origin, Volume volume) {
  if (oriented) {
    if (absl::Status s = SetOrientation(path, axes, origin, &volume); !s.ok()) return s;
  } else {
    volume.origin = origin;
  }
  return volume;
}

}  // namespace

absl::StatusOr<Volume> ReadVti(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<std::string> prefix = vi::ReadPrefix(path, kMaxHeaderBytes, options);
  if (!prefix.ok()) return prefix.status();
  absl::StatusOr<uint64_t> file_size = vi::FileSize(path, options);
  if (!file_size.ok()) return file_size.status();
  const std::string& text = *prefix;
  if (!absl::StrContains(text.substr(0, 4096), "<VTKFile")) {
    return Error(path, "not a VTK XML file (no <VTKFile> in its first 4096 bytes)");
  }
  const size_t appended = text.find("<AppendedData");
  // The tags are read from the first MiB: a longer file's text may end
  // inside one, which is left out.
  const bool cut = appended == std::string::npos && *file_size > text.size();
  size_t xml_end = appended == std::string::npos ? text.size() : appended;
  if (cut) {
    const size_t last_open = text.rfind('<');
    if (last_open != std::string::npos && text.find('>', last_open) == std::string::npos) {
      xml_end = last_open;
    }
  }
  const absl::string_view xml = absl::string_view(text).substr(0, xml_end);
  absl::StatusOr<std::vector<Tag>> tags = ParseTags(path, xml);
  if (!tags.ok()) return tags.status();
  const Tag* file = nullptr;
  const Tag* image = nullptr;
  const Tag* point_data = nullptr;
  std::vector<const Tag*> arrays;
  int pieces = 0;
  bool in_point_data = false;
  for (const Tag& t : *tags) {
    if (t.name == "VTKFile") file = &t;
    if (t.name == "ImageData") image = &t;
    if (t.name == "Piece") ++pieces;
    if (t.name == "PointData") {
      point_data = &t;
      in_point_data = true;
    } else if (t.name == "CellData") {
      in_point_data = false;
    } else if (t.name == "DataArray" && in_point_data) {
      arrays.push_back(&t);
    }
  }
  auto attr = [](const Tag* t, const char* key) -> const std::string* {
    auto it = t->attributes.find(key);
    return it == t->attributes.end() ? nullptr : &it->second;
  };
  if (file == nullptr) return Error(path, "no <VTKFile> tag");
  if (const std::string* type = attr(file, "type"); type == nullptr || *type != "ImageData") {
    return Error(path, absl::StrCat("VTKFile type '", type ? *type : "", "' is not ImageData"));
  }
  if (image == nullptr) return Error(path, "no <ImageData> tag");
  if (pieces != 1) {
    return Error(path, absl::StrCat(pieces, " pieces: only one <Piece> is supported"));
  }
  ByteOrder order = ByteOrder::kLittle;
  if (const std::string* bo = attr(file, "byte_order")) {
    if (*bo == "BigEndian") {
      order = ByteOrder::kBig;
    } else if (*bo != "LittleEndian") {
      return Error(path, absl::StrCat("byte_order '", *bo, "' is neither LittleEndian nor BigEndian"));
    }
  }
  size_t header_bytes = 4;
  if (const std::string* ht = attr(file, "header_type")) {
    if (*ht == "UInt64") {
      header_bytes = 8;
    } else if (*ht != "UInt32") {
      return Error(path, absl::StrCat("header_type '", *ht, "' is neither UInt32 nor UInt64"));
    }
  }
  Compressor compressor = Compressor::kNone;
  if (const std::string* c = attr(file, "compressor"); c && !c->empty()) {
    // The classes VTK's writers name (vtkXMLWriter::SetCompressorType).
    if (*c == "vtkZLibDataCompressor") {
      compressor = Compressor::kZlib;
    } else if (*c == "vtkLZ4DataCompressor") {
      compressor = Compressor::kLz4;
    } else if (*c == "vtkLZMADataCompressor") {
      compressor = Compressor::kLzma;
    } else {
      return Error(path, absl::StrCat("compressor '", *c,
                                      "' is not supported (supported: vtkZLibDataCompressor, "
                                      "vtkLZ4DataCompressor, vtkLZMADataCompressor)"));
    }
  }
  const bool compressed = compressor != Compressor::kNone;

  const std::string* extent_text = attr(image, "WholeExtent");
  if (extent_text == nullptr) return Error(path, "<ImageData> has no WholeExtent");
  absl::StatusOr<std::vector<double>> extent = vi::ParseNumbers(path, "WholeExtent", *extent_text, 6);
  if (!extent.ok()) return extent.status();
  std::array<int64_t, 3> dims;
  for (int a = 0; a < 3; ++a) {
    const double lo = (*extent)[2 * a], hi = (*extent)[2 * a + 1];
    if (lo != std::floor(lo) || hi != std::floor(hi) || std::fabs(lo) > 1e12 ||
        std::fabs(hi) > 1e12) {
      return Error(path, absl::StrCat("WholeExtent '", *extent_text, "' is not whole numbers"));
    }
    dims[a] = static_cast<int64_t>(hi) - static_cast<int64_t>(lo) + 1;
  }
  std::array<double, 3> spacing = {1, 1, 1}, origin = {0, 0, 0};
  // A negative spacing runs its axis backwards: that is a direction.
  std::array<std::array<double, 3>, 3> axes = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  bool oriented = false;
  if (const std::string* s = attr(image, "Spacing")) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "Spacing", *s, 3);
    if (!v.ok()) return v.status();
    for (int a = 0; a < 3; ++a) {
      if ((*v)[a] == 0) return Error(path, "Spacing: a spacing of 0");
      spacing[a] = std::fabs((*v)[a]);
      if ((*v)[a] < 0) {
        axes[a][a] = -1;
        oriented = true;
      }
    }
  }
  if (const std::string* d = attr(image, "Direction")) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "Direction", *d, 9);
    if (!v.ok()) return v.status();
    std::array<std::array<double, 3>, 3> sign = axes;
    for (int a = 0; a < 3; ++a) {
      for (int w = 0; w < 3; ++w) axes[a][w] = (*v)[3 * w + a] * sign[a][a];
    }
    oriented = true;
  }
  if (const std::string* o = attr(image, "Origin")) {
    absl::StatusOr<std::vector<double>> v = vi::ParseNumbers(path, "Origin", *o, 3);
    if (!v.ok()) return v.status();
    origin = {(*v)[0], (*v)[1], (*v)[2]};
  }

  if (arrays.empty()) return Error(path, "no point data array (<PointData><DataArray>)");
  const Tag* array = arrays.front();
  if (const std::string* scalars = point_data ? attr(point_data, "Scalars") : nullptr) {
    bool found = false;
    for (const Tag* a : arrays) {
      if (const std::string* name = attr(a, "Name"); name && *name == *scalars) {
        array = a;
        found = true;
      }
    }
    if (!found && cut) {
      return Error(path, absl::StrCat("the array Scalars names ('", *scalars,
                                      "') is not among the tags of the file's first ",
                                      kMaxHeaderBytes, " bytes: write it first, or appended"));
    }
  }
  const std::string* type_text = attr(array, "type");
  if (type_text == nullptr) return Error(path, "DataArray has no type");
  absl::StatusOr<ScalarType> type = ArrayType(path, *type_text);
  if (!type.ok()) return type.status();
  if (const std::string* n = attr(array, "NumberOfComponents"); n && *n != "1") {
    return Error(path, absl::StrCat("DataArray has ", *n,
                                    " components: only scalar arrays (1 component) are supported"));
  }
  const std::string* format = attr(array, "format");
  const std::string format_name = format ? *format : "";
  if (format_name != "appended" && format_name != "binary" && format_name != "ascii") {
    return Error(path, absl::StrCat("DataArray format '", format_name,
                                    "' is not supported (supported: appended, binary, ascii)"));
  }
  uint64_t start = 0;
  bool base64 = format_name == "binary";
  if (format_name != "appended") {
    // Inline: the array's content follows its tag.
    if (array->empty) {
      return Error(path, absl::StrCat("DataArray format '", format_name, "' has no content"));
    }
    start = array->end;
  } else {
    uint64_t array_offset = 0;
    if (const std::string* o = attr(array, "offset");
        o == nullptr || !absl::SimpleAtoi(*o, &array_offset)) {
      return Error(path, "DataArray has no valid offset");
    }
    if (appended == std::string::npos) return Error(path, "no <AppendedData> (truncated?)");
    const size_t tag_end = text.find('>', appended);
    if (tag_end == std::string::npos) return Error(path, "<AppendedData> tag without '>'");
    absl::StatusOr<std::vector<Tag>> t =
        ParseTags(path, absl::string_view(text).substr(appended, tag_end - appended + 1));
    if (!t.ok()) return t.status();
    const std::string* enc = t->empty() ? nullptr : attr(&t->front(), "encoding");
    if (enc == nullptr || (*enc != "raw" && *enc != "base64")) {
      return Error(path, absl::StrCat("AppendedData encoding '", enc ? *enc : "",
                                      "' is not supported (supported: raw, base64)"));
    }
    base64 = *enc == "base64";
    const size_t underscore = text.find('_', tag_end);
    if (underscore == std::string::npos) {
      return Error(path, "<AppendedData> has no '_' before its data");
    }
    if (!vi::CheckedAdd(underscore + 1, array_offset, &start) || start > *file_size) {
      return Error(
          path, absl::StrCat("DataArray offset ", array_offset, " lies past the end of the file"));
    }
  }

  absl::StatusOr<uint64_t> data_bytes = vi::CheckedDataBytes(path, dims, *type, options);
  if (!data_bytes.ok()) return data_bytes.status();
  const std::string layout = vi::DescribeLayout(dims, *type);

  Volume volume;
  volume.dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};
  volume.spacing = spacing;
  volume.source_type = *type;
  const uint64_t count = volume.VoxelCount();

  absl::StatusOr<vi::FilePtr> opened = vi::OpenFile(path, options);
  if (!opened.ok()) return opened.status();
  std::FILE* f = opened->get();
  if (::fseeko(f, static_cast<off_t>(start), SEEK_SET) != 0) return Error(path, "seek failed");
  if (format_name == "ascii") {
    if (absl::Status s = vi::ReadAsciiSamples(path, f, count, true, &volume.values); !s.ok()) {
      return s;
    }
    return Finish(path, oriented, axes, origin, std::move(volume));
  }
  ByteSource source(path, f, base64);
  // Header integers are in the file's byte order.
  auto read_uint = [&](uint64_t* v, const char* what) -> absl::Status {
    unsigned char b[8];
    if (absl::Status s = source.Read(b, header_bytes, what); !s.ok()) return s;
    *v = 0;
    for (size_t i = 0; i < header_bytes; ++i) {
      const size_t k = order == ByteOrder::kBig ? i : header_bytes - 1 - i;
      *v = *v << 8 | b[k];
    }
    return absl::OkStatus();
  };

  if (!compressed) {
    uint64_t bytes = 0;
    if (absl::Status s = read_uint(&bytes, "array's byte count"); !s.ok()) return s;
    if (bytes != *data_bytes) {
      return Error(path, absl::StrCat("extent says ", layout, ", the array's byte count is ", bytes));
    }
    if (!base64 && *file_size - start - header_bytes < bytes) {
      return Error(path, absl::StrCat("extent says ", layout, ", file holds ",
                                      *file_size - start - header_bytes, " bytes of it"));
    }
    if (!base64) volume.values.reserve(count);
    absl::Status s =
        vi::ReadSamples([&](unsigned char* dst, size_t n) { return source.Read(dst, n, "array"); },
                        count, *type, order, &volume.values);
    if (!s.ok()) return s;
  } else {
    uint64_t blocks = 0, block_size = 0, last_size = 0;
    for (auto [v, what] : {std::pair{&blocks, "block count"}, std::pair{&block_size, "block size"},
                           std::pair{&last_size, "last block's size"}}) {
      if (absl::Status s = read_uint(v, what); !s.ok()) return s;
    }
    if (block_size == 0 || block_size > kMaxBlockBytes || last_size > block_size) {
      return Error(path, absl::StrCat("compressed array: block size ", block_size,
                                      " and last block's size ", last_size, " are not valid"));
    }
    uint64_t total = 0;
    const uint64_t full = last_size == 0 ? blocks : blocks - 1;
    if (blocks == 0 || !vi::CheckedMul(full, block_size, &total) ||
        !vi::CheckedAdd(total, last_size, &total) || total != *data_bytes) {
      return Error(path, absl::StrCat("extent says ", layout, ", the compressed array's ", blocks,
                                      " blocks of ", block_size, " bytes (last ", last_size,
                                      ") do not hold that"));
    }
    // Each block size costs header_bytes of the file, which bounds the list.
    if (blocks > (*file_size - start) / header_bytes) {
      return Error(path, absl::StrCat("compressed array: ", blocks, " blocks, more than the file can hold"));
    }
    std::vector<uint64_t> sizes(blocks);
    uint64_t compressed_total = 0;
    for (uint64_t& s : sizes) {
      if (absl::Status st = read_uint(&s, "compressed block sizes"); !st.ok()) return st;
      if (s > kMaxBlockBytes || !vi::CheckedAdd(compressed_total, s, &compressed_total)) {
        return Error(path, absl::StrCat("compressed array: a block of ", s, " bytes is not valid"));
      }
    }
    const uint64_t data_start = start + header_bytes * (3 + blocks);
    if (!base64 && compressed_total > *file_size - std::min(*file_size, data_start)) {
      return Error(path, absl::StrCat("compressed array: blocks of ", compressed_total,
                                      " bytes in all, file holds ",
                                      *file_size - std::min(*file_size, data_start), " (truncated?)"));
    }
    std::vector<unsigned char> in, out(block_size);
    uint64_t block = 0, out_pos = 0, out_len = 0;
    // No reserve: blocks may lie about what they inflate to, and the
    // samples grow as blocks actually inflate.
    absl::Status s = vi::ReadSamples(
        [&](unsigned char* dst, size_t n) -> absl::Status {
          while (n > 0) {
            if (out_pos == out_len) {
              if (block == blocks) return Error(path, "compressed array: blocks end early");
              in.resize(sizes[block]);
              if (absl::Status r = source.Read(in.data(), in.size(), "compressed block"); !r.ok()) {
                return r;
              }
              const uint64_t want = (block + 1 == blocks && last_size != 0) ? last_size : block_size;
              if (!Inflate(compressor, in, want, out.data())) {
                return Error(path, absl::StrCat("compressed array: block ", block,
                                                " is corrupt or does not inflate to ", want,
                                                " bytes"));
              }
              ++block;
              out_pos = 0;
              out_len = want;
            }
            const size_t take = static_cast<size_t>(std::min<uint64_t>(n, out_len - out_pos));
            std::copy_n(out.data() + out_pos, take, dst);
            dst += take;
            out_pos += take;
            n -= take;
          }
          return absl::OkStatus();
        },
        count, *type, order, &volume.values);
    if (!s.ok()) return s;
  }
  return Finish(path, oriented, axes, origin, std::move(volume));
}

}  // namespace transtick
