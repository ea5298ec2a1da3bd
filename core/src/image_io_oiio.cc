// The OpenImageIO side of image_io.cc, built as its own shared module
// (libtranstick_imageio.so) that image_io.cc loads with dlopen only when a
// format other than PNG is written or an image is read. OpenImageIO brings
// some 260 shared libraries; linking it into every program made each
// `transtick` command spend 0.3-1 s in the dynamic loader before main.
//
// The interface is C: plain buffers in, an error message out.
#include <OpenImageIO/imageio.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "image_io_module.h"

namespace {

void SetError(char* error, size_t size, const std::string& message) {
  if (size == 0) return;
  std::strncpy(error, message.c_str(), size - 1);
  error[size - 1] = '\0';
}

int Write(const char* path, int width, int height, const float* rgb, const uint8_t* bytes,
          char* error, size_t error_size) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    SetError(error, error_size, "cannot write this image format (" + OIIO::geterror() + ")");
    return kTranstickImageioFormat;
  }
  OIIO::ImageSpec spec(width, height, 3, rgb ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8);
  spec.attribute("Software", "transtick");
  if (!out->open(path, spec)) {
    SetError(error, error_size, out->geterror());
    return kTranstickImageioIo;
  }
  const bool ok = rgb ? out->write_image(OIIO::TypeDesc::FLOAT, rgb)
                      : out->write_image(OIIO::TypeDesc::UINT8, bytes);
  if (!ok || !out->close()) {
    SetError(error, error_size, out->geterror());
    return kTranstickImageioIo;
  }
  return kTranstickImageioOk;
}

int Read(const char* path, int* width, int* height, float** rgb, char* error, size_t error_size) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    SetError(error, error_size, OIIO::geterror());
    return kTranstickImageioFormat;
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels < 3) {
    SetError(error, error_size, "has " + std::to_string(spec.nchannels) + " channels, need RGB");
    return kTranstickImageioFormat;
  }
  const size_t n = static_cast<size_t>(spec.width) * spec.height * 3;
  float* out = static_cast<float*>(std::malloc(n * sizeof(float)));
  if (out == nullptr) {
    SetError(error, error_size, "out of memory");
    return kTranstickImageioIo;
  }
  if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, out)) {
    std::free(out);
    SetError(error, error_size, in->geterror());
    return kTranstickImageioFormat;
  }
  *width = spec.width;
  *height = spec.height;
  *rgb = out;
  return kTranstickImageioOk;
}

// Runs `call`, an entry point's body; whatever it throws becomes an I/O
// error with its message.
template <typename Call>
int Guarded(char* error, size_t error_size, const Call& call) {
  try {
    return call();
  } catch (const std::exception& e) {
    SetError(error, error_size, std::string("OpenImageIO failed: ") + e.what());
  } catch (...) {
    SetError(error, error_size, "OpenImageIO failed");
  }
  return kTranstickImageioIo;
}

}  // namespace

// The entry points (image_io_module.h): nothing thrown inside, by
// OpenImageIO or an allocation, crosses into the program.
extern "C" {

int transtick_module_abi() { return kTranstickImageioAbi; }

int transtick_imageio_write(const char* path, int width, int height, const float* rgb,
                            const uint8_t* bytes, char* error, size_t error_size) {
  return Guarded(error, error_size,
                 [&] { return Write(path, width, height, rgb, bytes, error, error_size); });
}

int transtick_imageio_read(const char* path, int* width, int* height, float** rgb, char* error,
                           size_t error_size) {
  return Guarded(error, error_size,
                 [&] { return Read(path, width, height, rgb, error, error_size); });
}

void transtick_imageio_free(float* rgb) { std::free(rgb); }

}  // extern "C"
