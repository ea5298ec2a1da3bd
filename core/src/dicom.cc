// DICOM series reader: a directory of CT, MR or RT dose images, read
// with GDCM (Debian's libgdcm, the library DICOM toolkits and ITK build on),
// which lives in the module libtranstick_dicom.so (dicom_gdcm.cc, loaded on
// first use: dicom_module.h says why).
//
// Each frame of each DICOM image in the directory is one slice: a file of
// one frame, or each frame of a multi-frame image, placed by its
// functional groups (enhanced CT and MR, PS3.3 C.7.6.16: per frame, else
// shared, else the file's attributes) or by an RT dose's
// GridFrameOffsetVector (distances along the normal from the file's
// ImagePositionPatient) and scaled by its DoseGridScaling. DICOMDIR, names
// starting with '.', subdirectories, files that are not DICOM (no "DICM" at
// byte 128, and not starting as a data set without one does, with group
// 0002 or 0008) and DICOM files without pixel data (reports, presentation
// states) are passed over, and Volume::notes names them. The slices are
// grouped by SeriesInstanceUID: a directory of several series is read only
// when the path names one ("DIR#UID"), else the error lists them. Every
// file is read through ReadOptions::open (so the
// root's confinement holds), its element lengths walked (ElementWalk, below:
// GDCM would allocate whatever a length declares), and given to GDCM from
// memory. Each is read twice: first its header only (its bytes up to the
// pixel data's value, ReadHeaderChecked), which is checked (sizes, pixel
// format, frames) before GDCM reads any pixels, then in full, once per file
// whatever its frames, which decodes the pixels in whatever transfer syntax
// GDCM supports: native and RLE here, codecs' (JPEG, JPEG-LS, JPEG 2000) in
// a process of their own (dicom_decoder.h), where a crash or a hang on a
// damaged file is an error naming it. A listing of a directory's series
// (ListDicomSeries) reads the headers only.
//
// Attributes used:
//   (0020,000E) SeriesInstanceUID   all slices the same: one series
//   (0028,0010/0011) Rows, Columns  all slices the same
//   (0028,0002) SamplesPerPixel 1, (0028,0008) NumberOfFrames
//   (5200,9229/9230) Shared/PerFrameFunctionalGroupsSequence (dicom_module.h)
//   (3004,000C) GridFrameOffsetVector, (3004,000E) DoseGridScaling
//   (0028,0100) BitsAllocated 8/16/32, (0028,0103) PixelRepresentation
//   (0028,0030) PixelSpacing        row spacing \ column spacing, the same
//   (0020,0037) ImageOrientationPatient  row and column directions, the same
//   (0020,0032) ImagePositionPatient     where the first pixel lies
//   (0028,1053/1052) RescaleSlope, RescaleIntercept   value = stored × slope + intercept
//
// Slices are sorted by their position along the normal (row × column), so
// the volume's z axis is the normal and its direction a rotation. The gaps
// between consecutive positions give the z spacing: they must all be equal
// (to 1% or 0.01 mm). A gap that is a multiple of the others (a missing
// slice), two slices at one position (in a multi-frame image: several
// stacks), and positions off the normal (a tilted gantry) are refused,
// naming the files and frames.
#include <dirent.h>
#include <dlfcn.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "dicom_decoder.h"
#include "dicom_module.h"
#include "module_loader.h"
#include "transtick/orientation.h"
#include "transtick/volume_io.h"
#include "volume_io_internal.h"

