#include "datasets.h"

#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "balancer.h"
#include "clock.h"
#include "convert.h"
#include "transtick/image_io.h"
#include "transtick/partition.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

namespace fs = std::filesystem;
}  // namespace

absl::StatusOr<JobPlan> Datasets::Plan(const v1::Job& job) const {
  if (job.datasets_size() == 0) return absl::InvalidArgumentError("job: no datasets");
  if (job.balance_grid() < 0 || job.balance_grid() > 256) {
    return absl::InvalidArgumentError("job: balance_grid must be in [0, 256]");
  }
  JobPlan plan;
  if (auto r = ToBalanceRule(job.balance_rule()); !r.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("job: ", r.status().message()));
  } else {
    plan.rule = *r;
  }
  int views = 0;
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(data_dir_, ec);
  for (int d = 0; d < job.datasets_size(); ++d) {
    const v1::Dataset& ds = job.datasets(d);
    DatasetPlan& dp = plan.datasets.emplace_back();
    const std::string where = absl::StrCat("datasets[", d, "]");
    if (ds.volume().empty()) return absl::InvalidArgumentError(where + ": no volume given");
    fs::path rel(ds.volume());
    if (rel.is_absolute()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": volume '", ds.volume(),
                                                     "' must be relative to the data directory"));
    }
    fs::path full = fs::weakly_canonical(root / rel, ec);
    auto mismatch = std::mismatch(root.begin(), root.end(), full.begin(), full.end());
    if (ec || mismatch.first != root.end()) {
      return absl::PermissionDeniedError(
          absl::StrCat(where, ": volume '", ds.volume(), "' lies outside the data directory"));
    }
    if (!fs::is_regular_file(full, ec)) {
      return absl::NotFoundError(
          absl::StrCat(where, ": volume '", ds.volume(), "' not found in the data directory"));
    }
    if (!ds.materials_file().empty() || !ds.transfer_file().empty()) {
      return absl::InvalidArgumentError(
          where + ": materials_file and transfer_file are read by the client; send them inline");
    }
    if (ds.has_materials()) {
      auto c = ToClassification(ds.materials());
      if (!c.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", c.status().message()));
      }
      dp.classification = *std::move(c);
    } else if (ds.has_transfer()) {
      auto t = ToTransferFunction(ds.transfer());
      if (!t.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", t.status().message()));
      }
      dp.classification = *std::move(t);
    } else {
      return absl::InvalidArgumentError(where + ": needs materials or a transfer function");
    }
    if (ds.has_raw()) {
      if (ds.raw().dims_size() != 3) {
        return absl::InvalidArgumentError(where + ": raw.dims needs 3 sizes");
      }
      auto t = ParseScalarType(ds.raw().type());
      if (!t.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": raw: ", t.status().message()));
      }
      RawSpec& spec = dp.raw.emplace();
      for (int a = 0; a < 3; ++a) spec.dims[a] = ds.raw().dims(a);
      spec.type = *t;
      spec.byte_order = ds.raw().big_endian() ? ByteOrder::kBig : ByteOrder::kLittle;
      for (int a = 0; a < 3 && a < ds.raw().spacing_size(); ++a)
        spec.spacing[a] = ds.raw().spacing(a);
      spec.header_bytes = ds.raw().header_bytes();
    }
    if (ds.views_size() == 0) return absl::InvalidArgumentError(where + ": no views");
    for (int v = 0; v < ds.views_size(); ++v) {
      const v1::View& view = ds.views(v);
      const std::string vw = absl::StrCat(where, ".views[", v, "]");
      auto request = ToFrameRequest(view);
      if (!request.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(vw, ": ", request.status().message()));
      }
      dp.views.push_back(*std::move(request));
      auto mode = EffectiveBalance(job, view);
      if (!mode.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(vw, ": ", mode.status().message()));
      }
      dp.balance.push_back(*mode);
      if (!view.output().empty() && !IsSupportedImagePath(view.output())) {
        return absl::InvalidArgumentError(absl::StrCat(vw, ": output '", view.output(),
                                                       "' is not one of ", SupportedImageList()));
      }
      ++views;
    }
  }
  if (views > 10000) return absl::InvalidArgumentError("job: more than 10000 views");
  return plan;
}

absl::StatusOr<std::shared_ptr<LoadedDataset>> Datasets::Load(const v1::Dataset& ds,
                                                               const DatasetPlan& plan) {
  const fs::path path = fs::path(data_dir_) / ds.volume();
  struct stat st {};
  if (stat(path.c_str(), &st) != 0) {
    return absl::NotFoundError(absl::StrCat(ds.volume(), ": cannot open"));
  }
  v1::Dataset identity = ds;
  identity.clear_views();
  std::string key_text = absl::StrCat(ds.volume(), "|", st.st_size, "|", st.st_mtim.tv_sec, ".",
                                      st.st_mtim.tv_nsec, "|", identity.SerializeAsString());
  const std::string key = absl::StrFormat("%016x", std::hash<std::string>{}(key_text)) + "-" +
                          absl::StrFormat("%08x", static_cast<uint32_t>(key_text.size()));
  if (cache_ && cache_->key == key) return cache_;
  const auto t0 = Clock::now();
  ReadOptions ro;
  ro.max_bytes = max_volume_bytes_;
  absl::StatusOr<Volume> volume;
  if (plan.raw) {
    volume = ReadRaw(path.string(), *plan.raw, ro);
  } else {
    volume = ReadVolume(path.string(), ro);
  }
  if (!volume.ok()) return volume.status();
  auto data = std::make_shared<LoadedDataset>();
  data->key = key;
  data->spec = identity;
  absl::StatusOr<Scene> scene;
  if (const auto* c = std::get_if<Classification>(&plan.classification)) {
    data->mode = RenderMode::kSurfaces;
    scene = Scene::ForSurfaces(*volume, *c);
  } else {
    data->mode = RenderMode::kDvr;
    scene = Scene::ForDvr(*volume, std::get<TransferFunction>(plan.classification));
  }
  if (!scene.ok())
    return absl::Status(scene.status().code(),
                        absl::StrCat(ds.volume(), ": ", scene.status().message()));
  data->scene = *std::move(scene);
  data->load_ms = MsSince(t0);
  spdlog::info("dataset {} ({}): {}x{}x{}, {} sticks, prepared in {:.0f} ms", ds.volume(),
               RenderModeName(data->mode), volume->dims[0], volume->dims[1], volume->dims[2],
               data->scene.sticks().StickCount(), data->load_ms);
  cache_ = data;
  return data;
}

}  // namespace transtick
