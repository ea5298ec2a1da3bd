// Shared plumbing of the volume readers, the headerless raw reader and the
// dispatch by file extension. The format readers live in nrrd.cc, den.cc and
// nifti.cc.
#include "transtick/volume_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "volume_io_internal.h"

namespace transtick {
namespace volume_io_internal {
namespace {

// Chunk size for streaming reads: large enough to amortise calls, small
// enough that a lying header costs little memory.
constexpr size_t kChunkBytes = size_t{1} << 20;

absl::Status ErrnoError(const std::string& path, const char* what, int error) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", what, ": ", std::strerror(error)));
}

template <typename T>
T LoadSample(const unsigned char* p, bool swap) {
  static_assert(sizeof(T) <= 8);
  unsigned char bytes[sizeof(T)];
  if (swap) {
    for (size_t i = 0; i < sizeof(T); ++i) bytes[i] = p[sizeof(T) - 1 - i];
  } else {
    std::memcpy(bytes, p, sizeof(T));
  }
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

template <typename T>
void ConvertTyped(const unsigned char* src, size_t count, bool swap, float* dst) {
  for (size_t i = 0; i < count; ++i) {
    dst[i] = static_cast<float>(LoadSample<T>(src + i * sizeof(T), swap));
  }
}

// A double as a sample: the nearest float; beyond the largest float an
// infinity of its sign (what the renderers do with infinities:
// docs/security.md), and NaN stays NaN.
float NearestFloat(double v) {
  constexpr double kMax = std::numeric_limits<float>::max();
  return v > kMax    ? std::numeric_limits<float>::infinity()
         : v < -kMax ? -std::numeric_limits<float>::infinity()
                     : static_cast<float>(v);
}

template <>
void ConvertTyped<double>(const unsigned char* src, size_t count, bool swap, float* dst) {
  for (size_t i = 0; i < count; ++i) {
    dst[i] = NearestFloat(LoadSample<double>(src + i * sizeof(double), swap));
  }
}

}  // namespace

absl::StatusOr<FilePtr> OpenFile(const std::string& path, const ReadOptions& options) {
  int fd = -1;
  if (options.open) {
    absl::StatusOr<int> opened = options.open(path);
    if (!opened.ok()) return opened.status();
    fd = *opened;
  } else {
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
      const int error = errno;
      if (error == ENOENT || error == ENOTDIR) {
        return absl::NotFoundError(absl::StrCat(path, ": no such file"));
      }
      return ErrnoError(path, "cannot open", error);
    }
  }
  // The checks are on the file opened, not on the name, which may since
  // name another.
  struct stat info;
  if (::fstat(fd, &info) != 0) {
    const int error = errno;
    ::close(fd);
    return ErrnoError(path, "cannot stat", error);
  }
  if (!S_ISREG(info.st_mode)) {
    ::close(fd);
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a regular file"));
  }
  FilePtr file(::fdopen(fd, "rb"));
  if (file == nullptr) {
    const int error = errno;
    ::close(fd);
    return ErrnoError(path, "cannot open", error);
  }
  return file;
}

bool IsDirectory(const std::string& path, const ReadOptions& options) {
  int fd = -1;
  if (options.open) {
    absl::StatusOr<int> opened = options.open(path);
    if (!opened.ok()) return false;
    fd = *opened;
  } else {
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
  }
  struct stat info;
  const bool directory = ::fstat(fd, &info) == 0 && S_ISDIR(info.st_mode);
  ::close(fd);
  return directory;
}

absl::StatusOr<uint64_t> FileSize(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<FilePtr> file = OpenFile(path, options);
  if (!file.ok()) return file.status();
  struct stat info;
  if (::fstat(::fileno(file->get()), &info) != 0) return ErrnoError(path, "cannot stat", errno);
  return static_cast<uint64_t>(info.st_size);
}

absl::StatusOr<std::string> ReadPrefix(const std::string& path, uint64_t max_len, const ReadOptions& options) {
  absl::StatusOr<FilePtr> file = OpenFile(path, options);
  if (!file.ok()) return file.status();
  absl::StatusOr<uint64_t> size = FileSize(path, options);
  if (!size.ok()) return size.status();
  // Only a part wanted: no readahead past it (a DICOM listing reads the
  // headers of hundreds of files, and the kernel's readahead took 128 KiB
  // of each for a 16 KiB prefix).
  if (max_len < *size) ::posix_fadvise(::fileno(file->get()), 0, 0, POSIX_FADV_RANDOM);
  std::string data(static_cast<size_t>(std::min(*size, max_len)), '\0');
  size_t got = std::fread(data.data(), 1, data.size(), file->get());
  if (got != data.size() && std::ferror(file->get())) {
    return ErrnoError(path, "read failed", errno);
  }
  data.resize(got);
  return data;
}

absl::StatusOr<uint64_t> SkipLines(const std::string& path, uint64_t offset, uint64_t lines, const ReadOptions& options) {
  if (lines == 0) return offset;
  absl::StatusOr<FilePtr> file = OpenFile(path, options);
  if (!file.ok()) return file.status();
  if (::fseeko(file->get(), static_cast<off_t>(offset), SEEK_SET) != 0) {
    return ErrnoError(path, "seek failed", errno);
  }
  std::vector<char> buffer(64 * 1024);
  uint64_t position = offset;
  uint64_t seen = 0;
  while (true) {
    size_t got = std::fread(buffer.data(), 1, buffer.size(), file->get());
    if (got == 0) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": file ends after ", seen, " of the ",
                                                     lines, " lines the header says to skip"));
    }
    for (size_t i = 0; i < got; ++i) {
      if (buffer[i] == '\n' && ++seen == lines) return position + i + 1;
    }
    position += got;
  }
}

absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& path, const std::string& what,
                                                 const std::string& text, size_t want) {
  std::vector<double> out;
  for (absl::string_view t : absl::StrSplit(text, absl::ByAnyChar(" \t\r\n"), absl::SkipEmpty())) {
    double v = 0;
    if (!absl::SimpleAtod(t, &v) || !std::isfinite(v)) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": ", what, ": '", t, "' is not a finite number"));
    }
    out.push_back(v);
  }
  if (out.size() != want) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", what, ": expected ", want, " numbers, got ", out.size()));
  }
  return out;
}

std::string DirectoryOf(const std::string& path) {
  size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

bool CheckedMul(uint64_t a, uint64_t b, uint64_t* out) {
  return !__builtin_mul_overflow(a, b, out);
}

bool CheckedAdd(uint64_t a, uint64_t b, uint64_t* out) {
  return !__builtin_add_overflow(a, b, out);
}

std::string DescribeLayout(const std::array<int64_t, 3>& dims, ScalarType type) {
  std::string text =
      absl::StrCat(dims[0], "x", dims[1], "x", dims[2], " ", std::string(ScalarTypeName(type)));
  uint64_t bytes = ScalarTypeSize(type);
  for (int64_t d : dims) {
    if (d < 0 || !CheckedMul(bytes, static_cast<uint64_t>(d), &bytes)) {
      return absl::StrCat(text, " (size overflows 64 bits)");
    }
  }
  return absl::StrCat(text, " = ", bytes, " bytes");
}

absl::StatusOr<uint64_t> CheckedDataBytes(const std::string& path,
                                          const std::array<int64_t, 3>& dims, ScalarType type,
                                          const ReadOptions& options) {
  static constexpr char kAxis[] = "xyz";
  for (int i = 0; i < 3; ++i) {
    if (dims[i] <= 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          path, ": size along ", std::string(1, kAxis[i]), " is ", dims[i], ", must be positive"));
    }
    if (dims[i] > INT_MAX) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": size along ",
                                                     std::string(1, kAxis[i]), " is ", dims[i],
                                                     ", larger than the supported ", INT_MAX));
    }
  }
  uint64_t voxels = 1;
  for (int64_t d : dims) {
    if (!CheckedMul(voxels, static_cast<uint64_t>(d), &voxels)) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": sizes ", dims[0], "x", dims[1], "x",
                                                     dims[2], " overflow a 64-bit voxel count"));
    }
  }
  uint64_t float_bytes = 0;
  if (!CheckedMul(voxels, sizeof(float), &float_bytes) || float_bytes > options.max_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        path, ": ", dims[0], "x", dims[1], "x", dims[2], " = ", voxels, " voxels need ",
        float_bytes / (1 << 20), " MiB as float, more than the limit of ",
        options.max_bytes / (1 << 20), " MiB"));
  }
  // A double is twice a float: checked too, for limits near 2^64.
  uint64_t bytes = 0;
  if (!CheckedMul(voxels, ScalarTypeSize(type), &bytes)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", voxels, " samples of ",
                                                   std::string(ScalarTypeName(type)),
                                                   " overflow 64 bits"));
  }
  return bytes;
}