namespace transtick {
namespace {

namespace vi = volume_io_internal;

// More slices than this is not a series we can mean to read.
constexpr size_t kMaxSlices = 1 << 16;

absl::Status Error(const std::string& path, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

// The slice normal of an ImageOrientationPatient (row x column), of unit
// length; nullopt when row and column are too far from orthogonal unit
// vectors to give one.
std::optional<std::array<double, 3>> UnitNormal(const std::array<double, 6>& o) {
  std::array<double, 3> n = {o[1] * o[5] - o[2] * o[4], o[2] * o[3] - o[0] * o[5],
                             o[0] * o[4] - o[1] * o[3]};
  const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!(length > 0.5)) return std::nullopt;
  for (double& c : n) c /= length;
  return n;
}

absl::Status NotOrthonormal(const std::string& name) {
  return Error(name, "ImageOrientationPatient's row and column are not orthogonal unit vectors");
}

struct Slice {
  std::string path;
  std::string series;
  std::string modality, description, number;  // for the listing of a directory's series
  // Why this image cannot be a slice of a volume (colour, several frames,
  // a size or attribute out of range), or OK: an error only when its
  // series is the one read.
  absl::Status problem;
  int rows = 0, columns = 0;
  int bits = 0;
  bool is_signed = false;
  std::array<double, 2> pixel_spacing = {1, 1};  // between rows, between columns
  std::array<double, 6> orientation = {1, 0, 0, 0, 1, 0};
  std::array<double, 3> position = {0, 0, 0};
  double slope = 1, intercept = 0;
  double along_normal = 0;
  // A frame of a multi-frame image: which (from 0), of how many.
  int frame = 0, frames = 1;
  // The file, and the frame when it has several: what messages name.
  std::string Name() const { return frames > 1 ? absl::StrCat(path, " frame ", frame + 1) : path; }
  bool native = true;            // pixel data not encapsulated (compressed)
  uint32_t pixel_length = 0;     // the pixel data's declared value length
  uint64_t pixel_available = 0;  // bytes of the file from its value on
  uint64_t file_bytes = 0;       // the file's size
};

// The elements a slice's header is read for (group << 16 | element), in
// the order of DicomHeader::values.
enum Element : size_t {
  kSeries,          // (0020,000E) SeriesInstanceUID
  kRows,            // (0028,0010)
  kColumns,         // (0028,0011)
  kSamples,         // (0028,0002) SamplesPerPixel
  kFrames,          // (0028,0008) NumberOfFrames
  kBits,            // (0028,0100) BitsAllocated
  kRepresentation,  // (0028,0103) PixelRepresentation
  kPixelSpacing,    // (0028,0030)
  kOrientation,     // (0020,0037) ImageOrientationPatient
  kPosition,        // (0020,0032) ImagePositionPatient
  kSlope,           // (0028,1053) RescaleSlope
  kIntercept,       // (0028,1052) RescaleIntercept
  kModality,        // (0008,0060)
  kDescription,     // (0008,103E) SeriesDescription
  kSeriesNumber,    // (0020,0011)
  kFrameOffsets,    // (3004,000C) GridFrameOffsetVector (RT Dose)
  kDoseScaling,     // (3004,000E) DoseGridScaling (RT Dose)
  kElements
};
constexpr uint32_t kTags[kElements] = {0x0020000e, 0x00280010, 0x00280011, 0x00280002, 0x00280008,
                                       0x00280100, 0x00280103, 0x00280030, 0x00200037, 0x00200032,
                                       0x00281053, 0x00281052, 0x00080060, 0x0008103e, 0x00200011,
                                       0x3004000c, 0x3004000e};

// libtranstick_dicom.so's functions, or why it could not be loaded.
struct Gdcm {
  TranstickDicomReadHeader read_header = nullptr;
  TranstickDicomReadPixels read_pixels = nullptr;
  absl::Status status;
};

const Gdcm& LoadGdcm() {
  static const Gdcm gdcm = [] {
    static constexpr const char* kSymbols[] = {"transtick_dicom_read_header",
                                               "transtick_dicom_read_pixels", nullptr};
#ifdef TRANSTICK_DICOM_BUILD_PATH
    const char* build_path = TRANSTICK_DICOM_BUILD_PATH;
#else
    const char* build_path = nullptr;
#endif
    Gdcm g;
    absl::StatusOr<void*> handle = OpenModule("libtranstick_dicom.so", "TRANSTICK_DICOM_MODULE",
                                              build_path, "GDCM", kSymbols, kDicomModuleAbi);
    if (!handle.ok()) {
      g.status = handle.status();
      return g;
    }
    g.read_header = reinterpret_cast<TranstickDicomReadHeader>(::dlsym(*handle, kSymbols[0]));
    g.read_pixels = reinterpret_cast<TranstickDicomReadPixels>(::dlsym(*handle, kSymbols[1]));
    return g;
  }();
  return gdcm;
}

// Printable text of a header's string for a message: at most 64
// characters, anything but printable ASCII shown as '?'.
std::string Shown(std::string text) {
  if (text.size() > 64) text = text.substr(0, 61) + "...";
  for (char& c : text) {
    if (!absl::ascii_isprint(static_cast<unsigned char>(c))) c = '?';
  }
  return text;
}

// A string value trimmed of DICOM's padding.
std::string Trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\0' || s.back() == ' ')) s.pop_back();
  return std::string(absl::StripAsciiWhitespace(s));
}

// A string element's value, trimmed of DICOM's padding; "" when absent.
std::string Text(const DicomHeader& h, Element e) {
  return h.values[e] ? Trimmed(*h.values[e]) : "";
}

// A US element's value, or -1 when absent or malformed.
int Unsigned16(const DicomHeader& h, Element e) {
  if (!h.values[e] || h.values[e]->size() < 2) return -1;
  // Little endian: big-endian files are refused (ReadHeader).
  const unsigned char* p = reinterpret_cast<const unsigned char*>(h.values[e]->data());
  return p[0] | p[1] << 8;
}

// The backslash-separated numbers of a decimal string `text` (empty: none).
absl::StatusOr<std::vector<double>> DecimalsOf(const std::string& path, const std::string& text,
                                               const char* name, size_t want) {
  if (text.empty()) return std::vector<double>{};
  std::vector<double> out;
  for (absl::string_view part : absl::StrSplit(text, '\\')) {
    double v = 0;
    if (!absl::SimpleAtod(absl::StripAsciiWhitespace(part), &v) || !std::isfinite(v)) {
      return Error(path, absl::StrCat(name, " '", Shown(text), "' is not ",
                                      want == 0 ? "a list of" : absl::StrCat(want), " numbers"));
    }
    out.push_back(v);
  }
  if (want != 0 && out.size() != want) {
    return Error(path, absl::StrCat(name, " '", Shown(text), "' is not ", want, " numbers"));
  }
  return out;
}

// The numbers of element `e` of the header, as DecimalsOf (want 0: any
// count); an error when `required` and it is absent.
absl::StatusOr<std::vector<double>> Decimals(const std::string& path, const DicomHeader& h,
                                             Element e, const char* name, size_t want,
                                             bool required) {
  const std::string text = Text(h, e);
  if (text.empty() && required) {
    return Error(path,
                 absl::StrFormat("has no %s (%04X,%04X)", name, kTags[e] >> 16, kTags[e] & 0xffff));
  }
  return DecimalsOf(path, text, name, want);
}

// GDCM allocates every element's declared length before it reads the
// value (gdcm::ByteValue::SetLength): a file of a few bytes that declares a
// 4 GB element would make it allocate 4 GB (found by volume_fuzzer). So
// before GDCM sees a file, this walks its elements, nested sequences and
// items included, and checks that every defined length fits in what
// encloses it. Layout (PS3.5 section 7): a 128-byte preamble and "DICM"
// (optional), the file meta group 0002 in explicit VR little endian, then
// the data set in the transfer syntax (0002,0010) names: implicit VR little
// endian (1.2.840.10008.1.2), explicit VR big endian (...1.2.2) or explicit
// VR little endian (the others). An element is a tag (group, element: 2+2
// bytes), in explicit VR a 2-letter VR and then a 2-byte length, or for the
// VRs below 2 reserved bytes and a 4-byte length; in implicit VR a 4-byte
// length. 0xFFFFFFFF is an undefined length: a sequence of items (FFFE,E000)
// ended by (FFFE,E0DD); an item of undefined length ends with (FFFE,E00D).
// The VRs allowed for the attributes GDCM's image reader reads with
// gdcm::Attribute (PS3.6), "/"-separated; null for other tags.
const char* ImageAttributeVr(uint16_t group, uint16_t element) {
  struct Entry {
    uint16_t group, element;
    const char* vrs;
  };
  static constexpr Entry kEntries[] = {
      {0x0008, 0x0016, "UI"},    {0x0008, 0x0060, "CS"},    {0x0018, 0x0050, "DS"},
      {0x0018, 0x0088, "DS"},    {0x0018, 0x1164, "DS"},    {0x0020, 0x000d, "UI"},
      {0x0020, 0x000e, "UI"},    {0x0020, 0x0013, "IS"},    {0x0020, 0x0032, "DS"},
      {0x0020, 0x0037, "DS"},    {0x0028, 0x0002, "US"},    {0x0028, 0x0004, "CS"},
      {0x0028, 0x0006, "US"},    {0x0028, 0x0008, "IS"},    {0x0028, 0x0010, "US"},
      {0x0028, 0x0011, "US"},    {0x0028, 0x0030, "DS"},    {0x0028, 0x0034, "IS"},
      {0x0028, 0x0100, "US"},    {0x0028, 0x0101, "US"},    {0x0028, 0x0102, "US"},
      {0x0028, 0x0103, "US"},    {0x0028, 0x0106, "US/SS"}, {0x0028, 0x0107, "US/SS"},
      {0x0028, 0x1050, "DS"},    {0x0028, 0x1051, "DS"},    {0x0028, 0x1052, "DS"},
      {0x0028, 0x1053, "DS"},    {0x0028, 0x1054, "LO"},    {0x7fe0, 0x0010, "OB/OW"},
  };
  for (const Entry& e : kEntries) {
    if (e.group == group && e.element == element) return e.vrs;
  }
  return nullptr;
}

// A walk of the header only (`header_only`) stops at the data set's pixel
// data element (7FE0,0010) once its tag, VR and length are read, and says
// where its value begins (pixel_value_at): what follows is not looked at,
// so `bytes` may be a prefix of the file that ends there. GDCM's header
// reader stops at that element too (ReadUpToTag).
class ElementWalk {
 public:
  ElementWalk(const std::string& path, const std::string& bytes, bool header_only = false)
      : path_(path), bytes_(bytes), header_only_(header_only) {}

  // Where the pixel data's value begins, once a header-only walk stopped
  // there.
  std::optional<size_t> pixel_value_at() const { return pixel_value_at_; }
  // The transfer syntax UID the meta group names ("" without one).
  const std::string& syntax() const { return syntax_; }
  // The items of the data set's encapsulated pixel data, in order (the
  // basic offset table first): where each value begins, and its length.
  const std::vector<std::pair<size_t, size_t>>& fragments() const { return fragments_; }

  absl::Status Run() {
    size_t pos = 0;
    if (bytes_.size() >= 132 && bytes_.compare(128, 4, "DICM") == 0) {
      pos = 132;
      // The meta group: explicit VR little endian, whatever follows.
      explicit_ = true;
      big_ = false;
      std::string syntax;
      // GDCM asserts (and aborts; Debian builds it with assertions) on a
      // meta element that is cut short, holds a sequence or an undefined
      // length, and when the file ends with the meta group.
      while (pos + 4 <= bytes_.size() && U16(pos, false) == 0x0002) {
        const size_t start = pos;
        if (bytes_.size() - pos >= 6 && bytes_.compare(pos + 4, 2, "SQ") == 0) {
          return Error(path_, absl::StrCat("a sequence in the file meta group at byte ", pos));
        }
        absl::StatusOr<size_t> next = Element(pos, bytes_.size(), kMaxDepth);
        if (!next.ok()) return next.status();
        if (U16(start + 2, false) == 0x0010) syntax = Value(start, *next);
        pos = *next;
      }
      if (bytes_.size() - pos < 8) return Error(path_, "no data set after the file meta group");
      while (!syntax.empty() && (syntax.back() == '\0' || syntax.back() == ' ')) syntax.pop_back();
      syntax_ = syntax;
      if (syntax == "1.2.840.10008.1.2") {
        explicit_ = false;
      } else if (syntax == "1.2.840.10008.1.2.2") {
        big_ = true;
      } else if (syntax == "1.2.840.10008.1.2.1.99") {
        return Error(path_, "deflated transfer syntax is not supported");
      }
    } else {
      // No meta header: explicit VR when two capital letters follow the tag.
      explicit_ = bytes_.size() >= 6 && absl::ascii_isupper(static_cast<unsigned char>(bytes_[4])) &&
                  absl::ascii_isupper(static_cast<unsigned char>(bytes_[5]));
      big_ = false;
    }
    return Elements(pos, bytes_.size(), 0, /*until_item_end=*/false).status();
  }

