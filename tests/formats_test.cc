// The readers of MetaImage, VTK image data and DICOM series, orientation
// (every reader's, and the camera's mapping into the volume's frame), and
// the presets. Files are written by the tests: MetaImage and .vti by hand,
// DICOM with GDCM.
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <lz4.h>
#include <lzma.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "dicom_writer.h"
#include "transtick/camera.h"
#include "transtick/classification.h"
#include "transtick/orientation.h"
#include "transtick/presets.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

class FormatsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/transtick_formats_XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& bytes) {
    const std::string path = dir_ + "/" + name;
    std::filesystem::create_directories(std::filesystem::path(path).parent_path());
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }

  static void ExpectError(const absl::StatusOr<Volume>& v, const std::string& path,
                          const std::string& hint) {
    ASSERT_FALSE(v.ok()) << "read " << path << " though it is malformed (" << hint << ")";
    EXPECT_THAT(std::string(v.status().message()),
                HasSubstr(std::filesystem::path(path).filename().string()));
    EXPECT_THAT(std::string(v.status().message()), HasSubstr(hint));
  }

  std::string dir_;
};

// int16 samples 0, 7, 14, ... minus 100 (some negative), little-endian.
std::vector<int16_t> Samples(int n) {
  std::vector<int16_t> s(n);
  for (int i = 0; i < n; ++i) s[i] = static_cast<int16_t>(i * 7 - 100);
  return s;
}

std::string Bytes(const std::vector<int16_t>& s) {
  return std::string(reinterpret_cast<const char*>(s.data()), s.size() * 2);
}

std::string Zlib(const std::string& raw) {
  uLongf n = compressBound(raw.size());
  std::string out(n, '\0');
  EXPECT_EQ(compress(reinterpret_cast<Bytef*>(out.data()), &n,
                     reinterpret_cast<const Bytef*>(raw.data()), raw.size()),
            Z_OK);
  out.resize(n);
  return out;
}

void ExpectSamples(const Volume& v, const std::vector<int16_t>& s) {
  ASSERT_EQ(v.values.size(), s.size());
  for (size_t i = 0; i < s.size(); ++i) ASSERT_EQ(v.values[i], s[i]) << "sample " << i;
}

// ---------------------------------------------------------------------------
// MetaImage

std::string MhaHeader(const std::string& extra, bool compressed = false) {
  return "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
         "CompressedData = " +
         std::string(compressed ? "True" : "False") +
         "\nDimSize = 4 3 2\nElementSpacing = 0.5 0.75 2\nElementType = MET_SHORT\n" + extra +
         "ElementDataFile = LOCAL\n";
}

TEST_F(FormatsTest, MetaImageRawCompressedAndDetached) {
  const auto s = Samples(24);
  const std::string raw = Write("a.mha", MhaHeader("") + Bytes(s));
  const std::string zipped = Write("z.mha", MhaHeader("", true) + Zlib(Bytes(s)));
  for (const std::string& path : {raw, zipped}) {
    auto v = ReadVolume(path);
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ(v->dims, (std::array<int, 3>{4, 3, 2}));
    EXPECT_EQ(v->spacing, (std::array<double, 3>{0.5, 0.75, 2}));
    EXPECT_EQ(v->source_type, ScalarType::kInt16);
    EXPECT_TRUE(IsIdentity(v->direction));
    ExpectSamples(*v, s);
  }
  Write("d.raw", Bytes(s));
  std::string header = MhaHeader("");
  header.replace(header.find("LOCAL"), 5, "d.raw");
  auto v = ReadVolume(Write("d.mhd", header));
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(*v, s);
}

TEST_F(FormatsTest, MetaImageTransformMatrixAndOffset) {
  const auto s = Samples(24);
  // x along world y, y along world -x, z along z: a rotation by 90 degrees.
  auto v = ReadVolume(Write("r.mha", MhaHeader("TransformMatrix = 0 1 0 -1 0 0 0 0 1\n"
                                               "Offset = 10 20 30\n") +
                                         Bytes(s)));
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->direction, (Direction{{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}}));
  EXPECT_EQ(v->origin, (std::array<double, 3>{10, 20, 30}));
  EXPECT_FALSE(v->x_reversed);
  EXPECT_EQ(OrientationCode(v->direction), "PRS");
  ExpectSamples(*v, s);
}

TEST_F(FormatsTest, MetaImageErrorsNameTheFile) {
  const auto s = Samples(24);
  ExpectError(ReadVolume(Write("short.mha", MhaHeader("") + Bytes(s).substr(0, 40))), "short.mha",
              "holds 40");
  ExpectError(ReadVolume(Write("long.mha", MhaHeader("") + Bytes(s) + "xx")), "long.mha",
              "holds 50");
  std::string bad_type = MhaHeader("");
  bad_type.replace(bad_type.find("MET_SHORT"), 9, "MET_LONG");
  ExpectError(ReadVolume(Write("long.mha", bad_type + Bytes(s))), "long.mha", "MET_LONG");
  ExpectError(ReadVolume(Write("zcut.mha", MhaHeader("", true) + Zlib(Bytes(s)).substr(0, 10))),
              "zcut.mha", "truncated");
  std::string huge = MhaHeader("");
  huge.replace(huge.find("4 3 2"), 5, "100000 100000 100000");
  auto v = ReadVolume(Write("huge.mha", huge));
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.status().code(), absl::StatusCode::kResourceExhausted);
  ExpectError(ReadVolume(Write("noend.mha", "ObjectType = Image\nNDims = 3\n")), "noend.mha",
              "ElementDataFile");
  ExpectError(ReadVolume(Write("shear.mha", MhaHeader("TransformMatrix = 1 0 0 0.5 1 0 0 0 1\n") +
                                                Bytes(s))),
              "shear.mha", "not orthogonal");
  ExpectError(ReadVolume(Write("list.mha", MhaHeader("") + "")), "list.mha", "holds 0");
}

// ---------------------------------------------------------------------------
// VTK image data

std::string Vti(const std::string& file_attrs, const std::string& image_attrs,
                const std::string& array, const std::string& appended) {
  return "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" "
         "byte_order=\"LittleEndian\" header_type=\"UInt64\" " +
         file_attrs + ">\n  <ImageData WholeExtent=\"0 3 0 2 0 1\" Origin=\"1 2 3\" " +
         image_attrs + ">\n    <Piece Extent=\"0 3 0 2 0 1\">\n      <PointData Scalars=\"v\">\n" +
         "        <DataArray type=\"Int8\" Name=\"other\" format=\"appended\" offset=\"0\"/>\n" +
         "        " + array + "\n      </PointData>\n    </Piece>\n  </ImageData>\n" +
         "  <AppendedData encoding=\"raw\">\n   _" + appended + "\n  </AppendedData>\n</VTKFile>\n";
}

std::string U64(uint64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }

// One block as VTK's LZ4 compressor writes it: a raw LZ4 block.
std::string Lz4(const std::string& raw) {
  std::string out(LZ4_compressBound(static_cast<int>(raw.size())), '\0');
  const int n = LZ4_compress_default(raw.data(), out.data(), static_cast<int>(raw.size()),
                                     static_cast<int>(out.size()));
  EXPECT_GT(n, 0);
  out.resize(n);
  return out;
}

// One block as VTK's LZMA compressor writes it: an .xz stream.
std::string Lzma(const std::string& raw) {
  std::string out(lzma_stream_buffer_bound(raw.size()), '\0');
  size_t n = 0;
  EXPECT_EQ(lzma_easy_buffer_encode(6, LZMA_CHECK_CRC64, nullptr,
                                    reinterpret_cast<const uint8_t*>(raw.data()), raw.size(),
                                    reinterpret_cast<uint8_t*>(out.data()), &n, out.size()),
            LZMA_OK);
  out.resize(n);
  return out;
}

// base64 as VTK writes it: one run, padded with '='.
std::string Base64(const std::string& bytes) {
  static constexpr char kDigits[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t bits = 0;
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    for (size_t k = 0; k < 3; ++k) {
      bits = bits << 8 | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    }
    for (size_t k = 0; k < 4; ++k) out += k <= n ? kDigits[(bits >> (18 - 6 * k)) & 63] : '=';
  }
  return out;
}

TEST_F(FormatsTest, VtiRawAndZlibAppended) {
  const auto s = Samples(24);
  const std::string data = Bytes(s);
  // The other array (8 bytes of Int8 at offset 0) comes first; "v" follows.
  const std::string other = U64(24) + std::string(24, '\1');
  const std::string offset = std::to_string(other.size());
  const std::string array =
      "<DataArray type=\"Int16\" Name=\"v\" format=\"appended\" offset=\"" + offset + "\"/>";
  auto raw = ReadVolume(
      Write("raw.vti", Vti("", "Spacing=\"0.5 0.75 2\"", array, other + U64(data.size()) + data)));
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_EQ(raw->dims, (std::array<int, 3>{4, 3, 2}));
  EXPECT_EQ(raw->spacing, (std::array<double, 3>{0.5, 0.75, 2}));
  EXPECT_EQ(raw->origin, (std::array<double, 3>{1, 2, 3}));
  ExpectSamples(*raw, s);

  // Two blocks of 32 bytes and a last one of 48 - 32 = 16.
  const std::string b0 = Zlib(data.substr(0, 32)), b1 = Zlib(data.substr(32));
  const std::string zipped = U64(2) + U64(32) + U64(16) + U64(b0.size()) + U64(b1.size()) + b0 + b1;
  auto z = ReadVolume(Write("z.vti", Vti("compressor=\"vtkZLibDataCompressor\"",
                                         "Spacing=\"0.5 0.75 2\" Direction=\"0 -1 0 1 0 0 0 0 1\"",
                                         array, other + zipped)));
  ASSERT_TRUE(z.ok()) << z.status();
  ExpectSamples(*z, s);
  // Direction is row-major with the axes as columns: x along world y.
  EXPECT_EQ(z->direction, (Direction{{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}}));
}

