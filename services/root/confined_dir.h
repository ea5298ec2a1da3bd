// Files opened by paths relative to a directory, never outside it: no
// absolute path, no "..", no symbolic link leads out, whatever the
// directory's contents become between a check and an open. The root opens
// every volume file through one (docs/security.md, "The data directory").
#ifndef TRANSTICK_SERVICES_ROOT_CONFINED_DIR_H_
#define TRANSTICK_SERVICES_ROOT_CONFINED_DIR_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

class ConfinedDir {
 public:
  // Opens `dir`; fails NOT_FOUND naming it when it is not a directory.
  static absl::StatusOr<std::shared_ptr<const ConfinedDir>> Open(const std::string& dir);
  ~ConfinedDir();
  ConfinedDir(const ConfinedDir&) = delete;
  ConfinedDir& operator=(const ConfinedDir&) = delete;

  // Opens `relative` read-only and returns the descriptor, which the caller
  // closes. The kernel resolves the path beneath the directory (openat2
  // with RESOLVE_BENEATH); where it cannot, the last component must not be
  // a link and the opened file's resolved path must lie in the directory.
  // Errors name `relative`, never the directory's own path:
  // PERMISSION_DENIED for a path that leads outside, NOT_FOUND for one
  // that does not exist.
  absl::StatusOr<int> OpenFile(const std::string& relative) const;

  // The names in directory `relative` (a DICOM series), opened as OpenFile
  // opens, with "." and ".."; at most kMaxListed of them. Errors as
  // OpenFile's, or INVALID_ARGUMENT when it is not a directory.
  static constexpr size_t kMaxListed = 1 << 17;
  absl::StatusOr<std::vector<std::string>> ListDir(const std::string& relative) const;

  // What `relative` is, resolved as OpenFile resolves it (a link is
  // followed only while it stays inside), without opening the file for
  // reading (a FIFO does not block). Errors as OpenFile's.
  struct Entry {
    bool directory = false;
    bool regular = false;
    uint64_t bytes = 0;
    int64_t mtime_ns = 0;  // last modification, ns since the epoch
  };
  absl::StatusOr<Entry> Stat(const std::string& relative) const;

 private:
  // OpenFile with `flags` (O_RDONLY or O_PATH).
  absl::StatusOr<int> OpenWith(const std::string& relative, int flags) const;
  ConfinedDir(int fd, std::string real) : fd_(fd), real_(std::move(real)) {}
  const int fd_;            // O_PATH descriptor of the directory
  const std::string real_;  // its resolved path, for the fallback's check
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_CONFINED_DIR_H_
