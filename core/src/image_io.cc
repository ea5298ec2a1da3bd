// PNG is written here with zlib (png.h); the other formats, and reading,
// go through OpenImageIO in libtranstick_imageio.so (image_io_oiio.cc),
// loaded on first use, so a program that writes no such file never loads
// OpenImageIO's libraries.
#include "transtick/image_io.h"

#include <dlfcn.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <optional>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "image_io_module.h"
#include "module_loader.h"
#include "transtick/png.h"

namespace transtick {
namespace {

// The module's functions, or why it could not be loaded.
struct Module {
  TranstickImageioWrite write = nullptr;
  TranstickImageioRead read = nullptr;
  TranstickImageioFree free = nullptr;
  std::string error;
};

// libtranstick_imageio.so, found as OpenModule says.
const Module& LoadModule() {
  static const Module module = [] {
    static constexpr const char* kSymbols[] = {"transtick_imageio_write", "transtick_imageio_read",
                                               "transtick_imageio_free", nullptr};
#ifdef TRANSTICK_IMAGEIO_BUILD_PATH
    const char* build_path = TRANSTICK_IMAGEIO_BUILD_PATH;
#else
    const char* build_path = nullptr;
#endif
    Module m;
    absl::StatusOr<void*> handle =
        OpenModule("libtranstick_imageio.so", "TRANSTICK_IMAGEIO_MODULE", build_path, "OpenImageIO",
                   kSymbols, kTranstickImageioAbi);
    if (!handle.ok()) {
      m.error = std::string(handle.status().message());
      return m;
    }
    m.write = reinterpret_cast<TranstickImageioWrite>(::dlsym(*handle, kSymbols[0]));
    m.read = reinterpret_cast<TranstickImageioRead>(::dlsym(*handle, kSymbols[1]));
    m.free = reinterpret_cast<TranstickImageioFree>(::dlsym(*handle, kSymbols[2]));
    return m;
  }();
  return module;
}

// The 8-bit formats first, then the float ones.
constexpr std::array<std::string_view, 7> kExtensions = {"png",  "jpg", "jpeg", "tif",
                                                         "tiff", "exr", "hdr"};
constexpr size_t kFirstFloat = 3;

// The index of `path`'s extension in kExtensions, if it has one of them.
std::optional<size_t> FormatOf(std::string_view path) {
  const size_t dot = path.rfind('.');
  if (dot == std::string_view::npos) return std::nullopt;
  // absl::string_view is not std::string_view in Debian's absl.
  std::string ext(path.substr(dot + 1));
  for (char& c : ext) c = absl::ascii_tolower(static_cast<unsigned char>(c));
  for (size_t i = 0; i < kExtensions.size(); ++i) {
    if (ext == kExtensions[i]) return i;
  }
  return std::nullopt;
}

}  // namespace

std::span<const std::string_view> SupportedImageExtensions() { return kExtensions; }

bool IsSupportedImagePath(std::string_view path) { return FormatOf(path).has_value(); }

bool IsByteImagePath(std::string_view path) {
  const std::optional<size_t> format = FormatOf(path);
  return format && *format < kFirstFloat;
}

std::string SupportedImageList() {
  std::string list;
  for (std::string_view ext : kExtensions) {
    if (!list.empty()) list += ", ";
    list += ".";
    list += ext;
  }
  return list;
}

absl::Status WriteImage(const std::string& path, const Image& image) {
  const std::optional<size_t> format = FormatOf(path);
  if (!format) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": not an image format transtick writes (", SupportedImageList(), ")"));
  }
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != static_cast<size_t>(image.width) * image.height * 3) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": the image is empty or malformed"));
  }
  if (kExtensions[*format] == "png") {
    // zlib's fastest level: on cthead turntable frames at 400x400, level 6
    // took 3.1 times as long (5.5 ms a frame against 1.75) for files 3%
    // smaller (58 KiB against 60), and a client writing every frame of a
    // job spent most of its CPU there.
    auto png = EncodePng(image, /*level=*/1);
    if (!png.ok()) return absl::InvalidArgumentError(absl::StrCat(path, ": ", png.status().message()));
    FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) return absl::UnavailableError(absl::StrCat(path, ": cannot be created"));
    const bool written = std::fwrite(png->data(), 1, png->size(), f) == png->size();
    if (std::fclose(f) != 0 || !written) {
      return absl::UnavailableError(absl::StrCat(path, ": could not be written in full"));
    }
    return absl::OkStatus();
  }
  const Module& m = LoadModule();
  if (!m.write) {
    return absl::UnavailableError(absl::StrCat(path, ": writing .", std::string(kExtensions[*format]),
                                               " needs ", m.error));
  }
  const bool as_float = *format >= kFirstFloat;
  std::vector<uint8_t> bytes;
  if (!as_float) {
    bytes.resize(image.rgb.size());
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = ToByte(image.rgb[i]);
  }
  char error[512] = "";
  const int r = m.write(path.c_str(), image.width, image.height,
                        as_float ? image.rgb.data() : nullptr, as_float ? nullptr : bytes.data(),
                        error, sizeof(error));
  if (r == kTranstickImageioFormat) return absl::InvalidArgumentError(absl::StrCat(path, ": ", error));
  if (r != kTranstickImageioOk) return absl::UnavailableError(absl::StrCat(path, ": ", error));
  return absl::OkStatus();
}

absl::StatusOr<Image> ReadImage(const std::string& path) {
  const Module& m = LoadModule();
  if (!m.read) return absl::UnavailableError(absl::StrCat(path, ": reading needs ", m.error));
  Image img;
  float* rgb = nullptr;
  char error[512] = "";
  if (m.read(path.c_str(), &img.width, &img.height, &rgb, error, sizeof(error)) !=
      kTranstickImageioOk) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", error));
  }
  img.rgb.assign(rgb, rgb + static_cast<size_t>(img.width) * img.height * 3);
  m.free(rgb);
  return img;
}

}  // namespace transtick
