#include "transtick/image_io.h"

#include <cmath>
#include <filesystem>
#include <string>

#include "gtest/gtest.h"
#include "testing.h"

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

}  // namespace
}  // namespace transtick
