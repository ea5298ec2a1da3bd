// Writes DICOM slices with GDCM, for the tests and the fuzzers' seeds: a
// CT image (explicit VR little endian, int16 pixels, MONOCHROME2) with the
// attributes the series reader uses.
#ifndef TRANSTICK_TESTS_DICOM_WRITER_H_
#define TRANSTICK_TESTS_DICOM_WRITER_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace transtick::testing {

enum class DicomCodec { kNative, kRle, kJpegLossless, kJpegLs, kJpeg2000 };
// The least bytes of pixels a slice of kJpeg2000 may have (DicomSliceFile
// fails on fewer): GDCM's encoder overruns its buffer on small frames.
inline constexpr size_t kLeastJpeg2000Bytes = 4096;
// The codec's name, for test names and messages.
const char* CodecName(DicomCodec codec);

struct DicomSlice {
  std::string series = "1.2.3.4";
  std::array<double, 3> position = {0, 0, 0};              // ImagePositionPatient
  std::array<double, 6> orientation = {1, 0, 0, 0, 1, 0};  // ImageOrientationPatient
  std::array<double, 2> spacing = {0.5, 0.8};              // between columns (x), rows (y)
  double slope = 1, intercept = -1024;
  int columns = 4, rows = 3;
  std::vector<int16_t> pixels;  // columns * rows, row by row
  int number = 0;               // SeriesNumber (0020,0011) when not 0
  std::string description;      // SeriesDescription (0008,103E) when not empty
  // A private OB element (0009,1010) of this many bytes before the pixel
  // data, when not 0: a header longer than a reader's first look.
  size_t private_bytes = 0;
  // How the pixels are stored: native, or losslessly compressed
  // (encapsulated) in this transfer syntax.
  DicomCodec codec = DicomCodec::kNative;
};

// The file's bytes; empty if GDCM fails to write it.
std::string DicomSliceFile(const DicomSlice& slice);

// A multi-frame image (explicit VR little endian, int16, MONOCHROME2),
// its frames placed as an enhanced image places them: the shared
// functional groups hold the orientation and pixel spacing, each frame's
// per-frame group its position and rescale. With `grid_offsets` instead,
// as an RT dose: no functional groups, the file's ImageOrientationPatient,
// ImagePositionPatient (the first position) and a GridFrameOffsetVector of
// each position's distance along the normal from the first.
struct DicomMultiFrame {
  std::string series = "1.2.3.9";
  std::string sop_class = "1.2.840.10008.5.1.4.1.1.4.1";  // Enhanced MR Image Storage
  std::vector<std::array<double, 3>> positions;           // one per frame
  std::array<double, 6> orientation = {1, 0, 0, 0, 1, 0};
  std::array<double, 2> spacing = {0.5, 0.8};  // between columns (x), rows (y)
  std::vector<std::array<double, 2>> rescale;  // per frame {slope, intercept}; empty: none
  int columns = 4, rows = 3;
  std::vector<int16_t> pixels;  // frames * rows * columns
  bool grid_offsets = false;
  int declared_frames = 0;  // NumberOfFrames when not 0 (else one per position)
};
std::string DicomMultiFrameFile(const DicomMultiFrame& image);

// Writes the slices of a volume_fuzzer input of a DICOM series (its
// format: tests/fuzz/fuzz_volumes.h) to `dir` as s0, s1, ...; returns
// their paths, none when the input is not one.
std::vector<std::string> WriteFuzzSeries(const std::string& input_path, const std::string& dir);

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_DICOM_WRITER_H_
