// OpenModule (core/src/module_loader.h): where a module is looked for, in
// which order, and what a program says when it cannot load one. The real
// modules of the build (GDCM's and OpenImageIO's) stand in for a good one.
#include "module_loader.h"

#include <dlfcn.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "absl/strings/str_cat.h"
#include "dicom_module.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "image_io_module.h"
#include "testing.h"

namespace transtick {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr const char* kEnv = "TRANSTICK_MODULE_LOADER_TEST";
constexpr const char* kDicomSymbols[] = {"transtick_dicom_read_header",
                                         "transtick_dicom_read_pixels", nullptr};

class ModuleLoaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TempDir();
    ::unsetenv(kEnv);
  }
  void TearDown() override { ::unsetenv(kEnv); }
  std::string dir_;
};

// The path a handle was opened from.
std::string PathOf(void* handle, const char* symbol) {
  Dl_info info{};
  void* f = ::dlsym(handle, symbol);
  if (f == nullptr || ::dladdr(f, &info) == 0 || info.dli_fname == nullptr) return "";
  return fs::weakly_canonical(info.dli_fname).string();
}

TEST_F(ModuleLoaderTest, MissingEverywhereNamesTheModuleWhatItWrapsAndEveryPathTried) {
  const std::string env_path = dir_ + "/from-env/libtranstick_nothing.so";
  const std::string build_path = dir_ + "/from-build/libtranstick_nothing.so";
  ::setenv(kEnv, env_path.c_str(), 1);
  absl::StatusOr<void*> h = OpenModule("libtranstick_nothing.so", kEnv, build_path.c_str(),
                                       "Nothing", kDicomSymbols, kDicomModuleAbi);
  ASSERT_FALSE(h.ok());
  EXPECT_EQ(h.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(
      std::string(h.status().message()),
      AllOf(HasSubstr("libtranstick_nothing.so (Nothing) could not be loaded"), HasSubstr(env_path),
            HasSubstr(build_path), HasSubstr("/../lib/transtick/libtranstick_nothing.so")));
}

TEST_F(ModuleLoaderTest, AFileThatIsNotALibraryIsNamedAndPassedOver) {
  const std::string junk = dir_ + "/libtranstick_dicom.so";
  std::ofstream(junk) << "not a shared library\n";
  ::setenv(kEnv, junk.c_str(), 1);
  // Only the junk and paths where nothing is: the error says why each failed.
  absl::StatusOr<void*> h =
      OpenModule("libtranstick_nothing.so", kEnv, nullptr, "GDCM", kDicomSymbols, kDicomModuleAbi);
  ASSERT_FALSE(h.ok());
  EXPECT_THAT(std::string(h.status().message()), HasSubstr(junk));
  // With a good module further down the list, the junk is passed over.
  h = OpenModule("libtranstick_dicom.so", kEnv, TRANSTICK_DICOM_MODULE_PATH, "GDCM", kDicomSymbols,
                 kDicomModuleAbi);
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(PathOf(*h, kDicomSymbols[0]),
            fs::weakly_canonical(TRANSTICK_DICOM_MODULE_PATH).string());
}

TEST_F(ModuleLoaderTest, ALibraryWithoutTheFunctionsIsRefusedByName) {
  // OpenImageIO's module is a real library, but not GDCM's.
  ::setenv(kEnv, TRANSTICK_IMAGEIO_MODULE_PATH, 1);
  absl::StatusOr<void*> h =
      OpenModule("libtranstick_nothing.so", kEnv, nullptr, "GDCM", kDicomSymbols, kDicomModuleAbi);
  ASSERT_FALSE(h.ok());
  EXPECT_THAT(std::string(h.status().message()),
              HasSubstr(std::string(TRANSTICK_IMAGEIO_MODULE_PATH) +
                        ": lacks the function transtick_dicom_read_header"));
}

TEST_F(ModuleLoaderTest, AModuleOfAnotherInterfaceVersionIsPassedOver) {
  // The build's module, as a program built for the next version of the
  // interface sees it: refused, with both versions named.
  absl::StatusOr<void*> h = OpenModule("libtranstick_nothing.so", kEnv, TRANSTICK_DICOM_MODULE_PATH,
                                       "GDCM", kDicomSymbols, kDicomModuleAbi + 1);
  ASSERT_FALSE(h.ok());
  EXPECT_THAT(std::string(h.status().message()),
              HasSubstr(absl::StrCat(TRANSTICK_DICOM_MODULE_PATH, ": is interface version ",
                                     kDicomModuleAbi, ", this program needs ", kDicomModuleAbi + 1,
                                     ": built by another transtick")));
  // And the OpenImageIO module answers its own version.
  static constexpr const char* kNone[] = {nullptr};
  h = OpenModule("libtranstick_nothing.so", kEnv, TRANSTICK_IMAGEIO_MODULE_PATH, "OpenImageIO",
                 kNone, kTranstickImageioAbi);
  EXPECT_TRUE(h.ok()) << h.status();
}

TEST_F(ModuleLoaderTest, TheEnvironmentComesBeforeTheBuildTree) {
  // A copy of the module elsewhere, named by the variable, is the one opened
  // even though the build tree holds the original.
  const std::string copy = dir_ + "/elsewhere/libtranstick_dicom.so";
  fs::create_directories(dir_ + "/elsewhere");
  fs::copy_file(TRANSTICK_DICOM_MODULE_PATH, copy);
  ::setenv(kEnv, copy.c_str(), 1);
  absl::StatusOr<void*> h = OpenModule("libtranstick_dicom.so", kEnv, TRANSTICK_DICOM_MODULE_PATH,
                                       "GDCM", kDicomSymbols, kDicomModuleAbi);
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(PathOf(*h, kDicomSymbols[0]), fs::weakly_canonical(copy).string());
  // Unset, the build tree's.
  ::unsetenv(kEnv);
  h = OpenModule("libtranstick_dicom.so", kEnv, TRANSTICK_DICOM_MODULE_PATH, "GDCM", kDicomSymbols,
                 kDicomModuleAbi);
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(PathOf(*h, kDicomSymbols[0]),
            fs::weakly_canonical(TRANSTICK_DICOM_MODULE_PATH).string());
}

}  // namespace
}  // namespace transtick
