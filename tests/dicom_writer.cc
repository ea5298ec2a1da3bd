#include "dicom_writer.h"

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageChangeTransferSyntax.h>
#include <gdcmImageReader.h>
#include <gdcmImageWriter.h>
#include <gdcmItem.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTrace.h>
#include <gdcmUIDGenerator.h>
#include <gdcmWriter.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

namespace transtick::testing {

namespace {

// `bytes` with ImagePositionPatient set to `position` by a plain writer,
// which leaves the other attributes as they are (GDCM's image writer
// writes a 2-D image's origin without its z).
std::string WithPosition(const std::string& bytes, const std::array<double, 3>& position) {
  std::istringstream in(bytes);
  gdcm::Reader reader;
  reader.SetStream(in);
  if (!reader.Read()) return "";
  gdcm::Attribute<0x0020, 0x0032> at;
  for (int i = 0; i < 3; ++i) at.SetValue(position[i], i);
  reader.GetFile().GetDataSet().Replace(at.GetAsDataElement());
  std::ostringstream out;
  gdcm::Writer rewrite;
  rewrite.SetFile(reader.GetFile());
  rewrite.SetStream(out);
  if (!rewrite.Write()) return "";
  return out.str();
}

// `bytes` with its pixels compressed losslessly by `codec`.
std::string Compressed(const std::string& bytes, DicomCodec codec) {
  std::istringstream in(bytes);
  gdcm::ImageReader reader;
  reader.SetStream(in);
  if (!reader.Read()) return "";
  gdcm::ImageChangeTransferSyntax change;
  switch (codec) {
    case DicomCodec::kRle:
      change.SetTransferSyntax(gdcm::TransferSyntax::RLELossless);
      break;
    case DicomCodec::kJpegLossless:
      change.SetTransferSyntax(gdcm::TransferSyntax::JPEGLosslessProcess14_1);
      break;
    case DicomCodec::kJpegLs:
      change.SetTransferSyntax(gdcm::TransferSyntax::JPEGLSLossless);
      break;
    case DicomCodec::kJpeg2000:
      // GDCM's JPEG 2000 encoder writes the code stream into a buffer of
      // the raw frame's size, and past it when the stream is the larger
      // (found by AddressSanitizer on a 60-pixel frame): not for small
      // frames.
      if (reader.GetImage().GetBufferLength() < kLeastJpeg2000Bytes) return "";
      change.SetTransferSyntax(gdcm::TransferSyntax::JPEG2000Lossless);
      break;
    case DicomCodec::kNative:
      return bytes;
  }
  change.SetInput(reader.GetImage());
  if (!change.Change()) return "";
  gdcm::ImageWriter writer;
  writer.SetFile(reader.GetFile());
  writer.SetImage(change.GetOutput());
  std::ostringstream out;
  writer.SetStream(out);
  if (!writer.Write()) return "";
  return out.str();
}

}  // namespace

const char* CodecName(DicomCodec codec) {
  switch (codec) {
    case DicomCodec::kNative:
      return "native";
    case DicomCodec::kRle:
      return "rle";
    case DicomCodec::kJpegLossless:
      return "jpeg";
    case DicomCodec::kJpegLs:
      return "jpegls";
    case DicomCodec::kJpeg2000:
      return "j2k";
  }
  return "?";
}

std::string DicomSliceFile(const DicomSlice& slice) {
  gdcm::Trace::WarningOff();
  gdcm::ImageWriter writer;
  gdcm::Image& image = writer.GetImage();
  image.SetNumberOfDimensions(2);
  const unsigned int dims[2] = {static_cast<unsigned>(slice.columns),
                                static_cast<unsigned>(slice.rows)};
  image.SetDimensions(dims);
  image.SetPixelFormat(gdcm::PixelFormat::INT16);
  image.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::MONOCHROME2);
  image.SetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
  image.SetOrigin(slice.position.data());
  image.SetDirectionCosines(slice.orientation.data());
  const double spacing[3] = {slice.spacing[0], slice.spacing[1], 1};
  image.SetSpacing(spacing);
  image.SetSlope(slice.slope);
  image.SetIntercept(slice.intercept);
  std::vector<int16_t> pixels = slice.pixels;
  pixels.resize(static_cast<size_t>(slice.columns) * slice.rows);
  gdcm::DataElement pixel_data(gdcm::Tag(0x7fe0, 0x0010));
  pixel_data.SetByteValue(reinterpret_cast<const char*>(pixels.data()),
                          static_cast<uint32_t>(pixels.size() * 2));
  image.SetDataElement(pixel_data);
  gdcm::DataSet& ds = writer.GetFile().GetDataSet();
  gdcm::Attribute<0x0008, 0x0016> sop_class = {"1.2.840.10008.5.1.4.1.1.2"};  // CT Image Storage
  ds.Replace(sop_class.GetAsDataElement());
  gdcm::Attribute<0x0008, 0x0060> modality = {"CT"};
  ds.Replace(modality.GetAsDataElement());
  gdcm::Attribute<0x0020, 0x000e> series;
  series.SetValue(slice.series);
  ds.Replace(series.GetAsDataElement());
  if (slice.number != 0) {
    gdcm::Attribute<0x0020, 0x0011> number = {slice.number};
    ds.Replace(number.GetAsDataElement());
  }
  if (!slice.description.empty()) {
    gdcm::Attribute<0x0008, 0x103e> description;
    description.SetValue(slice.description);
    ds.Replace(description.GetAsDataElement());
  }
  if (slice.private_bytes > 0) {
    gdcm::DataElement creator(gdcm::Tag(0x0009, 0x0010));
    creator.SetVR(gdcm::VR::LO);
    creator.SetByteValue("TRANSTICK TEST ", 16);
    ds.Replace(creator);
    gdcm::DataElement blob(gdcm::Tag(0x0009, 0x1010));
    blob.SetVR(gdcm::VR::OB);
    const std::string bytes(slice.private_bytes + slice.private_bytes % 2, '\x5a');
    blob.SetByteValue(bytes.data(), static_cast<uint32_t>(bytes.size()));
    ds.Replace(blob);
  }
  std::ostringstream first;
  writer.SetStream(first);
  if (!writer.Write()) return "";
  std::string out = first.str();
  if (slice.codec != DicomCodec::kNative) out = Compressed(out, slice.codec);
  return out.empty() ? "" : WithPosition(out, slice.position);
}

