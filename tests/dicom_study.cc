// Writes a small DICOM study for the shell and browser tests, which have
// no DICOM writer of their own:
//
//   dicom_study DIR
//
// DIR/study: two CT series of 16x16 slices whose files interleave by name,
//   series 3 'AX BONE' (UID 1.2.840.99.1, 12 slices 1 mm apart, a ball of
//   radius 6 at 1100 in a field of 0, after a rescale intercept of -1024)
//   and series 4 (UID 1.2.840.99.12, 6 slices 2 mm apart, the same ball),
//   beside a README that is not DICOM.
// DIR/gap: one series whose third slice is missing.
//
// Prints the paths written, one a line.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "dicom_writer.h"

namespace {

using transtick::testing::DicomSlice;
using transtick::testing::DicomSliceFile;

bool Write(const std::string& path, const DicomSlice& s) {
  const std::string bytes = DicomSliceFile(s);
  if (bytes.empty()) return false;
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  std::printf("%s\n", path.c_str());
  return static_cast<bool>(out);
}

// A slice of the ball centred at (7.5, 7.5, 5.5 mm), z mm along.
DicomSlice Ball(const std::string& series, double z) {
  DicomSlice s;
  s.series = series;
  s.columns = s.rows = 16;
  s.spacing = {1, 1};
  s.position = {0, 0, z};
  s.pixels.resize(16 * 16);
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 16; ++x) {
      const double d = std::hypot(x - 7.5, y - 7.5, z - 5.5);
      s.pixels[y * 16 + x] = static_cast<int16_t>(d < 6 ? 1024 + 1100 : 1024);
    }
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: dicom_study DIR\n");
    return 2;
  }
  const std::string dir = argv[1];
  std::filesystem::create_directories(dir + "/study");
  std::filesystem::create_directories(dir + "/gap");
  bool ok = true;
  for (int i = 0; i < 12; ++i) {
    DicomSlice a = Ball("1.2.840.99.1", i);
    a.number = 3;
    a.description = "AX BONE";
    ok &= Write(dir + "/study/IM" + std::to_string(2 * i), a);
  }
  for (int i = 0; i < 6; ++i) {
    DicomSlice b = Ball("1.2.840.99.12", 2.0 * i);
    b.number = 4;
    ok &= Write(dir + "/study/IM" + std::to_string(2 * i + 1), b);
  }
  std::ofstream(dir + "/study/README.txt") << "exported by a viewer\n";
  for (int i : {0, 1, 3, 4})
    ok &= Write(dir + "/gap/IM" + std::to_string(i), Ball("1.2.840.99.8", i));
  if (!ok) {
    std::fprintf(stderr, "dicom_study: GDCM could not write a slice\n");
    return 1;
  }
  return 0;
}
