// PNG encoding, with zlib alone: what WriteImage writes to a .png file and
// what the web gateway sends the browser. 8-bit RGB, each channel ToByte of
// the float (image_io.h).
#ifndef TRANSTICK_PNG_H_
#define TRANSTICK_PNG_H_

#include <string>

#include "absl/status/statusor.h"
#include "transtick/framebuffer.h"

namespace transtick {

// `image` as a PNG file's bytes: one IDAT chunk, every row filtered with
// PNG's "Up" filter, deflated at zlib level `level` (1 fastest .. 9 smallest).
// InvalidArgument for an empty image or one whose rgb does not match its size.
absl::StatusOr<std::string> EncodePng(const Image& image, int level = 1);

}  // namespace transtick

#endif  // TRANSTICK_PNG_H_
