// Interactive sessions on an embedded cluster (docs/formats.md, "Session
// stream"): the frames equal the in-process render of their camera and
// classification bit for bit, a burst of cameras is not rendered one by
// one but ends on the newest, a bad request is an error event and the
// session goes on, and batch jobs still run beside a session, whose frames
// go first.
#include <chrono>
#include <fstream>
#include <limits>
#include <random>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client.h"
#include "convert.h"
#include "gtest/gtest.h"
#include "local_cluster.h"
#include "session_fixture.h"
#include "testing.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

using testing::Camera;
using testing::Materials;

class SessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TempDir();
    cluster_ = testing::PhantomCluster(dir_);
    ASSERT_TRUE(cluster_);
  }
  v1::Dataset Dataset(const v1::View& first, float lo = 45) {
    v1::Dataset d;
    d.set_volume("p.nrrd");
    *d.mutable_materials() = Materials(lo);
    *d.add_views() = first;
    return d;
  }
  Image Reference(const v1::View& view, float lo = 45) {
    return testing::PhantomReference(dir_, view, lo);
  }
  // Events until a full frame (not a preview) arrives.
  SessionClient::Event NextFull(SessionClient& s, std::vector<SessionClient::Event>* seen = nullptr) {
    while (true) {
      auto e = s.Next();
      EXPECT_TRUE(e.ok()) << e.status();
      if (!e.ok()) return {};
      if (seen) seen->push_back(*e);
      if (e->has_frame && !e->preview) return *e;
    }
  }
  std::string dir_;
  std::unique_ptr<LocalCluster> cluster_;
};

TEST_F(SessionTest, FramesAreTheInProcessRenderOfTheirCamera) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(30)), /*preview=*/4);
  ASSERT_TRUE(s.ok()) << s.status();
  auto ready = (*s)->Next();
  ASSERT_TRUE(ready.ok() && ready->ready) << ready.status();
  EXPECT_EQ(ready->ready->dims_size(), 3);
  EXPECT_EQ(ready->ready->dims(2), 40);
  ASSERT_EQ(ready->ready->histogram_size(), 64);
  ASSERT_EQ(ready->ready->range_size(), 2);
  {
    auto volume = ReadVolume(dir_ + "/p.nrrd");
    uint64_t total = 0, above = 0;
    const float mid = 0.5f * (ready->ready->range(0) + ready->ready->range(1));
    for (int b = 0; b < 64; ++b) {
      total += ready->ready->histogram(b);
      if (b >= 32) above += ready->ready->histogram(b);
    }
    EXPECT_EQ(total, volume->VoxelCount());
    EXPECT_EQ(ready->ready->range(0), volume->Range()[0]);
    uint64_t want_above = 0;  // the upper half of the bins holds the values from the middle up
    for (float v : volume->values) want_above += v >= mid;
    EXPECT_NEAR(static_cast<double>(above), static_cast<double>(want_above), 0.001 * total);
  }
  // The preview, a quarter of the size, then the frame.
  auto preview = (*s)->Next();
  ASSERT_TRUE(preview.ok() && preview->has_frame) << preview.status();
  EXPECT_TRUE(preview->preview);
  EXPECT_EQ(preview->image.width, 10);
  EXPECT_EQ(preview->image.height, 8);
  auto first = NextFull(**s);
  EXPECT_EQ(first.seq, 1u);
  EXPECT_EQ(first.image.rgb, Reference(Camera(30)).rgb);
  EXPECT_EQ(first.stats.width(), 40);
  for (double az : {75.0, 160.0, 250.0}) {
    auto seq = (*s)->SetView(Camera(az, 48, 40));
    ASSERT_TRUE(seq.ok());
    auto frame = NextFull(**s);
    EXPECT_EQ(frame.seq, *seq);
    EXPECT_EQ(frame.image.rgb, Reference(Camera(az, 48, 40)).rgb) << "azimuth " << az;
  }
  // A new classification: ready again, and the camera renders again.
  auto seq = (*s)->SetMaterials(Materials(30));
  ASSERT_TRUE(seq.ok());
  std::vector<SessionClient::Event> seen;
  auto frame = NextFull(**s, &seen);
  ASSERT_FALSE(seen.empty());
  EXPECT_TRUE(seen.front().ready.has_value())
      << "seq " << seen.front().seq << " error '" << seen.front().error << "' frame " << seen.front().has_frame << " preview " << seen.front().preview;
  EXPECT_EQ(frame.seq, *seq);
  EXPECT_EQ(frame.image.rgb, Reference(Camera(250, 48, 40), 30).rgb);
  EXPECT_TRUE((*s)->Close().ok());
}

