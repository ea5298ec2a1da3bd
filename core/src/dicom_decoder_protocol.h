// The messages between the DICOM reader and transtick-dicom-decode, the
// program that decodes compressed pixel data in a process of its own
// (docs/formats.md, "DICOM decoder process"). Both sides build them here.
#ifndef TRANSTICK_CORE_DICOM_DECODER_PROTOCOL_H_
#define TRANSTICK_CORE_DICOM_DECODER_PROTOCOL_H_

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>

namespace transtick::dicom_decoder {

inline constexpr uint32_t kVersion = 1;
inline constexpr size_t kHelloBytes = 8;
inline constexpr size_t kRequestBytes = 32;
inline constexpr size_t kReplyBytes = 16;
inline constexpr size_t kMaxReason = 4096;  // bytes of a refusal's text
inline constexpr uint32_t kDecoded = 0, kRefused = 1;
// What a request may ask: the decoder refuses anything else (exit status 2).
inline constexpr uint32_t kMaxSide = 65535;
inline constexpr uint32_t kMaxFrames = uint32_t{1} << 24;
inline constexpr uint64_t kMaxFileBytes = uint64_t{1} << 40;

inline void Put32(char* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<char>(v >> (8 * i));
}
inline void Put64(char* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<char>(v >> (8 * i));
}
inline uint32_t Get32(const char* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= uint32_t{static_cast<unsigned char>(p[i])} << (8 * i);
  return v;
}
inline uint64_t Get64(const char* p) { return Get32(p) | uint64_t{Get32(p + 4)} << 32; }

inline void MakeHello(char out[kHelloBytes]) {
  std::memcpy(out, "TTDH", 4);
  Put32(out + 4, kVersion);
}
// The protocol version of a hello, or nullopt when it is not one.
inline std::optional<uint32_t> ReadHello(const char in[kHelloBytes]) {
  if (std::memcmp(in, "TTDH", 4) != 0) return std::nullopt;
  return Get32(in + 4);
}

struct Request {
  uint32_t rows = 0, columns = 0, bits = 0, frames = 0;
  uint64_t length = 0;  // bytes of the file that follow
  // The bytes the decoded pixels take.
  uint64_t DecodedBytes() const { return uint64_t{rows} * columns * (bits / 8) * frames; }
  // Whether the decoder takes it.
  bool Valid() const {
    return rows >= 1 && rows <= kMaxSide && columns >= 1 && columns <= kMaxSide &&
           (bits == 8 || bits == 16 || bits == 32) && frames >= 1 && frames <= kMaxFrames &&
           length <= kMaxFileBytes;
  }
};
inline void MakeRequest(const Request& r, char out[kRequestBytes]) {
  std::memcpy(out, "TTDQ", 4);
  Put32(out + 4, r.rows);
  Put32(out + 8, r.columns);
  Put32(out + 12, r.bits);
  Put32(out + 16, r.frames);
  Put32(out + 20, 0);
  Put64(out + 24, r.length);
}
inline std::optional<Request> ReadRequest(const char in[kRequestBytes]) {
  if (std::memcmp(in, "TTDQ", 4) != 0 || Get32(in + 20) != 0) return std::nullopt;
  Request r;
  r.rows = Get32(in + 4);
  r.columns = Get32(in + 8);
  r.bits = Get32(in + 12);
  r.frames = Get32(in + 16);
  r.length = Get64(in + 24);
  return r;
}

struct Reply {
  uint32_t status = kDecoded;
  uint64_t length = 0;
};
inline void MakeReply(const Reply& r, char out[kReplyBytes]) {
  std::memcpy(out, "TTDR", 4);
  Put32(out + 4, r.status);
  Put64(out + 8, r.length);
}
inline std::optional<Reply> ReadReply(const char in[kReplyBytes]) {
  if (std::memcmp(in, "TTDR", 4) != 0) return std::nullopt;
  return Reply{Get32(in + 4), Get64(in + 8)};
}

}  // namespace transtick::dicom_decoder

#endif  // TRANSTICK_CORE_DICOM_DECODER_PROTOCOL_H_
