// The DICOM reader's side of transtick-dicom-decode: compressed pixel data
// decoded in a child process (docs/formats.md, "DICOM decoder process"), so
// that a codec that crashes, hangs, leaks or exhausts memory on a damaged
// file is an error naming the file, and the root or the CLI that reads it
// goes on.
#ifndef TRANSTICK_CORE_DICOM_DECODER_H_
#define TRANSTICK_CORE_DICOM_DECODER_H_

#include <sys/types.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

class DicomDecoder {
 public:
  // Starts the decoder, its address space limited to `max_memory` bytes,
  // and waits up to `seconds` for its hello. Unavailable when the program
  // is not installed (the error names every path tried) or does not start.
  static absl::StatusOr<std::unique_ptr<DicomDecoder>> Start(uint64_t max_memory, double seconds);
  // Stops the decoder and every process it started (SIGKILL to its process
  // group) and reaps it.
  ~DicomDecoder();
  DicomDecoder(const DicomDecoder&) = delete;
  DicomDecoder& operator=(const DicomDecoder&) = delete;

  // Decodes the file of `bytes` (named `path` in errors): `frames` frames
  // of `rows` x `columns` grey samples of `bits` bits, into `out`, host
  // byte order. Allows `seconds`, plus a second per 4 MiB of pixels. A
  // refusal (GDCM cannot decode it) leaves the decoder running; a decoder
  // that dies, overruns its time or breaks the protocol is stopped, the
  // error says which, and every later call fails.
  absl::Status Decode(const std::string& path, const std::string& bytes, int rows, int columns,
                      int bits, int frames, double seconds, std::vector<char>* out);

 private:
  DicomDecoder(pid_t pid, int socket, int errors) : pid_(pid), socket_(socket), errors_(errors) {}
  enum class Io { kDone, kTimedOut, kClosed };
  // Sends `out_n` bytes of `out`, or receives `in_n` into `in`, by the
  // monotonic deadline (ns), reading the decoder's standard error meanwhile.
  Io Pump(const char* out, size_t out_n, char* in, size_t in_n, int64_t deadline);
  void DrainErrors();
  // Stops the decoder (after `grace_ms` for it to end by itself) and
  // returns how it ended.
  std::string Stop(int grace_ms);
  // " (its last words: "...")": the last line it wrote on its standard
  // error, or "" when none.
  std::string Said() const;
  // An error for `path` after Pump returned `io` or the reply broke the
  // protocol (`what`), the decoder stopped.
  absl::Status Failed(const std::string& path, Io io, double seconds, const std::string& what);

  pid_t pid_;
  int socket_;
  int errors_;        // the read end of its standard error, or -1 once it ended
  std::string said_;  // the last bytes of its standard error
  bool stopped_ = false;
};

}  // namespace transtick

#endif  // TRANSTICK_CORE_DICOM_DECODER_H_
