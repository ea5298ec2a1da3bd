// Tests of the volume readers (NRRD, .den, NIfTI-1, raw) and the synthetic
// volumes. Files are written into a fresh temporary directory per test; the
// real volumes under shared/data are read when present.
#include "transtick/volume_io.h"

#include <stdlib.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "bzlib.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "transtick/synthetic.h"
#include "transtick/volume.h"
#include "zlib.h"

namespace transtick {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------
// Helpers

std::string DataDir() {
  if (const char* dir = std::getenv("TRANSTICK_DATA_DIR"); dir != nullptr && *dir != '\0') {
    return dir;
  }
  return TRANSTICK_SOURCE_DIR "/../shared/data";
}

std::string Bzip2(const std::string& data) {
  std::string out(data.size() + data.size() / 100 + 600, '\0');
  unsigned int n = static_cast<unsigned int>(out.size());
  EXPECT_EQ(BZ2_bzBuffToBuffCompress(out.data(), &n, const_cast<char*>(data.data()),
                                     static_cast<unsigned int>(data.size()), 9, 0, 0),
            BZ_OK);
  out.resize(n);
  return out;
}

std::string Gzip(const std::string& data) {
  z_stream stream{};
  // 15 + 16: a gzip wrapper, as NRRD writers and .nii.gz use.
  EXPECT_EQ(
      deflateInit2(&stream, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY),
      Z_OK);
  std::string out(deflateBound(&stream, data.size()) + 64, '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  stream.avail_in = static_cast<uInt>(data.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&stream, Z_FINISH), Z_STREAM_END);
  out.resize(stream.total_out);
  deflateEnd(&stream);
  return out;
}

// Appends `value` as a sample of `type` in `order`.
void AppendSample(double value, ScalarType type, ByteOrder order, std::string* out) {
  unsigned char bytes[8];
  uint64_t bits = 0;
  switch (type) {
    case ScalarType::kUint8:
    case ScalarType::kInt8:
      out->push_back(static_cast<char>(static_cast<int64_t>(value)));
      return;
    case ScalarType::kUint16:
    case ScalarType::kInt16:
      bits = static_cast<uint16_t>(static_cast<int64_t>(value));
      break;
    case ScalarType::kUint32:
    case ScalarType::kInt32:
      bits = static_cast<uint32_t>(static_cast<int64_t>(value));
      break;
    case ScalarType::kFloat32: {
      float f = static_cast<float>(value);
      uint32_t b32;
      std::memcpy(&b32, &f, 4);
      bits = b32;
      break;
    }
    case ScalarType::kFloat64:
      std::memcpy(&bits, &value, 8);
      break;
  }
  const size_t size = ScalarTypeSize(type);
  for (size_t i = 0; i < size; ++i) {
    const size_t shift = 8 * (order == ByteOrder::kLittle ? i : size - 1 - i);
    bytes[i] = static_cast<unsigned char>(bits >> shift);
  }
  out->append(reinterpret_cast<char*>(bytes), size);
}

std::string Encode(const std::vector<double>& values, ScalarType type, ByteOrder order) {
  std::string out;
  for (double v : values) AppendSample(v, type, order, &out);
  return out;
}

// 3x2x2 samples that exercise the range and sign of each type.
std::vector<double> SampleValues(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
      return {0, 1, 2, 127, 128, 200, 255, 3, 4, 5, 6, 7};
    case ScalarType::kInt8:
      return {0, 1, -1, 127, -128, 100, -100, 3, 4, -5, 6, 7};
    case ScalarType::kUint16:
      return {0, 1, 256, 65535, 1000, 3272, 40000, 3, 4, 5, 6, 7};
    case ScalarType::kInt16:
      return {0, 1, -1, 32767, -32768, 3272, -1000, 256, 4, 5, 6, 7};
    case ScalarType::kUint32:
      return {0, 1, 65536, 16777216, 1000, 70000, 3, 3, 4, 5, 6, 7};
    case ScalarType::kInt32:
      return {0, 1, -1, 16777216, -16777216, 70000, -70000, 3, 4, 5, 6, 7};
    case ScalarType::kFloat32:
      return {0, 1.5, -2.25, 1e10, -1e-3, 3.14159, 100, 3, 4, 5, 6, 7};
    case ScalarType::kFloat64:
      // Rounded to the nearest float; past the largest float, infinities.
      return {0, 1.5, -2.25, 1e300, -1e-3, 3.141592653589793, -1e300, 1e-320, 4, 5, 6, 7};
  }
  return {};
}

constexpr ScalarType kAllTypes[] = {ScalarType::kUint8,   ScalarType::kInt8,   ScalarType::kUint16,
                                    ScalarType::kInt16,   ScalarType::kUint32, ScalarType::kInt32,
                                    ScalarType::kFloat32, ScalarType::kFloat64};

// The float a sample of any type becomes: the nearest, or beyond the
// largest float an infinity of its sign.
float AsFloat(double v) {
  constexpr double kMax = std::numeric_limits<float>::max();
  return v > kMax ? INFINITY : v < -kMax ? -INFINITY : static_cast<float>(v);
}

void ExpectValues(const Volume& volume, const std::vector<double>& expected) {
  ASSERT_EQ(volume.values.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_FLOAT_EQ(volume.values[i], AsFloat(expected[i])) << "sample " << i;
  }
}

// A fresh directory per test, so tests can run in parallel and in any order.
class VolumeIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern = testing::TempDir() + "/transtick_volume_io_XXXXXX";
    ASSERT_NE(mkdtemp(pattern.data()), nullptr);
    dir_ = pattern;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& contents) {
    std::string path = dir_ + "/" + name;
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    EXPECT_TRUE(out.good()) << path;
    return path;
  }

  // Expects an error of `code` whose message names the file (by its base
  // name, which is in the path as given) and contains `hint`.
  static void ExpectError(const absl::Status& status, absl::StatusCode code,
                          const std::string& path, const std::string& hint) {
    EXPECT_EQ(status.code(), code) << status;
    const std::string name = std::filesystem::path(path).filename().string();
    EXPECT_THAT(std::string(status.message()), HasSubstr(name));
    EXPECT_THAT(std::string(status.message()), HasSubstr(hint));
  }

  std::string dir_;
};

// An attached NRRD header for a 3x2x2 volume, fields in a scrambled order
// with comments and a key/value pair, as real writers produce.
std::string NrrdHeader(const std::string& type, const std::string& encoding,
                       const std::string& endian, const std::string& extra = "") {
  std::string header = "NRRD0004\n# Complete NRRD file format specification at:\n";
  header += "encoding: " + encoding + "\n";
  header += "sizes: 3 2 2\n";
  header += "type: " + type + "\n";
  header += "creator:=transtick test\n";
  header += "dimension: 3\n";
  if (!endian.empty()) header += "endian: " + endian + "\n";
  header += extra;
  return header;
}

// ---------------------------------------------------------------------------
// Basics

TEST(ScalarTypeTest, NamesAndSizes) {
  EXPECT_EQ(ScalarTypeName(ScalarType::kInt16), "int16");
  EXPECT_EQ(ScalarTypeName(ScalarType::kFloat32), "float");
  EXPECT_EQ(ScalarTypeSize(ScalarType::kUint8), 1u);
  EXPECT_EQ(ScalarTypeSize(ScalarType::kInt16), 2u);
  EXPECT_EQ(ScalarTypeSize(ScalarType::kUint32), 4u);
  for (ScalarType type : kAllTypes) {
    absl::StatusOr<ScalarType> parsed = ParseScalarType(std::string(ScalarTypeName(type)));
    ASSERT_TRUE(parsed.ok()) << parsed.status();
    EXPECT_EQ(*parsed, type);
  }
}