TEST_F(FormatsTest, VtiErrorsNameTheFile) {
  const auto s = Samples(24);
  const std::string data = Bytes(s);
  const std::string array = "<DataArray type=\"Int16\" Name=\"v\" format=\"appended\" offset=\"0\"/>";
  ExpectError(ReadVolume(Write("count.vti", Vti("", "", array, U64(47) + data))), "count.vti",
              "byte count is 47");
  ExpectError(ReadVolume(Write("cut.vti", Vti("", "", array, U64(48) + data.substr(0, 5)))),
              "cut.vti", "");
  ExpectError(ReadVolume(Write("i64.vti", Vti("", "",
                                              "<DataArray type=\"Int64\" Name=\"v\" "
                                              "format=\"appended\" offset=\"0\"/>",
                                              U64(192) + data))),
              "i64.vti", "Int64");
  // Three bytes of base64, where the header needs eight.
  ExpectError(ReadVolume(Write("b64.vti", Vti("", "",
                                              "<DataArray type=\"Int16\" Name=\"v\" "
                                              "format=\"binary\">AAAA</DataArray>",
                                              ""))),
              "b64.vti", "byte count (truncated?)");
  const std::string inline_array = "<DataArray type=\"Int16\" Name=\"v\" format=\"binary\">";
  ExpectError(ReadVolume(Write("char.vti", Vti("", "", inline_array + "AAAA*AAA</DataArray>", ""))),
              "char.vti", "'*' is not base64");
  ExpectError(ReadVolume(Write("pad.vti", Vti("", "", inline_array + "A===</DataArray>", ""))),
              "pad.vti", "'=' after one character");
  ExpectError(ReadVolume(Write("none.vti", Vti("", "",
                                               "<DataArray type=\"Int16\" Name=\"v\" "
                                               "format=\"binary\"/>",
                                               ""))),
              "none.vti", "has no content");
  const std::string ascii = "<DataArray type=\"Int16\" Name=\"v\" format=\"ascii\">";
  std::string numbers;
  for (int16_t v : s) numbers += std::to_string(v) + " ";
  ExpectError(ReadVolume(Write("few.vti", Vti("", "", ascii + "1 2 3</DataArray>", ""))), "few.vti",
              "holds 3 samples, its header says 24");
  ExpectError(ReadVolume(Write("many.vti", Vti("", "", ascii + numbers + "7</DataArray>", ""))),
              "many.vti", "more than the 24 samples");
  ExpectError(ReadVolume(Write("word.vti", Vti("", "", ascii + "1 two 3</DataArray>", ""))),
              "word.vti", "'two' is not a number");
  ExpectError(ReadVolume(Write("zstd.vti", Vti("compressor=\"vtkZstdDataCompressor\"", "", array,
                                               U64(48) + data))),
              "zstd.vti", "vtkZstdDataCompressor");
  // Blocks that do not decompress to what the header says, in each codec.
  for (const char* c : {"vtkZLibDataCompressor", "vtkLZ4DataCompressor", "vtkLZMADataCompressor"}) {
    const std::string half = data.substr(0, 24);
    const std::string block = std::string(c) == "vtkZLibDataCompressor"  ? Zlib(half)
                              : std::string(c) == "vtkLZ4DataCompressor" ? Lz4(half)
                                                                         : Lzma(half);
    ExpectError(
        ReadVolume(Write("short.vti", Vti(absl::StrCat("compressor=\"", c, "\""), "", array,
                                          U64(1) + U64(48) + U64(0) + U64(block.size()) + block))),
        "short.vti", "does not inflate to 48 bytes");
  }
  const std::string lie = U64(1000000) + U64(32) + U64(0) + U64(10);
  ExpectError(ReadVolume(Write("blocks.vti",
                               Vti("compressor=\"vtkZLibDataCompressor\"", "", array, lie))),
              "blocks.vti", "blocks");
  const std::string corrupt = U64(1) + U64(48) + U64(0) + U64(6) + "garbag";
  ExpectError(ReadVolume(Write("corrupt.vti",
                               Vti("compressor=\"vtkZLibDataCompressor\"", "", array, corrupt))),
              "corrupt.vti", "corrupt");
  ExpectError(ReadVolume(Write("notxml.vti", "hello")), "notxml.vti", "not a VTK XML file");
}

// Every way VTK's XML writers store a volume's array: appended raw or in
// base64, inline in base64 (format "binary") or as numbers ("ascii"), each
// uncompressed or compressed in blocks of a random size by zlib, LZ4 or
// LZMA; base64 in several runs (VTK encodes the header and the data apart,
// each padded), with white space between characters inline; Int16 and
// Float64. 300 random volumes and ways, against their samples.
TEST_F(FormatsTest, VtiEveryLayoutVtkWrites) {
  std::mt19937 rng(20261206);
  for (int trial = 0; trial < 300; ++trial) {
    const bool f64 = trial % 2 == 1;
    std::vector<int16_t> s(24);
    for (int16_t& v : s)
      v = static_cast<int16_t>(std::uniform_int_distribution<int>(-32768, 32767)(rng));
    std::string data;
    if (f64) {
      for (int16_t v : s) {
        const double d = v;
        data.append(reinterpret_cast<const char*>(&d), 8);
      }
    } else {
      data = Bytes(s);
    }
    const int layout = std::uniform_int_distribution<int>(0, 3)(rng);  // raw, base64, binary, ascii
    // 0: none; 1, 2, 3: zlib, LZ4, LZMA.
    const int codec = layout == 3 ? 0 : std::uniform_int_distribution<int>(0, 3)(rng);
    const bool zlib = codec != 0;
    SCOPED_TRACE(absl::StrCat("trial ", trial, " layout ", layout, " codec ", codec,
                              f64 ? " Float64" : " Int16"));
    // The header and the data, as separate runs.
    std::vector<std::string> runs;
    if (zlib) {
      const size_t block = 2 * std::uniform_int_distribution<size_t>(1, data.size() / 2)(rng);
      std::vector<std::string> blocks;
      for (size_t i = 0; i < data.size(); i += block) {
        const std::string b = data.substr(i, block);
        blocks.push_back(codec == 1 ? Zlib(b) : codec == 2 ? Lz4(b) : Lzma(b));
      }
      std::string header = U64(blocks.size()) + U64(block) + U64(data.size() % block);
      for (const std::string& b : blocks) header += U64(b.size());
      runs.push_back(header);
      std::string joined;
      for (const std::string& b : blocks) joined += b;
      runs.push_back(joined);
    } else {
      runs = {U64(data.size()), data};
    }
    const std::string type = f64 ? "Float64" : "Int16";
    const char* const kCompressors[] = {"", "vtkZLibDataCompressor", "vtkLZ4DataCompressor",
                                        "vtkLZMADataCompressor"};
    const std::string compressor =
        zlib ? absl::StrCat("compressor=\"", kCompressors[codec], "\"") : "";
    std::string file;
    if (layout <= 1) {
      // The other array (Int8, 24 bytes) first, "v" after it.
      const std::vector<std::string> other = {U64(24), std::string(24, '\1')};
      std::string appended;
      auto put = [&](const std::vector<std::string>& rs) {
        for (const std::string& r : rs) appended += layout == 1 ? Base64(r) : r;
      };
      put(other);
      const size_t offset = appended.size();
      put(runs);
      file = Vti(compressor, "",
                 "<DataArray type=\"" + type + "\" Name=\"v\" format=\"appended\" offset=\"" +
                     std::to_string(offset) + "\"/>",
                 appended);
      if (layout == 1) {
        file.replace(file.find("encoding=\"raw\""), 14, "encoding=\"base64\"");
      }
    } else {
      std::string content;
      if (layout == 2) {
        for (const std::string& r : runs) content += Base64(r);
        // White space anywhere between characters, as line-wrapped text.
        for (int k = std::uniform_int_distribution<int>(0, 6)(rng); k > 0; --k) {
          const size_t at = std::uniform_int_distribution<size_t>(0, content.size())(rng);
          content.insert(at, rng() % 2 ? "\n          " : " ");
        }
      } else {
        for (int16_t v : s) absl::StrAppend(&content, rng() % 2 ? "\n" : " ", v, f64 ? ".0" : "");
      }
      file = Vti(compressor, "",
                 "<DataArray type=\"" + type + "\" Name=\"v\" format=\"" +
                     (layout == 2 ? "binary" : "ascii") + "\">" + content + "</DataArray>",
                 "");
    }
    auto v = ReadVolume(Write("v.vti", file));
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ(v->source_type, f64 ? ScalarType::kFloat64 : ScalarType::kInt16);
    ExpectSamples(*v, s);
  }
}

// ---------------------------------------------------------------------------
// DICOM series, written with GDCM

struct SliceSpec : testing::DicomSlice {
  int frame_value = 0;  // pixel i stores frame_value * 100 + i
};

