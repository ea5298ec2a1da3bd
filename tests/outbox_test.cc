// The worker's Outbox: how records become batches on a stream with one
// write in flight, when a batch goes, and what happens when the stream
// closes or breaks. The stream here is a recorder; the real streams are
// exercised end to end in cluster_test and daemons_test.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "frame.h"

namespace transtick {
namespace {

using std::chrono::microseconds;

constexpr size_t kRecord = 4;

// `n` records, every byte `tag`.
std::string Records(int n, char tag) { return std::string(n * kRecord, tag); }

// A stream that records what it was asked to write and when it was
// half-closed; writes complete only when the test says so.
struct Recorder {
  std::vector<std::string> writes;
  int done = 0;
  void Attach(Outbox& box, bool busy = false) {
    box.Attach([this](std::string b) { writes.push_back(std::move(b)); }, [this] { ++done; },
               busy);
  }
};

TEST(OutboxTest, BatchGoesWhenFullAndOneWriteIsInFlight) {
  Outbox box(kRecord, /*batch_records=*/4, microseconds(60'000'000));
  Recorder s;
  s.Attach(box);
  box.Append(Records(3, 'a'));
  EXPECT_TRUE(s.writes.empty()) << "3 of 4 records, linger not reached";
  box.Append(Records(1, 'b'));
  ASSERT_EQ(s.writes.size(), 1u);
  EXPECT_EQ(s.writes[0], absl::StrCat(Records(3, 'a'), Records(1, 'b')));
  // While that write is in flight, a full batch waits.
  box.Append(Records(6, 'c'));
  EXPECT_EQ(s.writes.size(), 1u);
  box.WriteDone(true);
  ASSERT_EQ(s.writes.size(), 2u);
  EXPECT_EQ(s.writes[1], Records(4, 'c')) << "at most one batch per write";
  box.WriteDone(true);
  EXPECT_EQ(s.writes.size(), 2u) << "2 records left, not a full batch";
  box.Flush();
  ASSERT_EQ(s.writes.size(), 3u);
  EXPECT_EQ(s.writes[2], Records(2, 'c'));
  EXPECT_EQ(s.done, 0);
}

TEST(OutboxTest, LingerSendsAPartialBatchOnTheNextAppend) {
  Outbox box(kRecord, /*batch_records=*/1000, microseconds(2000));
  Recorder s;
  s.Attach(box);
  box.Append(Records(1, 'a'));
  EXPECT_TRUE(s.writes.empty());
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  box.Append(Records(1, 'b'));
  ASSERT_EQ(s.writes.size(), 1u);
  EXPECT_EQ(s.writes[0], absl::StrCat(Records(1, 'a'), Records(1, 'b')));
}

TEST(OutboxTest, RecordsBeforeAttachWaitForTheStream) {
  Outbox box(kRecord, 4, microseconds(60'000'000));
  box.Append(Records(5, 'a'));
  Recorder s;
  s.Attach(box);
  ASSERT_EQ(s.writes.size(), 1u);
  EXPECT_EQ(s.writes[0], Records(4, 'a'));
}

TEST(OutboxTest, BusyAttachWaitsForTheStreamsOwnFirstWrite) {
  Outbox box(kRecord, 1, microseconds(60'000'000));
  Recorder s;
  s.Attach(box, /*busy=*/true);
  box.Append(Records(1, 'a'));
  EXPECT_TRUE(s.writes.empty()) << "the stream's first message is still in flight";
  box.WriteDone(true);
  ASSERT_EQ(s.writes.size(), 1u);
}

TEST(OutboxTest, CloseDrainsThenHalfClosesOnce) {
  Outbox box(kRecord, 4, microseconds(60'000'000));
  Recorder s;
  s.Attach(box);
  box.Append(Records(6, 'a'));  // one batch goes, 2 records wait
  box.Close();
  EXPECT_EQ(s.done, 0) << "a write is in flight";
  box.WriteDone(true);
  ASSERT_EQ(s.writes.size(), 2u);
  EXPECT_EQ(s.writes[1], Records(2, 'a'));
  EXPECT_EQ(s.done, 0) << "the last batch is in flight";
  box.WriteDone(true);
  EXPECT_EQ(s.done, 1);
  box.Close();
  box.Append(Records(1, 'z'));
  box.Flush();
  EXPECT_EQ(s.done, 1);
  EXPECT_EQ(s.writes.size(), 2u);
  EXPECT_EQ(box.dropped(), 1u) << "a record after Close is dropped, and counted";
}

TEST(OutboxTest, BrokenStreamDropsAndCountsAndHalfCloses) {
  Outbox box(kRecord, 4, microseconds(60'000'000));
  Recorder s;
  s.Attach(box);
  box.Append(Records(4, 'a'));
  box.Append(Records(3, 'b'));
  ASSERT_EQ(s.writes.size(), 1u);
  box.WriteDone(false);
  EXPECT_EQ(box.dropped(), 3u);
  EXPECT_EQ(s.done, 1) << "a broken stream is closed at once, so its call can end";
  box.Append(Records(2, 'c'));
  EXPECT_EQ(box.dropped(), 5u);
  EXPECT_EQ(s.writes.size(), 1u);
  box.Close();
  EXPECT_EQ(s.done, 1);
}

TEST(OutboxTest, ManyProducersLoseNothing) {
  Outbox box(kRecord, 64, microseconds(100));
  std::mutex mu;
  std::vector<std::string> writes;
  std::atomic<int> done{0};
  // Completes every write on its own thread, as gRPC does.
  std::vector<std::thread> completions;
  box.Attach(
      [&](std::string b) {
        std::lock_guard<std::mutex> lock(mu);
        writes.push_back(std::move(b));
        completions.emplace_back([&] { box.WriteDone(true); });
      },
      [&] { ++done; }, false);
  std::vector<std::thread> producers;
  for (int p = 0; p < 4; ++p) {
    producers.emplace_back([&, p] {
      for (int i = 0; i < 1000; ++i) box.Append(Records(1 + i % 3, static_cast<char>('a' + p)));
    });
  }
  for (auto& t : producers) t.join();
  box.Close();
  for (int spin = 0; spin < 2000 && done == 0; ++spin) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  std::vector<std::thread> finished;
  {
    std::lock_guard<std::mutex> lock(mu);  // no write starts after the half-close
    finished.swap(completions);
  }
  for (auto& t : finished) t.join();
  ASSERT_EQ(done, 1);
  size_t bytes = 0;
  std::array<size_t, 4> per_producer{};
  for (const std::string& w : writes) {
    EXPECT_LE(w.size(), 64 * kRecord);
    bytes += w.size();
    for (char c : w) per_producer[c - 'a'] += 1;
  }
  // Each producer appended 1000 runs of 1, 2 or 3 records.
  const size_t each = (334 * 1 + 333 * 2 + 333 * 3) * kRecord;
  EXPECT_EQ(bytes, 4 * each);
  for (size_t n : per_producer) EXPECT_EQ(n, each);
  EXPECT_EQ(box.dropped(), 0u);
}

}  // namespace
}  // namespace transtick

