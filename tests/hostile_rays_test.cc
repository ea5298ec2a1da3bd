// Hostile ray records over a real stream: a real worker and a real display
// on 127.0.0.1, driven the way the root drives them, and a peer that sends
// the worker a batch of damaged rays on its ring stream. The worker must
// drop and count them, abort the frame at the display at once with a reason
// that says so, end the frame promptly, and keep serving.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

#include "cluster.grpc.pb.h"
#include "daemon.h"
#include "display_service.h"
#include "gtest/gtest.h"
#include "transtick/ray_codec.h"
#include "transtick/synthetic.h"
#include "transtick/tracer.h"
#include "worker_service.h"

namespace transtick {
namespace {

constexpr double kDenormal = 4.9406564584124654e-324;

class HostileRaysTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto display = Server::Start("127.0.0.1:0", {&display_service_});
    ASSERT_TRUE(display.ok()) << display.status();
    display_ = *std::move(display);
    worker_service_ = std::make_unique<WorkerService>(WorkerOptions{"w-test", "", 2});
    auto worker = Server::Start("127.0.0.1:0", {worker_service_.get()});
    ASSERT_TRUE(worker.ok()) << worker.status();
    worker_ = *std::move(worker);
    worker_address_ = absl::StrCat("127.0.0.1:", worker_->port());
    display_address_ = absl::StrCat("127.0.0.1:", display_->port());
    worker_service_->set_address(worker_address_);
    worker_stub_ = v1::Worker::NewStub(MakeChannel(worker_address_));
    display_stub_ = v1::Display::NewStub(MakeChannel(display_address_));

    Volume v = MakeNoisyPhantom(dims_, 5);
    classification_.materials = {{.name = "soft", .min = 20, .max = 45, .opacity = 0.3f},
                                 {.name = "hard", .min = 45, .max = 1000, .opacity = 1.0f}};
    auto scene = Scene::ForSurfaces(v, classification_);
    ASSERT_TRUE(scene.ok()) << scene.status();
    scene_ = std::make_unique<Scene>(*std::move(scene));
    LoadWholeSlab(*scene_, "phantom");
    transfer_.points = {{0, {0, 0, 0, 0}}, {60, {1, 0.8f, 0.5f, 0.3f}}};
    auto dvr = Scene::ForDvr(v, transfer_);
    ASSERT_TRUE(dvr.ok()) << dvr.status();
    LoadWholeSlab(*dvr, "phantom-dvr");
  }
  void TearDown() override {
    if (worker_service_) worker_service_->CancelAll();
    if (worker_) worker_->Shutdown(std::chrono::milliseconds(500));
    if (display_) display_->Shutdown(std::chrono::milliseconds(500));
  }

  // The whole volume as one slab, sent as the root sends it.
  void LoadWholeSlab(const Scene& scene, const std::string& key) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(30));
    v1::LoadReply reply;
    auto writer = worker_stub_->LoadSlab(&ctx, &reply);
    v1::SlabChunk chunk;
    v1::SlabHeader* h = chunk.mutable_header();
    h->set_dataset_key(key);
    const bool dvr = scene.mode() == RenderMode::kDvr;
    h->set_mode(dvr ? "dvr" : "surfaces");
    for (int a = 0; a < 3; ++a) h->add_dims(dims_[a]);
    for (int a = 0; a < 3; ++a) h->add_spacing(1);
    h->add_value_range(scene.value_range()[0]);
    h->add_value_range(scene.value_range()[1]);
    for (const TransferPoint& tp : dvr ? transfer_.points : std::vector<TransferPoint>{}) {
      v1::TransferPoint* p = h->mutable_transfer()->add_points();
      p->set_value(tp.value);
      for (float c : tp.rgba) p->add_rgba(c);
    }
    for (const Material& m : dvr ? std::vector<Material>{} : classification_.materials) {
      v1::Material* pm = h->mutable_materials()->add_materials();
      pm->set_name(m.name);
      pm->set_min(m.min);
      pm->set_max(m.max);
      for (float c : m.color) pm->add_color(c);
      pm->set_opacity(m.opacity);
    }
    h->set_y_begin(0);
    h->set_y_end(dims_[1]);
    const auto& bricks = scene.bricks().bytes();
    h->set_brick_map(std::string(bricks.begin(), bricks.end()));
    h->set_scalar_count(scene.scalars().size());
    for (std::string& b : scene.sticks().EncodeRows(0, dims_[1])) chunk.add_blocks(std::move(b));
    AppendFloats(scene.scalars().data(), scene.scalars().size(), chunk.mutable_scalars());
    ASSERT_TRUE(writer->Write(chunk));
    writer->WritesDone();
    grpc::Status s = writer->Finish();
    ASSERT_TRUE(s.ok()) << s.error_message();
  }

  v1::FrameSpec Spec(uint64_t frame_id) {
    v1::FrameSpec spec;
    spec.set_frame_id(frame_id);
    spec.set_dataset_key("phantom");
    v1::View* view = spec.mutable_view();
    view->set_azimuth(30);
    view->set_elevation(10);
    view->set_width(kSize);
    view->set_height(kSize);
    spec.add_cuts(0);
    spec.add_cuts(dims_[1]);
    spec.set_index(0);
    spec.set_display(display_address_);
    spec.set_row_begin(0);
    spec.set_row_end(kSize);
    spec.set_row_step(1);
    return spec;
  }

  grpc::Status Prepare(uint64_t frame_id) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    v1::DisplayFrame df;
    df.set_frame_id(frame_id);
    df.set_width(kSize);
    df.set_height(kSize);
    grpc::ClientContext dctx;
    dctx.set_deadline(Deadline(10));
    if (grpc::Status s = display_stub_->BeginFrame(&dctx, df, &ack); !s.ok()) return s;
    return worker_stub_->PrepareFrame(&ctx, Spec(frame_id), &ack);
  }

  static constexpr int kSize = 48;
  const std::array<int, 3> dims_ = {40, 36, 44};
  Classification classification_;
  TransferFunction transfer_;
  std::unique_ptr<Scene> scene_;
  DisplayService display_service_;
  std::unique_ptr<Server> display_;
  std::unique_ptr<WorkerService> worker_service_;
  std::unique_ptr<Server> worker_;
  std::string worker_address_, display_address_;
  std::unique_ptr<v1::Worker::Stub> worker_stub_;
  std::unique_ptr<v1::Display::Stub> display_stub_;
};