void ConvertSamples(const unsigned char* src, size_t count, ScalarType type, ByteOrder order,
                    float* dst) {
  const bool host_little = std::endian::native == std::endian::little;
  const bool swap = (order == ByteOrder::kLittle) != host_little;
  switch (type) {
    case ScalarType::kUint8:
      ConvertTyped<uint8_t>(src, count, false, dst);
      break;
    case ScalarType::kInt8:
      ConvertTyped<int8_t>(src, count, false, dst);
      break;
    case ScalarType::kUint16:
      ConvertTyped<uint16_t>(src, count, swap, dst);
      break;
    case ScalarType::kInt16:
      ConvertTyped<int16_t>(src, count, swap, dst);
      break;
    case ScalarType::kUint32:
      ConvertTyped<uint32_t>(src, count, swap, dst);
      break;
    case ScalarType::kInt32:
      ConvertTyped<int32_t>(src, count, swap, dst);
      break;
    case ScalarType::kFloat32:
      ConvertTyped<float>(src, count, swap, dst);
      break;
    case ScalarType::kFloat64:
      ConvertTyped<double>(src, count, swap, dst);
      break;
  }
}

absl::Status ReadSamples(const ReadFn& read, uint64_t count, ScalarType type, ByteOrder order,
                         std::vector<float>* out) {
  const size_t sample_size = ScalarTypeSize(type);
  const size_t chunk_samples = kChunkBytes / sample_size;
  std::vector<unsigned char> buffer(std::min<uint64_t>(count, chunk_samples) * sample_size);
  uint64_t remaining = count;
  while (remaining > 0) {
    size_t n = static_cast<size_t>(std::min<uint64_t>(remaining, chunk_samples));
    absl::Status status = read(buffer.data(), n * sample_size);
    if (!status.ok()) return status;
    size_t old_size = out->size();
    out->resize(old_size + n);
    ConvertSamples(buffer.data(), n, type, order, out->data() + old_size);
    remaining -= n;
  }
  return absl::OkStatus();
}

absl::Status ReadRawSamples(const std::string& path, uint64_t offset, uint64_t count,
                            ScalarType type, ByteOrder order, std::vector<float>* out, const ReadOptions& options) {
  absl::StatusOr<FilePtr> file = OpenFile(path, options);
  if (!file.ok()) return file.status();
  if (::fseeko(file->get(), static_cast<off_t>(offset), SEEK_SET) != 0) {
    return ErrnoError(path, "seek failed", errno);
  }
  // The caller checked the file size, so the volume is known to fit.
  out->reserve(out->size() + count);
  std::FILE* f = file->get();
  return ReadSamples(
      [&](unsigned char* dst, size_t n) -> absl::Status {
        if (std::fread(dst, 1, n, f) != n) {
          // The file shrank since it was measured, or the disk failed.
          return absl::InvalidArgumentError(absl::StrCat(path, ": read failed or file shrank"));
        }
        return absl::OkStatus();
      },
      count, type, order, out);
}

absl::Status ReadAsciiSamples(const std::string& path, std::FILE* f, uint64_t count,
                              bool stop_at_tag, std::vector<float>* out) {
  std::string token;
  uint64_t read = 0;
  auto flush = [&]() -> absl::Status {
    if (token.empty()) return absl::OkStatus();
    double v = 0;
    if (token.size() > 64 || !absl::SimpleAtod(token, &v)) {
      return absl::InvalidArgumentError(absl::StrCat(
          path, ": ASCII data: '", absl::CEscape(token.substr(0, 64)), "' is not a number"));
    }
    if (++read > count) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": ASCII data holds more than the ",
                                                     count, " samples its header says"));
    }
    out->push_back(NearestFloat(v));
    token.clear();
    return absl::OkStatus();
  };
  while (true) {
    const int c = getc_unlocked(f);
    const bool end = c == EOF || (stop_at_tag && c == '<');
    if (end || absl::ascii_isspace(static_cast<unsigned char>(c))) {
      if (absl::Status s = flush(); !s.ok()) return s;
      if (end) break;
      continue;
    }
    if (token.size() > 64) continue;  // refused at its end, without growing
    token.push_back(static_cast<char>(c));
  }
  if (read < count) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": ASCII data holds ", read, " samples, its header says ", count, " (truncated?)"));
  }
  return absl::OkStatus();
}

