// Writes DICOM slices with GDCM, for the tests and the fuzzers' seeds: a
// CT image (explicit VR little endian, int16 pixels, MONOCHROME2) with the
// attributes the series reader uses.
#ifndef TRANSTICK_TESTS_DICOM_WRITER_H_
#define TRANSTICK_TESTS_DICOM_WRITER_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace transtick::testing {

struct DicomSlice {
  std::string series = "1.2.3.4";
  std::array<double, 3> position = {0, 0, 0};              // ImagePositionPatient
  std::array<double, 6> orientation = {1, 0, 0, 0, 1, 0};  // ImageOrientationPatient
  std::array<double, 2> spacing = {0.5, 0.8};              // between columns (x), rows (y)
  double slope = 1, intercept = -1024;
  int columns = 4, rows = 3;
  std::vector<int16_t> pixels;  // columns * rows, row by row
};

// The file's bytes; empty if GDCM fails to write it.
std::string DicomSliceFile(const DicomSlice& slice);

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_DICOM_WRITER_H_
