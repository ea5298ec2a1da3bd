// Little-endian fixed-width and varint encoding with bounds-checked decoding
// (in the manner of LevelDB's util/coding.h).
#ifndef TRANSTICK_CODING_H_
#define TRANSTICK_CODING_H_

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace transtick {

// Writes little-endian values at dst (which must have room).
inline char* EncodeFixed16(char* dst, uint16_t v) {
  dst[0] = static_cast<char>(v & 0xff);
  dst[1] = static_cast<char>(v >> 8);
  return dst + 2;
}
inline char* EncodeFixed32(char* dst, uint32_t v) {
  for (int i = 0; i < 4; ++i) dst[i] = static_cast<char>((v >> (8 * i)) & 0xff);
  return dst + 4;
}
inline char* EncodeFixed64(char* dst, uint64_t v) {
  for (int i = 0; i < 8; ++i) dst[i] = static_cast<char>((v >> (8 * i)) & 0xff);
  return dst + 8;
}
inline void PutFixed16(std::string* out, uint16_t v) {
  char b[2];
  out->append(b, EncodeFixed16(b, v) - b);
}
inline void PutFixed32(std::string* out, uint32_t v) {
  char b[4];
  out->append(b, EncodeFixed32(b, v) - b);
}
inline void PutVarint32(std::string* out, uint32_t v) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

// Writes v as a varint at dst (at most 10 bytes); returns the end.
inline char* EncodeVarint64(char* dst, uint64_t v) {
  while (v >= 0x80) {
    *dst++ = static_cast<char>((v & 0x7f) | 0x80);
    v >>= 7;
  }
  *dst++ = static_cast<char>(v);
  return dst;
}
// Zigzag (protobuf's sint): small magnitudes of either sign, short varints.
inline uint32_t ZigZag32(int32_t v) {
  return (static_cast<uint32_t>(v) << 1) ^ (0u - (static_cast<uint32_t>(v) >> 31));
}
inline int32_t UnZigZag32(uint32_t v) { return static_cast<int32_t>((v >> 1) ^ (0u - (v & 1))); }
inline uint64_t ZigZag64(int64_t v) {
  return (static_cast<uint64_t>(v) << 1) ^ (0ull - (static_cast<uint64_t>(v) >> 63));
}
inline int64_t UnZigZag64(uint64_t v) { return static_cast<int64_t>((v >> 1) ^ (0ull - (v & 1))); }

// Reads from a borrowed byte range; every Get returns false instead of
// reading past the end. The viewed bytes must outlive the decoder.
class Decoder {
 public:
  explicit Decoder(std::string_view bytes) : p_(bytes.data()), end_(bytes.data() + bytes.size()) {}

  size_t remaining() const { return static_cast<size_t>(end_ - p_); }

  bool GetBytes(void* dst, size_t n) {
    if (remaining() < n) return false;
    std::memcpy(dst, p_, n);
    p_ += n;
    return true;
  }
  bool GetByte(uint8_t* v) { return GetBytes(v, 1); }
  bool GetFixed16(uint16_t* v) {
    uint8_t b[2];
    if (!GetBytes(b, 2)) return false;
    *v = static_cast<uint16_t>(b[0] | (b[1] << 8));
    return true;
  }
  bool GetFixed32(uint32_t* v) {
    uint8_t b[4];
    if (!GetBytes(b, 4)) return false;
    *v = uint32_t{b[0]} | (uint32_t{b[1]} << 8) | (uint32_t{b[2]} << 16) | (uint32_t{b[3]} << 24);
    return true;
  }
  bool GetVarint32(uint32_t* v) {
    uint32_t result = 0;
    for (int shift = 0; shift <= 28 && p_ < end_; shift += 7) {
      uint32_t byte = static_cast<uint8_t>(*p_++);
      if (shift == 28 && byte > 0x0f) return false;  // more than 32 bits
      result |= (byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) {
        *v = result;
        return true;
      }
    }
    return false;
  }
  bool GetVarint64(uint64_t* v) {
    uint64_t result = 0;
    for (int shift = 0; shift <= 63 && p_ < end_; shift += 7) {
      const uint64_t byte = static_cast<uint8_t>(*p_++);
      if (shift == 63 && byte > 0x01) return false;  // more than 64 bits
      result |= (byte & 0x7f) << shift;
      if ((byte & 0x80) == 0) {
        *v = result;
        return true;
      }
    }
    return false;
  }

 private:
  const char* p_;
  const char* end_;
};

}  // namespace transtick

#endif  // TRANSTICK_CODING_H_
