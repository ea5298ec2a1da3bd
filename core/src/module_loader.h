// Finds and loads one of transtick's own modules (a shared library built
// with it, opened with dlopen only when first needed), so that a program
// that never uses what a module wraps never loads that module's libraries.
#ifndef TRANSTICK_CORE_MODULE_LOADER_H_
#define TRANSTICK_CORE_MODULE_LOADER_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

// Where to look for `file_name`, one of the files built and installed with
// transtick (a module, or a helper program), in order: $`env_var` when set;
// beside the program (PROGRAM_DIR/../lib/transtick/, as the image installs
// it, and PROGRAM_DIR itself); `build_path`, where the build tree put it
// (may be null).
std::vector<std::string> CompanionCandidates(const char* file_name, const char* env_var,
                                             const char* build_path);

// Opens the module `file_name` (e.g. "libtranstick_imageio.so") from the
// first of CompanionCandidates, then the library search path. Returns its handle, or an error
// naming `what` and every path tried, each with why it failed. Every symbol in `symbols`
// (null-terminated) must resolve, and the module's
// `int transtick_module_abi(void)` must return `abi`, the version of the
// interface the program was built with: a module left from another
// transtick (an older install, a stale copy on the search path) is passed
// over, since the types it takes may differ.
inline constexpr const char* kModuleAbiSymbol = "transtick_module_abi";
absl::StatusOr<void*> OpenModule(const char* file_name, const char* env_var, const char* build_path,
                                 const char* what, const char* const* symbols, int abi);

}  // namespace transtick

#endif  // TRANSTICK_CORE_MODULE_LOADER_H_
