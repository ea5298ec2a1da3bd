// libFuzzer entry for the volume readers: the input becomes a file that each
// reader parses. Every input must give a volume or a status; a crash, an
// out-of-bounds access (under ASan) or a large allocation is a bug.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "transtick/volume_io.h"

namespace {

// One scratch file per process, reused for every input.
const std::string& ScratchPath() {
  static const std::string* path = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp != nullptr ? tmp : "/tmp") + "/volume_fuzzer_XXXXXX";
    int fd = mkstemp(pattern.data());
    if (fd < 0) std::abort();
    close(fd);
    return new std::string(pattern);
  }();
  return *path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& path = ScratchPath();
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, file) != size) std::abort();
  std::fclose(file);

  // Small enough that a lying header cannot exhaust the fuzzer's memory.
  transtick::ReadOptions options;
  options.max_bytes = uint64_t{64} << 20;
  (void)transtick::ReadNrrd(path, options);
  (void)transtick::ReadNifti(path, options);
  (void)transtick::ReadDen(path, options);
  return 0;
}