// A session that asked for RGB8 frames (as the web gateway does): each
// frame, preview too, holds FromByte of the bytes of the in-process image.
TEST_F(SessionTest, ByteFramesAreTheBytesOfTheInProcessRender) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(30)), /*preview=*/4, "",
                               v1::RGB8);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_TRUE((*s)->Next()->ready);
  auto same_bytes = [](const Image& got, const Image& want) {
    if (got.width != want.width || got.height != want.height || got.rgb.size() != want.rgb.size()) {
      return false;
    }
    for (size_t i = 0; i < got.rgb.size(); ++i) {
      if (got.rgb[i] != FromByte(ToByte(want.rgb[i]))) return false;
    }
    return true;
  };
  std::vector<SessionClient::Event> seen;
  auto first = NextFull(**s, &seen);
  EXPECT_TRUE(same_bytes(first.image, Reference(Camera(30))));
  bool previewed = false;
  for (const auto& e : seen) previewed = previewed || (e.has_frame && e.preview);
  EXPECT_TRUE(previewed);
  for (double az : {75.0, 250.0}) {
    auto seq = (*s)->SetView(Camera(az, 48, 40));
    ASSERT_TRUE(seq.ok());
    auto frame = NextFull(**s);
    EXPECT_EQ(frame.seq, *seq);
    EXPECT_TRUE(same_bytes(frame.image, Reference(Camera(az, 48, 40)))) << "azimuth " << az;
  }
  // The encoding is the first request's: a later one is an error event.
  v1::SessionRequest late;
  late.set_image_encoding(v1::FLOAT32);
  *late.mutable_view() = Camera(10);
  auto seq = (*s)->Send(late);
  ASSERT_TRUE(seq.ok());
  auto e = (*s)->Next();
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->seq, *seq);
  EXPECT_NE(e->error.find("image_encoding belong"), std::string::npos) << e->error;
  EXPECT_TRUE((*s)->Close().ok());
  // One the build does not know ends the session at once, saying so.
  auto bad = SessionClient::Open(cluster_->root_address(), Dataset(Camera(30)), 0, "",
                                 static_cast<v1::ImageEncoding>(5));
  absl::Status why = bad.ok() ? (*bad)->Next().status() : bad.status();
  EXPECT_EQ(why.code(), absl::StatusCode::kInvalidArgument) << why;
  EXPECT_NE(why.message().find("image_encoding 5"), std::string::npos) << why;
}

TEST_F(SessionTest, ABurstOfCamerasEndsOnTheNewestWithoutRenderingEach) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(0, 96, 80)));
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->Next()->ready);
  uint64_t last = 0;
  for (int i = 1; i <= 40; ++i) last = *(*s)->SetView(Camera(i * 9, 96, 80));
  std::vector<uint64_t> rendered;
  SessionClient::Event e;
  do {
    e = NextFull(**s);
    rendered.push_back(e.seq);
  } while (e.seq != last && rendered.size() < 50);
  EXPECT_EQ(rendered.back(), last);
  EXPECT_LT(rendered.size(), 20u) << "stale cameras were rendered one by one";
  for (size_t i = 1; i < rendered.size(); ++i) EXPECT_GT(rendered[i], rendered[i - 1]);
  EXPECT_EQ(e.image.rgb, Reference(Camera(40 * 9, 96, 80)).rgb);
}

