// The C interface of libtranstick_imageio.so (image_io_oiio.cc), which
// image_io.cc loads with dlopen.
#ifndef TRANSTICK_CORE_IMAGE_IO_MODULE_H_
#define TRANSTICK_CORE_IMAGE_IO_MODULE_H_

#include <cstddef>
#include <cstdint>

// The version of the interface below, which the module returns from
// transtick_module_abi (module_loader.h). Bump it with any change to it.
inline constexpr int kTranstickImageioAbi = 1;

enum {
  kTranstickImageioOk = 0,
  kTranstickImageioFormat = 1,  // not a format it can write or read
  kTranstickImageioIo = 2,      // the file could not be written or read
};

extern "C" {
// Writes `width` x `height` RGB: 32-bit float from `rgb`, or, when `rgb` is
// null, 8-bit from `bytes`. The error's text goes to `error`.
typedef int (*TranstickImageioWrite)(const char* path, int width, int height, const float* rgb,
                                     const uint8_t* bytes, char* error, size_t error_size);
// Reads an image as float RGB into a buffer that transtick_imageio_free
// releases.
typedef int (*TranstickImageioRead)(const char* path, int* width, int* height, float** rgb,
                                    char* error, size_t error_size);
typedef void (*TranstickImageioFree)(float* rgb);
}

#endif  // TRANSTICK_CORE_IMAGE_IO_MODULE_H_
