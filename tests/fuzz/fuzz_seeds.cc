// Writes the generated seed corpora of the fuzzers (scripts/fuzz.sh runs it;
// the job seeds are text files in tests/fuzz/corpus/job and examples/):
//   DIR/volume/  small valid NRRD (raw, gzip, bzip2, ascii), NIfTI-1 (.nii
//                and .nii.gz), .den, MetaImage (raw and zlib) and .vti (raw
//                and zlib blocks, appended raw or base64, inline ascii)
//                files, several sample types and both byte orders,
//                and a DICOM series in the volume fuzzer's form;
//   DIR/batch/   ray batches as neighbours send them (fresh primaries, rays
//                handed on mid-flight, shadow rays) and deposit batches as
//                workers send them, each for the batch fuzzer's
//                configurations (batch_setup.h), through the codec's Append
//                functions;
//   DIR/sticks/  brick maps of a sphere and a shell at the sticks fuzzer's
//                dims, for surfaces and for dvr, and the field summary of
//                such a volume (the sticks fuzzer reads its whole input as
//                a brick map and as a field summary too).
// Usage: fuzz_seeds DIR
#include <bzlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "batch_setup.h"
#include "fuzz_volumes.h"
#include "transtick/ray_codec.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick::fuzz {
namespace {

namespace fs = std::filesystem;

// A .vti of raw appended data with its arrays in base64 instead (one run),
// as VTK's writers make by default.
std::string VtiAsBase64(std::string vti) {
  static constexpr char kDigits[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const std::string open = "<AppendedData encoding=\"raw\">\n_";
  const size_t begin = vti.find(open) + open.size();
  const size_t end = vti.rfind("\n</AppendedData>");
  const std::string bytes = vti.substr(begin, end - begin);
  std::string text;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t bits = 0;
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    for (size_t k = 0; k < 3; ++k) {
      bits = bits << 8 | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    }
    for (size_t k = 0; k < 4; ++k) text += k <= n ? kDigits[(bits >> (18 - 6 * k)) & 63] : '=';
  }
  vti.replace(begin, end - begin, text);
  vti.replace(vti.find("encoding=\"raw\""), 14, "encoding=\"base64\"");
  return vti;
}

// The same volume's samples inline as ASCII numbers.
std::string VtiAsAscii(std::string vti, const Volume& v) {
  std::string numbers;
  for (float x : v.values) absl::StrAppend(&numbers, x, " ");
  const std::string tag = "format=\"appended\" offset=\"0\"/>";
  vti.replace(vti.find(tag), tag.size(), "format=\"ascii\">" + numbers + "</DataArray>");
  return vti;
}

bool Write(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return static_cast<bool>(out);
}

// Writes a volume file and reads it back: a seed that does not read would
// start the fuzzer off in the readers' error paths only.
bool WriteVolume(const fs::path& path, const std::string& bytes, const Volume& expected) {
  if (!Write(path, bytes)) return false;
  auto volume = ReadVolume(path.string());
  if (!volume.ok() || volume->dims != expected.dims) {
    std::fprintf(stderr, "fuzz_seeds: %s does not read back: %s\n", path.c_str(),
                 std::string(volume.status().message()).c_str());
    return false;
  }
  return true;
}

bool WriteVolumes(const fs::path& dir) {
  Volume v = MakeNoisyPhantom({6, 5, 4}, 7);
  v.spacing = {0.5, 1, 2.5};
  bool ok = true;
  int n = 0;
  for (ScalarType type : {ScalarType::kUint8, ScalarType::kInt16, ScalarType::kFloat32}) {
    for (ByteOrder order : {ByteOrder::kLittle, ByteOrder::kBig}) {
      for (bool gzip : {false, true}) {
        ok &=
            WriteVolume(dir / absl::StrCat("nrrd-", n, ".nrrd"), NrrdFile(v, type, order, gzip), v);
        ok &= WriteVolume(dir / absl::StrCat("nifti-", n, gzip ? ".nii.gz" : ".nii"),
                          NiftiFile(v, type, order, gzip), v);
        ++n;
      }
    }
  }
  // Values a float file may hold: NaN, infinities, and a range wider than
  // a float (hi - lo overflows).
  Volume extreme = v;
  for (size_t i = 0; i < extreme.values.size(); i += 9) extreme.values[i] = 3e38f;
  for (size_t i = 4; i < extreme.values.size(); i += 13) extreme.values[i] = -3e38f;
  extreme.values[1] = NAN;
  extreme.values[2] = INFINITY;
  extreme.values[3] = -INFINITY;
  ok &= WriteVolume(dir / "extreme.nrrd",
                    NrrdFile(extreme, ScalarType::kFloat32, ByteOrder::kLittle, false), extreme);
  for (bool compressed : {false, true}) {
    for (ByteOrder order : {ByteOrder::kLittle, ByteOrder::kBig}) {
      const std::string tag = absl::StrCat(compressed ? "zlib" : "raw",
                                           order == ByteOrder::kBig ? "-big" : "");
      ok &= Write(dir / absl::StrCat("metaimage-", tag, ".mha"),
                  MetaImageFile(v, ScalarType::kInt16, order, compressed)) &&
            ReadVolume((dir / absl::StrCat("metaimage-", tag, ".mha")).string()).ok();
      const std::string vti = VtiFile(v, ScalarType::kUint16, order, compressed);
      ok &= Write(dir / absl::StrCat("vti-", tag, ".vti"), vti) &&
            ReadVolume((dir / absl::StrCat("vti-", tag, ".vti")).string()).ok();
      ok &= Write(dir / absl::StrCat("vti-base64-", tag, ".vti"), VtiAsBase64(vti)) &&
            ReadVolume((dir / absl::StrCat("vti-base64-", tag, ".vti")).string()).ok();
      if (!compressed) {
        ok &= Write(dir / absl::StrCat("vti-ascii-", tag, ".vti"), VtiAsAscii(vti, v)) &&
              ReadVolume((dir / absl::StrCat("vti-ascii-", tag, ".vti")).string()).ok();
      }
    }
  }
  // NRRD in its other two encodings: ASCII numbers and bzip2.
  {
    const std::string raw = NrrdFile(v, ScalarType::kFloat32, ByteOrder::kLittle, false);
    const size_t data = raw.find("\n\n") + 2;
    std::string numbers;
    for (float x : v.values) absl::StrAppend(&numbers, x, x == v.values.back() ? "\n" : " ");
    std::string ascii = raw.substr(0, data) + numbers;
    ascii.replace(ascii.find("encoding: raw"), 13, "encoding: ascii");
    ok &= WriteVolume(dir / "ascii.nrrd", ascii, v);
    std::string bz(raw.size() + raw.size() / 100 + 600, '\0');
    unsigned int bz_size = static_cast<unsigned int>(bz.size());
    std::string samples = raw.substr(data);
    ok &= BZ2_bzBuffToBuffCompress(bz.data(), &bz_size, samples.data(),
                                   static_cast<unsigned int>(samples.size()), 9, 0, 0) == BZ_OK;
    bz.resize(bz_size);
    std::string bzip2 = raw.substr(0, data) + bz;
    bzip2.replace(bzip2.find("encoding: raw"), 13, "encoding: bzip2");
    ok &= WriteVolume(dir / "bzip2.nrrd", bzip2, v);
  }
  // The volume fuzzer makes a directory of this input's slices.
  ok &= Write(dir / "series.dicom", DicomSeriesInput(v));
  // Compressed: RLE (checked before GDCM decodes it), and JPEG codecs that
  // transtick-dicom-decode runs in a process of its own. (JPEG 2000 slices
  // must be larger than an input of the fuzzer: kLeastJpeg2000Bytes.)
  for (testing::DicomCodec codec : {testing::DicomCodec::kRle, testing::DicomCodec::kJpegLossless,
                                    testing::DicomCodec::kJpegLs}) {
    ok &= Write(dir / absl::StrCat("series_", testing::CodecName(codec), ".dicom"),
                DicomSeriesInput(v, codec));
  }
  ok &= Write(dir / "enhanced.dicom", DicomMultiFrameInput(v, false));
  ok &= Write(dir / "rtdose.dicom", DicomMultiFrameInput(v, true));
  ok &= WriteVolume(dir / "little.den", DenFile(v, ByteOrder::kLittle), v);
  ok &= WriteVolume(dir / "big.den", DenFile(v, ByteOrder::kBig), v);
  return ok;
}

std::string Batch(uint8_t header, const std::vector<RayDescriptor>& rays) {
  std::string out(1, static_cast<char>(header)), records;
  for (const RayDescriptor& r : rays) AppendRay(r, &records);
  PackRays(records, &out);  // as a worker sends them
  return out;
}

bool WriteBatches(const fs::path& dir) {
  bool ok = true;
  for (int c = 0; c < kBatchConfigs; ++c) {
    BatchConfig& config = BatchSetup::Get().config(c);
    FuzzRing& ring = *config.ring;
    const RingLayout& layout = ring.layout();
    const Camera& camera = config.camera;
    // Primary rays of a sparse grid of pixels; each traced once on the slab
    // that holds its entry, which leaves it mid-flight (when it left the
    // slab) and gives the shadow rays it spawned there.
    std::vector<RayDescriptor> fresh, handed_on, shadows;
    for (int row = 1; row < camera.height(); row += 4) {
      for (int col = 1; col < camera.width(); col += 4) {
        const uint32_t pixel = static_cast<uint32_t>(row * camera.width() + col);
        RayDescriptor ray;
        if (!ring.tracer(0).MakePrimary(camera.Generate(col, row), pixel, &ray)) continue;
        if (!ring.tracer(0).Validate(ray).ok()) {
          std::fprintf(stderr, "fuzz_seeds: configuration %d: a primary ray fails Validate\n", c);
          return false;
        }
        fresh.push_back(ray);
        const int slab = layout.SlabOf(ray.cell[1]);
        std::vector<RayDescriptor> spawned;
        Deposit deposit;
        TraceCounters counters;
        if (ring.tracer(slab).Trace(ray, spawned, deposit, counters) ==
            Tracer::Outcome::kLeftSlab) {
          handed_on.push_back(ray);
        }
        shadows.insert(shadows.end(), spawned.begin(), spawned.end());
      }
    }
    // At most 30 records a seed: the fuzzer's inputs stay under 4 KB.
    auto first = [](std::vector<RayDescriptor> v) {
      if (v.size() > 30) v.resize(30);
      return v;
    };
    const std::string name = absl::StrCat("config-", c);
    ok &= Write(dir / (name + "-fresh"), Batch(RayHeader(c, 0, false), first(fresh)));
    if (!handed_on.empty()) {
      ok &= Write(dir / (name + "-handed-on"), Batch(RayHeader(c, 1, false), first(handed_on)));
    }
    if (!shadows.empty()) {
      ok &= Write(dir / (name + "-shadows"), Batch(RayHeader(c, 2, false), first(shadows)));
    }
    ok &= Write(dir / (name + "-repair"),
                Batch(RayHeader(c, 3, true), first(handed_on.empty() ? fresh : handed_on)));
    // The deposits of the image's first rows, as the display receives them.
    std::vector<Deposit> deposits;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < camera.width(); ++col) ring.RunPixel(col, row, &deposits);
    }
    if (deposits.size() > 180) deposits.resize(180);
    std::string batch = {static_cast<char>(kDepositBatch), static_cast<char>(camera.width() - 1),
                         static_cast<char>(camera.height() - 1)};
    std::string records;
    for (const Deposit& d : deposits) AppendDeposit(d, &records);
    // And misses past them as a worker queues its background: miss runs.
    const uint32_t image = static_cast<uint32_t>(camera.width() * camera.height());
    const uint32_t run_from =
        std::min<uint32_t>(image - 1, 3u * static_cast<uint32_t>(camera.width()));
    AppendMissRun(run_from, std::min<uint32_t>(image - run_from, 50), 1, {0.1f, 0.2f, 0.3f},
                  &records);
    PackDeposits(records, &batch);
    ok &= Write(dir / (name + "-deposits"), batch);
  }
  return ok;
}

}  // namespace
}  // namespace transtick::fuzz