namespace {

// A sequence of undefined length holding `items`.
gdcm::DataElement Sequence(uint16_t group, uint16_t element,
                           const std::vector<gdcm::DataSet>& items) {
  gdcm::SmartPointer<gdcm::SequenceOfItems> sq = new gdcm::SequenceOfItems();
  sq->SetLengthToUndefined();
  for (const gdcm::DataSet& ds : items) {
    gdcm::Item item;
    item.SetVLToUndefined();
    item.SetNestedDataSet(ds);
    sq->AddItem(item);
  }
  gdcm::DataElement de(gdcm::Tag(group, element));
  de.SetVR(gdcm::VR::SQ);
  de.SetValue(*sq);
  de.SetVLToUndefined();
  return de;
}

}  // namespace

std::string DicomMultiFrameFile(const DicomMultiFrame& image) {
  gdcm::Trace::WarningOff();
  const size_t frames = image.positions.size();
  gdcm::Writer writer;
  gdcm::File& file = writer.GetFile();
  file.GetHeader().SetDataSetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
  gdcm::DataSet& ds = file.GetDataSet();
  gdcm::UIDGenerator uid;
  ds.Replace(gdcm::Attribute<0x0008, 0x0016>{image.sop_class.c_str()}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0008, 0x0018>{uid.Generate()}.GetAsDataElement());
  ds.Replace(
      gdcm::Attribute<0x0008, 0x0060>{image.grid_offsets ? "RTDOSE" : "MR"}.GetAsDataElement());
  gdcm::Attribute<0x0020, 0x000e> series;
  series.SetValue(image.series);
  ds.Replace(series.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0002>{1}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0004>{"MONOCHROME2"}.GetAsDataElement());
  const size_t declared = image.declared_frames > 0 ? image.declared_frames : frames;
  ds.Replace(gdcm::Attribute<0x0028, 0x0008>{static_cast<int32_t>(declared)}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0010>{static_cast<uint16_t>(image.rows)}.GetAsDataElement());
  ds.Replace(
      gdcm::Attribute<0x0028, 0x0011>{static_cast<uint16_t>(image.columns)}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0100>{16}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0101>{16}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0102>{15}.GetAsDataElement());
  ds.Replace(gdcm::Attribute<0x0028, 0x0103>{1}.GetAsDataElement());
  gdcm::Attribute<0x0020, 0x0037> orientation;
  for (int i = 0; i < 6; ++i) orientation.SetValue(image.orientation[i], i);
  gdcm::Attribute<0x0028, 0x0030> spacing;
  spacing.SetValue(image.spacing[1], 0);  // between rows
  spacing.SetValue(image.spacing[0], 1);  // between columns
  auto position = [&](size_t k) {
    gdcm::Attribute<0x0020, 0x0032> p;
    for (int i = 0; i < 3; ++i) p.SetValue(image.positions[k][i], i);
    return p.GetAsDataElement();
  };
  if (image.grid_offsets) {
    ds.Replace(orientation.GetAsDataElement());
    ds.Replace(spacing.GetAsDataElement());
    ds.Replace(position(0));
    const std::array<double, 3> row = {image.orientation[0], image.orientation[1],
                                       image.orientation[2]};
    const std::array<double, 3> col = {image.orientation[3], image.orientation[4],
                                       image.orientation[5]};
    const std::array<double, 3> normal = {row[1] * col[2] - row[2] * col[1],
                                          row[2] * col[0] - row[0] * col[2],
                                          row[0] * col[1] - row[1] * col[0]};
    gdcm::Attribute<0x3004, 0x000c> offsets;
    std::vector<double> values;
    for (size_t k = 0; k < frames; ++k) {
      double d = 0;
      for (int i = 0; i < 3; ++i) d += (image.positions[k][i] - image.positions[0][i]) * normal[i];
      values.push_back(d);
    }
    offsets.SetValues(values.data(), static_cast<unsigned>(values.size()), true);
    ds.Replace(offsets.GetAsDataElement());
    if (!image.rescale.empty()) {
      gdcm::Attribute<0x3004, 0x000e> scaling;
      scaling.SetValue(image.rescale[0][0]);
      ds.Replace(scaling.GetAsDataElement());
    }
  } else {
    gdcm::DataSet shared;
    gdcm::DataSet plane_orientation;
    plane_orientation.Insert(orientation.GetAsDataElement());
    shared.Insert(Sequence(0x0020, 0x9116, {plane_orientation}));
    gdcm::DataSet measures;
    measures.Insert(spacing.GetAsDataElement());
    shared.Insert(Sequence(0x0028, 0x9110, {measures}));
    std::vector<gdcm::DataSet> per_frame;
    for (size_t k = 0; k < frames; ++k) {
      gdcm::DataSet item;
      gdcm::DataSet plane;
      plane.Insert(position(k));
      item.Insert(Sequence(0x0020, 0x9113, {plane}));
      if (!image.rescale.empty()) {
        gdcm::DataSet transform;
        gdcm::Attribute<0x0028, 0x1053> slope;
        slope.SetValue(image.rescale[k][0]);
        gdcm::Attribute<0x0028, 0x1052> intercept;
        intercept.SetValue(image.rescale[k][1]);
        transform.Insert(slope.GetAsDataElement());
        transform.Insert(intercept.GetAsDataElement());
        item.Insert(Sequence(0x0028, 0x9145, {transform}));
      }
      per_frame.push_back(item);
    }
    ds.Replace(Sequence(0x5200, 0x9229, {shared}));
    ds.Replace(Sequence(0x5200, 0x9230, per_frame));
  }
  std::vector<int16_t> pixels = image.pixels;
  pixels.resize(std::max(frames, declared) * image.rows * image.columns);
  gdcm::DataElement pixel_data(gdcm::Tag(0x7fe0, 0x0010));
  pixel_data.SetVR(gdcm::VR::OW);
  pixel_data.SetByteValue(reinterpret_cast<const char*>(pixels.data()),
                          static_cast<uint32_t>(pixels.size() * 2));
  ds.Replace(pixel_data);
  std::ostringstream out;
  writer.SetStream(out);
  if (!writer.Write()) return "";
  return out.str();
}

std::vector<std::string> WriteFuzzSeries(const std::string& input_path, const std::string& dir) {
  std::ifstream in(input_path, std::ios::binary);
  std::string input(std::istreambuf_iterator<char>(in), {});
  const std::string magic = "DICOM-SERIES\n", separator = "\n--next-slice--\n";
  std::vector<std::string> paths;
  if (input.compare(0, magic.size(), magic) != 0) return paths;
  std::filesystem::create_directories(dir);
  size_t at = magic.size();
  for (;;) {
    const size_t end = input.find(separator, at);
    const std::string path = dir + "/s" + std::to_string(paths.size());
    std::ofstream(path, std::ios::binary) << input.substr(at, end - at);
    paths.push_back(path);
    if (end == std::string::npos) break;
    at = end + separator.size();
  }
  return paths;
}

}  // namespace transtick::testing