void WriteSlice(const std::string& path, SliceSpec spec) {
  spec.pixels.resize(spec.columns * spec.rows);
  for (int i = 0; i < spec.columns * spec.rows; ++i) {
    spec.pixels[i] = static_cast<int16_t>(spec.frame_value * 100 + i);
  }
  const std::string bytes = testing::DicomSliceFile(spec);
  ASSERT_FALSE(bytes.empty()) << path;
  std::ofstream(path, std::ios::binary) << bytes;
}

TEST_F(FormatsTest, DicomSeriesSortedRescaledAndOriented) {
  const std::string dir = dir_ + "/ct";
  std::filesystem::create_directories(dir);
  // Written in scrambled order, slices 2 mm apart along z, names unrelated
  // to position.
  const int order[4] = {2, 0, 3, 1};
  for (int n = 0; n < 4; ++n) {
    SliceSpec s;
    s.frame_value = order[n];
    s.position = {-10, -20, 5.0 + 2.0 * order[n]};
    WriteSlice(dir + "/IM" + std::to_string(n), s);
  }
  Write("ct/DICOMDIR", "not read");
  auto v = ReadVolume(dir);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->dims, (std::array<int, 3>{4, 3, 4}));
  EXPECT_NEAR(v->spacing[0], 0.5, 1e-9);
  EXPECT_NEAR(v->spacing[1], 0.8, 1e-9);
  EXPECT_NEAR(v->spacing[2], 2.0, 1e-9);
  EXPECT_TRUE(IsIdentity(v->direction));
  EXPECT_EQ(v->origin, (std::array<double, 3>{-10, -20, 5}));
  for (int z = 0; z < 4; ++z) {
    for (int i = 0; i < 12; ++i) {
      ASSERT_EQ(v->At(i % 4, i / 4, z), z * 100 + i - 1024) << "slice " << z << " pixel " << i;
    }
  }
}

TEST_F(FormatsTest, DicomSeriesOrientationFromTheHeaders) {
  // A sagittal series: rows along world y (posterior), columns along -z
  // (down), slices along +x... sorted by position along row x column.
  const std::string dir = dir_ + "/sag";
  std::filesystem::create_directories(dir);
  for (int n = 0; n < 3; ++n) {
    SliceSpec s;
    s.orientation = {0, 1, 0, 0, 0, -1};
    s.position = {3.0 * n, 0, 0};
    s.frame_value = n;
    WriteSlice(dir + "/s" + std::to_string(n), s);
  }
  auto v = ReadVolume(dir + "/");
  ASSERT_TRUE(v.ok()) << v.status();
  // Normal = (0,1,0) x (0,0,-1) = (-1, 0, 0): slices sorted along -x.
  EXPECT_EQ(OrientationCode(v->direction), "PIR");
  EXPECT_NEAR(v->spacing[2], 3.0, 1e-9);
  EXPECT_EQ(v->At(0, 0, 0), 200 - 1024);  // the slice at x = 6 comes first
}

TEST_F(FormatsTest, DicomSeriesRefusesGapsMixedSeriesAndJunk) {
  auto series = [&](const std::string& name, std::vector<SliceSpec> slices) {
    const std::string dir = dir_ + "/" + name;
    std::filesystem::create_directories(dir);
    for (size_t n = 0; n < slices.size(); ++n) WriteSlice(dir + "/f" + std::to_string(n), slices[n]);
    return dir;
  };
  auto at = [](double z) {
    SliceSpec s;
    s.position = {0, 0, z};
    return s;
  };
  ExpectError(ReadVolume(series("gap", {at(0), at(1), at(2), at(4), at(5)})), "gap", "missing slice");
  ExpectError(ReadVolume(series("dup", {at(0), at(1), at(1)})), "dup", "same position");
  SliceSpec other = at(2);
  other.series = "9.9.9";
  ExpectError(ReadVolume(series("mixed", {at(0), at(1), other})), "mixed",
              "2 series in one directory; read one by its path: ");
  SliceSpec big = at(2);
  big.columns = 5;
  ExpectError(ReadVolume(series("sizes", {at(0), at(1), big})), "sizes", "differ");
  SliceSpec tilted = at(2);
  tilted.position = {0, 1, 2};
  ExpectError(ReadVolume(series("tilt", {at(0), at(1), tilted})), "tilt", "tilted gantry");
  // A slice that starts as DICOM does and is damaged is an error, never
  // passed over: the volume would silently lose it.
  const std::string junk = series("junk", {at(0), at(1), at(2)});
  std::filesystem::resize_file(junk + "/f2", 140);
  ExpectError(ReadVolume(junk), "f2", "not a DICOM file, or a damaged one");
  std::filesystem::create_directories(dir_ + "/empty");
  Write("empty/readme.txt", "no DICOM here");
  ExpectError(ReadVolume(dir_ + "/empty"), "empty",
              "no DICOM images; it passed over 1 file that is not DICOM (readme.txt)");
  // A slice cut short: its header reads, its pixels do not.
  const std::string cut = series("cut", {at(0), at(1)});
  std::filesystem::resize_file(cut + "/f1", std::filesystem::file_size(cut + "/f1") - 10);
  ExpectError(ReadVolume(cut), "f1", "");
}

// Found by volume_fuzzer: GDCM allocates an element's declared length before
// reading it, so a 150-byte file declaring a 1.3 GB element cost 1.3 GB. The
// reader walks the element lengths first and refuses the file.
// A study as exports and archives leave it: several series in one
// directory, beside subdirectories, notes and reports. The path names the
// series to read ("DIR#UID"); without one the error lists them all.
TEST_F(FormatsTest, DicomStudyDirectoryNamesItsSeries) {
  const std::string dir = dir_ + "/study";
  std::filesystem::create_directories(dir + "/more/deeper");
  // Series 1.2.3.4 of 4 slices and 1.2.3.40 of 2 (one UID a prefix of the
  // other), their files interleaved by name.
  for (int n = 0; n < 6; ++n) {
    SliceSpec s;
    const bool axial = n % 3 != 2;
    s.series = axial ? "1.2.3.4" : "1.2.3.40";
    const int z = axial ? n - n / 3 : n / 3;
    s.position = {0, 0, (axial ? 1.0 : 5.0) * z};
    s.frame_value = (axial ? 10 : 20) + z;
    WriteSlice(dir + "/IM" + std::to_string(n), s);
  }
  Write("study/readme.txt", "exported by a viewer");
  Write("study/annotations.xml", "<?xml version=\"1.0\"?><reads/>");
  Write("study/empty", "");
  // A DICOM object without pixel data, as a structured report is.
  std::string report(128, '\0');
  report += "DICM";
  report += std::string("\x02\x00\x10\x00UI\x14\x00", 8) + std::string("1.2.840.10008.1.2.1\0", 20);
  report += std::string(
      "\x08\x00\x60\x00"
      "CS"
      "\x02\x00"
      "SR",
      10);
  Write("study/report.dcm", report);
  Write("study/more/deeper/IM0", "not read");

  auto all = ReadVolume(dir);
  ASSERT_FALSE(all.ok());
  const std::string listing(all.status().message());
  EXPECT_THAT(listing, HasSubstr("2 series in one directory; read one by its path: " + dir +
                                 "#1.2.3.4 (CT, 4 files); " + dir + "#1.2.3.40 (CT, 2 files)"));

  auto axial = ReadVolume(dir + "#1.2.3.4");
  ASSERT_TRUE(axial.ok()) << axial.status();
  EXPECT_EQ(axial->dims, (std::array<int, 3>{4, 3, 4}));
  EXPECT_NEAR(axial->spacing[2], 1.0, 1e-9);
  for (int z = 0; z < 4; ++z) EXPECT_EQ(axial->At(1, 0, z), (10 + z) * 100 + 1 - 1024) << z;
  EXPECT_THAT(axial->notes,
              ::testing::ElementsAre(
                  "passed over 1 subdirectory (more/)",
                  "passed over 3 files that are not DICOM (annotations.xml, empty, readme.txt)",
                  "passed over 1 DICOM file without an image (report.dcm)",
                  "read series 1.2.3.4 (CT, 4 files) of 2 in the directory"));
  auto other = ReadVolume(dir + "/#1.2.3.40");  // a trailing slash on the directory is fine
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_EQ(other->dims[2], 2);
  EXPECT_NEAR(other->spacing[2], 5.0, 1e-9);
  EXPECT_EQ(other->At(0, 0, 1), 2100 - 1024);

  auto missing = ReadVolume(dir + "#1.2.3");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(missing.status().message()), HasSubstr("no series 1.2.3 in"));
  EXPECT_THAT(std::string(missing.status().message()), HasSubstr("1.2.3.40 (CT, 2 files)"));
  // A name with a '#' that exists is read as itself, not as a series.
  std::filesystem::create_directories(dir_ + "/one#2");
  for (int n = 0; n < 2; ++n) {
    SliceSpec s;
    s.position = {0, 0, 2.0 * n};
    WriteSlice(dir_ + "/one#2/f" + std::to_string(n), s);
  }
  auto hashed = ReadVolume(dir_ + "/one#2");
  ASSERT_TRUE(hashed.ok()) << hashed.status();
  EXPECT_TRUE(hashed->notes.empty());
  // A series is read whatever the other series in its directory hold, and
  // a series that cannot be read says why when it is named.
  SliceSpec odd;
  odd.series = "7.7";
  odd.spacing = {-0.5, 0.8};
  WriteSlice(dir + "/IM9", odd);
  EXPECT_TRUE(ReadVolume(dir + "#1.2.3.4").ok());
  ExpectError(ReadVolume(dir + "#7.7"), "IM9", "is not positive");
  // The listing a viewer offers: each series as the path that reads it,
  // and the reader's own refusal for the one that would not read.
  auto listed = ListDicomSeries(dir);
  ASSERT_TRUE(listed.ok()) << listed.status();
  ASSERT_EQ(listed->size(), 3u);
  const DicomSeriesInfo& first = (*listed)[0];
  EXPECT_EQ(first.uid, "1.2.3.4");
  EXPECT_EQ(first.path, dir + "#1.2.3.4");
  EXPECT_EQ(first.modality, "CT");
  EXPECT_EQ(first.summary, "CT, 4 files");
  EXPECT_EQ(first.files, 4u);
  EXPECT_EQ(first.frames, 4u);
  EXPECT_EQ(first.columns, 4);
  EXPECT_EQ(first.rows, 3);
  EXPECT_EQ(first.problem, "");
  uint64_t bytes = 0;
  for (int n : {0, 1, 3, 4}) bytes += std::filesystem::file_size(dir + "/IM" + std::to_string(n));
  EXPECT_EQ(first.bytes, bytes);
  EXPECT_EQ((*listed)[1].path, dir + "#1.2.3.40");
  EXPECT_EQ((*listed)[1].files, 2u);
  EXPECT_EQ((*listed)[2].path, dir + "#7.7");
  EXPECT_THAT((*listed)[2].problem, HasSubstr("is not positive"));
  // A directory of one series is listed as itself; a gap is what the
  // reader says it is.
  auto one = ListDicomSeries(dir_ + "/one#2");
  ASSERT_TRUE(one.ok()) << one.status();
  ASSERT_EQ(one->size(), 1u);
  EXPECT_EQ((*one)[0].path, dir_ + "/one#2");
  SliceSpec far;
  far.position = {0, 0, 8};
  WriteSlice(dir_ + "/one#2/f9", far);
  one = ListDicomSeries(dir_ + "/one#2");
  ASSERT_TRUE(one.ok()) << one.status();
  const absl::StatusOr<Volume> refused = ReadVolume(dir_ + "/one#2");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ((*one)[0].problem, refused.status().message());
  EXPECT_THAT((*one)[0].problem, HasSubstr("a missing slice"));
  // Nothing to list.
  EXPECT_FALSE(ListDicomSeries(dir + "/more").ok());
}