namespace transtick {
namespace {

TEST(BufferPool, KeepsBigBuffersUpToItsBoundAndHandsThemBackEmpty) {
  BufferPool pool(1 << 20);
  std::string small;
  small.reserve(1 << 10);
  pool.Give(std::move(small));
  EXPECT_EQ(pool.held_bytes(), 0u) << "a small buffer is not worth keeping";
  for (int i = 0; i < 8; ++i) {
    std::string big(256 << 10, 'x');
    pool.Give(std::move(big));
  }
  EXPECT_LE(pool.held_bytes(), size_t{1} << 20) << "the pool outgrew its bound";
  EXPECT_GE(pool.held_bytes(), size_t{768} << 10);
  const size_t held = pool.held_bytes();
  std::string taken = pool.Take(100 << 10);
  EXPECT_TRUE(taken.empty());
  EXPECT_GE(taken.capacity(), size_t{100} << 10);
  EXPECT_EQ(pool.held_bytes(), held - taken.capacity());
  // None big enough: a new buffer of the capacity asked for.
  std::string fresh = pool.Take(4 << 20);
  EXPECT_GE(fresh.capacity(), size_t{4} << 20);
  EXPECT_EQ(pool.held_bytes(), held - taken.capacity());
}

}  // namespace
}  // namespace transtick
