// A real worker and a real display on 127.0.0.1, each its own gRPC server,
// that a test drives by RPC the way the root does (or the way a crashed or
// hostile root would). The worker holds a noisy phantom as one whole slab,
// classified for surfaces ("phantom") and for dvr ("phantom-dvr").
#ifndef TRANSTICK_TESTS_NODES_FIXTURE_H_
#define TRANSTICK_TESTS_NODES_FIXTURE_H_

#include <grpcpp/grpcpp.h>

#include <array>
#include <chrono>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "cluster.grpc.pb.h"
#include "daemon.h"
#include "display_service.h"
#include "gtest/gtest.h"
#include "transtick/ray.h"
#include "transtick/scene.h"
#include "worker_service.h"

namespace transtick::testing {

// Polls `done` every 10 ms until it holds (true) or `patience` has passed,
// not counting time the process did not run (a stalled machine).
bool Eventually(const std::function<bool()>& done,
                std::chrono::milliseconds patience = std::chrono::seconds(10));

class NodesTest : public ::testing::Test {
 protected:
  // Image size of Spec's frames.
  static constexpr int kSize = 48;

  // The nodes' options; a test overrides them to shorten the limits.
  virtual WorkerOptions worker_options() const;
  virtual DisplayOptions display_options() const { return {}; }

  void SetUp() override;
  void TearDown() override;

  // A frame of the whole surfaces slab, kSize x kSize, every row.
  v1::FrameSpec Spec(uint64_t frame_id) const;
  // BeginFrame at the display, of Spec's size.
  grpc::Status Begin(uint64_t frame_id, int width = kSize, int height = kSize);
  // PrepareFrame at the worker.
  grpc::Status PrepareOnly(const v1::FrameSpec& spec);
  // Begin, then PrepareOnly(Spec(frame_id)): what the root does.
  grpc::Status Prepare(uint64_t frame_id);
  grpc::Status Run(uint64_t frame_id);
  // AwaitFrame to the end; counts the image rows received in `rows`.
  grpc::Status Await(uint64_t frame_id, int* rows = nullptr);
  absl::StatusOr<v1::WorkerFrameStats> End(uint64_t frame_id, bool cancel = false);
  // Run, the whole image awaited, and End: a prepared frame rendered as the
  // root renders it (a failure is the test's).
  void RunToImage(uint64_t frame_id);
  // Evict at the worker.
  grpc::Status Evict(const std::string& key);

  // A primary ray of Spec's view through the image's centre (pixel 0), as
  // the worker's own tracer makes it: what a left neighbour might send.
  RayDescriptor CentreRay() const;

  // The whole volume of `scene` as one slab under `key`, sent as the root
  // sends it, with `summary` as its field summary (null: the scene's own),
  // in one message that `edit` (when given) changes before it goes.
  grpc::Status SendSlab(const Scene& scene, const std::string& key,
                        const std::string* summary = nullptr,
                        const std::function<void(v1::SlabChunk&)>& edit = {});

  const std::array<int, 3> dims_ = {40, 36, 44};
  Classification classification_;
  TransferFunction transfer_;
  std::unique_ptr<Scene> scene_;  // the surfaces scene
  std::unique_ptr<DisplayService> display_service_;
  std::unique_ptr<Server> display_;
  std::unique_ptr<WorkerService> worker_service_;
  std::unique_ptr<Server> worker_;
  std::string worker_address_, display_address_;
  std::unique_ptr<v1::Worker::Stub> worker_stub_;
  std::unique_ptr<v1::Display::Stub> display_stub_;

 private:
  // SendSlab, which must succeed.
  void LoadWholeSlab(const Scene& scene, const std::string& key);
};

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_NODES_FIXTURE_H_