namespace transtick::fuzz {
namespace {

bool WriteBrickMaps(const std::filesystem::path& dir) {
  const std::array<int, 3> dims = {40, 70, 36};  // as sticks_fuzzer.cc
  std::vector<uint8_t> labels(static_cast<size_t>(dims[0]) * dims[1] * dims[2]);
  size_t i = 0;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x, ++i) {
        const double r = std::hypot(x - 20.0, y - 35.0, z - 18.0);
        labels[i] = r < 12 ? 1 : (r < 16 ? 2 : 0);
      }
  for (bool surfaces : {true, false}) {
    const std::vector<uint8_t> bytes = BrickMap::Build(labels, dims, surfaces).bytes();
    if (!Write(dir / (surfaces ? "bricks-surfaces" : "bricks-dvr"),
               std::string(bytes.begin(), bytes.end()))) {
      return false;
    }
  }
  // The field summary of a ball whose values fall off outward, with two
  // materials: 3 edges, 4 bands (kSummaryBands in sticks_fuzzer.cc).
  std::vector<float> values(labels.size());
  i = 0;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x, ++i) {
        values[i] = static_cast<float>(std::max(0.0, 100 - 5 * std::hypot(x - 20.0, y - 35.0, z - 18.0)));
      }
  Classification c;
  c.materials = {Material{.name = "shell", .min = 10, .max = 40},
                 Material{.name = "core", .min = 40, .max = 200}};
  const std::vector<uint8_t> summary = FieldSummary::Build(values, dims, Bands(c)).bytes();
  return Write(dir / "summary-ball", std::string(summary.begin(), summary.end()));
}

}  // namespace
}  // namespace transtick::fuzz

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seeds DIR\n");
    return 2;
  }
  const fs::path dir = argv[1];
  fs::create_directories(dir / "volume");
  fs::create_directories(dir / "batch");
  fs::create_directories(dir / "sticks");
  if (!transtick::fuzz::WriteVolumes(dir / "volume") ||
      !transtick::fuzz::WriteBatches(dir / "batch") ||
      !transtick::fuzz::WriteBrickMaps(dir / "sticks")) {
    std::fprintf(stderr, "fuzz_seeds: cannot write under %s\n", argv[1]);
    return 1;
  }
  return 0;
}
