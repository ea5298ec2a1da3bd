#include "transtick/image_io.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

bool IsFloatFormat(const std::string& path) {
  auto dot = path.rfind('.');
  if (dot == std::string::npos) return false;
  std::string ext = path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == "exr" || ext == "tif" || ext == "tiff" || ext == "hdr";
}

}  // namespace

absl::Status WriteImage(const std::string& path, const Image& image) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot write this image format (", OIIO::geterror(), ")"));
  }
  const bool as_float = IsFloatFormat(path);
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