TEST(ScalarTypeTest, ParsesEveryNrrdSpelling) {
  const std::pair<const char*, ScalarType> cases[] = {
      {"uchar", ScalarType::kUint8},
      {"unsigned char", ScalarType::kUint8},
      {"uint8", ScalarType::kUint8},
      {"uint8_t", ScalarType::kUint8},
      {"signed char", ScalarType::kInt8},
      {"int8", ScalarType::kInt8},
      {"int8_t", ScalarType::kInt8},
      {"short", ScalarType::kInt16},
      {"short int", ScalarType::kInt16},
      {"signed short", ScalarType::kInt16},
      {"signed short int", ScalarType::kInt16},
      {"int16", ScalarType::kInt16},
      {"int16_t", ScalarType::kInt16},
      {"ushort", ScalarType::kUint16},
      {"unsigned short", ScalarType::kUint16},
      {"unsigned short int", ScalarType::kUint16},
      {"uint16", ScalarType::kUint16},
      {"uint16_t", ScalarType::kUint16},
      {"int", ScalarType::kInt32},
      {"signed int", ScalarType::kInt32},
      {"int32", ScalarType::kInt32},
      {"int32_t", ScalarType::kInt32},
      {"uint", ScalarType::kUint32},
      {"unsigned int", ScalarType::kUint32},
      {"uint32", ScalarType::kUint32},
      {"uint32_t", ScalarType::kUint32},
      {"float", ScalarType::kFloat32},
      {"double", ScalarType::kFloat64},
      {"float64", ScalarType::kFloat64},
  };
  for (const auto& [name, type] : cases) {
    absl::StatusOr<ScalarType> parsed = ParseScalarType(name);
    ASSERT_TRUE(parsed.ok()) << name << ": " << parsed.status();
    EXPECT_EQ(*parsed, type) << name;
  }
  for (const char* bad : {"long double", "int64", "char", "block", ""}) {
    EXPECT_EQ(ParseScalarType(bad).status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
}

TEST(VolumeTest, Range) {
  Volume volume;
  EXPECT_EQ(volume.Range(), (std::array<float, 2>{0.0f, 0.0f}));
  volume.dims = {2, 2, 1};
  volume.values = {3.0f, -1.5f, NAN, 7.0f};
  EXPECT_EQ(volume.Range(), (std::array<float, 2>{-1.5f, 7.0f}));
  // Infinities are left out as well: a range must have a finite width.
  volume.values = {3.0f, -INFINITY, INFINITY, 7.0f};
  EXPECT_EQ(volume.Range(), (std::array<float, 2>{3.0f, 7.0f}));
  volume.values = {INFINITY, NAN, -INFINITY, INFINITY};
  EXPECT_EQ(volume.Range(), (std::array<float, 2>{0.0f, 0.0f}));
}

// ---------------------------------------------------------------------------
// NRRD: decoding

TEST_F(VolumeIoTest, NrrdAllTypesBothOrdersRawGzipBzip2AndAscii) {
  for (ScalarType type : kAllTypes) {
    for (ByteOrder order : {ByteOrder::kLittle, ByteOrder::kBig}) {
      for (const char* encoding : {"raw", "gzip", "bzip2", "ascii"}) {
        SCOPED_TRACE(absl::StrCat(std::string(ScalarTypeName(type)),
                                  order == ByteOrder::kBig ? " big " : " little ", encoding));
        const std::vector<double> values = SampleValues(type);
        std::string data = Encode(values, type, order);
        if (encoding == std::string("gzip")) data = Gzip(data);
        if (encoding == std::string("bzip2")) data = Bzip2(data);
        if (encoding == std::string("ascii")) {
          // As writers print them: several to a line, full precision.
          data.clear();
          for (size_t i = 0; i < values.size(); ++i) {
            data += absl::StrFormat("%.17g%s", values[i], i % 5 == 4 ? "\n" : " ");
          }
        }
        const std::string path =
            Write("v.nrrd", NrrdHeader(std::string(ScalarTypeName(type)), encoding,
                                       order == ByteOrder::kBig ? "big" : "little") +
                                "\n" + data);
        absl::StatusOr<Volume> volume = ReadNrrd(path);
        ASSERT_TRUE(volume.ok()) << volume.status();
        EXPECT_EQ(volume->dims, (std::array<int, 3>{3, 2, 2}));
        EXPECT_EQ(volume->source_type, type);
        EXPECT_EQ(volume->spacing, (std::array<double, 3>{1, 1, 1}));
        ExpectValues(*volume, values);
        EXPECT_FLOAT_EQ(volume->At(2, 1, 1), static_cast<float>(values[11]));
      }
    }
  }
}

TEST_F(VolumeIoTest, NrrdTypeSpellingsAndGzAlias) {
  const std::vector<double> values = SampleValues(ScalarType::kUint16);
  const std::string path =
      Write("u16.nrrd", NrrdHeader("unsigned short", "gz", "big") + "\n" +
                            Gzip(Encode(values, ScalarType::kUint16, ByteOrder::kBig)));
  absl::StatusOr<Volume> volume = ReadNrrd(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_EQ(volume->source_type, ScalarType::kUint16);
  ExpectValues(*volume, values);
}

TEST_F(VolumeIoTest, NrrdSingleByteTypesNeedNoEndian) {
  const std::vector<double> values = SampleValues(ScalarType::kInt8);
  const std::string path =
      Write("i8.nrrd", NrrdHeader("signed char", "raw", "") + "\n" +
                           Encode(values, ScalarType::kInt8, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadNrrd(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  ExpectValues(*volume, values);
}

TEST_F(VolumeIoTest, NrrdCrlfLineEndings) {
  const std::vector<double> values = SampleValues(ScalarType::kUint8);
  const std::string path = Write("crlf.nrrd",
                                 "NRRD0005\r\ntype: uint8\r\ndimension: 3\r\nsizes: 3 2 2\r\n"
                                 "encoding: raw\r\n\r\n" +
                                     Encode(values, ScalarType::kUint8, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadNrrd(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  ExpectValues(*volume, values);
}

TEST_F(VolumeIoTest, NrrdSpacings) {
  const std::vector<double> values = SampleValues(ScalarType::kUint8);
  const std::string path =
      Write("s.nrrd", NrrdHeader("uint8", "raw", "", "spacings: 3.2 -3.2 1.5\n") + "\n" +
                          Encode(values, ScalarType::kUint8, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadNrrd(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_DOUBLE_EQ(volume->spacing[0], 3.2);
  EXPECT_DOUBLE_EQ(volume->spacing[1], 3.2);  // the sign is a direction, not a size
  EXPECT_DOUBLE_EQ(volume->spacing[2], 1.5);
}

TEST_F(VolumeIoTest, NrrdSpaceDirections) {
  const std::vector<double> values = SampleValues(ScalarType::kUint8);
  const std::string path =
      Write("d.nrrd", NrrdHeader("uint8", "raw", "",
                                 "space: left-posterior-superior\n"
                                 "space directions: (0,2,0) ( -3, 0, 4) (0.4,0,0.3)\n"
                                 "space origin: (1,2,3)\nkinds: domain domain domain\n") +
                          "\n" + Encode(values, ScalarType::kUint8, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadNrrd(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_DOUBLE_EQ(volume->spacing[0], 2.0);
  EXPECT_DOUBLE_EQ(volume->spacing[1], 5.0);
  EXPECT_DOUBLE_EQ(volume->spacing[2], 0.5);
}

TEST_F(VolumeIoTest, NrrdByteSkipRawAndGzip) {
  const std::vector<double> values = SampleValues(ScalarType::kInt16);
  const std::string data = Encode(values, ScalarType::kInt16, ByteOrder::kLittle);
  const std::string junk(7, 'j');
  {
    const std::string path = Write(
        "skip.nrrd", NrrdHeader("int16", "raw", "little", "byte skip: 7\n") + "\n" + junk + data);
    absl::StatusOr<Volume> volume = ReadNrrd(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    ExpectValues(*volume, values);
  }
  {
    // Byte skip counts decompressed bytes.
    const std::string path =
        Write("skipgz.nrrd",
              NrrdHeader("int16", "gzip", "little", "byteskip: 7\n") + "\n" + Gzip(junk + data));
    absl::StatusOr<Volume> volume = ReadNrrd(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    ExpectValues(*volume, values);
  }
  {
    // -1: the data are the last bytes of the file.
    const std::string path =
        Write("skipend.nrrd",
              NrrdHeader("int16", "raw", "little", "byte skip: -1\n") + "\n" + junk + data);
    absl::StatusOr<Volume> volume = ReadNrrd(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    ExpectValues(*volume, values);
  }
}

TEST_F(VolumeIoTest, NrrdDetachedHeader) {
  const std::vector<double> values = SampleValues(ScalarType::kFloat32);
  const std::string data = Encode(values, ScalarType::kFloat32, ByteOrder::kBig);
  Write("vol.raw", data);
  Write("vol.raw.gz", Gzip(data));
  Write("lines.raw", "line one\nline two\n" + data);
  std::filesystem::create_directory(dir_ + "/sub");
  const std::string absolute = dir_ + "/vol.raw";
  const std::pair<std::string, std::string> cases[] = {
      {"relative.nhdr", "data file: vol.raw\n"},
      {"oldstyle.nhdr", "datafile: vol.raw\n"},
      {"sub/up.nhdr", "data file: ../vol.raw\n"},
      {"absolute.nhdr", "data file: " + absolute + "\n"},
      {"gz.nhdr", "data file: vol.raw.gz\n"},
      {"lines.nhdr", "data file: lines.raw\nline skip: 2\n"},
  };
  for (const auto& [name, field] : cases) {
    SCOPED_TRACE(name);
    const bool gz = name == "gz.nhdr";
    // A detached header may end at end of file, without a blank line.
    const std::string path = Write(name, NrrdHeader("float", gz ? "gzip" : "raw", "big", field));
    absl::StatusOr<Volume> volume = ReadVolume(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    ExpectValues(*volume, values);
  }
}

TEST_F(VolumeIoTest, ReadVolumeDispatchesByExtension) {
  const std::vector<double> values = SampleValues(ScalarType::kUint8);
  const std::string path =
      Write("UPPER.NRRD", NrrdHeader("uint8", "raw", "") + "\n" +
                              Encode(values, ScalarType::kUint8, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadVolume(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  ExpectValues(*volume, values);

  const std::string other = Write("volume.vtk", "whatever");
  ExpectError(ReadVolume(other).status(), absl::StatusCode::kInvalidArgument, other, ".vtk");
  const std::string none = Write("noextension", "whatever");
  ExpectError(ReadVolume(none).status(), absl::StatusCode::kInvalidArgument, none, "no extension");
}

// ---------------------------------------------------------------------------
// NRRD: malformed input

TEST_F(VolumeIoTest, NrrdMissingFile) {
  const std::string path = dir_ + "/absent.nrrd";
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kNotFound, path, "no such file");
  ExpectError(ReadVolume(path).status(), absl::StatusCode::kNotFound, path, "no such file");
}

TEST_F(VolumeIoTest, NrrdTruncatedRawData) {
  const std::string data =
      Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle);
  const std::string path =
      Write("short.nrrd", NrrdHeader("int16", "raw", "little") + "\n" + data.substr(0, 10));
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path,
              "header says 3x2x2 int16 = 24 bytes, file holds 10");
}

TEST_F(VolumeIoTest, NrrdTooMuchRawData) {
  const std::string data =
      Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle);
  const std::string path =
      Write("long.nrrd", NrrdHeader("int16", "raw", "little") + "\n" + data + "xx");
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, "file holds 26");
}

TEST_F(VolumeIoTest, NrrdTruncatedGzip) {
  const std::string gz =
      Gzip(Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle));
  const std::string path = Write(
      "shortgz.nrrd", NrrdHeader("int16", "gzip", "little") + "\n" + gz.substr(0, gz.size() - 12));
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, "truncated");
}

TEST_F(VolumeIoTest, NrrdGzipHoldsLessOrMoreThanHeaderSays) {
  const std::string data =
      Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle);
  const std::string less =
      Write("less.nrrd", NrrdHeader("int16", "gzip", "little") + "\n" + Gzip(data.substr(0, 20)));
  ExpectError(ReadNrrd(less).status(), absl::StatusCode::kInvalidArgument, less,
              "gzip data ends after 20");
  const std::string more =
      Write("more.nrrd", NrrdHeader("int16", "gzip", "little") + "\n" + Gzip(data + "extra"));
  ExpectError(ReadNrrd(more).status(), absl::StatusCode::kInvalidArgument, more, "holds more");
}

TEST_F(VolumeIoTest, NrrdHeaderThatLies) {
  // A 1000^3 volume (4 GB as float, under the default limit) with 24 bytes.
  const std::string data =
      Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle);
  const std::string header =
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 1000 1000 1000\nendian: little\n";
  const std::string raw = Write("lie.nrrd", header + "encoding: raw\n\n" + data);
  ExpectError(ReadNrrd(raw).status(), absl::StatusCode::kInvalidArgument, raw,
              "header says 1000x1000x1000 int16 = 2000000000 bytes, file holds 24");
  const std::string gz = Write("liegz.nrrd", header + "encoding: gzip\n\n" + Gzip(data));
  ExpectError(ReadNrrd(gz).status(), absl::StatusCode::kInvalidArgument, gz, "ends after 24");
}

TEST_F(VolumeIoTest, NrrdCorruptGzip) {
  std::string gz =
      Gzip(Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle));
  // Keep the 10-byte gzip header, replace the deflate stream with garbage.
  for (size_t i = 10; i < gz.size(); ++i) gz[i] = static_cast<char>(0xff);
  const std::string path = Write("corrupt.nrrd", NrrdHeader("int16", "gzip", "little") + "\n" + gz);
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, "corrupt gzip");

  // Not gzip at all.
  const std::string text = Write(
      "notgz.nrrd", NrrdHeader("int16", "gzip", "little") + "\nthis is not compressed data at all");
  ExpectError(ReadNrrd(text).status(), absl::StatusCode::kInvalidArgument, text, "gzip");

  // A flipped byte in the CRC trailer.
  std::string good =
      Gzip(Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle));
  good[good.size() - 6] ^= 0x55;
  const std::string crc = Write("crc.nrrd", NrrdHeader("int16", "gzip", "little") + "\n" + good);
  ExpectError(ReadNrrd(crc).status(), absl::StatusCode::kInvalidArgument, crc, "corrupt gzip");
}

TEST_F(VolumeIoTest, NrrdTruncatedHeader) {
  const std::string path = Write("trunc.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsiz");
  ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, "truncated");
  const std::string nomagic = Write("nomagic.nrrd", "NRRD");
  ExpectError(ReadNrrd(nomagic).status(), absl::StatusCode::kInvalidArgument, nomagic,
              "not a NRRD file");
  const std::string empty = Write("empty.nrrd", "");
  ExpectError(ReadNrrd(empty).status(), absl::StatusCode::kInvalidArgument, empty,
              "not a NRRD file");
}

TEST_F(VolumeIoTest, NrrdSizesThatOverflow) {
  const std::string big =
      Write("big.nrrd",
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4000000000 4000000000 4000000000\n"
            "encoding: raw\n\nxx");
  ExpectError(ReadNrrd(big).status(), absl::StatusCode::kInvalidArgument, big, "4000000000");
  const std::string product =
      Write("product.nrrd",
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2000000000 2000000000 "
            "2000000000\nencoding: raw\n\nxx");
  ExpectError(ReadNrrd(product).status(), absl::StatusCode::kInvalidArgument, product, "overflow");
  const std::string huge =
      Write("huge.nrrd",
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 99999999999999999999999 1 1\n"
            "encoding: raw\n\nxx");
  ExpectError(ReadNrrd(huge).status(), absl::StatusCode::kInvalidArgument, huge, "not an integer");
}

TEST_F(VolumeIoTest, NrrdMaxBytes) {
  const std::string data =
      Encode(SampleValues(ScalarType::kUint8), ScalarType::kUint8, ByteOrder::kLittle);
  const std::string path = Write("limit.nrrd", NrrdHeader("uint8", "raw", "") + "\n" + data);
  ReadOptions options;
  options.max_bytes = 47;  // 12 voxels need 48 bytes as float
  ExpectError(ReadNrrd(path, options).status(), absl::StatusCode::kResourceExhausted, path,
              "limit");
  options.max_bytes = 48;
  EXPECT_TRUE(ReadNrrd(path, options).ok());
  // The limit is checked before the header's sizes are compared to the file.
  const std::string huge = Write("hugelimit.nrrd",
                                 "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 100000 100000 "
                                 "100000\nencoding: raw\n\n" +
                                     data);
  ExpectError(ReadNrrd(huge).status(), absl::StatusCode::kResourceExhausted, huge, "limit");
}

TEST_F(VolumeIoTest, NrrdBadFields) {
  const std::string data =
      Encode(SampleValues(ScalarType::kInt16), ScalarType::kInt16, ByteOrder::kLittle);
  struct Case {
    const char* name;
    std::string header;
    const char* hint;
  };
  const std::string base_tail = "encoding: raw\nendian: little\n";
  const Case cases[] = {
      {"type.nrrd", "NRRD0004\ntype: int64\ndimension: 3\nsizes: 3 2 2\n" + base_tail,
       "unsupported sample type 'int64'"},
      {"encoding.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nencoding: hex\nendian: little\n",
       "unsupported encoding 'hex'"},
      {"notype.nrrd", "NRRD0004\ndimension: 3\nsizes: 3 2 2\n" + base_tail, "'type'"},
      {"nodim.nrrd", "NRRD0004\ntype: int16\nsizes: 3 2 2\n" + base_tail, "'dimension'"},
      {"nosizes.nrrd", "NRRD0004\ntype: int16\ndimension: 3\n" + base_tail, "'sizes'"},
      {"noenc.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nendian: little\n",
       "'encoding'"},
      {"noendian.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nencoding: raw\n",
       "'endian'"},
      {"dim2.nrrd", "NRRD0004\ntype: int16\ndimension: 2\nsizes: 6 2\n" + base_tail, "dimension 2"},
      {"dim4.nrrd", "NRRD0004\ntype: int16\ndimension: 4\nsizes: 1 3 2 2\n" + base_tail,
       "dimension 4"},
      {"twosizes.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 6 2\n" + base_tail,
       "expected 3 values"},
      {"negative.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 -2 2\n" + base_tail,
       "must be positive"},
      {"zero.nrrd", "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 0 2\n" + base_tail,
       "must be positive"},
      {"endian.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nencoding: raw\nendian: middle\n",
       "endian 'middle'"},
      {"skip.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nbyte skip: -5\n" + base_tail,
       "byte skip -5"},
      {"gzskip.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nbyte skip: -1\nencoding: gzip\n"
       "endian: little\n",
       "byte skip -1"},
      {"dup.nrrd", "NRRD0004\ntype: int16\ntype: int16\ndimension: 3\nsizes: 3 2 2\n" + base_tail,
       "appears twice"},
      {"spacings.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nspacings: 1 1\n" + base_tail,
       "spacings"},
      {"zerospacing.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nspacings: 1 0 1\n" + base_tail,
       "spacing 0"},
      {"directions.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\nspace directions: (1,0,0) "
       "(0,1,0\n" +
           base_tail,
       "space directions"},
      {"garbage.nrrd", "NRRD0004\ntype: int16\nthis line has no colon\n" + base_tail,
       "not 'field: value'"},
      {"list.nrrd",
       "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\ndata file: LIST\n" + base_tail,
       "single data file"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = Write(c.name, c.header + "\n" + data);
    ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, c.hint);
  }
}

// ASCII and bzip2 data that is cut short, too long, corrupt or not numbers
// is refused by name; ASCII data takes no byte skip (its lines are skipped).
TEST_F(VolumeIoTest, NrrdAsciiAndBzip2Errors) {
  const std::string header = "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 2 2\n";
  const std::string twelve = "1 2 3 4 5 6\n7 8 9 10 11 12\n";
  const std::pair<std::string, const char*> cases[] = {
      {header + "encoding: ascii\n\n1 2 3\n", "holds 3 samples, its header says 12"},
      {header + "encoding: ascii\n\n" + twelve + "13\n", "more than the 12 samples"},
      {header + "encoding: text\n\n1 2 x3 4\n", "'x3' is not a number"},
      {header + "encoding: ascii\nbyte skip: 4\n\n" + twelve, "byte skip is not allowed"},
      {header + "encoding: bzip2\nendian: little\n\n" + Bzip2(std::string(24, '\1')).substr(0, 20),
       "truncated"},
      {header + "encoding: bz2\nendian: little\n\n" + Bzip2(std::string(26, '\1')),
       "bzip2 data in file holds more"},
      {header + "encoding: bzip2\nendian: little\n\nBZh9 not bzip2 at all", "corrupt bzip2"},
  };
  for (const auto& [file, hint] : cases) {
    SCOPED_TRACE(hint);
    const std::string path = Write("bad.nrrd", file);
    ExpectError(ReadNrrd(path).status(), absl::StatusCode::kInvalidArgument, path, hint);
  }
  // A line skip before ASCII data, in a detached data file.
  Write("a.txt", "a comment line\n" + twelve);
  auto v = ReadNrrd(Write("a.nhdr", header + "encoding: ascii\ndata file: a.txt\nline skip: 1\n"));
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->values[11], 12.0f);
}

TEST_F(VolumeIoTest, NrrdDetachedErrors) {
  const std::string missing =
      Write("missing.nhdr", NrrdHeader("uint8", "raw", "", "data file: nowhere.raw\n"));
  ExpectError(ReadNrrd(missing).status(), absl::StatusCode::kNotFound, "nowhere.raw",
              "no such file");
  Write("short.raw", "abc");
  const std::string shortdata =
      Write("shortdata.nhdr", NrrdHeader("uint8", "raw", "", "data file: short.raw\n"));
  ExpectError(ReadNrrd(shortdata).status(), absl::StatusCode::kInvalidArgument, shortdata,
              "data file");
  const std::string lines =
      Write("lines.nhdr", NrrdHeader("uint8", "raw", "", "data file: short.raw\nline skip: 3\n"));
  ExpectError(ReadNrrd(lines).status(), absl::StatusCode::kInvalidArgument, "short.raw", "lines");
}

// Every prefix of a valid file is invalid and is refused without a crash.
TEST_F(VolumeIoTest, NrrdEveryTruncationFails) {
  std::vector<double> values(5 * 4 * 3);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(i * 37 % 300);
  const std::string data = Encode(values, ScalarType::kInt16, ByteOrder::kBig);
  const std::string header =
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 5 4 3\nendian: big\nspacings: 1 1 2\n";
  for (bool gzip : {false, true}) {
    const std::string full =
        header + (gzip ? "encoding: gzip\n\n" + Gzip(data) : "encoding: raw\n\n" + data);
    const std::string path = Write("full.nrrd", full);
    ASSERT_TRUE(ReadNrrd(path).ok());
    for (size_t length = 0; length < full.size(); ++length) {
      SCOPED_TRACE(absl::StrCat(gzip ? "gzip" : "raw", " truncated to ", length));
      const std::string cut = Write("cut.nrrd", full.substr(0, length));
      absl::StatusOr<Volume> volume = ReadNrrd(cut);
      ASSERT_FALSE(volume.ok());
      EXPECT_THAT(std::string(volume.status().message()), HasSubstr("cut.nrrd"));
    }
  }
}

// ---------------------------------------------------------------------------
// Raw

TEST_F(VolumeIoTest, RawReadsWithHeaderSkip) {
  const std::vector<double> values = SampleValues(ScalarType::kUint16);
  const std::string path =
      Write("v.raw", "HDR!" + Encode(values, ScalarType::kUint16, ByteOrder::kBig));
  RawSpec spec;
  spec.dims = {3, 2, 2};
  spec.type = ScalarType::kUint16;
  spec.byte_order = ByteOrder::kBig;
  spec.spacing = {1, 2, 3};
  spec.header_bytes = 4;
  absl::StatusOr<Volume> volume = ReadRaw(path, spec);
  ASSERT_TRUE(volume.ok()) << volume.status();
  ExpectValues(*volume, values);
  EXPECT_EQ(volume->spacing, (std::array<double, 3>{1, 2, 3}));

  spec.dims = {3, 3, 2};
  ExpectError(ReadRaw(path, spec).status(), absl::StatusCode::kInvalidArgument, path,
              "file holds 28 bytes");
  spec.dims = {3, -2, 2};
  ExpectError(ReadRaw(path, spec).status(), absl::StatusCode::kInvalidArgument, path,
              "must be positive");
}

// ---------------------------------------------------------------------------
// .den

std::string DenFile(int nx, int ny, int nz, bool big, int32_t map_length, const std::string& data) {
  std::string out;
  auto put16 = [&](int v) {
    const uint16_t u = static_cast<uint16_t>(v);
    out.push_back(static_cast<char>(big ? u >> 8 : u & 0xff));
    out.push_back(static_cast<char>(big ? u & 0xff : u >> 8));
  };
  put16(1);                                           // map_version
  for (int block = 0; block < 2; ++block) {           // orig, extr
    for (int v : {0, 0, 0}) put16(v);                 //   min
    for (int v : {nx - 1, ny - 1, nz - 1}) put16(v);  //   max
    for (int v : {nx, ny, nz}) put16(v);              //   len
  }
  for (int v : {0, 0, 0}) put16(v);                 // map_min
  for (int v : {nx - 1, ny - 1, nz - 1}) put16(v);  // map_max
  for (int v : {nx, ny, nz}) put16(v);              // map_len
  put16(0);                                         // map_warps
  const uint32_t length = static_cast<uint32_t>(map_length);
  for (int i = 0; i < 4; ++i) {
    out.push_back(static_cast<char>(length >> (8 * (big ? 3 - i : i))));
  }
  EXPECT_EQ(out.size(), 62u);
  return out + data;
}

std::string Ramp(size_t n) {
  std::string data;
  for (size_t i = 0; i < n; ++i) data.push_back(static_cast<char>(i * 7 % 256));
  return data;
}

TEST_F(VolumeIoTest, DenBothByteOrders) {
  const std::string data = Ramp(3 * 4 * 5);
  for (bool big : {false, true}) {
    SCOPED_TRACE(big ? "big" : "little");
    const std::string path = Write("v.den", DenFile(3, 4, 5, big, 60, data));
    absl::StatusOr<Volume> volume = ReadVolume(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    EXPECT_EQ(volume->dims, (std::array<int, 3>{3, 4, 5}));
    EXPECT_EQ(volume->source_type, ScalarType::kUint8);
    EXPECT_EQ(volume->spacing, (std::array<double, 3>{1, 1, 1}));
    for (int z = 0; z < 5; ++z) {
      for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 3; ++x) {
          const size_t i = static_cast<size_t>((z * 4 + y) * 3 + x);
          EXPECT_EQ(volume->At(x, y, z), static_cast<float>(static_cast<unsigned char>(data[i])));
        }
      }
    }
  }
}

TEST_F(VolumeIoTest, DenErrors) {
  const std::string data = Ramp(60);
  const std::string inconsistent = Write("inconsistent.den", DenFile(3, 4, 5, true, 61, data));
  ExpectError(ReadDen(inconsistent).status(), absl::StatusCode::kInvalidArgument, inconsistent,
              "map_length 61");
  const std::string truncated =
      Write("truncated.den", DenFile(3, 4, 5, false, 60, data.substr(0, 59)));
  ExpectError(ReadDen(truncated).status(), absl::StatusCode::kInvalidArgument, truncated,
              "header says 3x4x5 uint8 = 60 bytes, file holds 59");
  const std::string header = Write("header.den", DenFile(3, 4, 5, false, 60, "").substr(0, 40));
  ExpectError(ReadDen(header).status(), absl::StatusCode::kInvalidArgument, header,
              "truncated header");
  std::string bad_version = DenFile(3, 4, 5, false, 60, data);
  bad_version[0] = 2;
  const std::string version = Write("version.den", bad_version);
  ExpectError(ReadDen(version).status(), absl::StatusCode::kInvalidArgument, version,
              "map_version");
  const std::string negative = Write("negative.den", DenFile(3, -4, 5, false, -60, data));
  ExpectError(ReadDen(negative).status(), absl::StatusCode::kInvalidArgument, negative,
              "must be positive");
  const std::string path = Write("limit.den", DenFile(3, 4, 5, false, 60, data));
  ReadOptions options;
  options.max_bytes = 100;
  ExpectError(ReadDen(path, options).status(), absl::StatusCode::kResourceExhausted, path, "limit");
  ExpectError(ReadDen(dir_ + "/absent.den").status(), absl::StatusCode::kNotFound, "absent.den",
              "no such file");
}

TEST_F(VolumeIoTest, DenEveryTruncationFails) {
  const std::string full = DenFile(3, 4, 5, true, 60, Ramp(60));
  for (size_t length = 0; length < full.size(); ++length) {
    const std::string cut = Write("cut.den", full.substr(0, length));
    absl::StatusOr<Volume> volume = ReadDen(cut);
    ASSERT_FALSE(volume.ok()) << length;
    EXPECT_THAT(std::string(volume.status().message()), HasSubstr("cut.den"));
  }
}

// ---------------------------------------------------------------------------
// NIfTI-1

struct NiftiSpec {
  bool big = false;
  int datatype = 2;
  std::vector<int> dim = {3, 3, 2, 2};  // dim[0], then sizes
  float pixdim[3] = {1.0f, 1.0f, 1.0f};
  float vox_offset = 352.0f;
  float slope = 0.0f;
  float inter = 0.0f;
  int sizeof_hdr = 348;
  const char* magic = "n+1";
};

std::string NiftiHeader(const NiftiSpec& spec) {
  std::string h(352, '\0');  // header + 4-byte extension flag (all zero: none)
  auto put = [&](size_t offset, uint32_t bits, int width) {
    for (int i = 0; i < width; ++i) {
      const int shift = 8 * (spec.big ? width - 1 - i : i);
      h[offset + static_cast<size_t>(i)] = static_cast<char>(bits >> shift);
    }
  };
  auto put_float = [&](size_t offset, float f) {
    uint32_t bits;
    std::memcpy(&bits, &f, 4);
    put(offset, bits, 4);
  };
  put(0, static_cast<uint32_t>(spec.sizeof_hdr), 4);
  for (size_t i = 0; i < spec.dim.size(); ++i) {
    put(40 + 2 * i, static_cast<uint16_t>(spec.dim[i]), 2);
  }
  put(70, static_cast<uint16_t>(spec.datatype), 2);
  put(72, 8, 2);  // bitpix: not checked
  put_float(76, 1.0f);
  for (int i = 0; i < 3; ++i) put_float(80 + 4 * static_cast<size_t>(i), spec.pixdim[i]);
  put_float(108, spec.vox_offset);
  put_float(112, spec.slope);
  put_float(116, spec.inter);
  std::memcpy(h.data() + 344, spec.magic, 4);
  return h;
}

constexpr std::pair<int, ScalarType> kNiftiTypes[] = {
    {2, ScalarType::kUint8},    {4, ScalarType::kInt16},    {8, ScalarType::kInt32},
    {16, ScalarType::kFloat32}, {256, ScalarType::kInt8},   {512, ScalarType::kUint16},
    {768, ScalarType::kUint32}, {64, ScalarType::kFloat64},
};

// A .hdr/.img pair, NIfTI-1 ("ni1", samples from vox_offset of the .img)
// or Analyze 7.5 (no magic; its bytes where NIfTI keeps the qform and sform
// hold other things, here garbage, and are not read): every type, both byte
// orders, either file gzipped or not, named by either file, in either case.
TEST_F(VolumeIoTest, NiftiPairsAndAnalyze) {
  int n = 0;
  for (const auto& [datatype, type] : kNiftiTypes) {
    for (int variant = 0; variant < 16; ++variant) {
      const bool big = variant & 1, hdr_gz = variant & 2, img_gz = variant & 4,
                 analyze = variant & 8;
      const bool by_img = (n % 3) == 1, upper = (n % 5) == 2;
      ++n;
      SCOPED_TRACE(absl::StrCat(datatype, " variant ", variant, by_img ? " by .img" : "",
                                upper ? " upper case" : ""));
      NiftiSpec spec;
      spec.big = big;
      spec.datatype = datatype;
      spec.pixdim[0] = 0.5f;
      spec.vox_offset = analyze ? 0.0f : 8.0f;
      spec.magic = analyze ? "\0\0\0" : "ni1";
      std::string header = NiftiHeader(spec).substr(0, 348);
      if (analyze) {
        for (size_t i = 252; i < 344; ++i) header[i] = static_cast<char>(i * 37);
      }
      const std::vector<double> values = SampleValues(type);
      std::string img = std::string(analyze ? 0 : 8, '\7') +
                        Encode(values, type, big ? ByteOrder::kBig : ByteOrder::kLittle);
      const std::string stem = absl::StrCat("pair", n);
      const std::string h = upper ? ".HDR" : ".hdr", i = upper ? ".IMG" : ".img";
      const std::string hdr_path =
          Write(stem + h + (hdr_gz ? ".gz" : ""), hdr_gz ? Gzip(header) : header);
      const std::string img_path =
          Write(stem + i + (img_gz ? ".gz" : ""), img_gz ? Gzip(img) : img);
      absl::StatusOr<Volume> volume = ReadVolume(by_img ? img_path : hdr_path);
      ASSERT_TRUE(volume.ok()) << volume.status();
      EXPECT_EQ(volume->dims, (std::array<int, 3>{3, 2, 2}));
      EXPECT_EQ(volume->source_type, type);
      EXPECT_EQ(volume->spacing, (std::array<double, 3>{0.5, 1.0, 1.0}));
      EXPECT_EQ(volume->direction, kIdentityDirection);
      ExpectValues(*volume, values);
    }
  }
  // The other half missing; a single-file header in a pair; an offset
  // before the .img's start.
  NiftiSpec spec;
  spec.magic = "ni1";
  spec.vox_offset = 0.0f;
  const std::string lone = Write("lone.hdr", NiftiHeader(spec).substr(0, 348));
  ExpectError(ReadVolume(lone).status(), absl::StatusCode::kNotFound, lone, "its pair");
  spec.magic = "n+1";
  const std::string single = Write("single.hdr", NiftiHeader(spec).substr(0, 348));
  Write("single.img", std::string(12, '\1'));
  ExpectError(ReadVolume(single).status(), absl::StatusCode::kInvalidArgument, single,
              "name the file .nii");
  spec.magic = "ni1";
  spec.vox_offset = -4.0f;
  const std::string before = Write("before.hdr", NiftiHeader(spec).substr(0, 348));
  Write("before.img", std::string(12, '\1'));
  ExpectError(ReadVolume(before).status(), absl::StatusCode::kInvalidArgument, before,
              "into the .img");
  spec.vox_offset = 4.0f;
  const std::string shortimg = Write("short.hdr", NiftiHeader(spec).substr(0, 348));
  const std::string shortdata = Write("short.img", std::string(12, '\1'));
  ExpectError(ReadVolume(shortimg).status(), absl::StatusCode::kInvalidArgument, shortdata,
              "file holds 8");
}

TEST_F(VolumeIoTest, NiftiAllTypesBothOrdersRawAndGzip) {
  for (const auto& [datatype, type] : kNiftiTypes) {
    for (bool big : {false, true}) {
      for (bool gzip : {false, true}) {
        SCOPED_TRACE(absl::StrCat(datatype, big ? " big" : " little", gzip ? " gz" : ""));
        NiftiSpec spec;
        spec.big = big;
        spec.datatype = datatype;
        spec.pixdim[0] = 0.5f;
        spec.pixdim[1] = -2.0f;  // sign dropped
        spec.pixdim[2] = 0.0f;   // unset: 1
        const std::vector<double> values = SampleValues(type);
        std::string file =
            NiftiHeader(spec) + Encode(values, type, big ? ByteOrder::kBig : ByteOrder::kLittle);
        if (gzip) file = Gzip(file);
        const std::string path = Write(gzip ? "v.nii.gz" : "v.nii", file);
        absl::StatusOr<Volume> volume = ReadVolume(path);
        ASSERT_TRUE(volume.ok()) << volume.status();
        EXPECT_EQ(volume->dims, (std::array<int, 3>{3, 2, 2}));
        EXPECT_EQ(volume->source_type, type);
        EXPECT_EQ(volume->spacing, (std::array<double, 3>{0.5, 2.0, 1.0}));
        ExpectValues(*volume, values);
      }
    }
  }
}

TEST_F(VolumeIoTest, NiftiScalingOffsetAndTimeAxis) {
  NiftiSpec spec;
  spec.datatype = 4;
  spec.slope = 2.0f;
  spec.inter = -10.0f;
  spec.vox_offset = 400.0f;  // 48 bytes of extension data before the samples
  spec.dim = {4, 3, 2, 2, 1};
  const std::vector<double> values = SampleValues(ScalarType::kInt16);
  const std::string file = NiftiHeader(spec) + std::string(48, 'e') +
                           Encode(values, ScalarType::kInt16, ByteOrder::kLittle) + "trailer";
  for (bool gzip : {false, true}) {
    const std::string path = Write(gzip ? "s.nii.gz" : "s.nii", gzip ? Gzip(file) : file);
    absl::StatusOr<Volume> volume = ReadNifti(path);
    ASSERT_TRUE(volume.ok()) << volume.status();
    std::vector<double> scaled;
    for (double v : values) scaled.push_back(v * 2.0 - 10.0);
    ExpectValues(*volume, scaled);
  }
  // slope 1, inter 0: identity; slope 0: no scaling even with an intercept.
  spec.slope = 0.0f;
  spec.inter = 5.0f;
  spec.vox_offset = 0.0f;  // means 352
  const std::string path = Write(
      "noscale.nii", NiftiHeader(spec) + Encode(values, ScalarType::kInt16, ByteOrder::kLittle));
  absl::StatusOr<Volume> volume = ReadNifti(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  ExpectValues(*volume, values);
}

TEST_F(VolumeIoTest, NiftiErrors) {
  const std::string data =
      Encode(SampleValues(ScalarType::kUint8), ScalarType::kUint8, ByteOrder::kLittle);
  struct Case {
    const char* name;
    NiftiSpec spec;
    const char* hint;
  };
  std::vector<Case> cases;
  auto add = [&](const char* name, auto edit, const char* hint) {
    NiftiSpec spec;
    edit(spec);
    cases.push_back({name, spec, hint});
  };
  add(
      "int64.nii", [](NiftiSpec& s) { s.datatype = 1024; }, "datatype 1024 (int64)");
  add(
      "weird.nii", [](NiftiSpec& s) { s.datatype = 3; }, "datatype 3");
  add(
      "dim2.nii",
      [](NiftiSpec& s) {
        s.dim = {2, 6, 2};
      },
      "dim[0] is 2");
  add(
      "time.nii",
      [](NiftiSpec& s) {
        s.dim = {4, 3, 2, 2, 2};
      },
      "dim[4] is 2");
  add(
      "negative.nii",
      [](NiftiSpec& s) {
        s.dim = {3, 3, -2, 2};
      },
      "must be positive");
  add(
      "sizeof.nii", [](NiftiSpec& s) { s.sizeof_hdr = 347; }, "sizeof_hdr");
  add(
      "nifti2.nii", [](NiftiSpec& s) { s.sizeof_hdr = 540; }, "NIfTI-2");
  add(
      "pair.nii", [](NiftiSpec& s) { s.magic = "ni1"; }, "open it as the .hdr file");
  add(
      "magic.nii", [](NiftiSpec& s) { s.magic = "xyz"; }, "magic");
  add(
      "offset.nii", [](NiftiSpec& s) { s.vox_offset = 100.0f; }, "vox_offset");
  add(
      "fraction.nii", [](NiftiSpec& s) { s.vox_offset = 352.5f; }, "vox_offset");
  add(
      "nanoffset.nii", [](NiftiSpec& s) { s.vox_offset = NAN; }, "vox_offset");
  add(
      "bigsize.nii",
      [](NiftiSpec& s) {
        s.dim = {3, 30000, 30000, 30000};
      },
      "limit");
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = Write(c.name, NiftiHeader(c.spec) + data);
    const absl::StatusCode code = std::string(c.name) == "bigsize.nii"
                                      ? absl::StatusCode::kResourceExhausted
                                      : absl::StatusCode::kInvalidArgument;
    ExpectError(ReadNifti(path).status(), code, path, c.hint);
  }
  const std::string shortdata = Write("short.nii", NiftiHeader(NiftiSpec()) + data.substr(0, 5));
  ExpectError(ReadNifti(shortdata).status(), absl::StatusCode::kInvalidArgument, shortdata,
              "header says 3x2x2 uint8 = 12 bytes at offset 352, file holds 5");
  const std::string shortgz =
      Write("short.nii.gz", Gzip(NiftiHeader(NiftiSpec()) + data.substr(0, 5)));
  ExpectError(ReadNifti(shortgz).status(), absl::StatusCode::kInvalidArgument, shortgz,
              "gzip data ends after");
  const std::string header = Write("header.nii", NiftiHeader(NiftiSpec()).substr(0, 200));
  ExpectError(ReadNifti(header).status(), absl::StatusCode::kInvalidArgument, header,
              "truncated header");
  const std::string headergz =
      Write("header.nii.gz", Gzip(NiftiHeader(NiftiSpec()).substr(0, 200)));
  ExpectError(ReadNifti(headergz).status(), absl::StatusCode::kInvalidArgument, headergz,
              "348-byte NIfTI-1 header");
  std::string corrupt = Gzip(NiftiHeader(NiftiSpec()) + data);
  for (size_t i = 10; i < corrupt.size(); ++i) corrupt[i] = static_cast<char>(0xff);
  const std::string corruptgz = Write("corrupt.nii.gz", corrupt);
  ExpectError(ReadNifti(corruptgz).status(), absl::StatusCode::kInvalidArgument, corruptgz,
              "corrupt gzip");
}

TEST_F(VolumeIoTest, NiftiEveryTruncationFails) {
  NiftiSpec spec;
  spec.datatype = 512;
  std::vector<double> values(5 * 4 * 3);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(i * 1013 % 65536);
  spec.dim = {3, 5, 4, 3};
  const std::string raw =
      NiftiHeader(spec) + Encode(values, ScalarType::kUint16, ByteOrder::kLittle);
  for (bool gzip : {false, true}) {
    const std::string full = gzip ? Gzip(raw) : raw;
    const std::string name = gzip ? "cut.nii.gz" : "cut.nii";
    ASSERT_TRUE(ReadNifti(Write(name, full)).ok());
    // Stride through the header, every byte near the end.
    for (size_t length = 0; length < full.size(); length += (length < full.size() - 64 ? 5 : 1)) {
      SCOPED_TRACE(absl::StrCat(name, " truncated to ", length));
      const std::string cut = Write(name, full.substr(0, length));
      absl::StatusOr<Volume> volume = ReadNifti(cut);
      ASSERT_FALSE(volume.ok());
      EXPECT_THAT(std::string(volume.status().message()), HasSubstr(name));
    }
  }
}

// ---------------------------------------------------------------------------
// Real volumes

class RealDataTest : public ::testing::Test {
 protected:
  static absl::StatusOr<Volume> ReadOrSkip(const std::string& path, bool* skipped) {
    *skipped = !std::filesystem::exists(path);
    if (*skipped) return absl::NotFoundError(path);
    return ReadVolume(path);
  }
};

TEST_F(RealDataTest, CtHead) {
  bool skipped = false;
  absl::StatusOr<Volume> volume = ReadOrSkip(DataDir() + "/cthead.nrrd", &skipped);
  if (skipped) GTEST_SKIP() << "cthead.nrrd not found in " << DataDir();
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_EQ(volume->dims, (std::array<int, 3>{256, 256, 113}));
  EXPECT_EQ(volume->source_type, ScalarType::kInt16);
  EXPECT_EQ(volume->spacing, (std::array<double, 3>{1, 1, 2}));
  EXPECT_EQ(volume->values.size(), 256u * 256u * 113u);
  EXPECT_EQ(volume->Range(), (std::array<float, 2>{0.0f, 3272.0f}));
}

TEST_F(RealDataTest, HeadSq) {
  bool skipped = false;
  absl::StatusOr<Volume> volume = ReadOrSkip(DataDir() + "/headsq.nrrd", &skipped);
  if (skipped) GTEST_SKIP() << "headsq.nrrd not found in " << DataDir();
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_EQ(volume->dims, (std::array<int, 3>{64, 64, 93}));
  EXPECT_EQ(volume->source_type, ScalarType::kUint16);
  EXPECT_DOUBLE_EQ(volume->spacing[0], 3.2);
  EXPECT_DOUBLE_EQ(volume->spacing[1], 3.2);
  EXPECT_DOUBLE_EQ(volume->spacing[2], 1.5);
  EXPECT_EQ(volume->Range(), (std::array<float, 2>{0.0f, 3926.0f}));
}

TEST_F(RealDataTest, Neghip) {
  bool skipped = false;
  absl::StatusOr<Volume> volume = ReadOrSkip(DataDir() + "/neghip.nrrd", &skipped);
  if (skipped) GTEST_SKIP() << "neghip.nrrd not found in " << DataDir();
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_EQ(volume->dims, (std::array<int, 3>{66, 66, 66}));
  EXPECT_EQ(volume->source_type, ScalarType::kUint8);
  const std::array<float, 2> range = volume->Range();
  EXPECT_GE(range[0], 0.0f);
  EXPECT_LE(range[1], 255.0f);
  EXPECT_GT(range[1], range[0]);
}

TEST_F(RealDataTest, BrainSmallDen) {
  bool skipped = false;
  absl::StatusOr<Volume> volume =
      ReadOrSkip("/usr/share/doc/libvolpack1-dev/examples/brainsmall.den", &skipped);
  if (skipped) GTEST_SKIP() << "libvolpack1-dev's brainsmall.den is not installed";
  ASSERT_TRUE(volume.ok()) << volume.status();
  EXPECT_EQ(volume->dims, (std::array<int, 3>{128, 128, 84}));
  EXPECT_EQ(volume->source_type, ScalarType::kUint8);
  const std::array<float, 2> range = volume->Range();
  EXPECT_GE(range[0], 0.0f);
  EXPECT_LE(range[1], 255.0f);
  EXPECT_GT(range[1], 100.0f);  // an MR head, not an empty box
}

// ---------------------------------------------------------------------------
// Synthetic volumes

size_t CountNonZero(const Volume& volume) {
  size_t n = 0;
  for (float v : volume.values) n += v != 0.0f;
  return n;
}

TEST(SyntheticTest, SphereVolumeMatchesFormula) {
  for (double radius : {10.0, 20.0, 27.5}) {
    const Volume sphere = MakeSphere({64, 64, 64}, {32, 32, 32}, radius, 7.0f);
    EXPECT_EQ(sphere.dims, (std::array<int, 3>{64, 64, 64}));
    const double expected = 4.0 / 3.0 * kPi * radius * radius * radius;
    const double count = static_cast<double>(CountNonZero(sphere));
    EXPECT_NEAR(count / expected, 1.0, 0.02) << "radius " << radius;
    EXPECT_EQ(sphere.At(32, 32, 32), 7.0f);
    EXPECT_EQ(sphere.At(0, 0, 0), 0.0f);
  }
}

TEST(SyntheticTest, SphereIsSymmetric) {
  const Volume sphere = MakeSphere({20, 20, 20}, {10, 10, 10}, 6.3);
  for (int z = 0; z < 20; ++z) {
    for (int y = 0; y < 20; ++y) {
      for (int x = 0; x < 20; ++x) {
        ASSERT_EQ(sphere.At(x, y, z), sphere.At(19 - x, y, z));
        ASSERT_EQ(sphere.At(x, y, z), sphere.At(y, z, x));
      }
    }
  }
}

TEST(SyntheticTest, SlabCountIsExact) {
  for (int axis = 0; axis < 3; ++axis) {
    const Volume slab = MakeSlab({10, 20, 30}, axis, 3, 8, 50.0f);
    const size_t others = 10 * 20 * 30 / static_cast<size_t>(slab.dims[axis]);
    EXPECT_EQ(CountNonZero(slab), 5 * others) << "axis " << axis;
    EXPECT_EQ(slab.Range(), (std::array<float, 2>{0.0f, 50.0f}));
  }
  const Volume slab = MakeSlab({4, 4, 4}, 2, 1, 2);
  EXPECT_EQ(slab.At(3, 3, 1), 100.0f);
  EXPECT_EQ(slab.At(3, 3, 0), 0.0f);
  EXPECT_EQ(slab.At(3, 3, 2), 0.0f);
}

TEST(SyntheticTest, PhantomIsDeterministic) {
  const Volume a = MakeNoisyPhantom({32, 40, 24}, 42);
  const Volume b = MakeNoisyPhantom({32, 40, 24}, 42);
  const Volume c = MakeNoisyPhantom({32, 40, 24}, 43);
  EXPECT_EQ(a.values, b.values);
  EXPECT_NE(a.values, c.values);
  const std::array<float, 2> range = a.Range();
  EXPECT_GE(range[0], 0.0f);
  EXPECT_GT(range[1], 900.0f);  // the skull
  // Without noise, the centre of the head is brain (1000 - 600) and a corner is empty.
  const Volume clean = MakeNoisyPhantom({64, 64, 64}, 1, 0.0f);
  EXPECT_EQ(clean.At(0, 0, 0), 0.0f);
  EXPECT_EQ(clean.At(32, 32, 32), 400.0f);
}

TEST(SyntheticTest, RandomIsDeterministicAndInRange) {
  const Volume a = MakeRandom({16, 16, 16}, 7, 4);
  const Volume b = MakeRandom({16, 16, 16}, 7, 4);
  EXPECT_EQ(a.values, b.values);
  EXPECT_NE(a.values, MakeRandom({16, 16, 16}, 8, 4).values);
  std::array<int, 4> histogram = {0, 0, 0, 0};
  for (float v : a.values) {
    ASSERT_GE(v, 0.0f);
    ASSERT_LT(v, 4.0f);
    ASSERT_EQ(v, std::floor(v));
    ++histogram[static_cast<size_t>(v)];
  }
  for (int count : histogram) EXPECT_NEAR(count, 4096 / 4, 150);
}

}  // namespace
}  // namespace transtick