// Multi-frame images, as enhanced CT and MR scanners and RT planning
// systems write them: each frame a slice, placed and rescaled by its
// functional groups or an RT dose's frame offsets, sorted with the other
// files of the series.
TEST_F(FormatsTest, DicomMultiFrameImagesBecomeVolumes) {
  auto write = [&](const std::string& name, const testing::DicomMultiFrame& image) {
    std::filesystem::create_directories(std::filesystem::path(dir_ + "/" + name).parent_path());
    const std::string bytes = testing::DicomMultiFrameFile(image);
    ASSERT_FALSE(bytes.empty()) << name;
    Write(name, bytes);
  };
  // Frame k lies at z = 2 order[k] and stores k * 100 + i, rescaled by its
  // own slope and intercept.
  const int order[5] = {3, 0, 4, 1, 2};
  testing::DicomMultiFrame mr;
  for (int k = 0; k < 5; ++k) {
    mr.positions.push_back({-4, 6, 10.0 + 2.0 * order[k]});
    mr.rescale.push_back({k % 2 ? 2.0 : 1.0, -10.0 * k});
    for (int i = 0; i < 12; ++i) mr.pixels.push_back(static_cast<int16_t>(k * 100 + i));
  }
  write("mr/enhanced.dcm", mr);
  auto v = ReadVolume(dir_ + "/mr");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->dims, (std::array<int, 3>{4, 3, 5}));
  EXPECT_NEAR(v->spacing[0], 0.5, 1e-9);
  EXPECT_NEAR(v->spacing[1], 0.8, 1e-9);
  EXPECT_NEAR(v->spacing[2], 2.0, 1e-9);
  EXPECT_EQ(v->origin, (std::array<double, 3>{-4, 6, 10}));
  EXPECT_TRUE(v->notes.empty());
  for (int k = 0; k < 5; ++k) {
    for (int i = 0; i < 12; ++i) {
      ASSERT_EQ(v->At(i % 4, i / 4, order[k]), (k * 100 + i) * (k % 2 ? 2.0 : 1.0) - 10.0 * k)
          << "frame " << k << " pixel " << i;
    }
  }
  // The same frames as a sagittal stack.
  testing::DicomMultiFrame sagittal = mr;
  sagittal.orientation = {0, 1, 0, 0, 0, -1};
  for (int k = 0; k < 5; ++k) sagittal.positions[k] = {3.0 * order[k], 0, 0};
  write("sag/enhanced.dcm", sagittal);
  v = ReadVolume(dir_ + "/sag");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(OrientationCode(v->direction), "PIR");
  EXPECT_NEAR(v->spacing[2], 3.0, 1e-9);
  EXPECT_EQ(v->At(0, 0, 0), 200 - 20);  // frame 2 (x = 12) comes first along -x

  // A multi-frame file and single-frame files of one series make one
  // volume: frames at z 0..4, slices at 5 and 6.
  testing::DicomMultiFrame part = mr;
  part.series = "1.2.3.4";
  write("mixed/a_frames.dcm", part);
  for (int z = 5; z < 7; ++z) {
    SliceSpec s;
    s.position = {-4, 6, 10.0 + 2.0 * z};
    s.spacing = {0.5, 0.8};
    s.frame_value = z;
    WriteSlice(dir_ + "/mixed/z" + std::to_string(z), s);
  }
  v = ReadVolume(dir_ + "/mixed");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->dims[2], 7);
  EXPECT_EQ(v->At(1, 0, 0), 101 * 2 - 10);  // frame 1 at z = 0
  EXPECT_EQ(v->At(1, 0, 6), 601 - 1024);
  auto listed = ReadVolume(dir_ + "/mixed/");
  ASSERT_TRUE(listed.ok());

  // An RT dose: no functional groups; frame offsets along the normal and a
  // dose grid scaling.
  testing::DicomMultiFrame dose;
  dose.grid_offsets = true;
  dose.sop_class = "1.2.840.10008.5.1.4.1.1.481.2";  // RT Dose Storage
  dose.rescale = {{0.5, 0}};
  for (int k = 0; k < 4; ++k) {
    dose.positions.push_back({1, 2, -3.0 - 2.5 * k});  // descending z: sorted ascending
    for (int i = 0; i < 12; ++i) dose.pixels.push_back(static_cast<int16_t>(k * 100 + i));
  }
  write("dose/RD.dcm", dose);
  v = ReadVolume(dir_ + "/dose");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->dims, (std::array<int, 3>{4, 3, 4}));
  EXPECT_NEAR(v->spacing[2], 2.5, 1e-9);
  EXPECT_NEAR(v->origin[2], -10.5, 1e-9);
  EXPECT_EQ(v->At(3, 2, 0), (300 + 11) * 0.5);  // the last frame lies lowest
  EXPECT_EQ(v->At(3, 2, 3), 11 * 0.5);

  // Refused, naming the file and what is wrong.
  testing::DicomMultiFrame stacks = mr;
  stacks.positions = {{0, 0, 0}, {0, 0, 2}, {0, 0, 0}, {0, 0, 2}};  // two echoes of two slices
  stacks.rescale.resize(4);
  write("stacks/e.dcm", stacks);
  ExpectError(ReadVolume(dir_ + "/stacks"), "e.dcm", "the image holds several stacks");
  testing::DicomMultiFrame short_groups = mr;
  short_groups.declared_frames = 6;
  write("groups/g.dcm", short_groups);
  ExpectError(ReadVolume(dir_ + "/groups"), "g.dcm", "has 6 frames but functional groups for 5");
  testing::DicomMultiFrame few_offsets = dose;
  few_offsets.declared_frames = 5;
  write("offsets/o.dcm", few_offsets);
  ExpectError(ReadVolume(dir_ + "/offsets"), "o.dcm",
              "has 5 frames but no position for each (no per-frame functional groups, and a "
              "GridFrameOffsetVector of 4 values)");
  write("cut/c.dcm", mr);
  std::filesystem::resize_file(dir_ + "/cut/c.dcm",
                               std::filesystem::file_size(dir_ + "/cut/c.dcm") - 2);
  // Seen in the header, before the pixels are read.
  ExpectError(ReadVolume(dir_ + "/cut"), "c.dcm",
              "pixel data of 120 bytes (118 in the file) for 5 frames of 4x3 16-bit pixels that "
              "need 120 (truncated?)");
}

TEST(SeriesPathTest, OnlyADigitsAndDotsUidAfterTheLastHash) {
  auto parsed = ParseSeriesPath("data/study#1.2.840.113619.2.55");
  ASSERT_TRUE(parsed.has_value());
  EXPECT_EQ(parsed->dir, "data/study");
  EXPECT_EQ(parsed->series, "1.2.840.113619.2.55");
  EXPECT_EQ(ParseSeriesPath("a#b#12")->dir, "a#b");
  for (const char* not_a_series :
       {"study", "study#", "#1.2", "scan#1.nrrd", "study#1.2/IM1", "study#1 2", "a#-1",
        "s#12345678901234567890123456789012345678901234567890123456789012345"}) {
    EXPECT_FALSE(ParseSeriesPath(not_a_series).has_value()) << not_a_series;
  }
}

