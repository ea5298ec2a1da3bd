#include "module_loader.h"

#include <dlfcn.h>
#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <vector>

#include "absl/strings/str_cat.h"

namespace transtick {

absl::StatusOr<void*> OpenModule(const char* file_name, const char* env_var, const char* build_path,
                                 const char* what, const char* const* symbols) {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv(env_var); env && *env) candidates.push_back(env);
  char exe[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (n > 0) {
    std::string dir(exe, static_cast<size_t>(n));
    dir = dir.substr(0, dir.rfind('/'));
    candidates.push_back(absl::StrCat(dir, "/../lib/transtick/", file_name));
    candidates.push_back(absl::StrCat(dir, "/", file_name));
  }
  // Through StrCat: a std::string made from a literal draws a false
  // -Wstringop-overread from GCC 12 when linked with -flto.
  if (build_path != nullptr) candidates.push_back(absl::StrCat(build_path));
  candidates.push_back(file_name);
  std::string tried;
  for (const std::string& path : candidates) {
    void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      absl::StrAppend(&tried, tried.empty() ? "" : "; ", ::dlerror());
      continue;
    }
    bool all = true;
    for (const char* const* s = symbols; *s != nullptr; ++s) all = all && ::dlsym(handle, *s);
    if (all) return handle;
    ::dlclose(handle);
    absl::StrAppend(&tried, tried.empty() ? "" : "; ", path, " lacks a function it should have");
  }
  return absl::UnavailableError(
      absl::StrCat(file_name, " (", what, ") could not be loaded: ", tried));
}

}  // namespace transtick
