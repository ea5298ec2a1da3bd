// libFuzzer entry for the volume readers: the input becomes a file that each
// reader parses (NRRD, NIfTI-1, .den, MetaImage, .vti), or, when it starts
// with kDicomSeriesMagic, a directory of DICOM slices (the rest of the input
// cut at kDicomSliceSeparator, at most 8 files) that the DICOM series reader
// (GDCM) reads. Every input must give a volume or a status; a crash, an
// out-of-bounds access (under ASan), undefined behaviour (under UBSan) or a
// large allocation is a bug. A small volume that reads is then rendered as
// `transtick render` would render it, in both modes: classified, cut into
// slabs and a few pixels traced on a ring (fuzz_ring.h checks the rules on
// the way), so that hostile values and spacings reach the tracer.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "fuzz_ring.h"
#include "fuzz_volumes.h"
#include "transtick/check.h"
#include "transtick/framebuffer.h"
#include "transtick/partition.h"
#include "transtick/volume_io.h"

namespace transtick::fuzz {
namespace {

// One scratch file per process, reused for every input.
const std::string& ScratchPath() {
  static const std::string* path = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp != nullptr ? tmp : "/tmp") + "/volume_fuzzer_XXXXXX";
    int fd = mkstemp(pattern.data());
    if (fd < 0) std::abort();
    close(fd);
    return new std::string(pattern);
  }();
  return *path;
}

// A directory beside it for DICOM series.
const std::string& ScratchDir() {
  static const std::string* path = [] {
    std::string dir = ScratchPath() + ".series";
    if (mkdir(dir.c_str(), 0700) != 0) std::abort();
    return new std::string(dir);
  }();
  return *path;
}

constexpr int kMaxSlices = 8;

void RemoveScratch() {
  for (int i = 0; i < kMaxSlices; ++i) unlink((ScratchDir() + "/s" + std::to_string(i)).c_str());
  rmdir(ScratchDir().c_str());
  unlink(ScratchPath().c_str());
}

void WriteFile(const std::string& path, const char* data, size_t size) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, file) != size) std::abort();
  std::fclose(file);
}

// Volumes larger than this are read but not rendered (inputs stay fast).
constexpr size_t kMaxRenderedVoxels = 32 * 32 * 32;

void Render(const Volume& volume, const absl::StatusOr<Scene>& scene) {
  if (!scene.ok()) {
    TRANSTICK_CHECK(!scene.status().message().empty());
    return;
  }
  CameraSpec spec;
  spec.azimuth_deg = 30;
  spec.elevation_deg = 20;
  spec.width = spec.height = 6;
  const auto& d = volume.dims;
  const auto& sp = volume.spacing;
  auto camera = Camera::Create(spec, Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  if (!camera.ok()) return;
  RenderSettings settings;
  if (absl::Status s =
          CheckRenderSettings(settings, scene->mode(), d, sp, int64_t{spec.width} * spec.height);
      !s.ok()) {
    return;
  }
  FuzzRing ring(*scene, UniformCuts(d[1], std::min(2, d[1])), *camera, settings);
  std::vector<Deposit> deposits;
  for (int row = 0; row < spec.height; ++row) {
    for (int col = 0; col < spec.width; ++col) ring.RunPixel(col, row, &deposits);
  }
  // The whole image, as the display completes it.
  Framebuffer fb(spec.width, spec.height);
  for (const Deposit& deposit : deposits) (void)fb.Add(deposit);
  TRANSTICK_CHECK(fb.Complete());
}

// Surfaces with two materials across the volume's range, and dvr with a
// ramp over it.
void RenderBothModes(const Volume& volume) {
  if (volume.VoxelCount() > kMaxRenderedVoxels) return;
  auto [lo, hi] = volume.Range();
  if (!(lo < hi)) hi = lo + 1;
  const float mid = lo + (hi - lo) / 2;
  Classification c;
  c.materials = {{.name = "low", .min = lo, .max = mid, .opacity = 0.4f},
                 {.name = "high", .min = mid, .max = hi, .opacity = 1.0f}};
  if (c.Validate().ok()) Render(volume, Scene::ForSurfaces(volume, c));
  TransferFunction tf;
  tf.points = {{lo, {0, 0, 0, 0}}, {hi, {1, 0.8f, 0.6f, 0.7f}}};
  if (tf.Validate().ok()) Render(volume, Scene::ForDvr(volume, tf));
}

void Check(const absl::StatusOr<Volume>& volume) {
  if (!volume.ok()) {
    TRANSTICK_CHECK(!volume.status().message().empty());
    return;
  }
  TRANSTICK_CHECK_EQ(volume->values.size(), volume->VoxelCount());
  RenderBothModes(*volume);
}

}  // namespace
}  // namespace transtick::fuzz

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)transtick::fuzz::ScratchPath();
  (void)transtick::fuzz::ScratchDir();
  std::atexit(transtick::fuzz::RemoveScratch);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace tf = transtick::fuzz;
  // Small enough that a lying header cannot exhaust the fuzzer's memory.
  transtick::ReadOptions options;
  options.max_bytes = uint64_t{64} << 20;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::string_view magic = tf::kDicomSeriesMagic;
  if (input.substr(0, magic.size()) == magic) {
    std::string_view rest = input.substr(magic.size());
    const std::string_view separator = tf::kDicomSliceSeparator;
    int files = 0;
    while (files < tf::kMaxSlices) {
      const size_t cut = files + 1 < tf::kMaxSlices ? rest.find(separator) : std::string_view::npos;
      const std::string_view slice = rest.substr(0, cut);
      tf::WriteFile(tf::ScratchDir() + "/s" + std::to_string(files++), slice.data(), slice.size());
      if (cut == std::string_view::npos) break;
      rest = rest.substr(cut + separator.size());
    }
    for (int i = files; i < tf::kMaxSlices; ++i) {
      unlink((tf::ScratchDir() + "/s" + std::to_string(i)).c_str());
    }
    const absl::StatusOr<transtick::Volume> read =
        transtick::ReadDicomSeries(tf::ScratchDir(), options);
    tf::Check(read);
    // The root's listing reads the same files and judges every series as
    // the reader does: where the reader reads the directory, the listing
    // finds that one series and no problem with it.
    const auto listed = transtick::ListDicomSeries(tf::ScratchDir(), options);
    if (read.ok()) {
      TRANSTICK_CHECK(listed.ok());
      TRANSTICK_CHECK_EQ(listed->size(), 1u);
      TRANSTICK_CHECK((*listed)[0].problem.empty());
      TRANSTICK_CHECK_EQ((*listed)[0].frames, static_cast<size_t>(read->dims[2]));
    }
    return 0;
  }
  const std::string& path = tf::ScratchPath();
  tf::WriteFile(path, input.data(), input.size());
  tf::Check(transtick::ReadNrrd(path, options));
  tf::Check(transtick::ReadNifti(path, options));
  tf::Check(transtick::ReadDen(path, options));
  tf::Check(transtick::ReadMetaImage(path, options));
  tf::Check(transtick::ReadVti(path, options));
  return 0;
}