TEST_F(FormatsTest, DicomElementThatLiesAboutItsLength) {
  std::string file(128, '\0');
  file += "DICM";
  const std::string syntax("1.2.840.10008.1.2.1\0", 20);
  file += std::string("\x02\x00\x10\x00UI\x14\x00", 8) + syntax;
  // (0009,0010) OB, 2 reserved bytes, a length of 0x50000000, 8 bytes.
  file += std::string("\x09\x00\x10\x00OB\x00\x00\x00\x00\x00\x50", 12) + "12345678";
  const std::string dir = dir_ + "/lie";
  std::filesystem::create_directories(dir);
  Write("lie/slice", file);
  ExpectError(ReadVolume(dir), "slice", "declares 1342177280 bytes, 8 remain");
  // Cut inside an element's header, and a sequence whose item lies.
  Write("lie/slice", file.substr(0, 136));
  ExpectError(ReadVolume(dir), "slice", "cut short");
  std::string sequence = file.substr(0, 160);
  sequence += std::string("\x08\x00\x15\x11SQ\x00\x00\xff\xff\xff\xff", 12);
  sequence += std::string("\xfe\xff\x00\xe0\x00\x00\x00\x40", 8) + "xx";
  Write("lie/slice", sequence);
  ExpectError(ReadVolume(dir), "slice", "item");
  // Also found by volume_fuzzer: an element of an unknown VR, which GDCM
  // reads as implicit VR, taking later bytes ("0\\0\\") for a 1.5 GB length.
  std::string unknown = file.substr(0, 160);
  unknown += std::string("\x20\x00\x32\x00ZZ\x06\x000\\0\\0 ", 14);
  Write("lie/slice", unknown);
  ExpectError(ReadVolume(dir), "slice", "no valid VR");
  // Also found by volume_fuzzer: a file that ends with its meta group made
  // GDCM fail an assertion ("Should not happen") and abort the process.
  Write("lie/slice", file.substr(0, 160));
  ExpectError(ReadVolume(dir), "slice", "no data set after the file meta group");
  // Also found by volume_fuzzer: HighBit (0028,0102) of another VR than US
  // made GDCM's image reader fail an assertion.
  std::string high_bit = file.substr(0, 160);
  high_bit += std::string("\x28\x00\x02\x01" "DS" "\x02\x00" "15", 10);
  Write("lie/slice", high_bit);
  ExpectError(ReadVolume(dir), "slice", "has VR DS, not US");
  // Also found by volume_fuzzer: a RecognitionCode (0008,0010) that does
  // not name ACR-NEMA made GDCM's image reader fail an assertion.
  std::string recognition = file.substr(0, 160);
  recognition += std::string(
      "\x08\x00\x10\x00"
      "LO"
      "\x06\x00"
      "1.2.3 ",
      14);
  Write("lie/slice", recognition);
  ExpectError(ReadVolume(dir), "slice",
              "RecognitionCode (0008,0010) at byte 160 is not an ACR-NEMA one");
}

TEST_F(FormatsTest, DicomSeriesGoesThroughTheHooks) {
  const std::string dir = dir_ + "/hooked";
  std::filesystem::create_directories(dir);
  for (int n = 0; n < 2; ++n) {
    SliceSpec s;
    s.position = {0, 0, 1.0 * n};
    WriteSlice(dir + "/f" + std::to_string(n), s);
  }
  std::vector<std::string> opened, listed;
  ReadOptions options;
  options.open = [&](const std::string& path) -> absl::StatusOr<int> {
    opened.push_back(path);
    return ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  };
  options.list = [&](const std::string& path) -> absl::StatusOr<std::vector<std::string>> {
    listed.push_back(path);
    return std::vector<std::string>{".", "..", "f1", "f0"};
  };
  auto v = ReadVolume(dir, options);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(listed, std::vector<std::string>{dir});
  EXPECT_THAT(opened, ::testing::Contains(dir + "/f0"));
  EXPECT_THAT(opened, ::testing::Contains(dir + "/f1"));
  options.list = [](const std::string& path) -> absl::StatusOr<std::vector<std::string>> {
    return absl::PermissionDeniedError(path + ": outside");
  };
  EXPECT_EQ(ReadDicomSeries(dir, options).status().code(), absl::StatusCode::kPermissionDenied);
}

// A listing reads each file's header only: its bytes up to the pixel
// data's value, 16 KiB first and 4 times more while the header goes on.
TEST_F(FormatsTest, DicomListingReadsHeadersOnly) {
  const std::string dir = dir_ + "/big";
  std::filesystem::create_directories(dir);
  uint64_t total = 0;
  for (int n = 0; n < 3; ++n) {
    SliceSpec s;
    s.columns = s.rows = 256;  // 128 KiB of pixels a file
    s.position = {0, 0, 1.0 * n};
    WriteSlice(dir + "/f" + std::to_string(n), s);
    total += std::filesystem::file_size(dir + "/f" + std::to_string(n));
  }
  const uint64_t plenty = uint64_t{1} << 30;
  DicomReadBudget budget{plenty};
  auto listed = ListDicomSeries(dir, {}, &budget);
  ASSERT_TRUE(listed.ok()) << listed.status();
  ASSERT_EQ(listed->size(), 1u);
  EXPECT_EQ((*listed)[0].frames, 3u);
  EXPECT_EQ((*listed)[0].problem, "");
  EXPECT_EQ((*listed)[0].bytes, total);
  EXPECT_EQ(plenty - budget.bytes, 3 * kDicomFirstHeaderBytes) << "of " << total << " bytes";
  EXPECT_FALSE(budget.exhausted);
  // A budget that does not cover them: the listing stops, saying so.
  DicomReadBudget small{2 * kDicomFirstHeaderBytes + 100};
  auto cut = ListDicomSeries(dir, {}, &small);
  EXPECT_EQ(cut.status().code(), absl::StatusCode::kResourceExhausted) << cut.status();
  EXPECT_TRUE(small.exhausted);

  // Damage past the start of the pixel data (an element after it that
  // declares more than the file holds): the listing does not read there,
  // the reader does, and names it.
  std::ofstream(dir + "/f1", std::ios::binary | std::ios::app) << std::string(
      "\xfc\xff\xfc\xff"
      "OB"
      "\x00\x00"
      "\x00\x00\x00\x40",
      12);
  listed = ListDicomSeries(dir);
  ASSERT_TRUE(listed.ok()) << listed.status();
  EXPECT_EQ((*listed)[0].problem, "");
  ExpectError(ReadVolume(dir), "f1", "declares 1073741824 bytes");
  // Pixel data cut short is seen in the header: its length against the
  // file's size.
  std::filesystem::resize_file(dir + "/f1", std::filesystem::file_size(dir + "/f0") - 1000);
  listed = ListDicomSeries(dir);
  ASSERT_TRUE(listed.ok()) << listed.status();
  EXPECT_THAT((*listed)[0].problem, HasSubstr("truncated?"));

  // A header longer than the first look (a private element of 100,000
  // bytes before the pixel data): read in 16 KiB, 64 KiB, then whole.
  const std::string long_dir = dir_ + "/long";
  std::filesystem::create_directories(long_dir);
  for (int n = 0; n < 2; ++n) {
    SliceSpec s;
    s.private_bytes = 100000;
    s.position = {0, 0, 2.0 * n};
    s.frame_value = n;
    WriteSlice(long_dir + "/f" + std::to_string(n), s);
  }
  const uint64_t size = std::filesystem::file_size(long_dir + "/f0");
  ASSERT_GT(size, 4u * 16384);
  budget = DicomReadBudget{plenty};
  listed = ListDicomSeries(long_dir, {}, &budget);
  ASSERT_TRUE(listed.ok()) << listed.status();
  EXPECT_EQ((*listed)[0].problem, "");
  EXPECT_EQ((*listed)[0].frames, 2u);
  uint64_t looks = 0;  // 16 KiB, 64 KiB, then the whole file, of each
  for (int n = 0; n < 2; ++n) {
    // The sizes differ by a few bytes: GDCM's UIDs differ in length.
    const uint64_t file = std::filesystem::file_size(long_dir + "/f" + std::to_string(n));
    for (uint64_t want = kDicomFirstHeaderBytes;; want *= 4) {
      looks += std::min(want, file);
      if (want >= file) break;
    }
  }
  EXPECT_EQ(plenty - budget.bytes, looks);
  auto v = ReadVolume(long_dir);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(v->dims, (std::array<int, 3>{4, 3, 2}));
  EXPECT_EQ(v->values[1 * 12 + 5], 100 + 5 - 1024);  // frame 1, pixel 5, rescaled
}