TEST_F(HostileRaysTest, DamagedRecordsAreDroppedCountedAndAbortTheFrame) {
  constexpr uint64_t kFrame = 7;
  ASSERT_TRUE(Prepare(kFrame).ok());

  // One good ray, as the worker's own tracer makes it, then damaged ones.
  CameraSpec cs;
  cs.width = cs.height = kSize;
  cs.azimuth_deg = 30;
  cs.elevation_deg = 10;
  auto camera = Camera::Create(cs, Vec3{40, 36, 44});
  ASSERT_TRUE(camera.ok());
  const Tracer tracer(*scene_, RenderSettings{}, *camera);
  RayDescriptor good;
  ASSERT_TRUE(tracer.MakePrimary(camera->Generate(kSize / 2, kSize / 2), 0, &good));
  std::vector<RayDescriptor> bad(5, good);
  bad[0].direction = {kDenormal, kDenormal, kDenormal};  // the ray that spun a tracer for ever
  bad[1].t = std::nan("");
  bad[2].cell = {1 << 20, 0, 0};
  bad[3].t_start = -1e300;
  bad[4].transmittance = 7;
  std::string records;
  AppendRay(good, &records);
  for (const RayDescriptor& r : bad) AppendRay(r, &records);

  // The stream a left neighbour opens: the first batch names the frame.
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  auto stream = worker_stub_->Rays(&ctx);
  v1::RayBatch first;
  first.set_frame_id(kFrame);
  ASSERT_TRUE(stream->Write(first));
  v1::RayBatch batch;
  batch.set_frame_id(kFrame);
  batch.set_rays(records);
  ASSERT_TRUE(stream->Write(batch));

  // The display hears of it from the worker at once, well before any
  // frame timeout, with a reason naming the dropped records.
  const auto t0 = std::chrono::steady_clock::now();
  {
    grpc::ClientContext actx;
    actx.set_deadline(Deadline(10));
    v1::FrameRef ref;
    ref.set_frame_id(kFrame);
    auto reader = display_stub_->AwaitFrame(&actx, ref);
    v1::FrameProgress p;
    while (reader->Read(&p)) {
    }
    grpc::Status s = reader->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED) << s.error_message();
    EXPECT_NE(s.error_message().find("dropped 5 invalid ray record(s) from its left neighbour"),
              std::string::npos)
        << s.error_message();
    EXPECT_NE(s.error_message().find("non-finite"), std::string::npos) << s.error_message();
  }
  const double abort_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(abort_ms, 5000);
  stream->WritesDone();

  // Tracing starts and the frame ends (cancelled, as the root does after an
  // abort) within a short deadline: no tracer is spinning.
  {
    grpc::ClientContext rctx;
    rctx.set_deadline(Deadline(10));
    v1::FrameRef ref;
    ref.set_frame_id(kFrame);
    v1::FrameAck ack;
    EXPECT_TRUE(worker_stub_->RunFrame(&rctx, ref, &ack).ok());
    grpc::ClientContext ectx;
    ectx.set_deadline(Deadline(5));
    ref.set_cancel(true);
    v1::WorkerFrameStats stats;
    grpc::Status s = worker_stub_->EndFrame(&ectx, ref, &stats);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(stats.rays_rejected(), 5u);
    EXPECT_EQ(stats.received_left(), 1u);  // the good one was kept
    EXPECT_EQ(stats.rays_truncated(), 0u);
  }
  stream->Finish();

  // The worker goes on serving: a whole frame of its own completes.
  constexpr uint64_t kNext = 8;
  ASSERT_TRUE(Prepare(kNext).ok());
  v1::FrameRef ref;
  ref.set_frame_id(kNext);
  {
    grpc::ClientContext rctx;
    rctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    ASSERT_TRUE(worker_stub_->RunFrame(&rctx, ref, &ack).ok());
  }
  grpc::ClientContext actx;
  actx.set_deadline(Deadline(30));
  auto reader = display_stub_->AwaitFrame(&actx, ref);
  v1::FrameProgress p;
  int rows = 0;
  while (reader->Read(&p)) {
    if (p.has_image()) rows += p.image().row_end() - p.image().row_begin();
  }
  EXPECT_TRUE(reader->Finish().ok());
  EXPECT_EQ(rows, kSize);
  grpc::ClientContext ectx;
  ectx.set_deadline(Deadline(5));
  v1::WorkerFrameStats stats;
  EXPECT_TRUE(worker_stub_->EndFrame(&ectx, ref, &stats).ok());
  EXPECT_EQ(stats.rays_rejected(), 0u);
}

