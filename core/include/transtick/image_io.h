// Writing images with OpenImageIO, format by extension: 8-bit for PNG (and
// JPEG), 32-bit float for TIFF and EXR.
#ifndef TRANSTICK_IMAGE_IO_H_
#define TRANSTICK_IMAGE_IO_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "transtick/framebuffer.h"

namespace transtick {

absl::Status WriteImage(const std::string& path, const Image& image);

// Reads an image back as float RGB (for tests and comparisons).
absl::StatusOr<Image> ReadImage(const std::string& path);

// The 8-bit value written for a float channel: clamp to [0, 1], round.
inline uint8_t ToByte(float v) {
  v = v < 0 ? 0 : (v > 1 ? 1 : v);
  return static_cast<uint8_t>(v * 255.0f + 0.5f);
}

}  // namespace transtick

#endif  // TRANSTICK_IMAGE_IO_H_
