// The root's durable job queue: the SQLite store, recovery after a restart
// (queued and running jobs run again, delivered frames are not rendered
// again, a cancel request sticks), the limits on submissions, and watchers
// resuming with the frames they hold.
#include "job_queue.h"

#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include "gtest/gtest.h"
#include "job_store.h"
#include "testing.h"

namespace transtick {
namespace {

v1::Job MakeJob(int views, int width = 32, int height = 24) {
  v1::Job job;
  job.set_name("q");
  v1::Dataset* d = job.add_datasets();
  d->set_volume("v.nrrd");
  for (int i = 0; i < views; ++i) {
    v1::View* v = d->add_views();
    v->set_azimuth(10 * i);
    v->set_width(width);
    v->set_height(height);
  }
  return job;
}

absl::StatusOr<JobPlan> AnyPlan(const v1::Job&) { return JobPlan{}; }

std::string FreshDir(const std::string& name) {
  const std::string dir = testing::TempDir() + "/" + name;
  std::filesystem::remove_all(dir);
  return dir;
}

// The last chunk of a frame's image, as the runner publishes it.
v1::JobEvent LastChunk(int frame) {
  v1::JobEvent e;
  e.set_frame(frame);
  e.mutable_image()->set_width(1);
  e.mutable_image()->set_height(1);
  e.mutable_image()->set_row_end(1);
  e.mutable_image()->set_rgb(std::string(12, '\0'));
  e.mutable_stats()->set_frame_ms(1);
  return e;
}

// Renders (publishes) every pending frame of `job` and ends its turn.
void RunAll(Job& job) {
  while (auto f = job.NextFrame()) {
    ASSERT_TRUE(job.PublishImage(LastChunk(*f), 1 << 20, std::chrono::seconds(5)).ok());
    job.FrameRendered(*f);
  }
  ASSERT_TRUE(job.Complete(absl::OkStatus()));
}

// The frames of the images a watcher receives until the job ends.
std::set<int> Watch(Job& job, const std::set<int>& have = {}) {
  std::set<int> frames;
  job.Stream(
      [&](const v1::JobEvent& e) {
        if (e.has_image() && e.has_stats()) frames.insert(e.frame());
        return true;
      },
      [] { return false; }, have);
  return frames;
}

TEST(JobStoreTest, WhatIsWrittenIsReadBackAfterReopening) {
  const std::string dir = FreshDir("store_roundtrip");
  int64_t seq;
  {
    auto store = JobStore::Open(dir);
    ASSERT_TRUE(store.ok()) << store.status();
    StoredJob j;
    j.spec = MakeJob(3);
    j.owner = "ipv4:10.0.0.1";
    j.frames_total = 3;
    j.pixels_total = 3 * 32 * 24;
    j.submitted_unix = 1234.5;
    auto s = (*store)->Insert(j);
    ASSERT_TRUE(s.ok()) << s.status();
    seq = *s;
    ASSERT_TRUE((*store)->SetState(seq, v1::FAILED, "broke").ok());
    ASSERT_TRUE((*store)->SetCancel(seq).ok());
    ASSERT_TRUE((*store)->MarkDelivered(seq, 0).ok());
    ASSERT_TRUE((*store)->MarkDelivered(seq, 2).ok());
    ASSERT_TRUE((*store)->MarkDelivered(seq, 2).ok());  // twice is once
    ASSERT_TRUE((*store)->Undeliver(seq, {0}).ok());
  }
  auto store = JobStore::Open(dir);
  ASSERT_TRUE(store.ok()) << store.status();
  auto jobs = (*store)->Load();
  ASSERT_TRUE(jobs.ok()) << jobs.status();
  ASSERT_EQ(jobs->size(), 1u);
  const StoredJob& j = (*jobs)[0];
  EXPECT_EQ(j.seq, seq);
  EXPECT_EQ(j.spec.SerializeAsString(), MakeJob(3).SerializeAsString());
  EXPECT_EQ(j.owner, "ipv4:10.0.0.1");
  EXPECT_EQ(j.frames_total, 3);
  EXPECT_EQ(j.pixels_total, 3u * 32 * 24);
  EXPECT_EQ(j.submitted_unix, 1234.5);
  EXPECT_EQ(j.state, v1::FAILED);
  EXPECT_EQ(j.error, "broke");
  EXPECT_TRUE(j.cancel);
  EXPECT_EQ(j.delivered, (std::set<int>{2}));
  // Ids are never reused, even after the newest job is forgotten.
  ASSERT_TRUE((*store)->Forget(seq).ok());
  StoredJob next;
  next.spec = MakeJob(1);
  auto s2 = (*store)->Insert(next);
  ASSERT_TRUE(s2.ok());
  EXPECT_GT(*s2, seq);
}

TEST(JobStoreTest, OneRootPerStateDirectory) {
  const std::string dir = FreshDir("store_lock");
  auto first = JobStore::Open(dir);
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = JobStore::Open(dir);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(second.status().message().find("another root uses this state directory"),
            std::string::npos)
      << second.status();
  first->reset();
  EXPECT_TRUE(JobStore::Open(dir).ok()) << "the lock is released with the store";
}

TEST(JobStoreTest, RefusesAnotherSchemaAndGarbage) {
  const std::string dir = FreshDir("store_schema");
  ASSERT_TRUE(JobStore::Open(dir).ok());
  sqlite3* db;
  ASSERT_EQ(sqlite3_open((dir + "/jobs.db").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE meta SET value = '99' WHERE key = 'schema'", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  auto other = JobStore::Open(dir);
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.status().message().find("schema 99"), std::string::npos) << other.status();

  const std::string junk = FreshDir("store_junk");
  std::filesystem::create_directories(junk);
  std::ofstream(junk + "/jobs.db") << std::string(4096, 'x');
  auto bad = JobStore::Open(junk);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find(junk + "/jobs.db"), std::string::npos) << bad.status();
}

TEST(JobQueueTest, ARestartRunsUnfinishedJobsAndOnlyTheirUndeliveredFrames) {
  const std::string dir = FreshDir("queue_recover");
  std::string running_id, queued_id, cancelled_id, done_id;
  {
    auto store = JobStore::Open(dir);
    ASSERT_TRUE(store.ok());
    JobQueue queue(JobQueueOptions{}, **store);
    ASSERT_TRUE(queue.Recover(AnyPlan).ok());
    int position;
    auto done = queue.Submit(MakeJob(2), {}, "a", &position);
    auto running = queue.Submit(MakeJob(4), {}, "a", &position);
    auto queued = queue.Submit(MakeJob(1), {}, "a", &position);
    auto cancelled = queue.Submit(MakeJob(3), {}, "a", &position);
    ASSERT_TRUE(done.ok() && running.ok() && queued.ok() && cancelled.ok());
    EXPECT_EQ(position, 3);
    done_id = (*done)->id();
    running_id = (*running)->id();
    queued_id = (*queued)->id();
    cancelled_id = (*cancelled)->id();
    // The first job runs to the end and a watcher takes both frames.
    ASSERT_EQ(queue.Next(), *done);
    (*done)->SetRunning();
    RunAll(**done);
    EXPECT_EQ(Watch(**done), (std::set<int>{0, 1}));
    // The second delivers frames 0 and 2; frame 1 is rendered but nobody
    // took it; then the root dies (nothing more is written).
    ASSERT_EQ(queue.Next(), *running);
    (*running)->SetRunning();
    for (int f = 0; f < 3; ++f) {
      ASSERT_EQ((*running)->NextFrame(), f);
      ASSERT_TRUE((*running)->PublishImage(LastChunk(f), 1 << 20, std::chrono::seconds(5)).ok());
      (*running)->FrameRendered(f);
    }
    (*cancelled)->RequestCancel();
    std::thread watcher([&] {
      (*running)->Stream(
          [&](const v1::JobEvent& e) { return !(e.has_image() && e.frame() == 1); },
          [] { return false; }, {});
    });
    watcher.join();
    // Frame 0 went out whole; frame 1's write failed. Frame 2 is delivered
    // to a second watcher holding 1 already (say, from a broken stream).
    (*running)->Stream([](const v1::JobEvent&) { return true; }, [] { return true; }, {1});
  }
  auto store = JobStore::Open(dir);
  ASSERT_TRUE(store.ok()) << store.status();
  JobQueue queue(JobQueueOptions{}, **store);
  ASSERT_TRUE(queue.Recover(AnyPlan).ok());
  std::map<std::string, v1::JobState> states;
  for (const auto& s : queue.Summaries()) states[s.job_id()] = s.state();
  EXPECT_EQ(states[done_id], v1::DONE);
  EXPECT_EQ(states[running_id], v1::QUEUED);
  EXPECT_EQ(states[queued_id], v1::QUEUED);
  EXPECT_EQ(states[cancelled_id], v1::CANCELLED) << "a cancel asked before the restart sticks";
  // In submission order; the running job renders only frames 1 (its
  // image was lost) and 3 (never rendered). Frames 0 and 2 were
  // delivered (frame 2 counted delivered to the watcher that held it).
  auto job = queue.Next();
  ASSERT_EQ(job->id(), running_id);
  EXPECT_EQ(job->NextFrame(), 1);
  EXPECT_EQ(job->NextFrame(), 3);
  EXPECT_EQ(job->NextFrame(), std::nullopt);
  EXPECT_EQ(queue.Next()->id(), queued_id);
  // A new job gets a new id.
  int position;
  auto fresh = queue.Submit(MakeJob(1), {}, "a", &position);
  ASSERT_TRUE(fresh.ok());
  for (const std::string& id : {done_id, running_id, queued_id, cancelled_id}) {
    EXPECT_NE((*fresh)->id(), id);
  }
}

TEST(JobQueueTest, AStoppingRootLeavesItsJobsToTheNext) {
  const std::string dir = FreshDir("queue_stop");
  std::string id;
  {
    auto store = JobStore::Open(dir);
    ASSERT_TRUE(store.ok());
    JobQueue queue(JobQueueOptions{}, **store);
    int position;
    auto job = queue.Submit(MakeJob(2), {}, "a", &position);
    ASSERT_TRUE(job.ok());
    id = (*job)->id();
    ASSERT_EQ(queue.Next(), *job);
    (*job)->SetRunning();
    ASSERT_EQ((*job)->NextFrame(), 0);
    queue.Stop();
    EXPECT_TRUE((*job)->cancelled());
    EXPECT_TRUE((*job)->Complete(absl::CancelledError("cancelled")));
    EXPECT_TRUE((*job)->finished());
  }
  auto store = JobStore::Open(dir);
  ASSERT_TRUE(store.ok());
  JobQueue queue(JobQueueOptions{}, **store);
  ASSERT_TRUE(queue.Recover(AnyPlan).ok());
  auto job = queue.Next();
  ASSERT_NE(job, nullptr);
  EXPECT_EQ(job->id(), id);
  EXPECT_EQ(job->NextFrame(), 0);
}

TEST(JobQueueTest, ARecoveredJobThatNoLongerPlansFailsSayingWhy) {
  const std::string dir = FreshDir("queue_replan");
  {
    auto store = JobStore::Open(dir);
    ASSERT_TRUE(store.ok());
    JobQueue queue(JobQueueOptions{}, **store);
    int position;
    ASSERT_TRUE(queue.Submit(MakeJob(2), {}, "a", &position).ok());
  }
  auto store = JobStore::Open(dir);
  ASSERT_TRUE(store.ok());
  JobQueue queue(JobQueueOptions{}, **store);
  ASSERT_TRUE(queue.Recover([](const v1::Job&) -> absl::StatusOr<JobPlan> {
                     return absl::NotFoundError("datasets[0]: volume 'v.nrrd' not found");
                   }).ok());
  auto summaries = queue.Summaries();
  ASSERT_EQ(summaries.size(), 1u);
  EXPECT_EQ(summaries[0].state(), v1::FAILED);
  EXPECT_NE(summaries[0].error().find("v.nrrd' not found"), std::string::npos)
      << summaries[0].error();
  // ... and that is what the store says now.
  auto stored = (*store)->Load();
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ((*stored)[0].state, v1::FAILED);
}

TEST(JobQueueTest, LimitsPerClientAndPerJob) {
  auto store = JobStore::Open("");
  ASSERT_TRUE(store.ok());
  JobQueueOptions o;
  o.max_jobs_per_client = 2;
  o.max_queued = 3;
  o.max_job_pixels = 100 * 100 * 4;
  JobQueue queue(o, **store);
  int position;
  ASSERT_TRUE(queue.Submit(MakeJob(1), {}, "a", &position).ok());
  ASSERT_TRUE(queue.Submit(MakeJob(1), {}, "a", &position).ok());
  auto third = queue.Submit(MakeJob(1), {}, "a", &position);
  EXPECT_EQ(third.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(third.status().message().find("you have 2 jobs queued or running"), std::string::npos)
      << third.status();
  ASSERT_TRUE(queue.Submit(MakeJob(1), {}, "b", &position).ok()) << "another client is not held up";
  EXPECT_EQ(queue.Submit(MakeJob(1), {}, "c", &position).status().code(),
            absl::StatusCode::kResourceExhausted)
      << "the queue holds 3";
  // A finished job no longer counts against its client.
  auto first = queue.Next();
  RunAll(*first);
  EXPECT_TRUE(queue.Submit(MakeJob(1), {}, "a", &position).ok());

  auto big = queue.Submit(MakeJob(5, 100, 100), {}, "d", &position);
  EXPECT_EQ(big.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(big.status().message().find("50000 pixels"), std::string::npos) << big.status();
  EXPECT_NE(big.status().message().find("at most 40000"), std::string::npos) << big.status();
}

TEST(JobQueueTest, AResumingWatcherGetsTheFramesItLacksRenderedAgain) {
  auto store = JobStore::Open("");
  ASSERT_TRUE(store.ok());
  JobQueue queue(JobQueueOptions{}, **store);
  int position;
  auto job = queue.Submit(MakeJob(3), {}, "a", &position);
  ASSERT_TRUE(job.ok());
  ASSERT_EQ(queue.Next(), *job);
  RunAll(**job);
  EXPECT_EQ(Watch(**job), (std::set<int>{0, 1, 2}));
  // A watcher holding every frame needs nothing.
  EXPECT_FALSE((*job)->Resume({0, 1, 2}));
  // One that lost frame 1 (its stream broke after the root sent it): the
  // finished job runs again for that frame alone.
  EXPECT_TRUE((*job)->Resume({0, 2}));
  queue.Requeue(*job);
  EXPECT_FALSE((*job)->finished());
  EXPECT_EQ(queue.Next(), *job);
  EXPECT_EQ((*job)->NextFrame(), 1);
  ASSERT_TRUE((*job)->PublishImage(LastChunk(1), 1 << 20, std::chrono::seconds(5)).ok());
  (*job)->FrameRendered(1);
  EXPECT_EQ((*job)->NextFrame(), std::nullopt);
  ASSERT_TRUE((*job)->Complete(absl::OkStatus()));
  EXPECT_EQ(Watch(**job, {0, 2}), (std::set<int>{1}));
  // While a job runs, a frame it lacks becomes pending again and the
  // runner's turn does not end before it is rendered.
  auto second = queue.Submit(MakeJob(2), {}, "a", &position);
  ASSERT_TRUE(second.ok());
  ASSERT_EQ(queue.Next(), *second);
  while (auto f = (*second)->NextFrame()) {
    ASSERT_TRUE((*second)->PublishImage(LastChunk(*f), 1 << 20, std::chrono::seconds(5)).ok());
    (*second)->FrameRendered(*f);
  }
  std::thread([&] {
    (*second)->Stream([](const v1::JobEvent& e) { return !(e.has_image() && e.frame() == 1); },
                      [] { return false; }, {});
  }).join();
  EXPECT_FALSE((*second)->Resume({0})) << "still running: no requeue";
  EXPECT_FALSE((*second)->Complete(absl::OkStatus())) << "frame 1 is pending again";
  EXPECT_EQ((*second)->NextFrame(), 1);
}

}  // namespace
}  // namespace transtick
