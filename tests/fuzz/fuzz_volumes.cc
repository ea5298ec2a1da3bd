#include "fuzz_volumes.h"

#include <zlib.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "dicom_writer.h"

namespace transtick::fuzz {
namespace {

// `bits` as `width` bytes in `order`.
void Put(uint32_t bits, int width, ByteOrder order, std::string* out) {
  for (int i = 0; i < width; ++i) {
    const int shift = 8 * (order == ByteOrder::kBig ? width - 1 - i : i);
    out->push_back(static_cast<char>(bits >> shift));
  }
}

int NiftiDatatype(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
      return 2;
    case ScalarType::kInt16:
      return 4;
    case ScalarType::kInt32:
      return 8;
    case ScalarType::kFloat32:
      return 16;
    case ScalarType::kInt8:
      return 256;
    case ScalarType::kUint16:
      return 512;
    case ScalarType::kUint32:
      return 768;
    case ScalarType::kFloat64:
      return 64;
  }
  return 0;
}

}  // namespace

std::string RawSamples(const Volume& volume, ScalarType type, ByteOrder order) {
  std::string out;
  const int width = static_cast<int>(ScalarTypeSize(type));
  for (float v : volume.values) {
    const int64_t i = std::llround(v);
    const uint32_t bits =
        type == ScalarType::kFloat32 ? std::bit_cast<uint32_t>(v) : static_cast<uint32_t>(i);
    Put(bits, width, order, &out);
  }
  return out;
}

std::string NrrdFile(const Volume& volume, ScalarType type, ByteOrder order, bool gzip) {
  const std::string data = RawSamples(volume, type, order);
  return absl::StrCat(
      "NRRD0004\n# written by the fuzzers' seed writer\ntype: ", std::string(ScalarTypeName(type)),
      "\ndimension: 3\nsizes: ", volume.dims[0], " ", volume.dims[1], " ", volume.dims[2],
      "\nspacings: ", volume.spacing[0], " ", volume.spacing[1], " ", volume.spacing[2],
      "\nencoding: ", gzip ? "gzip" : "raw",
      "\nendian: ", order == ByteOrder::kBig ? "big" : "little", "\n\n", gzip ? Gzip(data) : data);
}

std::string NiftiFile(const Volume& volume, ScalarType type, ByteOrder order, bool gzip) {
  std::string h;
  Put(348, 4, order, &h);
  h.resize(40, '\0');
  for (int v : {3, volume.dims[0], volume.dims[1], volume.dims[2], 1, 1, 1, 1}) {
    Put(static_cast<uint32_t>(v), 2, order, &h);
  }
  h.resize(70, '\0');
  Put(static_cast<uint32_t>(NiftiDatatype(type)), 2, order, &h);
  Put(static_cast<uint32_t>(8 * ScalarTypeSize(type)), 2, order, &h);  // bitpix
  h.resize(76, '\0');
  for (float f :
       {1.0f, float(volume.spacing[0]), float(volume.spacing[1]), float(volume.spacing[2])}) {
    Put(std::bit_cast<uint32_t>(f), 4, order, &h);
  }
  h.resize(108, '\0');
  for (float f : {352.0f, 1.0f, 0.0f})
    Put(std::bit_cast<uint32_t>(f), 4, order, &h);  // offset, slope, inter
  h.resize(344, '\0');
  h.append("n+1\0", 4);
  h.append(4, '\0');  // no extensions
  const std::string file = h + RawSamples(volume, type, order);
  return gzip ? Gzip(file) : file;
}

std::string DenFile(const Volume& volume, ByteOrder order) {
  std::string out;
  const auto& d = volume.dims;
  Put(1, 2, order, &out);                                                 // map_version
  for (int block = 0; block < 3; ++block) {                               // orig, extr, map
    for (int v : {0, 0, 0}) Put(v, 2, order, &out);                       //   min
    for (int v : {d[0] - 1, d[1] - 1, d[2] - 1}) Put(v, 2, order, &out);  // max
    for (int v : {d[0], d[1], d[2]}) Put(v, 2, order, &out);              //   len
  }
  Put(0, 2, order, &out);  // map_warps
  Put(static_cast<uint32_t>(volume.VoxelCount()), 4, order, &out);
  return out + RawSamples(volume, ScalarType::kUint8, order);
}

