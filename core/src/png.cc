#include "transtick/png.h"

#include <zlib.h>

#include <cstdint>
#include <vector>

#include "absl/strings/str_cat.h"
#include "transtick/image_io.h"

namespace transtick {
namespace {

// PNG's integers: 4 bytes, big-endian.
void StoreU32(char* at, uint32_t v) {
  for (int i = 0; i < 4; ++i) at[i] = static_cast<char>(v >> (24 - 8 * i));
}

void PutU32(std::string* out, uint32_t v) {
  char b[4];
  StoreU32(b, v);
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
  std::string out("\x89PNG\r\n\x1a\n", 8);
  unsigned char header[13];
  StoreU32(reinterpret_cast<char*>(header), static_cast<uint32_t>(image.width));
  StoreU32(reinterpret_cast<char*>(header + 4), static_cast<uint32_t>(image.height));
  header[8] = 8;   // bits per channel
  header[9] = 2;   // RGB
  header[10] = 0;  // deflate
  header[11] = 0;  // adaptive filtering
  header[12] = 0;  // no interlace
  PutChunk(&out, "IHDR", header, sizeof(header));

  // IDAT, deflated a row at a time straight into `out` (its length is
  // written once known). At levels 1-9 these are the bytes compress2 makes
  // of the whole filtered image at once (at level 0 its stored blocks end
  // elsewhere), without the two image-sized buffers it needs, zeroed and
  // faulted in afresh for each image: a 400x400 image took 8.9 ms and 278
  // page faults that way, 5.3 ms and 136 this way (200 in a row each).
  const size_t idat = out.size();
  PutU32(&out, 0);
  out.append("IDAT", 4);
  z_stream z{};
  if (deflateInit(&z, level) != Z_OK) return absl::InternalError("zlib could not start deflating");
  struct End {
    z_stream* z;
    ~End() { deflateEnd(z); }
  } end{&z};
  // Output goes to the end of `out`, grown 64 KB at a time.
  constexpr size_t kGrow = 64 << 10;
  auto grow = [&] {
    const size_t at = out.size() - z.avail_out;
    out.resize(at + kGrow);
    z.next_out = reinterpret_cast<Bytef*>(out.data() + at);
    z.avail_out = static_cast<uInt>(kGrow);
  };
  // Deflates the input z holds: all of it (Z_NO_FLUSH), or to the end of
  // the stream (Z_FINISH). False on an error of zlib's.
  auto pump = [&](int flush) {
    for (;;) {
      if (z.avail_out == 0) grow();
      const int r = deflate(&z, flush);
      if (r == Z_STREAM_END) return true;
      if (r != Z_OK && r != Z_BUF_ERROR) return false;
      // Room left: the input is all taken (or, finishing, zlib is stuck).
      if (z.avail_out > 0) return flush == Z_NO_FLUSH;
    }
  };
  const size_t row = static_cast<size_t>(image.width) * 3;
  // Each row: its filter type (2, "Up"), then each byte minus the one above.
  std::vector<unsigned char> above(row, 0), current(row), line(row + 1);
  line[0] = 2;
  for (int y = 0; y < image.height; ++y) {
    const float* src = image.rgb.data() + y * row;
    for (size_t i = 0; i < row; ++i) current[i] = ToByte(src[i]);
    for (size_t i = 0; i < row; ++i) {
      line[i + 1] = static_cast<unsigned char>(current[i] - above[i]);
    }
    above.swap(current);
    z.next_in = line.data();
    z.avail_in = static_cast<uInt>(line.size());
    if (!pump(Z_NO_FLUSH)) return absl::InternalError("zlib could not deflate the image");
  }
  if (!pump(Z_FINISH)) return absl::InternalError("zlib could not deflate the image");
  // The room zlib left unused (never more than `out` holds: it was appended).
  out.erase(out.size() - z.avail_out);
  const size_t data = out.size() - idat - 8;
  StoreU32(out.data() + idat, static_cast<uint32_t>(data));
  const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(out.data() + idat + 4), data + 4);
  PutU32(&out, static_cast<uint32_t>(crc));
  PutChunk(&out, "IEND", nullptr, 0);
  return out;
}

}  // namespace transtick