CompressedFileReader::CompressedFileReader(std::string path, FilePtr file, Codec codec)
    : path_(std::move(path)), file_(std::move(file)), codec_(codec), in_(64 * 1024) {}

CompressedFileReader::~CompressedFileReader() {
  if (!initialized_) return;
  if (codec_ == Codec::kGzip) {
    inflateEnd(&stream_);
  } else {
    BZ2_bzDecompressEnd(&bz_);
  }
}

absl::StatusOr<std::unique_ptr<CompressedFileReader>> CompressedFileReader::Open(
    const std::string& path, uint64_t offset, const ReadOptions& options, Codec codec) {
  absl::StatusOr<FilePtr> file = OpenFile(path, options);
  if (!file.ok()) return file.status();
  if (::fseeko(file->get(), static_cast<off_t>(offset), SEEK_SET) != 0) {
    return ErrnoError(path, "seek failed", errno);
  }
  std::unique_ptr<CompressedFileReader> reader(
      new CompressedFileReader(path, *std::move(file), codec));
  if (codec == Codec::kGzip) {
    // 15 + 32: maximum window, and detect a gzip or zlib header automatically.
    if (inflateInit2(&reader->stream_, 15 + 32) != Z_OK) {
      return absl::ResourceExhaustedError(absl::StrCat(path, ": cannot initialise zlib"));
    }
  } else if (BZ2_bzDecompressInit(&reader->bz_, 0, 0) != BZ_OK) {
    return absl::ResourceExhaustedError(absl::StrCat(path, ": cannot initialise bzip2"));
  }
  reader->initialized_ = true;
  return reader;
}

absl::Status CompressedFileReader::Step(unsigned char* dst, size_t n, size_t* made,
                                        uint64_t before) {
  const size_t want = std::min<size_t>(n, size_t{1} << 30);
  if (codec_ == Codec::kGzip) {
    stream_.next_in = next_in_;
    stream_.avail_in = static_cast<uInt>(avail_in_);
    stream_.next_out = dst;
    stream_.avail_out = static_cast<uInt>(want);
    const int result = inflate(&stream_, Z_NO_FLUSH);
    *made = want - stream_.avail_out;
    next_in_ = stream_.next_in;
    avail_in_ = stream_.avail_in;
    switch (result) {
      case Z_OK:
      case Z_BUF_ERROR:  // no progress possible: more input needed, the loop reads it
        return absl::OkStatus();
      case Z_STREAM_END:
        stream_end_ = true;
        return absl::OkStatus();
      case Z_MEM_ERROR:
        return absl::ResourceExhaustedError(absl::StrCat(path_, ": zlib out of memory"));
      default:  // Z_DATA_ERROR, Z_NEED_DICT, Z_STREAM_ERROR
        return absl::InvalidArgumentError(
            absl::StrCat(path_, ": corrupt gzip data after ", before + *made,
                         " decompressed bytes: ", stream_.msg ? stream_.msg : "unknown error"));
    }
  }
  bz_.next_in = reinterpret_cast<char*>(next_in_);
  bz_.avail_in = static_cast<unsigned int>(avail_in_);
  bz_.next_out = reinterpret_cast<char*>(dst);
  bz_.avail_out = static_cast<unsigned int>(want);
  const int result = BZ2_bzDecompress(&bz_);
  *made = want - bz_.avail_out;
  next_in_ = reinterpret_cast<unsigned char*>(bz_.next_in);
  avail_in_ = bz_.avail_in;
  switch (result) {
    case BZ_OK:
      return absl::OkStatus();
    case BZ_STREAM_END:
      stream_end_ = true;
      return absl::OkStatus();
    case BZ_MEM_ERROR:
      return absl::ResourceExhaustedError(absl::StrCat(path_, ": bzip2 out of memory"));
    default:  // BZ_DATA_ERROR, BZ_DATA_ERROR_MAGIC, BZ_PARAM_ERROR
      return absl::InvalidArgumentError(absl::StrCat(path_, ": corrupt bzip2 data after ",
                                                     before + *made, " decompressed bytes"));
  }
}