 private:
  static constexpr uint32_t kUndefined = 0xffffffffu;
  static constexpr int kMaxDepth = 16;

  uint16_t U16(size_t at, bool big) const {
    const auto* p = reinterpret_cast<const unsigned char*>(bytes_.data() + at);
    return big ? static_cast<uint16_t>(p[0] << 8 | p[1]) : static_cast<uint16_t>(p[1] << 8 | p[0]);
  }
  uint32_t U32(size_t at, bool big) const {
    return big ? (uint32_t{U16(at, true)} << 16 | U16(at + 2, true))
               : (uint32_t{U16(at + 2, false)} << 16 | U16(at, false));
  }
  // The value of the element at `start` that ends at `end`, for short strings.
  std::string Value(size_t start, size_t end) const {
    const size_t header = 8;  // (0002,0010) is UI: a short-form header
    return start + header <= end && end - start - header < 256
               ? bytes_.substr(start + header, end - start - header)
               : std::string();
  }
  absl::Status Short(size_t at) const {
    return Error(path_, absl::StrCat("a data element at byte ", at, " is cut short (truncated?)"));
  }

  // Walks elements in [pos, end) and returns where it stopped: at `end`,
  // or past the delimiter that ends an item of undefined length.
  absl::StatusOr<size_t> Elements(size_t pos, size_t end, int depth, bool until_item_end) {
    while (pos < end) {
      if (end - pos < 8) return Short(pos);
      if (U16(pos, big_) == 0xfffe && U16(pos + 2, big_) == 0xe00d) {
        if (!until_item_end) return Error(path_, absl::StrCat("a stray item end at byte ", pos));
        return pos + 8;
      }
      absl::StatusOr<size_t> next = Element(pos, end, depth);
      if (!next.ok()) return next.status();
      pos = *next;
    }
    if (until_item_end) return Short(pos);
    return pos;
  }

  // One element at `pos` (inside [pos, end)); returns the position after it.
  absl::StatusOr<size_t> Element(size_t pos, size_t end, int depth) {
    if (depth > kMaxDepth) return Error(path_, "sequences nested too deep");
    if (end - pos < 8) return Short(pos);
    const bool meta = U16(pos, false) == 0x0002;
    const bool big = big_ && !meta;
    const uint16_t group = U16(pos, big), element = U16(pos + 2, big);
    size_t header = 8;
    uint32_t length = 0;
    bool sequence = false;
    if (explicit_ || meta) {
      const std::string vr = bytes_.substr(pos + 4, 2);
      // GDCM reads an element of an unknown VR by guesswork (as implicit VR,
      // whose 4-byte length is then read from other bytes), which this walk
      // cannot follow: such a file is refused.
      static const char* kVrs[] = {"AE", "AS", "AT", "CS", "DA", "DS", "DT", "FL", "FD", "IS",
                                   "LO", "LT", "OB", "OD", "OF", "OL", "OV", "OW", "PN", "SH",
                                   "SL", "SQ", "SS", "ST", "SV", "TM", "UC", "UI", "UL", "UN",
                                   "UR", "US", "UT", "UV"};
      bool known = false;
      for (const char* v : kVrs) known = known || vr == v;
      if (!known) {
        return Error(path_, absl::StrFormat("element (%04X,%04X) at byte %d has no valid VR", group,
                                            element, pos));
      }
      // GDCM's image reader asserts (gdcm::Attribute::SetFromDataElement)
      // that the attributes it reads have their dictionary VR (found by
      // volume_fuzzer: HighBit as another VR aborted the process).
      if (const char* want = ImageAttributeVr(group, element);
          want != nullptr && !absl::StrContains(want, vr)) {
        return Error(path_, absl::StrFormat("element (%04X,%04X) at byte %d has VR %s, not %s",
                                            group, element, pos, vr, want));
      }
      static const char* kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                    "SV", "UC", "UN", "UR", "UT", "UV"};
      bool long_form = false;
      for (const char* l : kLong) long_form = long_form || vr == l;
      if (long_form) {
        if (end - pos < 12) return Short(pos);
        header = 12;
        length = U32(pos + 8, big);
        sequence = vr == "SQ" || (vr == "UN" && length == kUndefined);
      } else {
        length = U16(pos + 6, big);
      }
    } else {
      length = U32(pos + 4, big);
      sequence = length == kUndefined;
    }
    const size_t value = pos + header;
    const bool pixels = group == 0x7fe0 && element == 0x0010;
    if (header_only_ && depth == 0 && pixels) {
      // The data set's own pixel data (depth 0: not an icon's in a
      // sequence): the walk ends at its value.
      pixel_value_at_ = value;
      return end;
    }
    if (length == kUndefined) {
      if (meta) return Error(path_, absl::StrCat("an undefined length in the file meta group at byte ", pos));
      if (!sequence && !pixels) {
        return Error(path_, absl::StrFormat(
                                "element (%04X,%04X) at byte %d has an undefined length", group,
                                element, pos));
      }
      if (pixels && depth == 0) {
        collect_ = true;
        absl::StatusOr<size_t> done = Items(value, end, depth + 1, /*fragments=*/true);
        collect_ = false;
        return done;
      }
      return Items(value, end, depth + 1, /*fragments=*/pixels);
    }
    if (length > end - value) {
      return Error(path_, absl::StrFormat(
                              "element (%04X,%04X) at byte %d declares %d bytes, %d remain",
                              group, element, pos, length, end - value));
    }
    // GDCM's image reader asserts that a RecognitionCode (0008,0010,
    // retired) that is not empty names ACR-NEMA (found by volume_fuzzer: a
    // UID written there aborted the process).
    if (depth == 0 && group == 0x0008 && element == 0x0010 && length > 0) {
      const std::string code = bytes_.substr(value, length);
      if (code != "ACR-NEMA 1.0" && code != "ACR-NEMA 2.0" && code != "ACRNEMA_LIBIDO_1.0" &&
          code != "ACRNEMA_LIBIDO_1.1") {
        return Error(
            path_,
            absl::StrFormat("RecognitionCode (0008,0010) at byte %d is not an ACR-NEMA one", pos));
      }
    }
    if (sequence) {
      absl::StatusOr<size_t> done = Items(value, value + length, depth + 1, false);
      if (!done.ok()) return done.status();
    }
    return value + length;
  }

  // Items from `pos` to `end` (a sequence of defined length) or to the
  // sequence delimiter. Pixel fragments hold bytes, not data sets.
  absl::StatusOr<size_t> Items(size_t pos, size_t end, int depth, bool fragments) {
    while (pos < end) {
      if (end - pos < 8) return Short(pos);
      const uint16_t group = U16(pos, big_), element = U16(pos + 2, big_);
      const uint32_t length = U32(pos + 4, big_);
      if (group != 0xfffe) return Error(path_, absl::StrCat("a sequence holds a non-item at byte ", pos));
      if (element == 0xe0dd) return pos + 8;  // sequence delimiter
      if (element != 0xe000) return Error(path_, absl::StrCat("a bad item tag at byte ", pos));
      const size_t value = pos + 8;
      if (length == kUndefined) {
        if (fragments) return Error(path_, "a pixel fragment of undefined length");
        absl::StatusOr<size_t> next = Elements(value, end, depth, /*until_item_end=*/true);
        if (!next.ok()) return next.status();
        pos = *next;
        continue;
      }
      if (length > end - value) {
        return Error(path_, absl::StrCat("an item at byte ", pos, " declares ", length, " bytes, ",
                                         end - value, " remain"));
      }
      if (!fragments) {
        absl::StatusOr<size_t> inner = Elements(value, value + length, depth, false);
        if (!inner.ok()) return inner.status();
      } else if (collect_) {
        fragments_.emplace_back(value, length);
      }
      pos = value + length;
    }
    return pos;
  }

