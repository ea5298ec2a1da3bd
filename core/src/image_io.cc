#include "transtick/image_io.h"

#include <OpenImageIO/imageio.h>

#include <array>
#include <optional>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

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
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot write this image format (", OIIO::geterror(), ")"));
  }
  const bool as_float = *format >= kFirstFloat;
  OIIO::ImageSpec spec(image.width, image.height, 3,
                       as_float ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8);
  spec.attribute("Software", "transtick");
  if (!out->open(path, spec)) {
    return absl::UnavailableError(absl::StrCat(path, ": ", out->geterror()));
  }
  bool ok;
  if (as_float) {
    ok = out->write_image(OIIO::TypeDesc::FLOAT, image.rgb.data());
  } else {
    std::vector<uint8_t> bytes(image.rgb.size());
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = ToByte(image.rgb[i]);
    ok = out->write_image(OIIO::TypeDesc::UINT8, bytes.data());
  }
  if (!ok || !out->close()) {
    return absl::UnavailableError(absl::StrCat(path, ": ", out->geterror()));
  }
  return absl::OkStatus();
}

absl::StatusOr<Image> ReadImage(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", OIIO::geterror()));
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels < 3) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": has ", spec.nchannels, " channels, need RGB"));
  }
  Image img;
  img.width = spec.width;
  img.height = spec.height;
  img.rgb.resize(static_cast<size_t>(spec.width) * spec.height * 3);
  if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, img.rgb.data())) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", in->geterror()));
  }
  return img;
}

}  // namespace transtick
