// Datasets on the root: validating a job's datasets against the data
// directory, loading a volume, classifying it and encoding its sticks, and
// keeping the last one loaded for the next job. Not thread-safe: the runner
// thread alone uses a Datasets (Plan is const and may run anywhere).
#ifndef TRANSTICK_SERVICES_ROOT_DATASETS_H_
#define TRANSTICK_SERVICES_ROOT_DATASETS_H_

#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"
#include "cluster_model.h"
#include "transtick/classification.h"
#include "transtick/partition.h"
#include "transtick/render.h"
#include "transtick/scalar_codec.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {

// What balancing remembers of a dataset between frames (balancer.h).
// What the frames of one view measured on the same cuts.
struct ViewCosts {
  std::vector<std::vector<double>> cpu_ms;  // summed tracer CPU, per ring and worker
  double frame_ms = 0;                      // summed frame time
  int frames = 0;
};

struct BalanceMemory {
  // The ring members the cuts below belong to (Layout::Members).
  std::string members;
  // Cuts the next frame starts from: the last frame's, or their re-cut from
  // its costs ("previous-frame").
  std::vector<std::vector<int>> next_cuts;
  // "test-rays" cuts by view (ViewKey), reused without a new prerender.
  std::map<std::string, std::vector<std::vector<int>>> view_cuts;
  // "test-rays": each view's work profile from its prerender, per ring and
  // plane (how a slab's measured cost spreads over its planes), and what
  // its frames measured since its cuts were last set (docs/balancing.md,
  // "Refined by measured frames").
  std::map<std::string, std::vector<std::vector<double>>> view_profiles;
  std::map<std::string, ViewCosts> view_costs;
  // The views above, oldest first (at most kMaxBalancedViews, balancer.h).
  std::deque<std::string> view_order;
  // "previous-frame": per ring and plane, how much more or less its work
  // has cost than the work profile counts (docs/balancing.md).
  std::vector<std::vector<double>> plane_scale;
  // What moving cuts between frames took last ("previous-frame": the
  // slab transfers of a layout whose workers fetched planes), in ms; < 0
  // until measured.
  double recut_ms = -1;
};

// A job converted from the API once, when it is accepted (Datasets::Plan),
// and kept with it: what the runner needs in core types.
struct DatasetPlan {
  std::optional<RawSpec> raw;  // a headerless raw file's layout
  // A preset's is provisional: Load resolves it against the volume's range.
  std::variant<Classification, TransferFunction> classification;
  bool preset = false;
  std::vector<FrameRequest> views;
  std::vector<v1::BalanceMode> balance;  // by view: its own or else its job's
};
struct JobPlan {
  std::vector<DatasetPlan> datasets;
  BalanceRule rule = BalanceRule::kCost;
  std::optional<int> rings;  // the job's own (kAutoRings: auto); none: the root's
};

// A dataset ready to be cut into slabs.
struct LoadedDataset {
  std::string key;   // content: file identity + classification
  RenderMode mode = RenderMode::kSurfaces;
  v1::Dataset spec;  // without its views
  Scene scene;
  // The volume's orientation (orientation.h): views go to the workers mapped
  // into its frame (ToVolumeFrame).
  Direction direction = kIdentityDirection;
  double load_ms = 0;
  // Frames of the dataset may overlap (pipelined frames, sessions): one
  // plans its layout (rings, balancing, slabs) or learns from its result at
  // a time.
  absl::Mutex mu;
  BalanceMemory balance ABSL_GUARDED_BY(mu);
  // What the last frame on the cluster cost, for the model (--rings auto),
  // and its pixels; 0 pixels: none measured yet.
  FrameCosts costs ABSL_GUARDED_BY(mu);
  double costs_pixels ABSL_GUARDED_BY(mu) = 0;
  // Materials or a transfer function that show nothing of the volume.
  std::vector<std::string> warnings;
  // The volume's smallest and largest finite value, and kHistogramBins
  // counts of equal width between them.
  static constexpr int kHistogramBins = 64;
  std::array<float, 2> range = {0, 0};
  std::vector<uint64_t> histogram;
  // The narrowest coding that gives back every sample: the widest in which
  // a piece of its slabs' scalars travels (docs/formats.md, "Slab scalars").
  ScalarsCoding coding = ScalarsCoding::kF32;
};

class Datasets {
 public:
  Datasets(std::string data_dir, uint64_t max_volume_bytes)
      : data_dir_(std::move(data_dir)), max_volume_bytes_(max_volume_bytes) {}

  // Checks a job against the data directory and its own consistency, and
  // converts it: relative volume paths that stay inside the data directory
  // and exist, materials or a transfer function that convert, views that
  // convert, balance modes, outputs. Errors name the dataset and view.
  absl::StatusOr<JobPlan> Plan(const v1::Job& job) const;

  // Dataset `dataset` of `plan`'s job, loaded and classified, or the
  // cached one when the file and its classification are unchanged.
  // Thread-safe: loads run one at a time.
  absl::StatusOr<std::shared_ptr<LoadedDataset>> Load(const v1::Dataset& dataset,
                                                      const DatasetPlan& plan);

 private:
  const std::string data_dir_;
  const uint64_t max_volume_bytes_;
  absl::Mutex mu_;
  std::shared_ptr<LoadedDataset> cache_ ABSL_GUARDED_BY(mu_);
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_DATASETS_H_
