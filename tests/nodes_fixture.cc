#include "nodes_fixture.h"

#include <chrono>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "transtick/ray_codec.h"
#include "transtick/synthetic.h"
#include "transtick/tracer.h"

namespace transtick::testing {

bool Eventually(const std::function<bool()>& done, std::chrono::milliseconds patience) {
  using Clock = std::chrono::steady_clock;
  auto give_up = Clock::now() + patience;
  auto last = Clock::now();
  while (!done()) {
    const auto now = Clock::now();
    // A poll more than a second late: the machine stalled, and the nodes
    // with it. That time is not the nodes' and is added to the patience.
    if (now - last > std::chrono::seconds(1)) give_up += now - last;
    last = now;
    if (now > give_up) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

WorkerOptions NodesTest::worker_options() const {
  WorkerOptions o;
  o.id = "w-test";
  o.threads = 2;
  return o;
}

void NodesTest::SetUp() {
  display_service_ = std::make_unique<DisplayService>(display_options());
  auto display = Server::Start("127.0.0.1:0", Role::kDisplay, {display_service_.get()});
  ASSERT_TRUE(display.ok()) << display.status();
  display_ = *std::move(display);
  worker_service_ = std::make_unique<WorkerService>(worker_options());
  auto worker = Server::Start("127.0.0.1:0", Role::kWorker, {worker_service_.get()});
  ASSERT_TRUE(worker.ok()) << worker.status();
  worker_ = *std::move(worker);
  worker_address_ = absl::StrCat("127.0.0.1:", worker_->port());
  display_address_ = absl::StrCat("127.0.0.1:", display_->port());
  worker_service_->set_address(worker_address_);
  worker_stub_ = v1::Worker::NewStub(MakeChannel(worker_address_, Role::kWorker));
  display_stub_ = v1::Display::NewStub(MakeChannel(display_address_, Role::kDisplay));

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

void NodesTest::TearDown() {
  if (worker_service_) worker_service_->CancelAll();
  if (worker_) worker_->Shutdown(std::chrono::milliseconds(500));
  if (display_) display_->Shutdown(std::chrono::milliseconds(500));
}

void NodesTest::LoadWholeSlab(const Scene& scene, const std::string& key) {
  grpc::Status s = SendSlab(scene, key);
  ASSERT_TRUE(s.ok()) << s.error_message();
}

grpc::Status NodesTest::SendSlab(const Scene& scene, const std::string& key,
                                 const std::string* summary,
                                 const std::function<void(v1::SlabChunk&)>& edit) {
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(30));
  v1::LoadReply reply;
  auto writer = worker_stub_->LoadSlab(&ctx, &reply);
  v1::SlabChunk chunk;
  v1::SlabHeader* h = chunk.mutable_header();
  h->set_dataset_key(key);
  const bool dvr = scene.mode() == RenderMode::kDvr;
  h->set_mode(dvr ? v1::DVR : v1::SURFACES);
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
  const auto& own = scene.summary().bytes();
  h->set_field_summary(summary ? *summary : std::string(own.begin(), own.end()));
  h->set_scalar_count(scene.scalars().size());
  for (std::string& b : scene.sticks().EncodeRows(0, dims_[1])) chunk.add_blocks(std::move(b));
  AppendFloats(scene.scalars().data(), scene.scalars().size(), chunk.mutable_scalars());
  if (edit) edit(chunk);
  writer->Write(chunk);
  writer->WritesDone();
  return writer->Finish();
}

v1::FrameSpec NodesTest::Spec(uint64_t frame_id) const {
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

namespace {

// A unary call of `stub` with a deadline of `seconds`; its reply in *reply.
template <typename Stub, typename Request, typename Reply>
grpc::Status Call(Stub& stub,
                  grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Reply*),
                  const Request& request, Reply* reply, double seconds = 10) {
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(seconds));
  return (stub.*method)(&ctx, request, reply);
}

v1::FrameRef Ref(uint64_t frame_id) {
  v1::FrameRef ref;
  ref.set_frame_id(frame_id);
  return ref;
}

}  // namespace

grpc::Status NodesTest::Begin(uint64_t frame_id, int width, int height) {
  v1::DisplayFrame df;
  df.set_frame_id(frame_id);
  df.set_width(width);
  df.set_height(height);
  v1::FrameAck ack;
  return Call(*display_stub_, &v1::Display::Stub::BeginFrame, df, &ack);
}

grpc::Status NodesTest::PrepareOnly(const v1::FrameSpec& spec) {
  v1::FrameAck ack;
  return Call(*worker_stub_, &v1::Worker::Stub::PrepareFrame, spec, &ack);
}

grpc::Status NodesTest::Prepare(uint64_t frame_id) {
  if (grpc::Status s = Begin(frame_id); !s.ok()) return s;
  return PrepareOnly(Spec(frame_id));
}

grpc::Status NodesTest::Run(uint64_t frame_id) {
  v1::FrameAck ack;
  return Call(*worker_stub_, &v1::Worker::Stub::RunFrame, Ref(frame_id), &ack);
}

grpc::Status NodesTest::Await(uint64_t frame_id, int* rows) {
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(30));
  auto reader = display_stub_->AwaitFrame(&ctx, Ref(frame_id));
  v1::FrameProgress p;
  int got = 0;
  while (reader->Read(&p)) {
    if (p.has_image()) got += p.image().row_end() - p.image().row_begin();
  }
  if (rows) *rows = got;
  return reader->Finish();
}

absl::StatusOr<v1::WorkerFrameStats> NodesTest::End(uint64_t frame_id, bool cancel) {
  v1::FrameRef ref = Ref(frame_id);
  ref.set_cancel(cancel);
  v1::WorkerFrameStats stats;
  grpc::Status s = Call(*worker_stub_, &v1::Worker::Stub::EndFrame, ref, &stats, 5);
  if (!s.ok()) return FromGrpc(s);
  return stats;
}

void NodesTest::RunToImage(uint64_t frame_id) {
  grpc::Status s = Run(frame_id);
  ASSERT_TRUE(s.ok()) << s.error_message();
  int rows = 0;
  s = Await(frame_id, &rows);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(rows, kSize);
  EXPECT_TRUE(End(frame_id).ok());
}

grpc::Status NodesTest::Evict(const std::string& key) {
  v1::DatasetRef ref;
  ref.set_dataset_key(key);
  v1::FrameAck ack;
  return Call(*worker_stub_, &v1::Worker::Stub::Evict, ref, &ack);
}

RayDescriptor NodesTest::CentreRay() const {
  CameraSpec cs;
  cs.width = cs.height = kSize;
  cs.azimuth_deg = 30;
  cs.elevation_deg = 10;
  auto camera =
      Camera::Create(cs, Vec3{static_cast<double>(dims_[0]), static_cast<double>(dims_[1]),
                              static_cast<double>(dims_[2])});
  EXPECT_TRUE(camera.ok()) << camera.status();
  const Tracer tracer(*scene_, RenderSettings{}, *camera);
  RayDescriptor ray;
  EXPECT_TRUE(tracer.MakePrimary(camera->Generate(kSize / 2, kSize / 2), 0, &ray));
  return ray;
}

}  // namespace transtick::testing