  const std::string& path_;
  const std::string& bytes_;
  const bool header_only_;
  std::optional<size_t> pixel_value_at_;
  std::string syntax_;
  bool collect_ = false;  // in the data set's encapsulated pixel data
  std::vector<std::pair<size_t, size_t>> fragments_;
  bool explicit_ = true;
  bool big_ = false;
};

// Checks RLE Lossless pixel data (PS3.5 Annex G) before GDCM decodes it:
// GDCM's decoder divides by the segment count a frame's header gives (0
// raised SIGFPE: found by volume_fuzzer), reads as many segment offsets as
// it says (over 15 read past the header), and asserts (aborting the
// process) on segments that run past their fragment, decode to more bytes
// than a plane holds, or end more than 2 bytes before the next begins.
// So: one fragment per frame after the basic offset table, each with a
// 64-byte header of bits / 8 segments, the first at byte 64, and each
// segment's runs (PackBits) decoding to exactly rows x columns bytes
// within the fragment, ending at most 2 bytes before the next segment.
absl::Status CheckRle(const std::string& path, const std::string& bytes,
                      const std::vector<std::pair<size_t, size_t>>& items, int rows, int columns,
                      int bits, int frames) {
  if (items.size() != static_cast<size_t>(frames) + 1) {
    return Error(path, absl::StrCat("RLE pixel data of ", items.empty() ? 0 : items.size() - 1,
                                    " fragments for ", frames, " frames"));
  }
  const uint64_t plane = static_cast<uint64_t>(rows) * columns;
  const uint32_t segments = static_cast<uint32_t>(bits / 8);
  auto u32 = [&](size_t at) {
    const auto* p = reinterpret_cast<const unsigned char*>(bytes.data() + at);
    return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
  };
  for (int f = 0; f < frames; ++f) {
    const auto [at, length] = items[f + 1];
    auto bad = [&](const std::string& what) {
      return Error(path, absl::StrCat("RLE frame ", f, " is damaged: ", what));
    };
    if (length < 64) return bad(absl::StrCat("a fragment of ", length, " bytes"));
    if (u32(at) != segments) {
      return bad(absl::StrCat(u32(at), " segments where ", bits, "-bit pixels take ", segments));
    }
    for (uint32_t i = 0; i < segments; ++i) {
      const uint64_t begin = u32(at + 4 + 4 * i);
      const uint64_t end = i + 1 < segments ? u32(at + 8 + 4 * i) : length;
      if ((i == 0 && begin != 64) || begin >= end || end > length) {
        return bad(absl::StrCat("segment ", i, " at bytes [", begin, ", ", end, ") of ", length));
      }
      // The runs: n in 0..127 copies the next n + 1 bytes, -127..-1 repeats
      // the next byte 1 - n times, -128 is nothing.
      uint64_t out = 0, pos = begin;
      while (out < plane) {
        if (pos >= end) return bad(absl::StrCat("segment ", i, " ends after ", out, " bytes"));
        const auto n = static_cast<int8_t>(bytes[at + pos]);
        ++pos;
        if (n >= 0) {
          out += uint64_t(n) + 1;
          pos += uint64_t(n) + 1;
        } else if (n != -128) {
          out += uint64_t(1 - n);
          pos += 1;
        }
        if (pos > end) return bad(absl::StrCat("segment ", i, " runs past its end"));
      }
      if (out != plane) {
        return bad(absl::StrCat("segment ", i, " decodes to ", out, " bytes, not ", plane));
      }
      if (i + 1 < segments && end - pos > 2) {
        return bad(
            absl::StrCat("segment ", i + 1, " begins ", end - pos, " bytes after ", i, " ends"));
      }
    }
  }
  return absl::OkStatus();
}

// A slice file's bytes, read through the hook and walked (ElementWalk):
// what GDCM then reads from memory. With `encoding`, how its pixel data is
// stored is set there, so that the caller can check RLE (CheckRle) and
// send compressed data to the decoder process.
struct PixelEncoding {
  std::string syntax;  // the transfer syntax UID ("" without a meta group)
  std::vector<std::pair<size_t, size_t>> items;  // its fragments, when encapsulated
  bool Rle() const { return syntax == "1.2.840.10008.1.2.5"; }
  // Native (the walk refuses the other native syntaxes: big endian, and
  // deflated) or RLE: decoded in this process. Every other syntax is a
  // codec's (JPEG, JPEG-LS, JPEG 2000, ...): decoded by transtick-dicom-decode.
  bool InProcess() const {
    return syntax.empty() || syntax == "1.2.840.10008.1.2" || syntax == "1.2.840.10008.1.2.1" ||
           Rle();
  }
};

// A slice file's size, refused past the volume limit (a slice is far
// smaller than the volume it belongs to).
absl::StatusOr<uint64_t> SliceFileSize(const std::string& path, const ReadOptions& options) {
  absl::StatusOr<uint64_t> size = vi::FileSize(path, options);
  if (size.ok() && *size > options.max_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat(path, ": a slice file of ", *size,
                                                     " bytes, more than the volume limit"));
  }
  return size;
}

// The error of an ElementWalk that failed on `path` (its message starts
// with the path).
absl::Status Damaged(const std::string& path, const absl::Status& walked) {
  return Error(path, absl::StrCat("not a DICOM file, or a damaged one: ",
                                  walked.message().substr(path.size() + 2)));
}

absl::StatusOr<std::string> ReadChecked(const std::string& path, const ReadOptions& options,
                                        PixelEncoding* encoding = nullptr) {
  absl::StatusOr<uint64_t> size = SliceFileSize(path, options);
  if (!size.ok()) return size.status();
  absl::StatusOr<std::string> bytes = vi::ReadPrefix(path, *size, options);
  if (!bytes.ok()) return bytes.status();
  ElementWalk walk(path, *bytes);
  if (absl::Status s = walk.Run(); !s.ok()) return Damaged(path, s);
  if (encoding) {
    encoding->syntax = walk.syntax();
    encoding->items = walk.fragments();
  }
  return bytes;
}

// A slice file's header: its bytes up to the pixel data's value (or the
// whole file when it has none), read in growing prefixes, each walked
// (ElementWalk, header only) before GDCM sees it; and the file's size. A
// walk that fails on a prefix tries a longer one, so an error is the one
// the whole file gives. `budget` (may be null) bounds the bytes read: past
// it, ResourceExhausted, and budget->exhausted is set.
struct HeaderBytes {
  std::string bytes;
  uint64_t file_size = 0;
};
absl::StatusOr<HeaderBytes> ReadHeaderChecked(const std::string& path, const ReadOptions& options,
                                              DicomReadBudget* budget) {
  absl::StatusOr<uint64_t> size = SliceFileSize(path, options);
  if (!size.ok()) return size.status();
  // Most headers take a few KiB; an enhanced image's functional groups
  // may take MiBs.
  uint64_t want = std::min<uint64_t>(*size, kDicomFirstHeaderBytes);
  for (;;) {
    if (budget) {
      if (want > budget->bytes) {
        budget->exhausted = true;
        return absl::ResourceExhaustedError(
            absl::StrCat(path, ": past the bound on header bytes read"));
      }
      budget->bytes -= want;
    }
    absl::StatusOr<std::string> bytes = vi::ReadPrefix(path, want, options);
    if (!bytes.ok()) return bytes.status();
    // The whole file: as long as it said, or shorter (it shrank).
    const bool whole = bytes->size() >= *size || bytes->size() < want;
    ElementWalk walk(path, *bytes, /*header_only=*/true);
    absl::Status walked = walk.Run();
    if (walked.ok() && walk.pixel_value_at()) {
      bytes->resize(*walk.pixel_value_at());
      return HeaderBytes{*std::move(bytes), *size};
    }
    if (whole) {
      if (!walked.ok()) return Damaged(path, walked);
      const uint64_t read = bytes->size();
      return HeaderBytes{*std::move(bytes), read};
    }
    want = std::min(*size, want * 4);
  }
}

