// The interface of libtranstick_dicom.so (dicom_gdcm.cc): the parts of the
// DICOM reader (dicom.cc) that need GDCM, in a module of their own that
// dicom.cc loads with dlopen on first use. Linked into a program, GDCM
// loads its data dictionaries at start-up, about 18 ms of CPU in every
// process (the CLI's `version` took 47 ms with it), whether it reads DICOM
// or not.
//
// The module is built with the rest of transtick by the same compiler, so
// the functions take C++ types; they are extern "C" only to be found by
// name. They never throw (an exception inside, even GDCM's or an
// allocation's, becomes an unreadable file or an error) and never abort on a file's content
// (ElementWalk in dicom.cc has checked its element lengths before either is called).
#ifndef TRANSTICK_CORE_DICOM_MODULE_H_
#define TRANSTICK_CORE_DICOM_MODULE_H_

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace transtick {

// The version of the interface below, which the module returns from
// transtick_module_abi (module_loader.h): a program refuses a module of
// another version, built by another transtick (its types may differ).
// Bump it with any change to the types or functions below.
inline constexpr int kDicomModuleAbi = 2;

// A slice file's header, up to its pixel data, as GDCM reads it.
struct DicomHeader {
  bool read = false;          // GDCM could read it
  bool encapsulated = false;  // the pixel data is compressed (its transfer syntax's)
  bool big_endian = false;    // the retired explicit VR big endian syntax
  // Where the pixel data's value begins in the file, or -1 when there is
  // none; and the value length before it, as stored (little endian).
  int64_t pixel_value_at = -1;
  uint32_t pixel_length = 0;
  // The byte value of each element asked for, in order (tags as group <<
  // 16 | element); nullopt when absent or without a byte value.
  std::vector<std::optional<std::string>> values;
};

// A slice's pixels, decoded.
struct DicomPixels {
  std::string error;        // why they could not be, or "" when `bytes` holds them
  std::vector<char> bytes;  // rows x columns samples of bits / 8 bytes, host byte order
};

extern "C" {
// Reads the header of the file in `bytes`, which it may move from (a
// slice's whole file: not copied).
typedef void (*TranstickDicomReadHeader)(std::string* bytes, const uint32_t* tags, size_t count,
                                         DicomHeader* out);
// Decodes the pixels of the file in `bytes`, which it may move from, and
// which must be one frame of `rows` x `columns` grey samples of `bits` bits.
typedef void (*TranstickDicomReadPixels)(std::string* bytes, int rows, int columns, int bits,
                                         DicomPixels* out);
}

}  // namespace transtick

#endif  // TRANSTICK_CORE_DICOM_MODULE_H_
