// Hostile ray records and slabs over a real stream: a real worker and a real display
// on 127.0.0.1, driven the way the root drives them, and a peer that sends
// the worker a batch of damaged rays on its ring stream. The worker must
// drop and count them, abort the frame at the display at once with a reason
// that says so, end the frame promptly, and keep serving.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include "cluster.grpc.pb.h"
#include "gtest/gtest.h"
#include "nodes_fixture.h"
#include "transtick/ray_codec.h"
#include "transtick/scalar_codec.h"

namespace transtick {
namespace {

constexpr double kDenormal = 4.9406564584124654e-324;

using HostileRaysTest = testing::NodesTest;

TEST_F(HostileRaysTest, DamagedRecordsAreDroppedCountedAndAbortTheFrame) {
  constexpr uint64_t kFrame = 7;
  ASSERT_TRUE(Prepare(kFrame).ok());

  // One good ray, as the worker's own tracer makes it, then damaged ones.
  const RayDescriptor good = CentreRay();
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
  PackRays(records, batch.mutable_packed());
  ASSERT_TRUE(stream->Write(batch));

  // The display hears of it from the worker at once, well before any
  // frame timeout, with a reason naming the dropped records.
  const auto t0 = std::chrono::steady_clock::now();
  {
    grpc::Status s = Await(kFrame);
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
    EXPECT_TRUE(Run(kFrame).ok());
    auto stats = End(kFrame, /*cancel=*/true);
    ASSERT_TRUE(stats.ok()) << stats.status();
    EXPECT_EQ(stats->rays_rejected(), 5u);
    EXPECT_EQ(stats->received_left(), 1u);  // the good one was kept
    EXPECT_EQ(stats->rays_truncated(), 0u);
  }
  stream->Finish();

  // The worker goes on serving: a whole frame of its own completes.
  constexpr uint64_t kNext = 8;
  ASSERT_TRUE(Prepare(kNext).ok());
  ASSERT_TRUE(Run(kNext).ok());
  int rows = 0;
  EXPECT_TRUE(Await(kNext, &rows).ok());
  EXPECT_EQ(rows, kSize);
  auto stats = End(kNext);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->rays_rejected(), 0u);
}

// A batch whose packing is broken, or that carries the unpacked records of
// a worker older than packing, is refused whole, by name; the frame is
// aborted and the worker goes on.
TEST_F(HostileRaysTest, BrokenRayBatchesAreRefusedWholeByName) {
  std::string records;
  AppendRay(CentreRay(), &records);
  AppendRay(CentreRay(), &records);
  std::string packed;
  PackRays(records, &packed);
  struct Case {
    std::string packed, unpacked, why;
    uint64_t rejected;
  };
  const Case cases[] = {
      {packed.substr(0, packed.size() - 1), "", "record 1 is cut short", 2},
      {packed + std::string("\x00\x80", 2), "", "record 2 has an unknown field", 3},
      {"", records, "unpacked ray records (field 2)", 2},
  };
  uint64_t frame = 40;
  for (const Case& c : cases) {
    ++frame;
    ASSERT_TRUE(Prepare(frame).ok());
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    auto stream = worker_stub_->Rays(&ctx);
    v1::RayBatch batch;
    batch.set_frame_id(frame);
    ASSERT_TRUE(stream->Write(batch));
    batch.set_packed(c.packed);
    batch.set_rays(c.unpacked);
    ASSERT_TRUE(stream->Write(batch));
    grpc::Status s = Await(frame);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED) << s.error_message();
    EXPECT_NE(s.error_message().find(c.why), std::string::npos) << s.error_message();
    stream->WritesDone();
    EXPECT_TRUE(Run(frame).ok());
    auto stats = End(frame, /*cancel=*/true);
    ASSERT_TRUE(stats.ok()) << stats.status();
    EXPECT_EQ(stats->rays_rejected(), c.rejected) << c.why;
    EXPECT_EQ(stats->received_left(), 0u) << c.why;  // nothing of it kept
    stream->Finish();
  }
  // The worker goes on serving: a whole frame of its own completes.
  ASSERT_TRUE(Prepare(++frame).ok());
  ASSERT_TRUE(Run(frame).ok());
  EXPECT_TRUE(Await(frame).ok());
  auto stats = End(frame);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->rays_rejected(), 0u);
}