// A dvr frame whose step would take unbounded samples is refused when it is
// prepared, with the reason; a step at the bound is accepted, and so is any
// step for surfaces, which take no samples.
TEST_F(HostileRaysTest, AbsurdStepIsRefusedAtPrepare) {
  auto prepare = [&](uint64_t id, const std::string& key, double step) {
    v1::FrameSpec spec = Spec(id);
    spec.set_dataset_key(key);
    spec.mutable_view()->set_step(step);
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    return worker_stub_->PrepareFrame(&ctx, spec, &ack);
  };
  grpc::Status s = prepare(20, "phantom-dvr", 1e-9);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("finer than the finest allowed"), std::string::npos)
      << s.error_message();
  EXPECT_TRUE(prepare(21, "phantom-dvr", 1.0 / kMaxSamplesPerVoxel).ok());
  EXPECT_TRUE(prepare(22, "phantom", 1e-9).ok());
}

// Cuts that do not cut the volume into increasing slabs from 0 are refused
// when the frame is prepared, even when the worker's own slab matches: the
// ring's layout is built from them, and a slab of no planes or beyond the
// volume would make it route rays nowhere.
TEST_F(HostileRaysTest, BadCutsAreRefusedAtPrepare) {
  auto prepare = [&](uint64_t id, std::vector<int> cuts, int index) {
    v1::FrameSpec spec = Spec(id);
    spec.clear_cuts();
    for (int c : cuts) spec.add_cuts(c);
    spec.set_index(index);
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    return worker_stub_->PrepareFrame(&ctx, spec, &ack);
  };
  const int ny = dims_[1];
  uint64_t id = 30;
  for (auto [cuts, index] : std::vector<std::pair<std::vector<int>, int>>{
           {{0, ny, ny}, 0}, {{0, ny, ny + 9}, 0}, {{-5, 0, ny}, 1}, {{0}, 0}, {{}, 0}}) {
    grpc::Status s = prepare(id++, cuts, index);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << ::testing::PrintToString(cuts);
    EXPECT_NE(s.error_message().find("cuts"), std::string::npos) << s.error_message();
  }
  // The worker goes on preparing good frames.
  EXPECT_TRUE(prepare(id++, {0, ny}, 0).ok());
}

// Evict names what it evicts: an empty key is refused (it used to wipe every
// slab while the root thought them loaded), and the slab stays usable.
TEST_F(HostileRaysTest, EvictNeedsAKey) {
  auto evict = [&](const std::string& key) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::DatasetRef ref;
    ref.set_dataset_key(key);
    v1::FrameAck ack;
    return worker_stub_->Evict(&ctx, ref, &ack);
  };
  grpc::Status s = evict("");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_EQ(evict("no-such-slab").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(Prepare(40).ok());  // the slab is still here
  EXPECT_TRUE(evict("phantom-dvr").ok());
  EXPECT_EQ(evict("phantom-dvr").error_code(), grpc::StatusCode::NOT_FOUND);
}

}  // namespace
}  // namespace transtick