// Encapsulated pixel data (RLE lossless, an undefined length): its header
// ends where the fragments begin, and the pixels decode to what a native
// series of the same slices holds.
TEST_F(FormatsTest, DicomEncapsulatedSeriesReadsAsTheNativeOne) {
  // Native and RLE pixel data is decoded in this process, JPEG lossless,
  // JPEG-LS and JPEG 2000 by transtick-dicom-decode in a process of its own
  // (docs/formats.md, "DICOM decoder process"): every one reads to the
  // native series' volume.
  using testing::DicomCodec;
  const std::pair<DicomCodec, const char*> codecs[] = {
      {DicomCodec::kNative, "1.2.840.10008.1.2.1"},
      {DicomCodec::kRle, "1.2.840.10008.1.2.5"},
      {DicomCodec::kJpegLossless, "1.2.840.10008.1.2.4.70"},
      {DicomCodec::kJpegLs, "1.2.840.10008.1.2.4.80"},
      {DicomCodec::kJpeg2000, "1.2.840.10008.1.2.4.90"}};
  auto contents = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  absl::StatusOr<Volume> native;
  for (const auto& [codec, syntax] : codecs) {
    const std::string kind = testing::CodecName(codec);
    std::filesystem::create_directories(dir_ + "/" + kind);
    for (int n = 0; n < 3; ++n) {
      SliceSpec s;
      s.columns = 64;  // kLeastJpeg2000Bytes
      s.rows = 40;
      s.codec = codec;
      s.position = {0, 0, 1.5 * n};
      s.frame_value = 7 * n - 10;  // negative values too
      WriteSlice(dir_ + "/" + kind + "/f" + std::to_string(n), s);
    }
    // Stored in its transfer syntax: compressed, all but the first.
    const std::string file = contents(dir_ + "/" + kind + "/f0");
    EXPECT_THAT(file, HasSubstr(syntax)) << kind;
    if (codec == DicomCodec::kNative) {
      native = ReadVolume(dir_ + "/" + kind);
      ASSERT_TRUE(native.ok()) << native.status();
      continue;
    }
    EXPECT_THAT(file, Not(HasSubstr(codecs[0].second))) << kind;
    auto read = ReadVolume(dir_ + "/" + kind);
    ASSERT_TRUE(read.ok()) << kind << ": " << read.status();
    EXPECT_EQ(read->dims, native->dims) << kind;
    EXPECT_EQ(read->spacing, native->spacing) << kind;
    EXPECT_EQ(read->values, native->values) << kind;
  }
  for (const char* kind : {"rle", "jpeg", "jpegls", "j2k"}) {
    auto listed = ListDicomSeries(dir_ + "/" + kind);
    ASSERT_TRUE(listed.ok()) << listed.status();
    ASSERT_EQ(listed->size(), 1u);
    EXPECT_EQ((*listed)[0].problem, "") << kind;
    EXPECT_EQ((*listed)[0].frames, 3u) << kind;
  }

  // Damaged RLE is refused before GDCM decodes it: a frame of no segments
  // made GDCM divide by zero (SIGFPE, found by volume_fuzzer), and more
  // than 15 read past the frame's header.
  const std::string good = contents(dir_ + "/rle/f1");
  const std::string header("\x02\x00\x00\x00\x40\x00\x00\x00", 8);  // 2 segments, at 64
  const size_t at = good.find(header);
  ASSERT_NE(at, std::string::npos);
  auto damaged = [&](size_t offset, char value, const std::string& hint) {
    std::string bytes = good;
    bytes[at + offset] = value;
    Write("rle/f1", bytes);
    ExpectError(ReadVolume(dir_ + "/rle"), "f1", hint);
  };
  damaged(0, 0, "RLE frame 0 is damaged: 0 segments where 16-bit pixels take 2");
  damaged(0, 16, "16 segments");
  damaged(4, 0x41, "segment 0 at bytes [65, ");
  // A run that copies more than the plane holds.
  damaged(64, 127, "RLE frame 0 is damaged: segment 0");
  Write("rle/f1", good);
  EXPECT_TRUE(ReadVolume(dir_ + "/rle").ok());
}

// A process's state letter from /proc (Z: a zombie), or 0 when it is gone.
char ProcessState(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return 0;
  const size_t paren = line.rfind(')');
  return paren + 2 < line.size() ? line[paren + 2] : 0;
}

// Compressed pixel data is decoded in a process of its own: a codec that
// aborts on a damaged file, a decoder that hangs and one that is not
// transtick's are errors that name the file, and this process goes on.
TEST_F(FormatsTest, DicomDecoderFailuresAreErrorsNamingTheFile) {
  // JPEG-lossless slices, damaged in a few bytes by volume_fuzzer: GDCM's
  // JPEG decoder fails an assertion (gdcm::JPEG16Codec::GetHeaderInfo) and
  // aborts. Before the decoder had a process of its own, that ended the
  // fuzzer, the test, and the root that read such a series.
  const std::vector<std::string> damaged = testing::WriteFuzzSeries(
      TRANSTICK_SOURCE_DIR "/tests/fuzz/corpus/volume/dicom-jpeg16-assertion", dir_ + "/damaged");
  ASSERT_EQ(damaged.size(), 4u);
  auto v = ReadVolume(dir_ + "/damaged");
  ASSERT_FALSE(v.ok());
  const std::string message(v.status().message());
  EXPECT_THAT(message, HasSubstr(dir_ + "/damaged/s"));
  EXPECT_THAT(message, HasSubstr("the DICOM decoder (GDCM, in a process of its own) was killed by "
                                 "signal 6 (Aborted) while decoding its compressed pixel data"));
  EXPECT_THAT(message, HasSubstr("Assertion"));  // its last words
  EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument);

  // A good JPEG series reads, after and beside the damaged one.
  std::filesystem::create_directories(dir_ + "/good");
  for (int n = 0; n < 2; ++n) {
    SliceSpec s;
    s.codec = testing::DicomCodec::kJpegLossless;
    s.position = {0, 0, 2.0 * n};
    s.frame_value = n;
    WriteSlice(dir_ + "/good/f" + std::to_string(n), s);
  }
  auto good = ReadVolume(dir_ + "/good");
  ASSERT_TRUE(good.ok()) << good.status();
  EXPECT_EQ(good->At(3, 2, 1), 100 + 11 - 1024);

  // A JPEG stream of zeros: GDCM refuses it, and the decoder says so.
  {
    std::ifstream in(dir_ + "/good/f1", std::ios::binary);
    const std::string bytes(std::istreambuf_iterator<char>(in), {});
    const std::string item("\xfe\xff\x00\xe0", 4);  // (FFFE,E000): the offset table, a fragment
    const size_t table = bytes.find(item);
    const size_t fragment = bytes.find(item, table + 4);
    ASSERT_NE(fragment, std::string::npos);
    const uint32_t length = static_cast<unsigned char>(bytes[fragment + 4]) |
                            static_cast<unsigned char>(bytes[fragment + 5]) << 8;
    std::string zeroed = bytes;
    zeroed.replace(fragment + 8, length, std::string(length, '\0'));
    Write("zeroed/f1", zeroed);
    std::filesystem::copy_file(dir_ + "/good/f0", dir_ + "/zeroed/f0");
    ExpectError(ReadVolume(dir_ + "/zeroed"), "zeroed/f1", "GDCM cannot decode its pixel data");
  }

  // A decoder that says hello and then never answers, as a hung codec: the
  // read is stopped after its time, and so is what the decoder started
  // (its process group).
  const std::string pid_file = dir_ + "/sleeper.pid";
  const std::string hung = Write("hung-decoder",
                                 "#!/bin/sh\nprintf 'TTDH\\001\\000\\000\\000'\n"
                                 "/bin/sleep 600 &\necho $! > " +
                                     pid_file + "\nwait\n");
  ASSERT_EQ(chmod(hung.c_str(), 0755), 0);
  ASSERT_EQ(setenv("TRANSTICK_DICOM_DECODER", hung.c_str(), 1), 0);
  ReadOptions quick;
  quick.decode_seconds = 0.5;
  auto hang = ReadVolume(dir_ + "/good", quick);
  ASSERT_FALSE(hang.ok());
  EXPECT_EQ(hang.status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_THAT(std::string(hang.status().message()),
              HasSubstr(dir_ + "/good/f0: decoding its compressed pixel data took longer than"));
  std::ifstream pid_in(pid_file);
  pid_t sleeper = 0;
  ASSERT_TRUE(pid_in >> sleeper);
  // Killed: gone, or a zombie until whoever adopted it reaps it.
  for (int i = 0; i < 100 && ProcessState(sleeper) != 0 && ProcessState(sleeper) != 'Z'; ++i) {
    usleep(10000);
  }
  const char state = ProcessState(sleeper);
  EXPECT_TRUE(state == 0 || state == 'Z') << "the hung decoder's child is still running: " << state;

  // A program that is not the decoder.
  ASSERT_EQ(setenv("TRANSTICK_DICOM_DECODER", "/bin/true", 1), 0);
  auto wrong = ReadVolume(dir_ + "/good");
  ASSERT_EQ(unsetenv("TRANSTICK_DICOM_DECODER"), 0);
  ASSERT_FALSE(wrong.ok());
  EXPECT_THAT(std::string(wrong.status().message()),
              HasSubstr(dir_ + "/good/f0: cannot decode its compressed pixel data "
                               "(1.2.840.10008.1.2.4.70): /bin/true (the DICOM decoder) exited "
                               "with status 0 as it started"));
  EXPECT_TRUE(ReadVolume(dir_ + "/good").ok());
}

