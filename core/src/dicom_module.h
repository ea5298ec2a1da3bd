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
inline constexpr int kDicomModuleAbi = 3;

// What a multi-frame image's functional groups say of one frame (PS3.3
// C.7.6.16): the byte values of ImagePositionPatient in its
// PlanePositionSequence (0020,9113), ImageOrientationPatient in
// PlaneOrientationSequence (0020,9116), PixelSpacing in
// PixelMeasuresSequence (0028,9110), and RescaleSlope and RescaleIntercept
// in PixelValueTransformationSequence (0028,9145); the frame's own item of
// the per-frame groups first, else the shared groups' item. nullopt when
// neither has it.
struct DicomFrame {
  std::optional<std::string> position, orientation, spacing, slope, intercept;
};

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
  // One per item of the PerFrameFunctionalGroupsSequence (5200,9230), at
  // most `max_frames` (read_header's argument) of them: empty when the
  // file has none (a single-frame image, or frames placed otherwise).
  std::vector<DicomFrame> frames;
  bool more_frames = false;  // the sequence held more items than max_frames
};

// An image's pixels, decoded.
struct DicomPixels {
  std::string error;  // why they could not be, or "" when `bytes` holds them
  // frames x rows x columns samples of bits / 8 bytes, host byte order
  std::vector<char> bytes;
};

extern "C" {
// Reads the header of the file in `bytes`, which it may move from (a
// slice's whole file: not copied), and at most `max_frames` frames'
// functional groups.
typedef void (*TranstickDicomReadHeader)(std::string* bytes, const uint32_t* tags, size_t count,
                                         size_t max_frames, DicomHeader* out);
// Decodes the pixels of the file in `bytes`, which it may move from, and
// which must be `frames` frames of `rows` x `columns` grey samples of
// `bits` bits.
typedef void (*TranstickDicomReadPixels)(std::string* bytes, int rows, int columns, int bits,
                                         int frames, DicomPixels* out);
}

}  // namespace transtick

#endif  // TRANSTICK_CORE_DICOM_MODULE_H_