TEST_F(SessionTest, ABadRequestIsAnErrorAndTheSessionGoesOn) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(10)));
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->Next()->ready);
  NextFull(**s);
  auto bad = (*s)->SetView(Camera(10, 0, 32));
  auto e = (*s)->Next();
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->seq, *bad);
  EXPECT_NE(e->error.find("0x32"), std::string::npos) << e->error;
  v1::TransferFunction tf;  // a surfaces session takes materials
  auto wrong = (*s)->SetTransfer(tf);
  e = (*s)->Next();
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->seq, *wrong);
  EXPECT_NE(e->error.find("materials"), std::string::npos) << e->error;
  auto good = (*s)->SetView(Camera(100));
  auto frame = NextFull(**s);
  EXPECT_EQ(frame.seq, *good);
  EXPECT_EQ(frame.image.rgb, Reference(Camera(100)).rgb);
}

// Hostile and broken cameras, thrown at a session in bursts: every one is
// answered by an error or a frame (or superseded), nothing crashes or
// hangs, and a good camera afterwards still gets the exact image.
TEST_F(SessionTest, RandomBrokenCamerasNeverBreakTheSession) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(10)), /*preview=*/3);
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->Next()->ready);
  std::mt19937 rng(20261202);
  auto pick = [&](std::initializer_list<double> values) {
    std::vector<double> v(values);
    return v[std::uniform_int_distribution<size_t>(0, v.size() - 1)(rng)];
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  uint64_t last = 0;
  for (int i = 0; i < 300; ++i) {
    v1::View v = Camera(pick({0, 45, -720, 1e300, nan, inf}),
                        static_cast<int>(pick({0, -5, 1, 3, 24, 9000})),
                        static_cast<int>(pick({0, 1, 2, 17, 100000})));
    if (rng() % 3 == 0) v.set_zoom(pick({0, -1, 1e-300, 1e300, nan, 2}));
    if (rng() % 4 == 0) v.set_fov(pick({0, 179.9, 180, -30, nan, 60}));
    if (rng() % 5 == 0) v.set_samples(static_cast<int>(pick({0, 1, 64, 65, -3})));
    if (rng() % 6 == 0) {
      for (int k = 0; k < 3; ++k) v.add_background(static_cast<float>(pick({0, 1, 2, -1, nan})));
    }
    if (rng() % 7 == 0) {
      auto* e = v.mutable_explicit_view();
      for (int k = 0; k < 3; ++k) e->add_eye(pick({0, 100, nan}));
      for (int k = 0; k < static_cast<int>(pick({0, 2, 3})); ++k) e->add_target(0);
    }
    if (rng() % 8 == 0) v.set_step(pick({-1, 1e-30, 0.5}));
    auto seq = (*s)->SetView(v);
    ASSERT_TRUE(seq.ok()) << seq.status();
    last = *seq;
    if (i % 25 == 24) {  // drain now and then: answers come in order of seq
      while (true) {
        auto e = (*s)->Next();
        ASSERT_TRUE(e.ok()) << e.status();
        if (e->seq == last && (!e->error.empty() || (e->has_frame && !e->preview))) break;
        if (e->seq == last && e->has_frame && e->preview) continue;
        ASSERT_LE(e->seq, last);
      }
    }
  }
  auto good = (*s)->SetView(Camera(77));
  auto frame = NextFull(**s);
  EXPECT_EQ(frame.seq, *good);
  EXPECT_EQ(frame.image.rgb, Reference(Camera(77)).rgb);
  EXPECT_TRUE((*s)->Close().ok());
}

// A session opened with a preset takes materials afterwards (its mode is
// the preset's), and its frames are those of the in-process render.
TEST_F(SessionTest, APresetSessionTakesMaterialsLater) {
  v1::Dataset d = Dataset(Camera(20));
  d.mutable_preset()->set_name("mr-brain");
  auto s = SessionClient::Open(cluster_->root_address(), d);
  ASSERT_TRUE(s.ok());
  auto ready = (*s)->Next();
  ASSERT_TRUE(ready.ok() && ready->ready) << ready.status();
  EXPECT_EQ(ready->ready->mode(), v1::SURFACES);
  auto first = NextFull(**s);
  EXPECT_FALSE(first.image.rgb.empty());
  auto seq = (*s)->SetMaterials(Materials(45));
  ASSERT_TRUE(seq.ok());
  std::vector<SessionClient::Event> seen;
  auto frame = NextFull(**s, &seen);
  for (const auto& e : seen) EXPECT_EQ(e.error, "");
  EXPECT_EQ(frame.seq, *seq);
  EXPECT_EQ(frame.image.rgb, Reference(Camera(20)).rgb);
}

