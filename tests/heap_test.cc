// The daemons' heap policy (services/common/heap.h): when the idle detector
// trims, and that the heap really holds freed memory while busy and gives it
// back on a trim.

#include "heap.h"

#include <gtest/gtest.h>
#include <malloc.h>

#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace transtick {
namespace {

using std::chrono::milliseconds;
using std::chrono::nanoseconds;

TEST(IdleTrim, TrimsOncePerIdleSpellAfterBusyOnes) {
  IdleTrim idle;
  const milliseconds second(1000);
  nanoseconds cpu(0);
  // The start counts as busy: the first quiet second trims.
  EXPECT_TRUE(idle.Poll(cpu, second));
  EXPECT_FALSE(idle.Poll(cpu += milliseconds(2), second));   // still idle
  EXPECT_FALSE(idle.Poll(cpu += milliseconds(9), second));   // 0.9%: idle
  EXPECT_FALSE(idle.Poll(cpu += milliseconds(10), second));  // 1%: busy
  EXPECT_TRUE(idle.Poll(cpu += milliseconds(3), second));
  EXPECT_FALSE(idle.Poll(cpu, second));
}

TEST(IdleTrim, RandomLoadsTrimExactlyAtBusyToIdleEdges) {
  std::mt19937 rng(17);
  for (int run = 0; run < 200; ++run) {
    IdleTrim idle;
    const nanoseconds interval = milliseconds(100 + rng() % 2000);
    nanoseconds cpu(0);
    bool was_busy = true;
    for (int poll = 0; poll < 100; ++poll) {
      // Half the polls busy (at least 1% of the interval), half idle.
      const bool busy = rng() % 2;
      const auto used = busy ? interval / 100 + nanoseconds(rng() % 2000000000)
                             : nanoseconds(rng() % (interval.count() / 100));
      cpu += used;
      EXPECT_EQ(idle.Poll(cpu, interval), was_busy && !busy) << run << " " << poll;
      was_busy = busy;
    }
  }
}

int64_t ResidentKb() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stoll(line.substr(6));
  }
  return -1;
}

TEST(Heap, HoldsFreedBlocksUnderTheThresholdAndTrimGivesThemBack) {
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  mallopt(M_TRIM_THRESHOLD, 64 << 20);
  malloc_trim(0);
  const int64_t base = ResidentKb();
  {
    // 48 MB in blocks of 256 KB, touched, then freed: what a frame's ray
    // batches do.
    std::vector<std::vector<char>> blocks;
    for (int i = 0; i < 192; ++i) blocks.emplace_back(256 << 10, char(i));
  }
  const int64_t held = ResidentKb();
  EXPECT_GT(held - base, 40 << 10) << "freed blocks were not kept for the next frame";
  malloc_trim(0);
  const int64_t trimmed = ResidentKb();
  EXPECT_LT(trimmed - base, 8 << 10) << "a trim did not return the freed blocks";
}

}  // namespace
}  // namespace transtick
