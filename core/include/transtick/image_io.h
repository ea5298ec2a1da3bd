// Writing images with OpenImageIO, format by extension: 8-bit for PNG and
// JPEG, 32-bit float for TIFF, EXR and Radiance HDR.
#ifndef TRANSTICK_IMAGE_IO_H_
#define TRANSTICK_IMAGE_IO_H_

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "transtick/framebuffer.h"

namespace transtick {

// The image formats transtick writes, as file extensions in lower case
// without the dot: "png", "jpg", "jpeg" (8-bit), "tif", "tiff", "exr", "hdr"
// (32-bit float). This is the one list: the CLI and the root check output
// paths against it, and WriteImage writes nothing else. The view is of
// static storage.
std::span<const std::string_view> SupportedImageExtensions();

// True when `path` ends in "." and one of SupportedImageExtensions(), in any
// case ("a/b.PNG" is supported, "png" and "a.png/" are not).
bool IsSupportedImagePath(std::string_view path);

// True when `path` is supported and its format stores 8-bit values (PNG,
// JPEG): WriteImage keeps only ToByte of each float there.
bool IsByteImagePath(std::string_view path);

// The same list for messages: ".png, .jpg, .jpeg, .tif, .tiff, .exr, .hdr".
std::string SupportedImageList();

// Writes `image` in the format of `path`'s extension. An extension outside
// SupportedImageExtensions() is an InvalidArgument error that lists them.
absl::Status WriteImage(const std::string& path, const Image& image);

// Reads an image back as float RGB (for tests and comparisons).
absl::StatusOr<Image> ReadImage(const std::string& path);

// The 8-bit value written for a float channel: clamp to [0, 1], round.
inline uint8_t ToByte(float v) {
  v = v < 0 ? 0 : (v > 1 ? 1 : v);
  return static_cast<uint8_t>(v * 255.0f + 0.5f);
}

// The float an 8-bit value stands for, whose ToByte is that value again:
// ToByte(FromByte(b)) == b for every b (image_io_test checks all 256).
inline float FromByte(uint8_t b) { return static_cast<float>(b) / 255.0f; }

}  // namespace transtick

#endif  // TRANSTICK_IMAGE_IO_H_
