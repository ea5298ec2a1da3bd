#include "dicom_writer.h"

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageWriter.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>
#include <gdcmWriter.h>

#include <sstream>

namespace transtick::testing {

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
  std::ostringstream first;
  writer.SetStream(first);
  if (!writer.Write()) return "";
  // GDCM writes a 2-D image's origin without its z: put the whole position
  // in with a plain writer, which leaves the other attributes as they are.
  std::istringstream in(first.str());
  gdcm::Reader reader;
  reader.SetStream(in);
  if (!reader.Read()) return "";
  gdcm::Attribute<0x0020, 0x0032> position;
  for (int i = 0; i < 3; ++i) position.SetValue(slice.position[i], i);
  reader.GetFile().GetDataSet().Replace(position.GetAsDataElement());
  std::ostringstream out;
  gdcm::Writer rewrite;
  rewrite.SetFile(reader.GetFile());
  rewrite.SetStream(out);
  if (!rewrite.Write()) return "";
  return out.str();
}

}  // namespace transtick::testing