// A dvr frame whose step would take unbounded samples is refused when it is
// prepared, with the reason; a step at the bound is accepted, and so is any
// step for surfaces, which take no samples.
// A deposit stream to the display that carries `batch` after the first
// message naming the frame; returns how the display ended it.
grpc::Status SendDeposits(v1::Display::Stub& display, uint64_t frame,
                          const v1::DepositBatch& batch) {
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::FrameAck ack;
  auto writer = display.Deposits(&ctx, &ack);
  v1::DepositBatch first;
  first.set_frame_id(frame);
  writer->Write(first);
  writer->Write(batch);
  writer->WritesDone();
  return writer->Finish();
}

TEST_F(HostileRaysTest, HostileDepositsAreRefusedByNameAndTheDisplayGoesOn) {
  constexpr uint64_t kFrame = 21;
  ASSERT_TRUE(Begin(kFrame, 4, 2).ok());
  v1::DepositBatch batch;
  batch.set_frame_id(kFrame);
  // 20-byte records, as a worker older than the display sent them.
  std::string records;
  AppendDeposit(Deposit{0, RayKind::kPrimary, 0, {1, 1, 1}}, &records);
  batch.set_records(records);
  grpc::Status s = SendDeposits(*display_stub_, kFrame, batch);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("from a worker older than this display"), std::string::npos)
      << s.error_message();
  // Packed, but for a pixel beyond the 4x2 image, and cut short.
  batch.clear_records();
  std::string packed;
  AppendDeposit(Deposit{8, RayKind::kPrimary, 0, {1, 1, 1}}, &records);
  PackDeposits(records.substr(20), &packed);
  batch.set_packed(packed);
  s = SendDeposits(*display_stub_, kFrame, batch);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("pixel 8 of 8"), std::string::npos) << s.error_message();
  batch.set_packed(packed.substr(0, 3));
  s = SendDeposits(*display_stub_, kFrame, batch);
  EXPECT_NE(s.error_message().find("cut short"), std::string::npos) << s.error_message();
  // A run of misses past the image's last pixel: refused, and none of its
  // pixels is taken (else the frame below would complete too soon).
  records.clear();
  packed.clear();
  AppendMissRun(5, 4, 1, {0, 0, 0}, &records);
  PackDeposits(records, &packed);
  batch.set_packed(packed);
  s = SendDeposits(*display_stub_, kFrame, batch);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("run record 0 is invalid (pixels 5 + 4 of 8"), std::string::npos)
      << s.error_message();
  // The frame is still the display's to complete: every pixel, packed, the
  // last three a run of misses.
  records.clear();
  for (uint32_t p = 0; p < 5; ++p) {
    AppendDeposit(Deposit{p, RayKind::kPrimary, 1, {0.5f, 0, 0}}, &records);
    AppendDeposit(Deposit{p, RayKind::kShadow, 0, {0.25f, 0, 0}}, &records);
  }
  AppendMissRun(5, 3, 1, {0, 0, 0}, &records);
  packed.clear();
  EXPECT_EQ(PackDeposits(records, &packed), 6u);
  batch.set_packed(packed);
  EXPECT_TRUE(SendDeposits(*display_stub_, kFrame, batch).ok());
  int rows = 0;
  s = Await(kFrame, &rows);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(rows, 2);
}