absl::Status CompressedFileReader::Inflate(unsigned char* dst, size_t n, size_t* produced) {
  *produced = 0;
  while (*produced < n && !stream_end_) {
    if (avail_in_ == 0 && !file_eof_) {
      size_t got = std::fread(in_.data(), 1, in_.size(), file_.get());
      if (got < in_.size()) {
        if (std::ferror(file_.get())) return ErrnoError(path_, "read failed", errno);
        file_eof_ = true;
      }
      next_in_ = in_.data();
      avail_in_ = got;
    }
    const size_t before = *produced;
    size_t made = 0;
    if (absl::Status s = Step(dst + *produced, n - *produced, &made, position_ + before); !s.ok()) {
      return s;
    }
    *produced += made;
    // Out of input, and the codec made nothing of what it had: cut short.
    if (avail_in_ == 0 && file_eof_ && !stream_end_ && made == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": ", codec_name(), " data is truncated (stream cut off after ",
                       position_ + *produced, " decompressed bytes)"));
    }
  }
  position_ += *produced;
  return absl::OkStatus();
}

absl::Status CompressedFileReader::Read(unsigned char* dst, size_t n) {
  size_t produced = 0;
  absl::Status status = Inflate(dst, n, &produced);
  if (!status.ok()) return status;
  if (produced < n) {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": ", codec_name(), " data ends after ",
                                                   position_, " decompressed bytes"));
  }
  return absl::OkStatus();
}

absl::Status CompressedFileReader::Skip(uint64_t n) {
  unsigned char scratch[4096];
  while (n > 0) {
    size_t step = static_cast<size_t>(std::min<uint64_t>(n, sizeof(scratch)));
    absl::Status status = Read(scratch, step);
    if (!status.ok()) return status;
    n -= step;
  }
  return absl::OkStatus();
}

absl::StatusOr<bool> CompressedFileReader::AtEnd() {
  if (stream_end_) return true;
  unsigned char probe;
  size_t produced = 0;
  absl::Status status = Inflate(&probe, 1, &produced);
  if (!status.ok()) return status;
  return produced == 0;
}

absl::StatusOr<uint64_t> CompressedFileReader::SkipToEnd(uint64_t limit) {
  const uint64_t start = position_;
  unsigned char scratch[4096];
  while (!stream_end_) {
    size_t produced = 0;
    absl::Status status = Inflate(scratch, sizeof(scratch), &produced);
    if (!status.ok()) return status;
    if (position_ - start > limit) {
      return absl::InvalidArgumentError(absl::StrCat(path_, ": ", codec_name(),
                                                     " data goes on for more than ", limit,
                                                     " bytes after the samples"));
    }
  }
  return position_ - start;
}

absl::StatusOr<bool> IsGzipFile(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<std::string> prefix = ReadPrefix(path, 2, options);
  if (!prefix.ok()) return prefix.status();
  return prefix->size() == 2 && static_cast<unsigned char>((*prefix)[0]) == 0x1f &&
         static_cast<unsigned char>((*prefix)[1]) == 0x8b;
}

}  // namespace volume_io_internal

namespace vi = volume_io_internal;

absl::StatusOr<ScalarType> ParseScalarType(const std::string& name) {
  // NRRD's spellings (teem's airEnum for nrrdType) plus "float32".
  static const std::pair<const char*, ScalarType> kNames[] = {
      {"uchar", ScalarType::kUint8},
      {"unsigned char", ScalarType::kUint8},
      {"uint8", ScalarType::kUint8},
      {"uint8_t", ScalarType::kUint8},
      {"signed char", ScalarType::kInt8},
      {"int8", ScalarType::kInt8},
      {"int8_t", ScalarType::kInt8},
      {"short", ScalarType::kInt16},
      {"short int", ScalarType::kInt16},
      {"signed short", ScalarType::kInt16},
      {"signed short int", ScalarType::kInt16},
      {"int16", ScalarType::kInt16},
      {"int16_t", ScalarType::kInt16},
      {"ushort", ScalarType::kUint16},
      {"unsigned short", ScalarType::kUint16},
      {"unsigned short int", ScalarType::kUint16},
      {"uint16", ScalarType::kUint16},
      {"uint16_t", ScalarType::kUint16},
      {"int", ScalarType::kInt32},
      {"signed int", ScalarType::kInt32},
      {"int32", ScalarType::kInt32},
      {"int32_t", ScalarType::kInt32},
      {"uint", ScalarType::kUint32},
      {"unsigned int", ScalarType::kUint32},
      {"uint32", ScalarType::kUint32},
      {"uint32_t", ScalarType::kUint32},
      {"float", ScalarType::kFloat32},
      {"float32", ScalarType::kFloat32},
      {"double", ScalarType::kFloat64},
      {"float64", ScalarType::kFloat64},
  };
  std::string key = absl::AsciiStrToLower(absl::StripAsciiWhitespace(name));
  for (const auto& [spelling, type] : kNames) {
    if (key == spelling) return type;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unsupported sample type '", name,
                   "' (supported: uint8, int8, uint16, int16, uint32, int32, float, double)"));
}