// The decoder confines itself before it reads a request: code that a
// hostile file takes over there cannot open a file (the root's TLS key, its
// database) or a socket. The decoder's probe opens a file and a socket
// before and after it confines itself.
TEST_F(FormatsTest, DicomDecoderCannotOpenFilesOrSockets) {
  const std::string secret = Write("secret.key", "not for the decoder");
  const std::string command =
      absl::StrCat(TRANSTICK_DICOM_DECODER_PATH, " --probe-sandbox=", secret, " 2>&1");
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string said;
  char buf[256];
  while (fgets(buf, sizeof(buf), pipe) != nullptr) said += buf;
  EXPECT_EQ(pclose(pipe), 0) << said;
  EXPECT_EQ(said,
            "before: open ok, socket ok\n"
            "after: open Operation not permitted, socket Operation not permitted\n");
}

// A real series when Debian's sample data is installed (gdcm-data ships none
// as a series; this reads what a system has, else skips).
TEST_F(FormatsTest, RealDicomSeriesIfInstalled) {
  const char* dir = std::getenv("TRANSTICK_DICOM_SERIES");
  if (dir == nullptr) GTEST_SKIP() << "TRANSTICK_DICOM_SERIES not set";
  auto v = ReadVolume(dir);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_GT(v->dims[2], 1);
}

// ---------------------------------------------------------------------------
// Orientation: NRRD and NIfTI headers

std::string Nrrd(const std::string& fields, const std::string& data) {
  return "NRRD0004\ntype: int16\ndimension: 3\nsizes: 4 3 2\nencoding: raw\nendian: little\n" +
         fields + "\n" + data;
}

TEST_F(FormatsTest, NrrdOrientationAndReflection) {
  const auto s = Samples(24);
  // RAS with x toward the right: in LPS, x runs along -x... and y along -y:
  // a rotation by 180 degrees about z.
  auto ras = ReadVolume(Write("ras.nrrd", Nrrd("space: right-anterior-superior\n"
                                               "space directions: (1,0,0) (0,1,0) (0,0,2)\n"
                                               "space origin: (5,6,7)\n",
                                               Bytes(s))));
  ASSERT_TRUE(ras.ok()) << ras.status();
  EXPECT_EQ(OrientationCode(ras->direction), "RAS");
  EXPECT_EQ(ras->origin, (std::array<double, 3>{-5, -6, 7}));
  EXPECT_FALSE(ras->x_reversed);
  ExpectSamples(*ras, s);

  // LPS with x reversed only: a reflection, read with x reversed.
  auto mirror = ReadVolume(Write("mirror.nrrd", Nrrd("space: left-posterior-superior\n"
                                                     "space directions: (-2,0,0) (0,1,0) (0,0,1)\n"
                                                     "space origin: (10,0,0)\n",
                                                     Bytes(s))));
  ASSERT_TRUE(mirror.ok()) << mirror.status();
  EXPECT_TRUE(mirror->x_reversed);
  EXPECT_TRUE(IsIdentity(mirror->direction));
  // The file's sample x = 3 lay at world x = 10 - 2*3 = 4: now index 0.
  EXPECT_EQ(mirror->origin, (std::array<double, 3>{4, 0, 0}));
  EXPECT_EQ(mirror->At(0, 1, 1), s[(1 * 3 + 1) * 4 + 3]);
  EXPECT_EQ(mirror->At(3, 1, 1), s[(1 * 3 + 1) * 4 + 0]);

  ExpectError(ReadVolume(Write("shear.nrrd",
                               Nrrd("space directions: (1,0,0) (1,1,0) (0,0,1)\n", Bytes(s)))),
              "shear.nrrd", "not orthogonal");
  ExpectError(ReadVolume(Write("space.nrrd", Nrrd("space: 3D-left-handed\n"
                                                  "space directions: (1,0,0) (0,1,0) (0,0,1)\n",
                                                  Bytes(s)))),
              "space.nrrd", "3D-left-handed");
  ExpectError(ReadVolume(Write("origin.nrrd", Nrrd("space directions: (1,0,0) (0,1,0) (0,0,1)\n"
                                                   "space origin: (1,2)\n",
                                                   Bytes(s)))),
              "origin.nrrd", "space origin");
}

std::string NiftiHeader(int qform, int sform, float qfac, const std::array<float, 3>& quat,
                        const std::array<float, 12>& srow) {
  std::string h(352, '\0');
  auto put32 = [&](size_t o, const void* p) { std::memcpy(&h[o], p, 4); };
  auto put16 = [&](size_t o, int16_t v) { std::memcpy(&h[o], &v, 2); };
  const int32_t size = 348;
  put32(0, &size);
  put16(40, 3);
  put16(42, 4);
  put16(44, 3);
  put16(46, 2);
  put16(70, 4);  // int16
  const float pixdim[4] = {qfac, 1, 1, 1};
  for (int i = 0; i < 4; ++i) put32(76 + 4 * i, &pixdim[i]);
  const float vox = 352;
  put32(108, &vox);
  put16(252, static_cast<int16_t>(qform));
  put16(254, static_cast<int16_t>(sform));
  for (int i = 0; i < 3; ++i) put32(256 + 4 * i, &quat[i]);
  const float offset[3] = {1, 2, 3};
  for (int i = 0; i < 3; ++i) put32(268 + 4 * i, &offset[i]);
  for (int i = 0; i < 12; ++i) put32(280 + 4 * i, &srow[i]);
  std::memcpy(&h[344], "n+1\0", 4);
  return h;
}