TEST_F(SessionTest, OpeningIsChecked) {
  v1::Dataset no_views = Dataset(Camera(0));
  no_views.clear_views();
  auto s = SessionClient::Open(cluster_->root_address(), no_views);
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(absl::IsInvalidArgument((*s)->Next().status()));
  v1::Dataset outside = Dataset(Camera(0));
  outside.set_volume("../p.nrrd");
  s = SessionClient::Open(cluster_->root_address(), outside);
  ASSERT_TRUE(s.ok());
  auto e = (*s)->Next();
  EXPECT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("p.nrrd"), std::string::npos) << e.status();
}

TEST_F(SessionTest, BatchJobsRunBesideAnOpenSession) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(30)));
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->Next()->ready);
  NextFull(**s);
  v1::Job job;
  v1::Dataset d = Dataset(Camera(45));
  d.mutable_views(0)->set_output(dir_ + "/job.exr");
  *job.add_datasets() = d;
  auto stats = SubmitAndWatch(cluster_->root_address(), job, WatchOptions{});
  ASSERT_TRUE(stats.ok()) << stats.status();
  auto image = ReadImage(dir_ + "/job.exr");
  ASSERT_TRUE(image.ok());
  EXPECT_EQ(image->rgb, Reference(Camera(45)).rgb);
  auto seq = (*s)->SetView(Camera(60));
  EXPECT_EQ(NextFull(**s).seq, *seq);
}

// A session's frame does not wait for the batch frame that traces when it
// comes: the root gives it a turn at once, and the workers trace it first
// (FrameSpec.interactive, TraceOrder), the batch frame's rays waiting in
// their inboxes meanwhile. Both images stay bit for bit the in-process ones.
TEST_F(SessionTest, ASessionFrameGoesBeforeABatchFrameThatIsTracing) {
  auto s = SessionClient::Open(cluster_->root_address(), Dataset(Camera(30)));
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->Next()->ready);
  NextFull(**s);
  // A batch frame of a few seconds on this cluster: 64 samples a pixel.
  v1::View big = Camera(45, 640, 512);
  big.set_samples(64);
  big.set_output(dir_ + "/big.exr");
  v1::Job job;
  *job.add_datasets() = Dataset(big);
  absl::StatusOr<std::vector<v1::ClusterFrameStats>> stats;
  const auto submitted = std::chrono::steady_clock::now();
  std::thread batch([&] { stats = SubmitAndWatch(cluster_->root_address(), job, WatchOptions{}); });
  // Well inside the batch frame (which starts within milliseconds).
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  auto seq = (*s)->SetView(Camera(60));
  ASSERT_TRUE(seq.ok());
  auto frame = NextFull(**s);
  const double session_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - submitted)
          .count();
  batch.join();
  ASSERT_TRUE(stats.ok()) << stats.status();
  ASSERT_EQ(stats->size(), 1u);
  EXPECT_EQ(frame.seq, *seq);
  EXPECT_EQ(frame.image.rgb, Reference(Camera(60)).rgb);
  auto image = ReadImage(dir_ + "/big.exr");
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->rgb, Reference(big).rgb);
  // Waiting for its turn, the session's frame would come only once the
  // batch frame had traced, about since_submit_ms + frame_ms after the
  // submission; first on the workers, it comes in the batch frame's
  // first half.
  const double batch_start_ms = stats->front().since_submit_ms();
  const double batch_ms = stats->front().frame_ms();
  EXPECT_LT(session_ms, batch_start_ms + 0.5 * batch_ms)
      << "the batch frame took " << batch_ms << " ms from " << batch_start_ms << " ms";
}

}  // namespace
}  // namespace transtick
