#include "transtick/image_io.h"

#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/png.h"

namespace transtick {
namespace {

bool IsFloat(std::string_view ext) {
  return ext == "tif" || ext == "tiff" || ext == "exr" || ext == "hdr";
}

Image Gradient(int width, int height) {
  Image img;
  img.width = width;
  img.height = height;
  img.rgb.resize(static_cast<size_t>(width) * height * 3);
  for (size_t i = 0; i < img.rgb.size(); ++i) {
    img.rgb[i] = 0.25f + 0.5f * static_cast<float>(i) / static_cast<float>(img.rgb.size());
  }
  return img;
}

TEST(ImageIoTest, SupportedPathsGoByTheExtensionInAnyCase) {
  for (const char* path : {"a.png", "dir/b.PNG", "c.jpg", "d.jpeg", "e.tif", "f.TIFF", "g.exr",
                           "h.Hdr", "/abs/path.with.dots/i.png"}) {
    EXPECT_TRUE(IsSupportedImagePath(path)) << path;
  }
  for (const char* path : {"", "png", "a.", "a.bmp", "a.png.txt", "a.png/", "dir.png/file"}) {
    EXPECT_FALSE(IsSupportedImagePath(path)) << path;
  }
  for (std::string_view ext : SupportedImageExtensions()) {
    EXPECT_TRUE(IsSupportedImagePath(std::string("x.") + std::string(ext))) << ext;
  }
}

TEST(ImageIoTest, ByteFormatsArePngAndJpegOnly) {
  for (const char* path : {"a.png", "dir/b.PNG", "c.jpg", "d.JPEG"}) {
    EXPECT_TRUE(IsByteImagePath(path)) << path;
  }
  for (const char* path : {"e.tif", "f.tiff", "g.exr", "h.hdr", "", "png", "a.bmp", "a.png/"}) {
    EXPECT_FALSE(IsByteImagePath(path)) << path;
  }
}

// An image that travels in 8 bits (docs/formats.md, "Image chunks") is
// written from FromByte of its bytes: every byte must come back.
TEST(ImageIoTest, FromByteGivesEveryByteBack) {
  for (int b = 0; b < 256; ++b) {
    const float v = FromByte(static_cast<uint8_t>(b));
    EXPECT_EQ(ToByte(v), b);
    EXPECT_GE(v, 0.0f);
    EXPECT_LE(v, 1.0f);
  }
  EXPECT_EQ(FromByte(0), 0.0f);
  EXPECT_EQ(FromByte(255), 1.0f);
}

TEST(ImageIoTest, EverySupportedFormatRoundTrips) {
  const std::string dir = testing::TempDir();
  const Image want = Gradient(7, 5);
  for (std::string_view ext : SupportedImageExtensions()) {
    const std::string path = dir + "/img." + std::string(ext);
    ASSERT_TRUE(WriteImage(path, want).ok()) << path;
    auto got = ReadImage(path);
    ASSERT_TRUE(got.ok()) << got.status();
    ASSERT_EQ(got->width, want.width) << ext;
    ASSERT_EQ(got->height, want.height) << ext;
    ASSERT_EQ(got->rgb.size(), want.rgb.size()) << ext;
    if (ext == "tif" || ext == "tiff" || ext == "exr") {
      EXPECT_EQ(got->rgb, want.rgb) << ext << " is written as 32-bit float";
      continue;
    }
    for (size_t i = 0; i < want.rgb.size(); ++i) {
      if (ext == "png") {
        ASSERT_EQ(ToByte(got->rgb[i]), ToByte(want.rgb[i])) << ext << " value " << i;
      } else {
        // JPEG is lossy, Radiance HDR shares one exponent per pixel.
        ASSERT_NEAR(got->rgb[i], want.rgb[i], IsFloat(ext) ? 0.01 : 0.05) << ext << " value " << i;
      }
    }
  }
}

TEST(ImageIoTest, OtherFormatsAreRefusedWithTheList) {
  const std::string path = testing::TempDir() + "/img.bmp";
  absl::Status s = WriteImage(path, Gradient(2, 2));
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("img.bmp"), std::string_view::npos) << s;
  EXPECT_NE(s.message().find(".png, .jpg"), std::string_view::npos) << s;
  EXPECT_FALSE(std::filesystem::exists(path));
}

uint32_t BigEndian(const std::string& s, size_t at) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = v << 8 | static_cast<unsigned char>(s[at + i]);
  return v;
}

TEST(PngTest, IdatIsZlibsOneCallDeflateOfTheUpFilteredRows) {
  // The encoder deflates row by row; at every level but 0 that must be the
  // very bytes compress2 makes of the whole filtered image, here built
  // independently, in a file whose chunks have the lengths and CRCs PNG
  // requires.
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> value(-0.1f, 1.1f);
  for (int t = 0; t < 60; ++t) {
    Image image;
    image.width = 1 + static_cast<int>(rng() % (t < 45 ? 40 : 700));
    image.height = 1 + static_cast<int>(rng() % (t < 45 ? 40 : 300));
    image.rgb.resize(static_cast<size_t>(image.width) * image.height * 3);
    // Noise, flat runs and gradients: both well and badly compressible.
    for (size_t i = 0; i < image.rgb.size(); ++i) {
      image.rgb[i] = t % 3 == 0   ? value(rng)
                     : t % 3 == 1 ? (i % 300 < 200 ? 0.0f : value(rng))
                                  : static_cast<float>(i % 997) / 997;
    }
    const int level = 1 + t % 9;
    auto png = EncodePng(image, level);
    ASSERT_TRUE(png.ok()) << png.status();
    const size_t row = static_cast<size_t>(image.width) * 3;
    std::vector<unsigned char> raw;
    std::vector<unsigned char> above(row, 0);
    for (int y = 0; y < image.height; ++y) {
      raw.push_back(2);
      for (size_t i = 0; i < row; ++i) {
        const unsigned char b = ToByte(image.rgb[y * row + i]);
        raw.push_back(static_cast<unsigned char>(b - above[i]));
        above[i] = b;
      }
    }
    uLongf size = compressBound(raw.size());
    std::vector<unsigned char> want(size);
    ASSERT_EQ(compress2(want.data(), &size, raw.data(), raw.size(), level), Z_OK);
    const std::string& f = *png;
    ASSERT_EQ(f.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    ASSERT_EQ(BigEndian(f, 8), 13u);         // IHDR's length
    const size_t idat = 8 + 4 + 4 + 13 + 4;  // after IHDR
    ASSERT_EQ(f.substr(idat + 4, 4), "IDAT");
    const uint32_t length = BigEndian(f, idat);
    ASSERT_EQ(length, size) << image.width << "x" << image.height << " level " << level;
    EXPECT_EQ(f.compare(idat + 8, length, reinterpret_cast<const char*>(want.data()), size), 0)
        << image.width << "x" << image.height << " level " << level;
    const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(f.data() + idat + 4), length + 4);
    EXPECT_EQ(BigEndian(f, idat + 8 + length), static_cast<uint32_t>(crc));
    EXPECT_EQ(f.substr(idat + 12 + length), std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12));
  }
}

}  // namespace
}  // namespace transtick