TEST_F(FormatsTest, NiftiQformAndSform) {
  const auto s = Samples(24);
  // No transform: the identity.
  auto plain = ReadVolume(Write("plain.nii", NiftiHeader(0, 0, 1, {0, 0, 0}, {}) + Bytes(s)));
  ASSERT_TRUE(plain.ok()) << plain.status();
  EXPECT_TRUE(IsIdentity(plain->direction));
  // qform: the identity quaternion in RAS is x right, y anterior in LPS.
  auto q = ReadVolume(Write("q.nii", NiftiHeader(1, 0, 1, {0, 0, 0}, {}) + Bytes(s)));
  ASSERT_TRUE(q.ok()) << q.status();
  EXPECT_EQ(OrientationCode(q->direction), "RAS");
  EXPECT_EQ(q->origin, (std::array<double, 3>{-1, -2, 3}));
  // qfac -1 reverses k: a reflection, read with x reversed.
  auto qf = ReadVolume(Write("qf.nii", NiftiHeader(1, 0, -1, {0, 0, 0}, {}) + Bytes(s)));
  ASSERT_TRUE(qf.ok()) << qf.status();
  EXPECT_TRUE(qf->x_reversed);
  EXPECT_EQ(OrientationCode(qf->direction), "LAI");
  // sform wins over qform: x along RAS +y (anterior), y along RAS -x (right).
  auto sf = ReadVolume(Write(
      "sf.nii", NiftiHeader(1, 1, 1, {0, 0, 0}, {0, -1, 0, 9, 1, 0, 0, 8, 0, 0, 1, 7}) + Bytes(s)));
  ASSERT_TRUE(sf.ok()) << sf.status();
  EXPECT_EQ(OrientationCode(sf->direction), "AL" "S");
  EXPECT_EQ(sf->origin, (std::array<double, 3>{-9, -8, 7}));
  // A sheared sform falls back to the qform; without one it is refused.
  const std::array<float, 12> shear = {1, 1, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  auto fallback = ReadVolume(Write("fb.nii", NiftiHeader(1, 1, 1, {0, 0, 0}, shear) + Bytes(s)));
  ASSERT_TRUE(fallback.ok()) << fallback.status();
  EXPECT_EQ(OrientationCode(fallback->direction), "RAS");
  ExpectError(ReadVolume(Write("shear.nii", NiftiHeader(0, 1, 1, {0, 0, 0}, shear) + Bytes(s))),
              "shear.nii", "not orthogonal");
}

// ---------------------------------------------------------------------------
// A known asymmetric volume against its expected projection

// An L of voxels (a foot along x, a stem along y, the stem deeper in z)
// in a grid of nx x ny x nz with spacing (1, 1.5, 2), in the world's axes.
constexpr int kNx = 12, kNy = 10, kNz = 6;
constexpr double kSpacing[3] = {1, 1.5, 2};
bool InL(int i, int j, int k) {
  const bool foot = i >= 2 && i < 10 && j >= 2 && j < 4 && k >= 1 && k < 3;
  const bool stem = i >= 2 && i < 4 && j >= 2 && j < 9 && k >= 1 && k < 5;
  return foot || stem;
}

// The orthographic image of the L seen along a world axis, from the
// definition: a pixel is lit when its ray's (right, up) coordinates fall in
// a voxel's world box. -1 where the pixel's centre lies within a quarter
// pixel of a voxel's edge (either answer is right there).
std::vector<int> ExpectedMask(const Camera& world_camera, double half_height, int size) {
  std::vector<int> mask(size * size, 0);
  const Vec3 right = world_camera.right(), up = world_camera.up();
  const double pixel = 2 * half_height / size, slack = 0.25 * pixel;
  for (int py = 0; py < size; ++py) {
    for (int px = 0; px < size; ++px) {
      const double sx = (2.0 * (px + 0.5) / size - 1.0) * half_height;
      const double sy = (1.0 - 2.0 * (py + 0.5) / size) * half_height;
      int lit = 0;
      bool edge = false;
      for (int k = 0; k < kNz; ++k)
        for (int j = 0; j < kNy; ++j)
          for (int i = 0; i < kNx; ++i) {
            if (!InL(i, j, k)) continue;
            const Vec3 lo{(i - kNx / 2.0) * kSpacing[0], (j - kNy / 2.0) * kSpacing[1],
                          (k - kNz / 2.0) * kSpacing[2]};
            const Vec3 hi = lo + Vec3{kSpacing[0], kSpacing[1], kSpacing[2]};
            // The box's interval along a camera axis (axis-aligned views).
            auto interval = [&](const Vec3& axis) {
              const double a = Dot(lo, axis), b = Dot(hi, axis);
              return std::array<double, 2>{std::min(a, b), std::max(a, b)};
            };
            const auto x = interval(right), y = interval(up);
            const bool in_x = sx > x[0] && sx < x[1], in_y = sy > y[0] && sy < y[1];
            if (in_x && in_y) lit = 1;
            const bool near_x = std::fabs(sx - x[0]) < slack || std::fabs(sx - x[1]) < slack;
            const bool near_y = std::fabs(sy - y[0]) < slack || std::fabs(sy - y[1]) < slack;
            if ((near_x && (in_y || near_y)) || (near_y && (in_x || near_x))) edge = true;
          }
      mask[py * size + px] = edge ? -1 : lit;
    }
  }
  return mask;
}

std::vector<int> RenderedMask(const Volume& volume, const CameraSpec& world) {
  Classification c;
  Material m;
  m.name = "l";
  m.min = 50;
  m.max = 150;
  c.materials.push_back(m);
  c.surface = SurfaceModel::kVoxel;
  auto scene = Scene::ForSurfaces(volume, c);
  EXPECT_TRUE(scene.ok()) << scene.status();
  const Vec3 extent{volume.dims[0] * volume.spacing[0], volume.dims[1] * volume.spacing[1],
                    volume.dims[2] * volume.spacing[2]};
  auto local = ToVolumeFrame(world, volume.direction, extent);
  EXPECT_TRUE(local.ok()) << local.status();
  auto camera = Camera::Create(*local, extent);
  EXPECT_TRUE(camera.ok()) << camera.status();
  RenderSettings settings;
  settings.shadows = false;
  auto image = RenderLocal(*scene, *camera, settings, 2, nullptr);
  EXPECT_TRUE(image.ok()) << image.status();
  std::vector<int> mask(image->width * image->height);
  for (size_t p = 0; p < mask.size(); ++p) {
    mask[p] = image->rgb[3 * p] + image->rgb[3 * p + 1] + image->rgb[3 * p + 2] > 0 ? 1 : 0;
  }
  return mask;
}

TEST_F(FormatsTest, AsymmetricVolumeProjectsAsItsDefinitionSays) {
  // The same object twice: in the world's axes (identity), and stored as a
  // NRRD whose index axes are a permutation with a flip (x along world -y,
  // y along world z, z along world x: a reflection, so the reader reverses
  // x), with the samples placed to match.
  Volume identity;
  identity.dims = {kNx, kNy, kNz};
  identity.spacing = {kSpacing[0], kSpacing[1], kSpacing[2]};
  identity.values.resize(identity.VoxelCount());
  for (int k = 0; k < kNz; ++k)
    for (int j = 0; j < kNy; ++j)
      for (int i = 0; i < kNx; ++i) identity.values[identity.Index(i, j, k)] = InL(i, j, k) ? 100 : 0;
  // Stored sample (p, q, r) is world voxel (i, j, k) = (r, ny - 1 - p, q).
  std::vector<int16_t> stored(kNx * kNy * kNz);
  for (int r = 0; r < kNx; ++r)
    for (int q = 0; q < kNz; ++q)
      for (int p = 0; p < kNy; ++p) {
        stored[(static_cast<size_t>(r) * kNz + q) * kNy + p] = InL(r, kNy - 1 - p, q) ? 100 : 0;
      }
  const std::string path = Write(
      "l.nrrd",
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 10 6 12\nencoding: raw\nendian: little\n"
      "space: left-posterior-superior\nspace directions: (0,-1.5,0) (0,0,2) (1,0,0)\n"
      "space origin: (0,0,0)\n\n" +
          Bytes(stored));
  auto oriented = ReadVolume(path);
  ASSERT_TRUE(oriented.ok()) << oriented.status();
  EXPECT_TRUE(oriented->x_reversed);
  EXPECT_EQ(OrientationCode(oriented->direction), "PSL");

  constexpr int kSize = 48;
  for (const auto& [az, el] : std::vector<std::pair<double, double>>{{0, 0}, {90, 0}, {180, 0}, {0, 90}, {-90, 0}}) {
    SCOPED_TRACE(::testing::Message() << "azimuth " << az << " elevation " << el);
    CameraSpec world;
    world.projection = Projection::kOrthographic;
    world.azimuth_deg = az;
    world.elevation_deg = el;
    world.width = world.height = kSize;
    const Vec3 extent{kNx * kSpacing[0], kNy * kSpacing[1], kNz * kSpacing[2]};
    auto world_camera = Camera::Create(world, extent);
    ASSERT_TRUE(world_camera.ok());
    const double half_height = 0.5 * Length(extent) * 1.05;
    const std::vector<int> expected = ExpectedMask(*world_camera, half_height, kSize);
    const std::vector<int> a = RenderedMask(identity, world);
    const std::vector<int> b = RenderedMask(*oriented, world);
    int compared = 0, lit = 0;
    for (int p = 0; p < kSize * kSize; ++p) {
      if (expected[p] < 0) continue;
      ++compared;
      lit += expected[p];
      ASSERT_EQ(a[p], expected[p]) << "identity volume, pixel " << p % kSize << "," << p / kSize;
      ASSERT_EQ(b[p], expected[p]) << "oriented volume, pixel " << p % kSize << "," << p / kSize;
    }
    EXPECT_GT(lit, 20);
    EXPECT_GT(compared, kSize * kSize / 2);
  }
}

TEST(ToVolumeFrameTest, IdentityKeepsTheSpecAndRotationsKeepTheImagePlane) {
  CameraSpec world;
  world.azimuth_deg = 33;
  world.elevation_deg = -12;
  auto same = ToVolumeFrame(world, kIdentityDirection, Vec3{10, 20, 30});
  ASSERT_TRUE(same.ok());
  EXPECT_FALSE(same->view.has_value());
  EXPECT_EQ(same->azimuth_deg, 33);
  // Under a rotation, the local camera's axes are the world camera's
  // rotated: right, up and forward each.
  const Direction d = {{{0, 0, 1}, {1, 0, 0}, {0, 1, 0}}};
  auto local = ToVolumeFrame(world, d, Vec3{10, 20, 30});
  ASSERT_TRUE(local.ok());
  auto wc = Camera::Create(world, Vec3{10, 20, 30});
  auto lc = Camera::Create(*local, Vec3{10, 20, 30});
  ASSERT_TRUE(wc.ok() && lc.ok());
  auto rotate = [&](const Vec3& w) {
    return Vec3{Dot(Vec3{d[0][0], d[0][1], d[0][2]}, w), Dot(Vec3{d[1][0], d[1][1], d[1][2]}, w),
                Dot(Vec3{d[2][0], d[2][1], d[2][2]}, w)};
  };
  for (const auto& [w, l] : {std::pair{wc->right(), lc->right()}, std::pair{wc->up(), lc->up()},
                             std::pair{wc->forward(), lc->forward()}}) {
    const Vec3 r = rotate(w);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(r[a], l[a], 1e-12);
  }
}

// ---------------------------------------------------------------------------
// Presets

TEST(PresetsTest, EveryPresetResolvesAndValidates) {
  const auto presets = ListPresets();
  ASSERT_GE(presets.size(), 4u);
  for (const char* name : {"ct-bone", "ct-skin-bone", "ct-angio", "mr-brain"}) {
    bool found = false;
    for (const PresetInfo& p : presets) found = found || p.name == name;
    EXPECT_TRUE(found) << name;
  }
  for (const PresetInfo& p : presets) {
    SCOPED_TRACE(p.name);
    EXPECT_FALSE(p.description.empty());
    EXPECT_TRUE(p.dvr) << "every preset has a colormap for dvr";
    EXPECT_TRUE(PresetTransfer(p.name, {0, 255}).ok());
    EXPECT_EQ(PresetMaterials(p.name, {0, 255}).ok(), p.surfaces);
  }
}

TEST(PresetsTest, AbsoluteAndRelativeValues) {
  // CT presets are in Hounsfield units whatever the range.
  auto bone = PresetMaterials("ct-bone", {0, 255});
  ASSERT_TRUE(bone.ok());
  EXPECT_EQ(bone->materials[0].min, 300);
  // MR is relative: a fraction of the range.
  auto mr = PresetMaterials("mr-brain", {100, 1100});
  ASSERT_TRUE(mr.ok());
  EXPECT_FLOAT_EQ(mr->materials[1].min, 100 + 0.3f * 1000);
  // A volume of one value still gets increasing points.
  EXPECT_TRUE(PresetTransfer("hot", {7, 7}).ok());
}

TEST(PresetsTest, ErrorsNameThePresetAndTheChoices) {
  auto unknown = PresetMaterials("ct-bones", {0, 1});
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(unknown.status().message()), HasSubstr("ct-bones"));
  EXPECT_THAT(std::string(unknown.status().message()), HasSubstr("ct-skin-bone"));
  auto colormap = PresetMaterials("hot", {0, 1});
  EXPECT_THAT(std::string(colormap.status().message()), HasSubstr("dvr"));
}

}  // namespace
}  // namespace transtick