// Checks the image attributes of the file whose header is `h`, and fills
// `s` from them: its size, pixel format and frames, and, for a file of one
// frame, where that frame lies. The error says why the image cannot be a
// slice.
absl::Status CheckImage(const DicomHeader& h, uint64_t file_size, Slice& s) {
  const std::string& path = s.path;
  if (h.big_endian) {
    // Retired since 2004; the attributes below are read little-endian.
    return Error(path, "uses the retired explicit VR big endian transfer syntax, not supported");
  }
  // As stored, little endian: big-endian files are refused above.
  s.pixel_length = h.pixel_length;
  s.pixel_available = file_size - static_cast<uint64_t>(h.pixel_value_at);
  s.rows = Unsigned16(h, kRows);
  s.columns = Unsigned16(h, kColumns);
  if (s.rows <= 0 || s.columns <= 0) {
    return Error(path, absl::StrCat("has no image size (Rows ", s.rows, ", Columns ", s.columns, ")"));
  }
  const int samples = Unsigned16(h, kSamples);
  if (samples != -1 && samples != 1) {
    return Error(path, absl::StrCat("has ", samples,
                                    " samples per pixel: only grey-level (1) images are supported"));
  }
  if (const std::string frames = Text(h, kFrames); !frames.empty()) {
    if (!absl::SimpleAtoi(frames, &s.frames) || s.frames < 1 ||
        s.frames > static_cast<int>(kMaxSlices)) {
      return Error(path, absl::StrCat("NumberOfFrames '", Shown(frames), "' is not in [1, ",
                                      kMaxSlices, "]"));
    }
  }
  s.bits = Unsigned16(h, kBits);
  if (s.bits != 8 && s.bits != 16 && s.bits != 32) {
    return Error(path, absl::StrCat("BitsAllocated ", s.bits, " is not 8, 16 or 32"));
  }
  const int representation = Unsigned16(h, kRepresentation);
  s.is_signed = representation == 1;
  absl::StatusOr<std::vector<double>> v =
      Decimals(path, h, kPixelSpacing, "PixelSpacing", 2, false);
  if (!v.ok()) return v.status();
  if (!v->empty()) s.pixel_spacing = {(*v)[0], (*v)[1]};
  // The orientation and position are required of a single frame; the
  // frames of a multi-frame image may have theirs in functional groups.
  const bool multi = s.frames > 1 || !h.frames.empty();
  v = Decimals(path, h, kOrientation, "ImageOrientationPatient", 6, !multi);
  if (!v.ok()) return v.status();
  if (!v->empty()) std::copy(v->begin(), v->end(), s.orientation.begin());
  v = Decimals(path, h, kPosition, "ImagePositionPatient", 3, !multi);
  if (!v.ok()) return v.status();
  if (!v->empty()) std::copy(v->begin(), v->end(), s.position.begin());
  v = Decimals(path, h, kSlope, "RescaleSlope", 1, false);
  if (!v.ok()) return v.status();
  if (!v->empty()) {
    s.slope = (*v)[0];
  } else {
    // An RT dose grid's scale to grays.
    v = Decimals(path, h, kDoseScaling, "DoseGridScaling", 1, false);
    if (!v.ok()) return v.status();
    if (!v->empty()) s.slope = (*v)[0];
  }
  v = Decimals(path, h, kIntercept, "RescaleIntercept", 1, false);
  if (!v.ok()) return v.status();
  if (!v->empty()) s.intercept = (*v)[0];
  // Before GDCM reads the pixels (and allocates their declared length):
  // native pixel data must hold the image and lie within the file.
  const uint64_t bytes =
      uint64_t{static_cast<uint32_t>(s.rows)} * s.columns * (s.bits / 8) * s.frames;
  if (s.native && (s.pixel_length < bytes || s.pixel_length > s.pixel_available)) {
    return Error(path, absl::StrCat("pixel data of ", s.pixel_length, " bytes (", s.pixel_available,
                                    " in the file) for ",
                                    s.frames == 1 ? "" : absl::StrCat(s.frames, " frames of "),
                                    s.columns, "x", s.rows, " ", s.bits, "-bit pixels that need ",
                                    bytes, " (truncated?)"));
  }
  if (!s.native && s.pixel_length != 0xffffffffu && s.pixel_length > s.pixel_available) {
    return Error(path, absl::StrCat("pixel data of ", s.pixel_length, " bytes, the file holds ",
                                    s.pixel_available, " (truncated?)"));
  }
  return absl::OkStatus();
}

// The spacing, orientation, position and rescale of each frame of a file
// checked by CheckImage (`file`), appended to `out` as slices. A frame's
// functional groups (DicomFrame) override the file's attributes; frames
// without them are placed by an RT dose's GridFrameOffsetVector, offsets
// along the normal from the first frame's position.
absl::Status Frames(const DicomHeader& h, const Slice& file, std::vector<Slice>* out) {
  const std::string& path = file.path;
  const int n = file.frames;
  if (!h.frames.empty() && (h.frames.size() != static_cast<size_t>(n) || h.more_frames)) {
    return Error(path, absl::StrCat("has ", n, " frames but functional groups for ",
                                    h.more_frames ? "more" : absl::StrCat(h.frames.size())));
  }
  std::vector<double> offsets;
  if (h.frames.empty() && n > 1) {
    absl::StatusOr<std::vector<double>> v =
        Decimals(path, h, kFrameOffsets, "GridFrameOffsetVector", 0, false);
    if (!v.ok()) return v.status();
    offsets = *std::move(v);
    if (offsets.size() != static_cast<size_t>(n)) {
      return Error(path, absl::StrCat("has ", n,
                                      " frames but no position for each (no per-frame functional "
                                      "groups, and a GridFrameOffsetVector of ",
                                      offsets.size(), " values)"));
    }
  }
  if (h.frames.empty() && n > 1) {
    // Placed by the file's own orientation and position.
    for (Element e : {kOrientation, kPosition}) {
      if (Text(h, e).empty()) {
        return Error(path, absl::StrFormat("has %d frames and no %s (%04X,%04X)", n,
                                           e == kOrientation ? "ImageOrientationPatient"
                                                             : "ImagePositionPatient",
                                           kTags[e] >> 16, kTags[e] & 0xffff));
      }
    }
  }
  for (int k = 0; k < n; ++k) {
    Slice s = file;
    s.frame = k;
    if (!h.frames.empty()) {
      const DicomFrame& f = h.frames[k];
      const std::string name = s.Name();
      auto read = [&](const std::optional<std::string>& value, const char* what, size_t want,
                      double* to) -> absl::Status {
        if (!value) return absl::OkStatus();
        absl::StatusOr<std::vector<double>> v = DecimalsOf(name, Trimmed(*value), what, want);
        if (!v.ok()) return v.status();
        std::copy(v->begin(), v->end(), to);
        return absl::OkStatus();
      };
      if (!f.position) {
        return Error(name, "has no ImagePositionPatient in its PlanePositionSequence (0020,9113)");
      }
      if (!f.orientation && Text(h, kOrientation).empty()) {
        return Error(name,
                     "has no ImageOrientationPatient (0020,0037), in its functional groups or "
                     "the file's");
      }
      for (absl::Status st :
           {read(f.position, "ImagePositionPatient", 3, s.position.data()),
            read(f.orientation, "ImageOrientationPatient", 6, s.orientation.data()),
            read(f.spacing, "PixelSpacing", 2, s.pixel_spacing.data()),
            read(f.slope, "RescaleSlope", 1, &s.slope),
            read(f.intercept, "RescaleIntercept", 1, &s.intercept)}) {
        if (!st.ok()) return st;
      }
    } else if (n > 1) {
      const std::optional<std::array<double, 3>> normal = UnitNormal(s.orientation);
      if (!normal) return NotOrthonormal(path);
      for (int a = 0; a < 3; ++a) s.position[a] += (offsets[k] - offsets[0]) * (*normal)[a];
    }
    if (!(s.pixel_spacing[0] > 0) || !(s.pixel_spacing[1] > 0)) {
      return Error(s.Name(), absl::StrCat("PixelSpacing ", s.pixel_spacing[0], "\\",
                                          s.pixel_spacing[1], " is not positive"));
    }
    out->push_back(std::move(s));
  }
  return absl::OkStatus();
}

