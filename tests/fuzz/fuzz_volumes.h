// Small volume files written in code, in each format the readers take: the
// volume fuzzer's seeds and the job fuzzer's data directory. Each returns the
// file's bytes; the samples are the volume's values rounded into `type`.
#ifndef TRANSTICK_TESTS_FUZZ_FUZZ_VOLUMES_H_
#define TRANSTICK_TESTS_FUZZ_FUZZ_VOLUMES_H_

#include <string>

#include "dicom_writer.h"
#include "transtick/volume.h"
#include "transtick/volume_io.h"

namespace transtick::fuzz {

// The samples alone, x fastest (a raw file, or the data of the others).
std::string RawSamples(const Volume& volume, ScalarType type, ByteOrder order);

// An attached NRRD header (with "spacings") and its data.
std::string NrrdFile(const Volume& volume, ScalarType type, ByteOrder order, bool gzip);

// A single-file NIfTI-1 (.nii): the 348-byte header, the 4-byte extension
// flag, the samples. `gzip` gives the bytes of a .nii.gz.
std::string NiftiFile(const Volume& volume, ScalarType type, ByteOrder order, bool gzip);

// A Levoy .den file: the 62-byte header and uint8 samples.
std::string DenFile(const Volume& volume, ByteOrder order);

// A MetaImage (.mha) with its data attached, raw or zlib-compressed, and a
// rotation with a flip in TransformMatrix.
std::string MetaImageFile(const Volume& volume, ScalarType type, ByteOrder order, bool compressed);

// A VTK image data file (.vti) with one appended array, raw or in two
// vtkZLibDataCompressor blocks, and a Direction with a flip.
std::string VtiFile(const Volume& volume, ScalarType type, ByteOrder order, bool compressed);

// The volume fuzzer's form of a DICOM series: kDicomSeriesMagic, then the
// slices' files (written by GDCM, int16; with `rle` their pixels RLE
// lossless, encapsulated) joined by kDicomSliceSeparator.
inline constexpr char kDicomSeriesMagic[] = "DICOM-SERIES\n";
inline constexpr char kDicomSliceSeparator[] = "\n--next-slice--\n";
std::string DicomSeriesInput(const Volume& volume,
                             testing::DicomCodec codec = testing::DicomCodec::kNative);
// The same as one multi-frame file: an enhanced image's functional groups,
// or with `grid_offsets` an RT dose's frame offsets; then a file that is
// not DICOM, which the reader passes over.
std::string DicomMultiFrameInput(const Volume& volume, bool grid_offsets);

// The gzip form of `data`.
std::string Gzip(const std::string& data);

}  // namespace transtick::fuzz

#endif  // TRANSTICK_TESTS_FUZZ_FUZZ_VOLUMES_H_