std::string Gzip(const std::string& data) {
  z_stream stream{};
  // 15 + 16: a gzip wrapper, as NRRD writers and .nii.gz use.
  if (deflateInit2(&stream, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) !=
      Z_OK) {
    std::abort();
  }
  std::string out(deflateBound(&stream, data.size()) + 64, '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  stream.avail_in = static_cast<uInt>(data.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = static_cast<uInt>(out.size());
  if (deflate(&stream, Z_FINISH) != Z_STREAM_END) std::abort();
  out.resize(stream.total_out);
  deflateEnd(&stream);
  return out;
}

std::string MetaImageFile(const Volume& volume, ScalarType type, ByteOrder order, bool compressed) {
  static const char* kTypes[] = {"MET_UCHAR", "MET_CHAR", "MET_USHORT", "MET_SHORT",
                                 "MET_UINT",  "MET_INT",  "MET_FLOAT"};
  const std::string data = RawSamples(volume, type, order);
  std::string zipped;
  if (compressed) {
    uLongf n = compressBound(data.size());
    zipped.resize(n);
    compress(reinterpret_cast<Bytef*>(zipped.data()), &n,
             reinterpret_cast<const Bytef*>(data.data()), data.size());
    zipped.resize(n);
  }
  return absl::StrCat(
      "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = ",
      order == ByteOrder::kBig ? "True" : "False", "\nCompressedData = ",
      compressed ? "True" : "False", "\nTransformMatrix = 0 1 0 1 0 0 0 0 1\nOffset = 1 2 3",
      "\nElementSpacing = ", volume.spacing[0], " ", volume.spacing[1], " ", volume.spacing[2],
      "\nDimSize = ", volume.dims[0], " ", volume.dims[1], " ", volume.dims[2],
      "\nElementType = ", kTypes[static_cast<int>(type)], "\nElementDataFile = LOCAL\n",
      compressed ? zipped : data);
}

std::string VtiFile(const Volume& volume, ScalarType type, ByteOrder order, bool compressed) {
  static const char* kTypes[] = {"UInt8", "Int8", "UInt16", "Int16", "UInt32", "Int32", "Float32"};
  const std::string data = RawSamples(volume, type, order);
  std::string appended;
  auto put64 = [&](uint64_t v) { Put(static_cast<uint32_t>(v), 4, order, &appended); };
  if (!compressed) {
    put64(data.size());
    appended += data;
  } else {
    const size_t block = (data.size() + 1) / 2;
    std::string blocks[2];
    for (int b = 0; b < 2; ++b) {
      const std::string part = data.substr(b * block, block);
      uLongf n = compressBound(part.size());
      blocks[b].resize(n);
      compress(reinterpret_cast<Bytef*>(blocks[b].data()), &n,
               reinterpret_cast<const Bytef*>(part.data()), part.size());
      blocks[b].resize(n);
    }
    put64(2);
    put64(block);
    put64(data.size() - block == block ? 0 : data.size() - block);
    put64(blocks[0].size());
    put64(blocks[1].size());
    appended += blocks[0] + blocks[1];
  }
  return absl::StrCat(
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"",
      order == ByteOrder::kBig ? "BigEndian" : "LittleEndian", "\" header_type=\"UInt32\"",
      compressed ? " compressor=\"vtkZLibDataCompressor\"" : "", ">\n<ImageData WholeExtent=\"0 ",
      volume.dims[0] - 1, " 0 ", volume.dims[1] - 1, " 0 ", volume.dims[2] - 1,
      "\" Origin=\"0 0 0\" Spacing=\"", volume.spacing[0], " ", volume.spacing[1], " ",
      volume.spacing[2], "\" Direction=\"0 0 1 1 0 0 0 1 0\">\n<Piece Extent=\"0 ",
      volume.dims[0] - 1, " 0 ", volume.dims[1] - 1, " 0 ", volume.dims[2] - 1,
      "\">\n<PointData Scalars=\"v\">\n<DataArray type=\"", kTypes[static_cast<int>(type)],
      "\" Name=\"v\" format=\"appended\" offset=\"0\"/>\n</PointData>\n</Piece>\n</ImageData>\n"
      "<AppendedData encoding=\"raw\">\n_",
      appended, "\n</AppendedData>\n</VTKFile>\n");
}

std::string DicomSeriesInput(const Volume& volume, testing::DicomCodec codec) {
  std::string out = kDicomSeriesMagic;
  for (int z = 0; z < volume.dims[2]; ++z) {
    testing::DicomSlice slice;
    slice.columns = volume.dims[0];
    slice.rows = volume.dims[1];
    slice.spacing = {volume.spacing[0], volume.spacing[1]};
    slice.position = {0, 0, z * volume.spacing[2]};
    for (int y = 0; y < volume.dims[1]; ++y) {
      for (int x = 0; x < volume.dims[0]; ++x) {
        slice.pixels.push_back(static_cast<int16_t>(std::lround(volume.At(x, y, z))));
      }
    }
    slice.intercept = 0;
    slice.codec = codec;
    if (z > 0) out += kDicomSliceSeparator;
    out += testing::DicomSliceFile(slice);
  }
  return out;
}

std::string DicomMultiFrameInput(const Volume& volume, bool grid_offsets) {
  testing::DicomMultiFrame image;
  image.columns = volume.dims[0];
  image.rows = volume.dims[1];
  image.spacing = {volume.spacing[0], volume.spacing[1]};
  image.grid_offsets = grid_offsets;
  for (int z = 0; z < volume.dims[2]; ++z) {
    image.positions.push_back({0, 0, z * volume.spacing[2]});
    image.rescale.push_back({1, 0});
    for (int y = 0; y < volume.dims[1]; ++y) {
      for (int x = 0; x < volume.dims[0]; ++x) {
        image.pixels.push_back(static_cast<int16_t>(std::lround(volume.At(x, y, z))));
      }
    }
  }
  return absl::StrCat(kDicomSeriesMagic, testing::DicomMultiFrameFile(image), kDicomSliceSeparator,
                      "a note beside the image");
}

}  // namespace transtick::fuzz
