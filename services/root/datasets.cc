#include "datasets.h"

#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "balancer.h"
#include "clock.h"
#include "confined_dir.h"
#include "convert.h"
#include "security.h"
#include "transtick/image_io.h"
#include "transtick/partition.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

// The client's path as a log or an error may show it: escaped, so that no
// character of it can forge a line.
std::string Shown(const std::string& path) { return Printable(path); }

// Opens (confined) what `relative` names: the file or directory, or for a
// path that names none, "DIR#UID" (one series of a DICOM directory,
// ParseSeriesPath), the directory; its descriptor, which the caller closes.
absl::StatusOr<int> OpenVolume(const ConfinedDir& dir, const std::string& relative) {
  auto fd = dir.OpenFile(relative);
  if (fd.ok() || fd.status().code() != absl::StatusCode::kNotFound) return fd;
  std::optional<SeriesPath> sp = ParseSeriesPath(relative);
  if (!sp) return fd;
  auto series_dir = dir.OpenFile(sp->dir);
  if (!series_dir.ok()) return fd;
  struct stat st {};
  if (::fstat(*series_dir, &st) == 0 && S_ISDIR(st.st_mode)) return series_dir;
  ::close(*series_dir);
  return fd;
}

// OK when `relative` opens (confined) as a regular file or a directory.
absl::Status CheckVolume(const ConfinedDir& dir, const std::string& relative) {
  auto fd = OpenVolume(dir, relative);
  if (!fd.ok()) return absl::Status(fd.status().code(), Shown(std::string(fd.status().message())));
  struct stat st {};
  // A directory is a DICOM series.
  const bool regular = ::fstat(*fd, &st) == 0 && (S_ISREG(st.st_mode) || S_ISDIR(st.st_mode));
  ::close(*fd);
  if (!regular) {
    return absl::InvalidArgumentError(
        absl::StrCat("'", Shown(relative), "' is not a regular file or a directory"));
  }
  return absl::OkStatus();
}

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
  if (auto e = ToImageEncoding(job.image_encoding(), "job: image_encoding"); !e.ok()) {
    return e.status();
  }
  if (!job.rings().empty()) {
    auto rings = ParseRings(job.rings());
    if (!rings.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("job: ", rings.status().message()));
    }
    plan.rings = *rings;
  }
  int views = 0;
  auto dir = ConfinedDir::Open(data_dir_);
  if (!dir.ok()) return absl::UnavailableError("the root's data directory cannot be opened");
  for (int d = 0; d < job.datasets_size(); ++d) {
    const v1::Dataset& ds = job.datasets(d);
    DatasetPlan& dp = plan.datasets.emplace_back();
    const std::string where = absl::StrCat("datasets[", d, "]");
    if (ds.volume().empty()) return absl::InvalidArgumentError(where + ": no volume given");
    // A check for an early, clear error. The file is opened again, just as
    // confined, when the job runs: what the name means may change between.
    if (absl::Status s = CheckVolume(**dir, ds.volume()); !s.ok()) {
      return absl::Status(s.code(), absl::StrCat(where, ": volume ", s.message()));
    }
    if (!ds.materials_file().empty() || !ds.transfer_file().empty()) {
      return absl::InvalidArgumentError(
          where + ": materials_file and transfer_file are read by the client; send them inline");
    }
    // A preset is checked here with a provisional range; Load resolves it
    // against the volume's.
    auto resolved = ResolvePreset(ds, {0.0f, 1.0f});
    if (!resolved.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": ", resolved.status().message()));
    }
    dp.preset = ds.has_preset();
    if (resolved->has_materials()) {
      auto c = ToClassification(resolved->materials());
      if (!c.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", c.status().message()));
      }
      dp.classification = *std::move(c);
    } else if (resolved->has_transfer()) {
      auto t = ToTransferFunction(resolved->transfer());
      if (!t.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", t.status().message()));
      }
      dp.classification = *std::move(t);
    } else {
      return absl::InvalidArgumentError(where + ": needs materials, a transfer function or a preset");
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
  // Every file the reader opens (the volume, a detached data file) is
  // opened beneath the data directory, and errors name paths relative to it.
  auto dir = ConfinedDir::Open(data_dir_);
  if (!dir.ok()) return absl::UnavailableError("the root's data directory cannot be opened");
  struct stat st {};
  {
    auto fd = OpenVolume(**dir, ds.volume());
    if (!fd.ok()) return fd.status();
    const int r = ::fstat(*fd, &st);
    ::close(*fd);
    if (r != 0) return absl::NotFoundError(absl::StrCat(Shown(ds.volume()), ": cannot stat"));
  }
  v1::Dataset identity = ds;
  identity.clear_views();
  std::string key_text = absl::StrCat(ds.volume(), "|", st.st_size, "|", st.st_mtim.tv_sec, ".",
                                      st.st_mtim.tv_nsec, "|", identity.SerializeAsString());
  const std::string key = absl::StrFormat("%016x", std::hash<std::string>{}(key_text)) + "-" +
                          absl::StrFormat("%08x", static_cast<uint32_t>(key_text.size()));
  absl::MutexLock lock(&mu_);
  if (cache_ && cache_->key == key) return cache_;
  const auto t0 = Clock::now();
  ReadOptions ro;
  ro.max_bytes = max_volume_bytes_;
  ro.open = [dir = *dir](const std::string& path) { return dir->OpenFile(path); };
  ro.list = [dir = *dir](const std::string& path) { return dir->ListDir(path); };
  absl::StatusOr<Volume> volume;
  if (plan.raw) {
    volume = ReadRaw(ds.volume(), *plan.raw, ro);
  } else {
    volume = ReadVolume(ds.volume(), ro);
  }
  if (!volume.ok()) return volume.status();
  auto data = std::make_shared<LoadedDataset>();
  data->key = key;
  data->spec = identity;
  std::variant<Classification, TransferFunction> classification = plan.classification;
  if (plan.preset) {
    // The workers get the preset's materials or transfer function inline,
    // for this volume's range.
    auto resolved = ResolvePreset(identity, volume->Range());
    if (!resolved.ok()) return resolved.status();
    data->spec = *std::move(resolved);
    if (data->spec.has_materials()) {
      auto c = ToClassification(data->spec.materials());
      if (!c.ok()) return c.status();
      classification = *std::move(c);
    } else {
      auto t = ToTransferFunction(data->spec.transfer());
      if (!t.ok()) return t.status();
      classification = *std::move(t);
    }
  }
  // What the user is told of the values comes from the volume, before the
  // scene takes its samples (they are not copied: SceneUse::kCut keeps them
  // as the scalars it sends).
  data->range = volume->Range();
  data->histogram = Histogram(volume->values, data->range, LoadedDataset::kHistogramBins);
  data->coding = NarrowestCoding(volume->values.data(), volume->values.size());
  absl::StatusOr<Scene> scene;
  if (const auto* c = std::get_if<Classification>(&classification)) {
    data->mode = RenderMode::kSurfaces;
    data->warnings = UnseenMaterials(*c, *volume);
    // The root only cuts it into slabs (SceneUse::kCut).
    scene = Scene::ForSurfaces(std::move(*volume), *c, SceneUse::kCut);
  } else {
    data->mode = RenderMode::kDvr;
    const auto& transfer = std::get<TransferFunction>(classification);
    data->warnings = UnseenTransfer(transfer, *volume);
    scene = Scene::ForDvr(std::move(*volume), transfer, SceneUse::kCut);
  }
  // What the reader passed over or chose (a DICOM directory's other files
  // and series) comes first: the user sees which data was rendered.
  data->warnings.insert(data->warnings.begin(), volume->notes.begin(), volume->notes.end());
  for (const std::string& w : data->warnings) spdlog::info("{}: {}", Shown(ds.volume()), w);
  if (!scene.ok())
    return absl::Status(scene.status().code(),
                        absl::StrCat(Shown(ds.volume()), ": ", scene.status().message()));
  data->scene = *std::move(scene);
  data->direction = volume->direction;
  data->load_ms = MsSince(t0);
  spdlog::info(
      "dataset {} ({}): {}x{}x{}, {} sticks, scalars sent in {} bytes or fewer, prepared "
      "in {:.0f} ms",
      Shown(ds.volume()), RenderModeName(data->mode), volume->dims[0], volume->dims[1],
      volume->dims[2], data->scene.sticks().StickCount(), ScalarsCodingBytes(data->coding),
      data->load_ms);
  cache_ = data;
  return data;
}

}  // namespace transtick
