// libtranstick_dicom.so: what the DICOM reader (dicom.cc) asks of GDCM
// (dicom_module.h). Loaded with dlopen only when a DICOM series is read.
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTrace.h>

#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "dicom_module.h"

namespace {

void Quiet() {
  // GDCM's own warnings go to stderr; every problem that matters is
  // reported by the reader instead.
  gdcm::Trace::WarningOff();
  gdcm::Trace::DebugOff();
  gdcm::Trace::ErrorOff();
}

// The items of sequence `tag` of `ds`, when the element is one whose items
// the walk (dicom.cc, ElementWalk) has checked before GDCM read the file:
// of VR SQ, or of undefined length. Null otherwise: GDCM would parse the
// bytes of any other element as items, lengths unchecked.
gdcm::SmartPointer<gdcm::SequenceOfItems> Items(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return nullptr;
  const gdcm::DataElement& de = ds.GetDataElement(tag);
  if (de.GetVR() != gdcm::VR::SQ && !de.GetVL().IsUndefined()) return nullptr;
  return de.GetValueAsSQ();
}

// The byte value of `tag` in the first item of sequence `sequence` of
// `ds`, or nullopt.
std::optional<std::string> InItem(const gdcm::DataSet& ds, const gdcm::Tag& sequence,
                                  const gdcm::Tag& tag) {
  gdcm::SmartPointer<gdcm::SequenceOfItems> items = Items(ds, sequence);
  if (!items || items->GetNumberOfItems() < 1) return std::nullopt;
  const gdcm::DataSet& item = items->GetItem(1).GetNestedDataSet();
  if (!item.FindDataElement(tag)) return std::nullopt;
  const gdcm::ByteValue* bv = item.GetDataElement(tag).GetByteValue();
  if (bv == nullptr) return std::nullopt;
  return std::string(bv->GetPointer(), bv->GetLength());
}

// A frame's values from one functional groups item (PS3.3 C.7.6.16).
transtick::DicomFrame FrameOf(const gdcm::DataSet& groups) {
  transtick::DicomFrame f;
  f.position = InItem(groups, gdcm::Tag(0x0020, 0x9113), gdcm::Tag(0x0020, 0x0032));
  f.orientation = InItem(groups, gdcm::Tag(0x0020, 0x9116), gdcm::Tag(0x0020, 0x0037));
  f.spacing = InItem(groups, gdcm::Tag(0x0028, 0x9110), gdcm::Tag(0x0028, 0x0030));
  f.slope = InItem(groups, gdcm::Tag(0x0028, 0x9145), gdcm::Tag(0x0028, 0x1053));
  f.intercept = InItem(groups, gdcm::Tag(0x0028, 0x9145), gdcm::Tag(0x0028, 0x1052));
  return f;
}

// The per-frame functional groups, each value the frame's own or else the
// shared groups'.
void ReadFrames(const gdcm::DataSet& ds, size_t max_frames, transtick::DicomHeader* out) {
  const gdcm::Tag per_frame(0x5200, 0x9230), shared(0x5200, 0x9229);
  gdcm::SmartPointer<gdcm::SequenceOfItems> items = Items(ds, per_frame);
  if (!items) return;
  transtick::DicomFrame common;
  if (gdcm::SmartPointer<gdcm::SequenceOfItems> s = Items(ds, shared);
      s && s->GetNumberOfItems() >= 1) {
    common = FrameOf(s->GetItem(1).GetNestedDataSet());
  }
  const size_t n = items->GetNumberOfItems();
  out->more_frames = n > max_frames;
  for (size_t i = 1; i <= n && i <= max_frames; ++i) {
    transtick::DicomFrame f = FrameOf(items->GetItem(i).GetNestedDataSet());
    if (!f.position) f.position = common.position;
    if (!f.orientation) f.orientation = common.orientation;
    if (!f.spacing) f.spacing = common.spacing;
    if (!f.slope) f.slope = common.slope;
    if (!f.intercept) f.intercept = common.intercept;
    out->frames.push_back(std::move(f));
  }
}

void ReadHeader(std::string* bytes, const uint32_t* tags, size_t count, size_t max_frames,
                transtick::DicomHeader* out) {
  *out = transtick::DicomHeader();
  const uint64_t file_size = bytes->size();
  std::istringstream stream(std::move(*bytes));
  gdcm::Reader reader;
  reader.SetStream(stream);
  // Skipping the pixel data leaves the stream at its value: nothing of it
  // is read, and its length is checked before GDCM reads it.
  const gdcm::Tag pixel_tag(0x7fe0, 0x0010);
  std::set<gdcm::Tag> skip = {pixel_tag};
  if (!reader.ReadUpToTag(pixel_tag, skip)) return;
  out->read = true;
  const gdcm::TransferSyntax& syntax = reader.GetFile().GetHeader().GetDataSetTransferSyntax();
  out->encapsulated = syntax.IsEncapsulated();
  out->big_endian = syntax.GetSwapCode() == gdcm::SwapCode::BigEndian;
  stream.clear();
  const std::streamoff at = stream.tellg();
  if (at >= 8 && static_cast<uint64_t>(at) <= file_size) {
    // The value length precedes the value, in either VR form, and the tag
    // (7FE0,0010) precedes that: 8 bytes before the value in implicit VR,
    // 12 in explicit VR. Without the tag the reader stopped at the end of a
    // file that has no pixel data (a report, a presentation state).
    unsigned char head[12] = {};
    const std::streamoff from = at >= 12 ? at - 12 : at - 8;
    stream.seekg(from);
    if (stream.read(reinterpret_cast<char*>(head), at - from)) {
      const unsigned char* vl = head + (at - from) - 4;
      auto tag_at = [&](std::streamoff back) {
        if (at - back < from) return false;
        const unsigned char* t = head + (at - back - from);
        return (t[0] == 0xe0 && t[1] == 0x7f && t[2] == 0x10 && t[3] == 0x00) ||
               (t[0] == 0x7f && t[1] == 0xe0 && t[2] == 0x00 && t[3] == 0x10);  // big endian
      };
      if (tag_at(8) || tag_at(12)) {
        out->pixel_value_at = at;
        out->pixel_length = uint32_t{vl[3]} << 24 | vl[2] << 16 | vl[1] << 8 | vl[0];
      }
    }
  }
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  out->values.resize(count);
  for (size_t i = 0; i < count; ++i) {
    const gdcm::Tag tag(static_cast<uint16_t>(tags[i] >> 16), static_cast<uint16_t>(tags[i]));
    if (!ds.FindDataElement(tag)) continue;
    const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
    if (bv == nullptr) continue;
    out->values[i] = std::string(bv->GetPointer(), bv->GetLength());
  }
  ReadFrames(ds, max_frames, out);
}

void ReadPixels(std::string* bytes, int rows, int columns, int bits, int frames,
                transtick::DicomPixels* out) {
  *out = transtick::DicomPixels();
  std::istringstream stream(std::move(*bytes));
  gdcm::ImageReader reader;
  reader.SetStream(stream);
  if (!reader.Read()) {
    out->error = "GDCM cannot read its pixel data";
    return;
  }
  const gdcm::Image& image = reader.GetImage();
  const unsigned int* dims = image.GetDimensions();
  const gdcm::PixelFormat& pf = image.GetPixelFormat();
  const unsigned depth = image.GetNumberOfDimensions() == 3 ? dims[2] : 1;
  if (image.GetNumberOfDimensions() < 2 || dims[0] != static_cast<unsigned>(columns) ||
      dims[1] != static_cast<unsigned>(rows) || depth != static_cast<unsigned>(frames) ||
      pf.GetSamplesPerPixel() != 1 || pf.GetBitsAllocated() != bits) {
    out->error = "its pixel data does not match its header";
    return;
  }
  const size_t want = static_cast<size_t>(rows) * columns * (bits / 8) * frames;
  // GDCM accepts native pixel data cut short (it keeps what it read, and
  // GetBuffer pads): check what the file held.
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  const gdcm::Tag pixel_tag(0x7fe0, 0x0010);
  if (!ds.FindDataElement(pixel_tag)) {
    out->error = "has no pixel data (7FE0,0010)";
    return;
  }
  const gdcm::DataElement& pixel_data = ds.GetDataElement(pixel_tag);
  if (const gdcm::ByteValue* bv = pixel_data.GetByteValue();
      bv != nullptr && bv->GetLength() < want) {
    out->error = absl::StrCat("pixel data holds ", static_cast<uint32_t>(bv->GetLength()),
                              " bytes, ", frames, " frame", frames == 1 ? "" : "s", " of ", columns,
                              "x", rows, " ", bits, "-bit pixels need ", want, " (truncated?)");
    return;
  }
  if (image.GetBufferLength() != want) {
    out->error = absl::StrCat("pixel data holds ", image.GetBufferLength(),
                              " bytes, the header says ", want);
    return;
  }
  out->bytes.resize(want);
  if (!image.GetBuffer(out->bytes.data())) {
    out->bytes.clear();
    out->error = "GDCM cannot decode its pixel data";
  }
}

}  // namespace

// The entry points (dicom_module.h): nothing thrown inside, by GDCM or an
// allocation, crosses into the program.
extern "C" __attribute__((visibility("default"))) int transtick_module_abi() {
  return transtick::kDicomModuleAbi;
}

extern "C" __attribute__((visibility("default"))) void transtick_dicom_read_header(
    std::string* bytes, const uint32_t* tags, size_t count, size_t max_frames,
    transtick::DicomHeader* out) {
  Quiet();
  try {
    ReadHeader(bytes, tags, count, max_frames, out);
  } catch (...) {
    *out = transtick::DicomHeader();  // not read
  }
}

extern "C" __attribute__((visibility("default"))) void transtick_dicom_read_pixels(
    std::string* bytes, int rows, int columns, int bits, int frames, transtick::DicomPixels* out) {
  Quiet();
  try {
    ReadPixels(bytes, rows, columns, bits, frames, out);
  } catch (const std::exception& e) {
    *out = transtick::DicomPixels();
    out->error = absl::StrCat("GDCM failed on its pixel data (", e.what(), ")");
  } catch (...) {
    *out = transtick::DicomPixels();
    out->error = "GDCM failed on its pixel data";
  }
}
