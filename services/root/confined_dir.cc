#include "confined_dir.h"

#include <fcntl.h>
#include <dirent.h>
#include <linux/openat2.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstring>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

absl::Status OpenError(const std::string& relative, int error) {
  switch (error) {
    case ENOENT:
    case ENOTDIR:
      return absl::NotFoundError(
          absl::StrCat("'", relative, "' is not in the data directory"));
    case EXDEV:  // RESOLVE_BENEATH: the path leaves the directory
    case ELOOP:  // a link where none may be
      return absl::PermissionDeniedError(
          absl::StrCat("'", relative, "' leads outside the data directory"));
    default:
      return absl::PermissionDeniedError(
          absl::StrCat("'", relative, "': cannot open (", std::strerror(error), ")"));
  }
}

}  // namespace

absl::StatusOr<std::shared_ptr<const ConfinedDir>> ConfinedDir::Open(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_PATH | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    return absl::NotFoundError(absl::StrCat("data directory ", dir, ": ", std::strerror(errno)));
  }
  char real[PATH_MAX];
  const std::string self = absl::StrCat("/proc/self/fd/", fd);
  const ssize_t n = ::readlink(self.c_str(), real, sizeof(real) - 1);
  std::string resolved = n > 0 ? std::string(real, n) : dir;
  return std::shared_ptr<const ConfinedDir>(new ConfinedDir(fd, std::move(resolved)));
}

ConfinedDir::~ConfinedDir() { ::close(fd_); }

absl::StatusOr<int> ConfinedDir::OpenFile(const std::string& relative) const {
  return OpenWith(relative, O_RDONLY);
}

absl::StatusOr<ConfinedDir::Entry> ConfinedDir::Stat(const std::string& relative) const {
  auto fd = OpenWith(relative, O_PATH);
  if (!fd.ok()) return fd.status();
  struct stat st {};
  const int r = ::fstat(*fd, &st);
  ::close(*fd);
  if (r != 0) return OpenError(relative, errno);
  Entry e;
  e.directory = S_ISDIR(st.st_mode);
  e.regular = S_ISREG(st.st_mode);
  e.bytes = e.regular ? static_cast<uint64_t>(st.st_size) : 0;
  e.mtime_ns = int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
  return e;
}

absl::StatusOr<int> ConfinedDir::OpenWith(const std::string& relative, int flags) const {
  if (relative.empty() || relative.front() == '/') {
    return absl::PermissionDeniedError(
        absl::StrCat("'", relative, "' must be a path relative to the data directory"));
  }
  open_how how{};
  // openat2 refuses O_PATH with flags other than O_CLOEXEC, O_DIRECTORY and
  // O_NOFOLLOW (open ignores them).
  const int extra = (flags & O_PATH) ? O_CLOEXEC : O_CLOEXEC | O_NOCTTY;
  how.flags = static_cast<uint64_t>(flags | extra);
  how.resolve = RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS;
  int fd = static_cast<int>(::syscall(SYS_openat2, fd_, relative.c_str(), &how, sizeof(how)));
  if (fd >= 0) return fd;
  const int error = errno;
  // Kernels before 5.6, or a seccomp filter that refuses openat2.
  if (error != ENOSYS && error != EPERM) return OpenError(relative, error);
  fd = ::openat(fd_, relative.c_str(), flags | extra | O_NOFOLLOW);
  if (fd < 0) return OpenError(relative, errno);
  char real[PATH_MAX];
  const std::string self = absl::StrCat("/proc/self/fd/", fd);
  const ssize_t n = ::readlink(self.c_str(), real, sizeof(real) - 1);
  if (n <= 0 || !absl::StartsWith(std::string(real, n), real_ + "/")) {
    ::close(fd);
    return OpenError(relative, EXDEV);
  }
  return fd;
}

absl::StatusOr<std::vector<std::string>> ConfinedDir::ListDir(const std::string& relative) const {
  auto fd = OpenFile(relative);
  if (!fd.ok()) return fd.status();
  DIR* dir = ::fdopendir(*fd);  // takes the descriptor; fails on a file
  if (dir == nullptr) {
    ::close(*fd);
    return absl::InvalidArgumentError(absl::StrCat("'", relative, "' is not a directory"));
  }
  std::vector<std::string> names;
  while (const dirent* e = ::readdir(dir)) {
    if (names.size() >= kMaxListed) break;
    names.emplace_back(e->d_name);
  }
  ::closedir(dir);
  return names;
}

}  // namespace transtick