// What a file in a series directory is.
enum class FileKind {
  kImage,     // a DICOM image: a slice, or a slice per frame (its problem aside)
  kNotDicom,  // no DICOM file at all (a text, an image of another format)
  kNoImage,   // DICOM without pixel data (a report, a presentation state)
};

// Reads a file's header. A file that starts as DICOM does ("DICM" at byte
// 128) and cannot be read is an error (a damaged slice must not go
// unnoticed); one that does not, and is not read as a data set without a
// preamble either, is kNotDicom. An image appends its frames to `out` as
// slices, or one slice holding its problem.
absl::StatusOr<FileKind> ReadHeader(const Gdcm& gdcm, const std::string& path,
                                    const ReadOptions& options, DicomReadBudget* budget,
                                    std::vector<Slice>* out) {
  absl::StatusOr<std::string> prefix = vi::ReadPrefix(path, 132, options);
  if (!prefix.ok()) return prefix.status();
  const bool magic = prefix->size() == 132 && prefix->compare(128, 4, "DICM") == 0;
  if (!magic) {
    // A data set without the preamble begins with an element of the meta
    // group or of group 0008 (identification), little endian.
    const unsigned group = prefix->size() >= 8 ? static_cast<unsigned char>((*prefix)[0]) |
                                                     static_cast<unsigned char>((*prefix)[1]) << 8
                                               : 0;
    if (group != 0x0002 && group != 0x0008) return FileKind::kNotDicom;
  }
  absl::StatusOr<HeaderBytes> header = ReadHeaderChecked(path, options, budget);
  if (!header.ok()) {
    if (!magic && header.status().code() == absl::StatusCode::kInvalidArgument) {
      return FileKind::kNotDicom;
    }
    return header.status();
  }
  const uint64_t file_size = header->file_size;
  DicomHeader h;
  // Up to the pixel data: nothing of it is read (the bytes end at its
  // value), and its length is checked below before GDCM reads it. The
  // module takes the bytes.
  gdcm.read_header(&header->bytes, kTags, kElements, kMaxSlices, &h);
  if (!h.read) {
    if (!magic) return FileKind::kNotDicom;
    return Error(path, "is not a DICOM file GDCM can read");
  }
  const int64_t value_at = h.pixel_value_at;
  if (value_at < 4 || static_cast<uint64_t>(value_at) > file_size) return FileKind::kNoImage;
  Slice s;
  s.path = path;
  s.file_bytes = file_size;
  s.native = !h.encapsulated;
  s.series = Text(h, kSeries);
  s.modality = Text(h, kModality);
  s.description = Text(h, kDescription);
  s.number = Text(h, kSeriesNumber);
  s.problem = CheckImage(h, file_size, s);
  if (s.problem.ok()) {
    std::vector<Slice> frames;
    s.problem = Frames(h, s, &frames);
    if (s.problem.ok()) {
      for (Slice& f : frames) out->push_back(std::move(f));
      return FileKind::kImage;
    }
  }
  out->push_back(std::move(s));
  return FileKind::kImage;
}

ScalarType TypeOf(const Slice& s) {
  switch (s.bits) {
    case 8:
      return s.is_signed ? ScalarType::kInt8 : ScalarType::kUint8;
    case 16:
      return s.is_signed ? ScalarType::kInt16 : ScalarType::kUint16;
    default:
      return s.is_signed ? ScalarType::kInt32 : ScalarType::kUint32;
  }
}

// The decoder process of one series read (dicom_decoder.h), started for
// its first file of compressed pixel data, with an address space of
// `max_memory` bytes.
struct Decoding {
  uint64_t max_memory = 0;
  std::unique_ptr<DicomDecoder> decoder;
};

// Room for the decoder to decode any of `slices`' files: its own code and
// GDCM's (about 100 MiB), a file's bytes twice and its pixels three times
// over (GDCM's buffers, and ours).
uint64_t DecoderMemory(const std::vector<Slice>& slices) {
  uint64_t most = 0;
  for (const Slice& s : slices) {
    const uint64_t pixels = uint64_t(s.rows) * s.columns * (s.bits / 8) * s.frames;
    most = std::max(most, 2 * s.file_bytes + 3 * pixels);
  }
  return (uint64_t{1} << 30) + most;
}