TEST_F(HostileRaysTest, AbsurdStepIsRefusedAtPrepare) {
  auto prepare = [&](uint64_t id, const std::string& key, double step) {
    v1::FrameSpec spec = Spec(id);
    spec.set_dataset_key(key);
    spec.mutable_view()->set_step(step);
    return PrepareOnly(spec);
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
    return PrepareOnly(spec);
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
  grpc::Status s = Evict("");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_EQ(Evict("no-such-slab").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(Prepare(40).ok());  // the slab is still here
  EXPECT_TRUE(Evict("phantom-dvr").ok());
  EXPECT_EQ(Evict("phantom-dvr").error_code(), grpc::StatusCode::NOT_FOUND);
}

// A slab whose field summary is damaged (the wrong size, a band the
// materials do not have) is refused with the reason; the worker keeps the
// slabs it has.
TEST_F(HostileRaysTest, DamagedFieldSummaryIsRefused) {
  const auto& good = scene_->summary().bytes();
  ASSERT_FALSE(good.empty());
  const std::string bytes(good.begin(), good.end());
  const std::string cases[] = {bytes.substr(1), bytes + "x",
                               std::string(1, '\x07') + bytes.substr(1)};
  for (const std::string& bad : cases) {
    grpc::Status s = SendSlab(*scene_, "damaged", &bad);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_NE(s.error_message().find("field summary"), std::string::npos) << s.error_message();
  }
  EXPECT_TRUE(SendSlab(*scene_, "whole", &bytes).ok());
  EXPECT_TRUE(Prepare(50).ok());  // the first slab is still here
}

// Slab scalars that do not decode (docs/formats.md, "Slab scalars"), or
// do not add up to what the header announced, are refused by name, and an
// absurd count is refused before anything is allocated for it (times 4 it
// wraps around to 0); the worker keeps the slabs it has and loads a good one.
TEST_F(HostileRaysTest, BrokenSlabScalarsAreRefusedByName) {
  const uint64_t count = scene_->scalars().size();
  struct Case {
    std::function<void(v1::SlabChunk&)> edit;
    grpc::StatusCode code;
    const char* why;
  };
  const Case cases[] = {
      {[](v1::SlabChunk& c) { c.mutable_header()->set_scalar_count(uint64_t{1} << 62); },
       grpc::StatusCode::RESOURCE_EXHAUSTED, "exceed this worker's limit"},
      {[](v1::SlabChunk& c) { c.set_scalars_coding(static_cast<v1::ScalarsCoding>(7)); },
       grpc::StatusCode::INVALID_ARGUMENT, "unknown coding 7"},
      {[](v1::SlabChunk& c) {
         c.set_scalars_coding(v1::SCALARS_I16);
         c.mutable_scalars()->push_back('x');
       },
       grpc::StatusCode::INVALID_ARGUMENT, "not a whole number of 2-byte samples"},
      {[count](v1::SlabChunk& c) { c.mutable_header()->set_scalar_count(count - 1); },
       grpc::StatusCode::INVALID_ARGUMENT, "were left to fill"},
      {[](v1::SlabChunk& c) { c.mutable_scalars()->resize(c.scalars().size() - 4); },
       grpc::StatusCode::INVALID_ARGUMENT, "scalars arrived, header said"},
      // Floats read as shorts are twice the samples the header announced.
      {[](v1::SlabChunk& c) { c.set_scalars_coding(v1::SCALARS_I16); },
       grpc::StatusCode::INVALID_ARGUMENT, "were left to fill"},
      {[](v1::SlabChunk& c) {
         c.set_scalars_coding(v1::SCALARS_U8);
         c.mutable_scalars()->resize(c.scalars().size() / 8);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "scalars arrived, header said"},
  };
  for (const Case& c : cases) {
    grpc::Status s = SendSlab(*scene_, "broken", nullptr, c.edit);
    EXPECT_EQ(s.error_code(), c.code) << s.error_message();
    EXPECT_NE(s.error_message().find(c.why), std::string::npos) << s.error_message();
  }
  EXPECT_EQ(Evict("broken").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(Prepare(60).ok());  // the first slab is still here
  // A slab of integers coded as shorts loads.
  std::vector<float> rounded(scene_->scalars().begin(), scene_->scalars().end());
  for (float& v : rounded) v = std::round(v);
  ASSERT_EQ(NarrowestCoding(rounded.data(), rounded.size()), ScalarsCoding::kI16);
  EXPECT_TRUE(SendSlab(*scene_, "bytes", nullptr, [&](v1::SlabChunk& c) {
                c.set_scalars_coding(v1::SCALARS_I16);
                c.clear_scalars();
                AppendScalars(rounded.data(), rounded.size(), ScalarsCoding::kI16,
                              c.mutable_scalars());
              }).ok());
}

}  // namespace
}  // namespace transtick