absl::StatusOr<Volume> ReadRaw(const std::string& path, const RawSpec& spec,
                               const ReadOptions& options) {
  const std::array<int64_t, 3> dims = {spec.dims[0], spec.dims[1], spec.dims[2]};
  absl::StatusOr<uint64_t> data_bytes = vi::CheckedDataBytes(path, dims, spec.type, options);
  if (!data_bytes.ok()) return data_bytes.status();
  absl::StatusOr<uint64_t> file_size = vi::FileSize(path, options);
  if (!file_size.ok()) return file_size.status();
  uint64_t needed = 0;
  if (!vi::CheckedAdd(spec.header_bytes, *data_bytes, &needed) || needed != *file_size) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": raw spec says ", spec.header_bytes, "-byte header + ",
                     vi::DescribeLayout(dims, spec.type), ", file holds ", *file_size, " bytes"));
  }
  for (double s : spec.spacing) {
    if (!(s > 0.0) || !std::isfinite(s)) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": raw spec spacing ", s, " is not a positive number"));
    }
  }
  Volume volume;
  volume.dims = spec.dims;
  volume.spacing = spec.spacing;
  volume.source_type = spec.type;
  absl::Status status = vi::ReadRawSamples(path, spec.header_bytes, volume.VoxelCount(), spec.type,
                                           spec.byte_order, &volume.values, options);
  if (!status.ok()) return status;
  return volume;
}

std::span<const std::string_view> VolumeFileExtensions() {
  // A .hdr/.img pair is named by its .hdr (the .img is read with it).
  static constexpr std::string_view kExtensions[] = {".nrrd", ".nhdr",   ".den", ".nii", ".nii.gz",
                                                     ".hdr",  ".hdr.gz", ".mha", ".mhd", ".vti"};
  return kExtensions;
}

bool IsVolumeFileName(std::string_view path) {
  const std::string lower = absl::AsciiStrToLower(std::string(path));
  for (std::string_view e : VolumeFileExtensions()) {
    if (lower.size() > e.size() && lower.compare(lower.size() - e.size(), e.size(), e) == 0) {
      return true;
    }
  }
  return false;
}

absl::StatusOr<Volume> ReadVolume(const std::string& path, const ReadOptions& options) {
  const std::string lower = absl::AsciiStrToLower(path);
  if (absl::EndsWith(lower, ".nrrd") || absl::EndsWith(lower, ".nhdr")) {
    return ReadNrrd(path, options);
  }
  if (absl::EndsWith(lower, ".den")) return ReadDen(path, options);
  for (const char* e : {".nii", ".nii.gz", ".hdr", ".hdr.gz", ".img", ".img.gz"}) {
    if (absl::EndsWith(lower, e)) return ReadNifti(path, options);
  }
  if (absl::EndsWith(lower, ".mha") || absl::EndsWith(lower, ".mhd")) {
    return ReadMetaImage(path, options);
  }
  if (absl::EndsWith(lower, ".vti")) return ReadVti(path, options);
  if (absl::EndsWith(path, "/") || vi::IsDirectory(path, options)) {
    return ReadDicomSeries(path, options);
  }
  // "DIR#UID": one series of a DICOM directory.
  if (std::optional<SeriesPath> sp = ParseSeriesPath(path);
      sp && vi::IsDirectory(sp->dir, options)) {
    return ReadDicomSeries(path, options);
  }
  // Name the extension we saw so a typo ("cthead.nrd") is easy to spot.
  size_t slash = path.find_last_of('/');
  size_t dot = path.find_last_of('.');
  std::string extension = (dot == std::string::npos || (slash != std::string::npos && dot < slash))
                              ? "no extension"
                              : absl::StrCat("extension '", path.substr(dot), "'");
  std::string expected;
  for (std::string_view e : VolumeFileExtensions()) absl::StrAppend(&expected, std::string(e), ", ");
  return absl::InvalidArgumentError(
      absl::StrCat(path, ": unknown volume format (", extension, "; expected ", expected,
                   "a directory of DICOM files, or DIR#UID for one series of it)"));
}

}  // namespace transtick
