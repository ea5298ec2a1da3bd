// libFuzzer entry for job files: the input is a job file that `transtick
// submit` reads (LoadJobFile: protobuf JSON, with materials_file and
// transfer_file read beside it). A job that loads goes through what the root
// does with a submitted job: Datasets::Plan against a data directory of
// small volume files, then, for a job it accepts, what the runner and a
// worker do before a frame runs (the dataset loaded and classified, the
// balancer, CheckRenderSettings, the camera) and 25 pixels of each view
// traced on a ring of slabs (fuzz_ring.h checks the rules on the way).
// Every input must give a job or a status with a message; a crash, an
// out-of-bounds access, undefined behaviour or a large allocation is a bug.
#include <spdlog/spdlog.h>
#include <stdlib.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "balancer.h"
#include "client.h"
#include "convert.h"
#include "datasets.h"
#include "fuzz_ring.h"
#include "fuzz_volumes.h"
#include "transtick/check.h"
#include "transtick/partition.h"
#include "transtick/synthetic.h"

namespace transtick::fuzz {
namespace {

namespace fs = std::filesystem;

// Small enough that a job naming a huge raw volume is refused at once.
constexpr uint64_t kMaxVolumeBytes = uint64_t{16} << 20;
// Work per input: the first datasets and views.
constexpr int kMaxDatasets = 3;
constexpr int kMaxViews = 4;

void Write(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) std::abort();
}

// A scratch directory per process: job/ holds the job file and the example
// materials files beside it, data/ the root's data directory, whose volumes
// the seeds (tests/fuzz/corpus/job and examples/) name.
struct Scratch {
  fs::path base, job_file, data_dir;
};

const Scratch& GetScratch() {
  static const Scratch* scratch = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp != nullptr ? tmp : "/tmp") + "/job_fuzzer_XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) std::abort();
    auto* s =
        new Scratch{pattern, fs::path(pattern) / "job" / "job.json", fs::path(pattern) / "data"};
    fs::create_directories(s->job_file.parent_path());
    fs::create_directories(s->data_dir);
    for (const auto& entry : fs::directory_iterator(fs::path(TRANSTICK_SOURCE_DIR) / "examples")) {
      if (entry.path().extension() == ".json" &&
          entry.path().filename().string().find("_job") == std::string::npos) {
        fs::copy_file(entry.path(), s->job_file.parent_path() / entry.path().filename());
      }
    }
    // Values across the example materials' intervals (CT numbers for
    // cthead, 8-bit MRI for brainsmall).
    Volume ct = MakeNoisyPhantom({16, 14, 12}, 1);
    for (float& v : ct.values) v *= 30;
    ct.spacing = {1, 1, 2};
    Write(s->data_dir / "cthead.nrrd", NrrdFile(ct, ScalarType::kInt16, ByteOrder::kBig, false));
    Volume mri = MakeNoisyPhantom({12, 12, 10}, 2);
    for (float& v : mri.values) v *= 2;
    Write(s->data_dir / "brainsmall.den", DenFile(mri, ByteOrder::kLittle));
    Write(s->data_dir / "head.nii.gz",
          NiftiFile(mri, ScalarType::kUint8, ByteOrder::kLittle, true));
    Write(s->data_dir / "vol.raw", RawSamples(ct, ScalarType::kInt16, ByteOrder::kLittle));
    return s;
  }();
  return *scratch;
}

void RemoveScratch() {
  std::error_code ec;
  fs::remove_all(GetScratch().base, ec);
}

// TRANSTICK_FUZZ_VERBOSE=1 prints how far each input got: to see why a
// seed stops where it does.
bool Verbose() {
  static const bool verbose = std::getenv("TRANSTICK_FUZZ_VERBOSE") != nullptr;
  return verbose;
}

// A status that explains itself.
void CheckExplains(const absl::Status& status) {
  TRANSTICK_CHECK(!status.ok());
  TRANSTICK_CHECK(!status.message().empty());
  if (Verbose()) std::fprintf(stderr, "job_fuzzer: %s\n", status.ToString().c_str());
}

// What the runner (RunView) and a worker (WorkerService::Prepare) do with a
// view before its frame runs, then a few of its pixels traced.
void RunView(const v1::Job& job, const JobPlan& plan, const v1::View& view,
             const FrameRequest& request, v1::BalanceMode mode, const LoadedDataset& data) {
  auto balancer = MakeBalancer(mode, plan.rule, job.balance_grid());
  TRANSTICK_CHECK(balancer != nullptr);
  (void)ViewKey(view);
  const Scene& scene = data.scene;
  const auto& d = scene.dims();
  const auto& sp = scene.spacing();
  const RenderSettings& settings = request.settings;
  if (absl::Status s = CheckRenderSettings(settings, scene.mode(), d, sp,
                                           int64_t{request.camera.width} * request.camera.height);
      !s.ok()) {
    CheckExplains(s);
    return;
  }
  // A worker converts the view it is sent: the same request.
  auto spec = ToCameraSpec(view);
  TRANSTICK_CHECK(spec.ok());  // planned
  TRANSTICK_CHECK_EQ(spec->width, request.camera.width);
  auto camera = Camera::Create(request.camera, Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  if (!camera.ok()) {
    CheckExplains(camera.status());
    return;
  }
  FuzzRing ring(scene, UniformCuts(d[1], std::min(3, d[1])), *camera, settings);
  // A 5x5 grid from corner to corner.
  const int w = camera->width(), h = camera->height();
  std::vector<Deposit> deposits;
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) ring.RunPixel((w - 1) * i / 4, (h - 1) * j / 4, &deposits);
  }
  if (Verbose()) {
    std::fprintf(stderr, "job_fuzzer: traced 25 pixels of a %dx%d view: %zu deposits\n", w, h,
                 deposits.size());
  }
}

void Run(const std::string& bytes) {
  const Scratch& scratch = GetScratch();
  Write(scratch.job_file, bytes);
  auto job = LoadJobFile(scratch.job_file.string());
  if (!job.ok()) {
    CheckExplains(job.status());
    return;
  }
  Datasets datasets(scratch.data_dir.string(), kMaxVolumeBytes);
  auto plan = datasets.Plan(*job);
  if (!plan.ok()) {
    CheckExplains(plan.status());
    return;
  }
  TRANSTICK_CHECK_EQ(plan->datasets.size(), static_cast<size_t>(job->datasets_size()));
  for (int i = 0; i < std::min(job->datasets_size(), kMaxDatasets); ++i) {
    const v1::Dataset& ds = job->datasets(i);
    const DatasetPlan& dp = plan->datasets[i];
    TRANSTICK_CHECK_EQ(dp.views.size(), static_cast<size_t>(ds.views_size()));
    auto data = datasets.Load(ds, dp);
    if (!data.ok()) {
      CheckExplains(data.status());
      continue;
    }
    for (int v = 0; v < std::min(ds.views_size(), kMaxViews); ++v) {
      RunView(*job, *plan, ds.views(v), dp.views[v], dp.balance[v], **data);
    }
  }
}

}  // namespace
}  // namespace transtick::fuzz

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::warn);  // no line per dataset loaded
  (void)transtick::fuzz::GetScratch();
  std::atexit(transtick::fuzz::RemoveScratch);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  transtick::fuzz::Run(std::string(reinterpret_cast<const char*>(data), size));
  return 0;
}