// Decodes the file of `slices` (frames of one file, with their places in
// the volume: z[i] for slices[i]) once, and writes each frame, rescaled, to
// its plane of `out`. Native and RLE pixel data is decoded here, the rest
// by `decoding`'s process.
absl::Status ReadPixels(const Gdcm& gdcm, Decoding& decoding,
                        const std::vector<const Slice*>& slices, const std::vector<int>& z,
                        const ReadOptions& options, float* out) {
  const Slice& s = *slices.front();
  // Read and walked again: the file may have changed since its header was.
  PixelEncoding encoding;
  absl::StatusOr<std::string> contents = ReadChecked(s.path, options, &encoding);
  if (!contents.ok()) return contents.status();
  if (encoding.Rle()) {
    absl::Status checked =
        CheckRle(s.path, *contents, encoding.items, s.rows, s.columns, s.bits, s.frames);
    if (!checked.ok()) return checked;
  }
  DicomPixels pixels;
  if (encoding.InProcess()) {
    gdcm.read_pixels(&*contents, s.rows, s.columns, s.bits, s.frames, &pixels);
    if (!pixels.error.empty()) return Error(s.path, pixels.error);
  } else {
    if (!decoding.decoder) {
      absl::StatusOr<std::unique_ptr<DicomDecoder>> started =
          DicomDecoder::Start(decoding.max_memory, options.decode_seconds);
      if (!started.ok()) {
        return absl::Status(
            started.status().code(),
            absl::StrCat(s.path, ": cannot decode its compressed pixel data (",
                         Shown(encoding.syntax), "): ", started.status().message()));
      }
      decoding.decoder = *std::move(started);
    }
    absl::Status decoded =
        decoding.decoder->Decode(s.path, *contents, s.rows, s.columns, s.bits, s.frames,
                                 options.decode_seconds, &pixels.bytes);
    if (!decoded.ok()) return decoded;
  }
  const size_t count = static_cast<size_t>(s.rows) * s.columns;
  const size_t frame_bytes = count * (s.bits / 8);
  if (pixels.bytes.size() != frame_bytes * s.frames) {
    return Error(s.path, "GDCM decoded a different number of pixels");
  }
  for (size_t i = 0; i < slices.size(); ++i) {
    const Slice& f = *slices[i];
    float* plane = out + static_cast<size_t>(z[i]) * count;
    // GDCM hands pixels over in the host's byte order.
    vi::ConvertSamples(
        reinterpret_cast<const unsigned char*>(pixels.bytes.data()) + frame_bytes * f.frame, count,
        TypeOf(f), ByteOrder::kLittle, plane);
    if (f.slope != 1 || f.intercept != 0) {
      for (size_t k = 0; k < count; ++k) {
        plane[k] = static_cast<float>(plane[k] * f.slope + f.intercept);
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<std::string>> ListDirectory(const std::string& path,
                                                       const ReadOptions& options) {
  if (options.list) return options.list(path);
  DIR* dir = ::opendir(path.c_str());
  if (dir == nullptr) return absl::NotFoundError(absl::StrCat(path, ": cannot list the directory"));
  std::vector<std::string> names;
  while (dirent* e = ::readdir(dir)) {
    if (names.size() > kMaxSlices) break;
    names.push_back(e->d_name);
  }
  ::closedir(dir);
  return names;
}

double Dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Up to `limit` of `names`, comma-separated, and how many more.
std::string NameSome(const std::vector<std::string>& names, size_t limit = 3) {
  std::string out;
  for (size_t i = 0; i < names.size() && i < limit; ++i) {
    absl::StrAppend(&out, i ? ", " : "", Shown(names[i]));
  }
  if (names.size() > limit) absl::StrAppend(&out, " and ", names.size() - limit, " more");
  return out;
}

// One series of a directory: its slices (frames) in file name order.
struct Series {
  std::string uid;
  std::vector<Slice> slices;
  size_t files = 0;
  uint64_t bytes = 0;  // the files' sizes
  // "CT, series 2 'AX 5mm', 120 files", "... 1 file, 96 frames"
  std::string Summary() const {
    const Slice& f = slices.front();
    std::string what = f.modality.empty() ? "" : Shown(f.modality);
    if (!f.number.empty())
      absl::StrAppend(&what, what.empty() ? "" : ", ", "series ", Shown(f.number));
    if (!f.description.empty())
      absl::StrAppend(&what, what.empty() ? "" : " ", "'", Shown(f.description), "'");
    absl::StrAppend(&what, what.empty() ? "" : ", ", files, files == 1 ? " file" : " files");
    if (slices.size() != files) absl::StrAppend(&what, ", ", slices.size(), " frames");
    return what;
  }
  // "1.2.3 (CT, series 2 'AX 5mm', 120 files)"
  std::string Describe() const {
    return absl::StrCat(uid.empty() ? "(no SeriesInstanceUID)" : Shown(uid), " (", Summary(), ")");
  }
  // Whether a path can name it, "DIR#UID" (ParseSeriesPath): a UID of
  // digits and dots.
  bool Nameable() const { return ParseSeriesPath(absl::StrCat("d#", uid)).has_value(); }
};

// What a directory holds: its series, and notes naming what was passed over.
struct DirectoryScan {
  std::vector<Series> all;
  std::vector<std::string> notes;
};

// Reads the header of every file in `directory` (errors name `path`).
absl::StatusOr<DirectoryScan> ScanDirectory(const Gdcm& gdcm, const std::string& path,
                                            const std::string& directory,
                                            const ReadOptions& options,
                                            DicomReadBudget* budget = nullptr) {
  absl::StatusOr<std::vector<std::string>> names = ListDirectory(directory, options);
  if (!names.ok()) return names.status();
  std::sort(names->begin(), names->end());
  const std::string dir = absl::StrCat(absl::StripSuffix(directory, "/"), "/");
  DirectoryScan scan;
  std::vector<Series>& all = scan.all;
  std::vector<std::string> subdirectories, not_dicom, no_image;
  size_t files = 0;
  for (const std::string& name : *names) {
    if (name.empty() || name[0] == '.' || absl::AsciiStrToUpper(name) == "DICOMDIR") continue;
    if (++files > kMaxSlices) {
      return Error(path, absl::StrCat("more than ", kMaxSlices, " files"));
    }
    const std::string file = dir + name;
    if (vi::IsDirectory(file, options)) {
      subdirectories.push_back(name + "/");
      continue;
    }
    std::vector<Slice> frames;
    absl::StatusOr<FileKind> kind = ReadHeader(gdcm, file, options, budget, &frames);
    if (!kind.ok()) return kind.status();
    if (*kind == FileKind::kNotDicom) {
      not_dicom.push_back(name);
      continue;
    }
    if (*kind == FileKind::kNoImage) {
      no_image.push_back(name);
      continue;
    }
    const std::string& uid = frames.front().series;
    auto it = std::find_if(all.begin(), all.end(), [&](const Series& x) { return x.uid == uid; });
    if (it == all.end()) {
      all.push_back({uid, {}, 0, 0});
      it = all.end() - 1;
    }
    ++it->files;
    it->bytes += frames.front().file_bytes;
    for (Slice& f : frames) it->slices.push_back(std::move(f));
    if (it->slices.size() > kMaxSlices) {
      return Error(path, absl::StrCat("more than ", kMaxSlices, " slices in series ", Shown(uid)));
    }
  }
  std::vector<std::string>& notes = scan.notes;
  if (!subdirectories.empty()) {
    notes.push_back(absl::StrCat("passed over ", subdirectories.size(), " subdirector",
                                 subdirectories.size() == 1 ? "y" : "ies", " (",
                                 NameSome(subdirectories), ")"));
  }
  if (!not_dicom.empty()) {
    notes.push_back(absl::StrCat("passed over ", not_dicom.size(),
                                 not_dicom.size() == 1 ? " file that is" : " files that are",
                                 " not DICOM (", NameSome(not_dicom), ")"));
  }
  if (!no_image.empty()) {
    notes.push_back(absl::StrCat("passed over ", no_image.size(), " DICOM file",
                                 no_image.size() == 1 ? "" : "s", " without an image (",
                                 NameSome(no_image), ")"));
  }
  if (all.empty()) {
    return Error(path, absl::StrCat("the directory holds no DICOM images",
                                    notes.empty() ? "" : "; it ", absl::StrJoin(notes, "; ")));
  }
  return scan;
}

// Where a series' slices lie: the directions of its rows, columns and
// slices, and the slices' spacing.
struct Geometry {
  std::array<double, 3> row, column, normal;
  double z_spacing = 1;
};

// Checks that `slices` (frames) make one volume, one problem at a time
// (each file's own, then sizes, orientation, spacing, gaps, tilt, the
// volume's size), and sorts them along their normal.
absl::StatusOr<Geometry> Arrange(const std::string& path, const ReadOptions& options,
                                 std::vector<Slice>* slices_in) {
  std::vector<Slice>& slices = *slices_in;
  const Slice& first = slices.front();
  for (const Slice& s : slices) {
    if (!s.problem.ok()) return s.problem;
  }
  for (const Slice& s : slices) {
    if (s.rows != first.rows || s.columns != first.columns || s.bits != first.bits ||
        s.is_signed != first.is_signed) {
      return Error(path, absl::StrCat(s.Name(), " is ", s.columns, "x", s.rows, " ", s.bits,
                                      "-bit, ", first.Name(), " ", first.columns, "x", first.rows,
                                      " ", first.bits, "-bit: the slices differ"));
    }
    for (int i = 0; i < 6; ++i) {
      if (std::fabs(s.orientation[i] - first.orientation[i]) > 1e-4) {
        return Error(path, absl::StrCat(s.Name(), " and ", first.Name(),
                                        " have different ImageOrientationPatient"));
      }
    }
    for (int i = 0; i < 2; ++i) {
      if (std::fabs(s.pixel_spacing[i] - first.pixel_spacing[i]) > 1e-4 * first.pixel_spacing[i]) {
        return Error(path,
                     absl::StrCat(s.Name(), " and ", first.Name(), " have different PixelSpacing"));
      }
    }
  }
  const std::optional<std::array<double, 3>> unit = UnitNormal(first.orientation);
  if (!unit) return Error(path, NotOrthonormal(first.Name()).message());
  Geometry g;
  g.row = {first.orientation[0], first.orientation[1], first.orientation[2]};
  g.column = {first.orientation[3], first.orientation[4], first.orientation[5]};
  g.normal = *unit;
  const std::array<double, 3>& normal = g.normal;
  for (Slice& s : slices) s.along_normal = Dot(s.position, normal);
  std::sort(slices.begin(), slices.end(),
            [](const Slice& a, const Slice& b) { return a.along_normal < b.along_normal; });

  if (slices.size() > 1) {
    std::vector<double> gaps;
    for (size_t i = 1; i < slices.size(); ++i) {
      gaps.push_back(slices[i].along_normal - slices[i - 1].along_normal);
    }
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double typical = sorted[sorted.size() / 2];
    for (size_t i = 0; i < gaps.size(); ++i) {
      const Slice& a = slices[i];
      const Slice& b = slices[i + 1];
      if (gaps[i] < 1e-3) {
        return Error(path, absl::StrCat(a.Name(), " and ", b.Name(), " lie at the same position",
                                        a.path == b.path
                                            ? " (the image holds several stacks: echoes, phases or "
                                              "time points, which are not supported)"
                                            : " (a duplicate slice, or two series with one UID)"));
      }
      if (std::fabs(gaps[i] - typical) > 0.01 * typical + 0.01) {
        return Error(path,
                     absl::StrFormat("%sa gap of %.3f mm between %s and %s, where the slices are "
                                     "%.3f mm apart (a missing slice?)",
                                     gaps[i] > typical ? "" : "uneven spacing: ", gaps[i], a.Name(),
                                     b.Name(), typical));
      }
      // Successive positions must move along the normal only.
      std::array<double, 3> step;
      for (int w = 0; w < 3; ++w) step[w] = b.position[w] - a.position[w];
      const double off = std::sqrt(std::max(0.0, Dot(step, step) - gaps[i] * gaps[i]));
      if (off > 0.01 * gaps[i] + 0.01) {
        return Error(path, absl::StrFormat(
                               "%s lies %.3f mm off the normal of %s (a tilted gantry or a sheared "
                               "series), which is not supported",
                               b.Name(), off, a.Name()));
      }
    }
    double sum = 0;
    for (double gap : gaps) sum += gap;
    g.z_spacing = sum / gaps.size();
  }
  const std::array<int64_t, 3> dims = {first.columns, first.rows,
                                       static_cast<int64_t>(slices.size())};
  absl::StatusOr<uint64_t> data_bytes = vi::CheckedDataBytes(path, dims, TypeOf(first), options);
  if (!data_bytes.ok()) return data_bytes.status();
  return g;
}

}  // namespace

std::optional<SeriesPath> ParseSeriesPath(std::string_view path) {
  const size_t hash = path.rfind('#');
  if (hash == std::string_view::npos || hash == 0) return std::nullopt;
  const std::string_view uid = path.substr(hash + 1);
  // A UID: digits and dots, at most 64 characters (PS3.5 9.1).
  if (uid.empty() || uid.size() > 64) return std::nullopt;
  for (char c : uid) {
    if (!(absl::ascii_isdigit(static_cast<unsigned char>(c)) || c == '.')) return std::nullopt;
  }
  return SeriesPath{std::string(path.substr(0, hash)), std::string(uid)};
}

absl::StatusOr<Volume> ReadDicomSeries(const std::string& path, const ReadOptions& options) {
  const Gdcm& gdcm = LoadGdcm();
  if (!gdcm.status.ok()) {
    return absl::UnavailableError(
        absl::StrCat(path, ": cannot read DICOM: ", gdcm.status.message()));
  }
  // The directory, and the series the path names in it (if any).
  std::string directory = path;
  std::string wanted;
  bool select = false;
  if (!vi::IsDirectory(path, options)) {
    if (std::optional<SeriesPath> sp = ParseSeriesPath(path);
        sp && vi::IsDirectory(sp->dir, options)) {
      directory = sp->dir;
      wanted = sp->series;
      select = true;
    }
  }
  absl::StatusOr<DirectoryScan> scan = ScanDirectory(gdcm, path, directory, options);
  if (!scan.ok()) return scan.status();
  const std::vector<Series>& all = scan->all;
  std::vector<std::string>& notes = scan->notes;
  // Each series as the path that reads it, "DIR#UID (CT, ...)"; a UID
  // that is not one (empty, or not digits and dots) cannot be named so.
  const std::string base(absl::StripSuffix(directory, "/"));
  auto list = [&] {
    std::vector<std::string> lines;
    for (const Series& x : all) {
      lines.push_back(x.Nameable() ? absl::StrCat(base, "#", x.Describe())
                                   : absl::StrCat(x.Describe(), ", which no path can name"));
    }
    return absl::StrJoin(lines, "; ");
  };
  const Series* chosen = nullptr;
  if (select) {
    for (const Series& x : all) {
      if (x.uid == wanted) chosen = &x;
    }
    if (chosen == nullptr) {
      return absl::NotFoundError(
          absl::StrCat(path, ": no series ", wanted, " in ", base, ", which holds ", list()));
    }
  } else if (all.size() == 1) {
    chosen = &all.front();
  } else {
    return Error(
        path, absl::StrCat(all.size(), " series in one directory; read one by its path: ", list()));
  }
  if (all.size() > 1) {
    notes.push_back(
        absl::StrCat("read series ", chosen->Describe(), " of ", all.size(), " in the directory"));
  }
  std::vector<Slice> slices = chosen->slices;
  absl::StatusOr<Geometry> geometry = Arrange(path, options, &slices);
  if (!geometry.ok()) return geometry.status();
  const Slice& first = slices.front();
  const double z_spacing = geometry->z_spacing;

  Volume volume;
  volume.dims = {first.columns, first.rows, static_cast<int>(slices.size())};
  volume.spacing = {first.pixel_spacing[1], first.pixel_spacing[0], z_spacing};
  volume.source_type = TypeOf(first);
  volume.values.resize(volume.VoxelCount());
  // Each file once, in the order of its first plane, with every frame of
  // it the volume holds.
  std::vector<size_t> order(slices.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return slices[a].path < slices[b].path; });
  std::vector<std::pair<size_t, size_t>> runs;  // [begin, end) of order, by first plane
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    while (j < order.size() && slices[order[j]].path == slices[order[i]].path) ++j;
    runs.push_back({i, j});
    i = j;
  }
  std::sort(runs.begin(), runs.end(),
            [&](const auto& a, const auto& b) { return order[a.first] < order[b.first]; });
  Decoding decoding;
  decoding.max_memory = DecoderMemory(slices);
  for (const auto& [begin, end] : runs) {
    std::vector<const Slice*> frames;
    std::vector<int> z;
    for (size_t i = begin; i < end; ++i) {
      frames.push_back(&slices[order[i]]);
      z.push_back(static_cast<int>(order[i]));
    }
    if (absl::Status st = ReadPixels(gdcm, decoding, frames, z, options, volume.values.data());
        !st.ok()) {
      return st;
    }
  }
  if (absl::Status s = SetOrientation(path, {geometry->row, geometry->column, geometry->normal},
                                      slices.front().position, &volume);
      !s.ok()) {
    return s;
  }
  volume.notes = std::move(notes);
  return volume;
}

absl::StatusOr<std::vector<DicomSeriesInfo>> ListDicomSeries(const std::string& path,
                                                             const ReadOptions& options,
                                                             DicomReadBudget* budget) {
  const Gdcm& gdcm = LoadGdcm();
  if (!gdcm.status.ok()) {
    return absl::UnavailableError(
        absl::StrCat(path, ": cannot read DICOM: ", gdcm.status.message()));
  }
  absl::StatusOr<DirectoryScan> scan = ScanDirectory(gdcm, path, path, options, budget);
  if (!scan.ok()) return scan.status();
  const std::string base(absl::StripSuffix(path, "/"));
  std::vector<DicomSeriesInfo> out;
  for (const Series& x : scan->all) {
    DicomSeriesInfo info;
    const Slice& f = x.slices.front();
    info.uid = x.uid;
    if (scan->all.size() == 1) {
      info.path = base;
    } else if (x.Nameable()) {
      info.path = absl::StrCat(base, "#", x.uid);
    }
    info.modality = f.modality;
    info.number = f.number;
    info.description = f.description;
    info.summary = x.Summary();
    info.files = x.files;
    info.bytes = x.bytes;
    info.frames = x.slices.size();
    info.columns = f.columns;
    info.rows = f.rows;
    std::vector<Slice> slices = x.slices;
    if (absl::StatusOr<Geometry> g =
            Arrange(info.path.empty() ? base : info.path, options, &slices);
        !g.ok()) {
      info.problem = std::string(g.status().message());
    }
    out.push_back(std::move(info));
  }
  return out;
}

}  // namespace transtick
