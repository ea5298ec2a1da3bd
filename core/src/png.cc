#include "transtick/png.h"

#include <zlib.h>

#include <cstdint>
#include <vector>

#include "absl/strings/str_cat.h"
#include "transtick/image_io.h"

namespace transtick {
namespace {

void PutU32(std::string* out, uint32_t v) {
  const char b[4] = {static_cast<char>(v >> 24), static_cast<char>(v >> 16),
                     static_cast<char>(v >> 8), static_cast<char>(v)};
  out->append(b, 4);
}

// A chunk: length, type, data, and the CRC of type and data.
void PutChunk(std::string* out, const char type[4], const unsigned char* data, size_t size) {
  PutU32(out, static_cast<uint32_t>(size));
  const size_t start = out->size();
  out->append(type, 4);
  out->append(reinterpret_cast<const char*>(data), size);
  const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(out->data() + start), size + 4);
  PutU32(out, static_cast<uint32_t>(crc));
}

}  // namespace

absl::StatusOr<std::string> EncodePng(const Image& image, int level) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != static_cast<size_t>(image.width) * image.height * 3) {
    return absl::InvalidArgumentError(absl::StrCat("cannot encode a ", image.width, "x",
                                                   image.height, " image of ", image.rgb.size(),
                                                   " values as PNG"));
  }
  const size_t row = static_cast<size_t>(image.width) * 3;
  // Each row: its filter type (2, "Up"), then each byte minus the one above.
  std::vector<unsigned char> raw((row + 1) * image.height);
  std::vector<unsigned char> above(row, 0), current(row);
  for (int y = 0; y < image.height; ++y) {
    const float* src = image.rgb.data() + y * row;
    for (size_t i = 0; i < row; ++i) current[i] = ToByte(src[i]);
    unsigned char* dst = raw.data() + y * (row + 1);
    dst[0] = 2;
    for (size_t i = 0; i < row; ++i) dst[i + 1] = static_cast<unsigned char>(current[i] - above[i]);
    above.swap(current);
  }
  uLongf deflated_size = compressBound(raw.size());
  std::vector<unsigned char> deflated(deflated_size);
  if (compress2(deflated.data(), &deflated_size, raw.data(), raw.size(), level) != Z_OK) {
    return absl::InternalError("zlib could not deflate the image");
  }
  std::string out("\x89PNG\r\n\x1a\n", 8);
  unsigned char header[13];
  const uint32_t w = static_cast<uint32_t>(image.width), h = static_cast<uint32_t>(image.height);
  for (int i = 0; i < 4; ++i) {
    header[i] = static_cast<unsigned char>(w >> (24 - 8 * i));
    header[4 + i] = static_cast<unsigned char>(h >> (24 - 8 * i));
  }
  header[8] = 8;   // bits per channel
  header[9] = 2;   // RGB
  header[10] = 0;  // deflate
  header[11] = 0;  // adaptive filtering
  header[12] = 0;  // no interlace
  PutChunk(&out, "IHDR", header, sizeof(header));
  PutChunk(&out, "IDAT", deflated.data(), deflated_size);
  PutChunk(&out, "IEND", nullptr, 0);
  return out;
}

}  // namespace transtick
