#include "module_loader.h"

#include <dlfcn.h>
#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace transtick {

std::vector<std::string> CompanionCandidates(const char* file_name, const char* env_var,
                                             const char* build_path) {
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
  return candidates;
}

absl::StatusOr<void*> OpenModule(const char* file_name, const char* env_var, const char* build_path,
                                 const char* what, const char* const* symbols, int abi) {
  std::vector<std::string> candidates = CompanionCandidates(file_name, env_var, build_path);
  candidates.push_back(absl::StrCat(file_name));
  std::string tried;
  auto failed = [&tried](const std::string& path, absl::string_view why) {
    // dlerror names the file it could not open, which is not the
    // candidate when one of the module's own libraries is missing.
    absl::StrAppend(&tried, tried.empty() ? "" : "; ",
                    absl::StartsWith(why, path) ? "" : absl::StrCat(path, ": "), why);
  };
  for (const std::string& path : candidates) {
    void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* why = ::dlerror();
      failed(path, why ? why : "cannot be opened");
      continue;
    }
    std::string missing;
    for (const char* const* s = symbols; *s != nullptr && missing.empty(); ++s) {
      if (::dlsym(handle, *s) == nullptr) missing = *s;
    }
    using Abi = int (*)();
    const auto module_abi = reinterpret_cast<Abi>(::dlsym(handle, kModuleAbiSymbol));
    ::dlerror();  // a failed dlsym leaves its error pending: not the caller's
    if (missing.empty() && module_abi != nullptr && module_abi() == abi) return handle;
    if (!missing.empty()) {
      failed(path, absl::StrCat("lacks the function ", missing, " (not ", what, "'s module?)"));
    } else if (module_abi == nullptr) {
      failed(path, absl::StrCat("has no interface version (", kModuleAbiSymbol,
                                "): built by an older transtick"));
    } else {
      failed(path, absl::StrCat("is interface version ", module_abi(), ", this program needs ", abi,
                                ": built by another transtick"));
    }
    ::dlclose(handle);
  }
  return absl::UnavailableError(
      absl::StrCat(file_name, " (", what, ") could not be loaded: ", tried));
}

}  // namespace transtick
