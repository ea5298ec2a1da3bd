// Helpers shared by the volume readers (volume_io.cc, nrrd.cc, den.cc,
// nifti.cc). Private to the core library.
//
// Every function that can fail returns a status whose message starts with the
// path as the caller gave it, so a user sees which file is wrong.
#ifndef TRANSTICK_CORE_SRC_VOLUME_IO_INTERNAL_H_
#define TRANSTICK_CORE_SRC_VOLUME_IO_INTERNAL_H_

#include <array>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "bzlib.h"
#include "transtick/volume.h"
#include "transtick/volume_io.h"
#include "zlib.h"

namespace transtick::volume_io_internal {

struct FileCloser {
  void operator()(std::FILE* file) const { std::fclose(file); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// Opens a regular file for binary reading: NotFound if it does not exist,
// InvalidArgument if it is a directory or unreadable.
absl::StatusOr<FilePtr> OpenFile(const std::string& path, const ReadOptions& options);

// True if `path` opens (through options.open) as a directory.
bool IsDirectory(const std::string& path, const ReadOptions& options);

// Size in bytes of the regular file at `path`.
absl::StatusOr<uint64_t> FileSize(const std::string& path, const ReadOptions& options);

// Reads up to `max_len` bytes from the start of the file (fewer if the file is
// shorter). Used for headers, whose length is not known in advance.
absl::StatusOr<std::string> ReadPrefix(const std::string& path, uint64_t max_len, const ReadOptions& options);

// Returns the offset just past the `lines`-th '\n' at or after `offset`.
absl::StatusOr<uint64_t> SkipLines(const std::string& path, uint64_t offset, uint64_t lines, const ReadOptions& options);

// The whitespace-separated numbers of a header field, exactly `want` of
// them, each finite; errors name the file and `what`.
absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& path, const std::string& what,
                                                 const std::string& text, size_t want);

// The directory part of `path`, with a trailing '/', or "" for a bare name:
// where a detached header's data file is named from.
std::string DirectoryOf(const std::string& path);

// a * b, a + b; false on unsigned 64-bit overflow.
bool CheckedMul(uint64_t a, uint64_t b, uint64_t* out);
bool CheckedAdd(uint64_t a, uint64_t b, uint64_t* out);

// "256x256x113 int16 = 14811136 bytes": how messages describe a layout.
std::string DescribeLayout(const std::array<int64_t, 3>& dims, ScalarType type);

// Validates dims as a header states them (each in [1, INT_MAX]), checks that
// the float volume fits in `options.max_bytes` (ResourceExhausted if not) and
// returns the number of bytes the samples occupy on disk. Nothing is
// allocated: this is the check that must come before any allocation.
absl::StatusOr<uint64_t> CheckedDataBytes(const std::string& path,
                                          const std::array<int64_t, 3>& dims, ScalarType type,
                                          const ReadOptions& options);

// Converts `count` samples of `type` stored in `order` at `src` to float.
// REQUIRES: src holds count * ScalarTypeSize(type) bytes; dst holds count floats.
void ConvertSamples(const unsigned char* src, size_t count, ScalarType type, ByteOrder order,
                    float* dst);

// A source of bytes: reads exactly `n` bytes into `dst` or fails.
using ReadFn = std::function<absl::Status(unsigned char* dst, size_t n)>;

// Reads `count` samples through `read` in bounded chunks and appends them, as
// float, to `*out`. `*out` grows as data actually arrives, so a header that
// claims more voxels than a (compressed) stream holds costs at most one chunk
// of extra memory, not the claimed size.
absl::Status ReadSamples(const ReadFn& read, uint64_t count, ScalarType type, ByteOrder order,
                         std::vector<float>* out);

// Reads `count` samples of `type` from [offset, offset + count * size) of a
// plain file. REQUIRES: the caller checked that the file holds those bytes.
absl::Status ReadRawSamples(const std::string& path, uint64_t offset, uint64_t count,
                            ScalarType type, ByteOrder order, std::vector<float>* out, const ReadOptions& options);

// `count` samples written as numbers separated by white space, from the
// file's current position to its end, or with `stop_at_tag` to the first
// '<' (an XML element's content); each becomes the nearest float (an
// infinity beyond the largest). Too few, too many, or a token that is no
// number is an InvalidArgument error naming the file.
absl::Status ReadAsciiSamples(const std::string& path, std::FILE* f, uint64_t count,
                              bool stop_at_tag, std::vector<float>* out);

// Streams the decompressed content of a gzip or zlib stream (detected from
// its first bytes), or of a bzip2 stream, that starts at `offset` in a file.
// Reading past the end of the stream, or a corrupt stream, is an
// InvalidArgument error naming the file; memory use is bounded by one input
// buffer (and bzip2's 3.7 MB of tables) whatever the stream holds.
//
// Not thread-safe; owns its file handle.
class CompressedFileReader {
 public:
  enum class Codec { kGzip, kBzip2 };
  static absl::StatusOr<std::unique_ptr<CompressedFileReader>> Open(const std::string& path,
                                                                    uint64_t offset,
                                                                    const ReadOptions& options,
                                                                    Codec codec = Codec::kGzip);
  ~CompressedFileReader();
  CompressedFileReader(const CompressedFileReader&) = delete;
  CompressedFileReader& operator=(const CompressedFileReader&) = delete;

  // Reads exactly `n` decompressed bytes.
  absl::Status Read(unsigned char* dst, size_t n);
  // Discards `n` decompressed bytes.
  absl::Status Skip(uint64_t n);
  // True when the stream has ended, false if it still has data; an error if
  // that cannot be told because the stream is corrupt or cut short.
  absl::StatusOr<bool> AtEnd();
  // Reads on to the end of the stream, which checks the gzip trailer (CRC and
  // length), and returns how many bytes were left; an error if more than
  // `limit` remain, or if the stream is corrupt or cut short.
  absl::StatusOr<uint64_t> SkipToEnd(uint64_t limit);
  // Decompressed bytes delivered so far (read or skipped).
  uint64_t position() const { return position_; }

 private:
  CompressedFileReader(std::string path, FilePtr file, Codec codec);
  // Inflates into [dst, dst + n); sets *produced. Stops early only at the end
  // of the stream.
  absl::Status Inflate(unsigned char* dst, size_t n, size_t* produced);
  // One step of the codec from the input buffer into [dst, dst + n): how
  // many bytes it made; sets stream_end_.
  absl::Status Step(unsigned char* dst, size_t n, size_t* made, uint64_t before);
  const char* codec_name() const { return codec_ == Codec::kGzip ? "gzip" : "bzip2"; }

  std::string path_;
  FilePtr file_;
  Codec codec_;
  z_stream stream_{};
  bz_stream bz_{};
  size_t avail_in_ = 0;  // input bytes at next_in_ not yet given to the codec
  unsigned char* next_in_ = nullptr;
  bool initialized_ = false;
  bool stream_end_ = false;
  bool file_eof_ = false;
  uint64_t position_ = 0;
  std::vector<unsigned char> in_;
};

// True if the file starts with the gzip magic bytes 1f 8b.
absl::StatusOr<bool> IsGzipFile(const std::string& path, const ReadOptions& options);

}  // namespace transtick::volume_io_internal

#endif  // TRANSTICK_CORE_SRC_VOLUME_IO_INTERNAL_H_
