#include "transtick/parallel.h"

#include <algorithm>
#include <atomic>
#include <system_error>
#include <thread>
#include <vector>

namespace transtick {
namespace {

std::atomic<int> build_threads{0};  // 0: one per core

}  // namespace

int BuildThreads() {
  const int n = build_threads.load(std::memory_order_relaxed);
  if (n > 0) return n;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

void SetBuildThreads(int n) { build_threads.store(std::max(n, 0), std::memory_order_relaxed); }

void ParallelFor(size_t n, size_t grain, const std::function<void(size_t, size_t)>& fn) {
  if (n == 0) return;
  grain = std::max<size_t>(grain, 1);
  const size_t ranges = std::min<size_t>(static_cast<size_t>(BuildThreads()), n / grain);
  if (ranges <= 1) {
    fn(0, n);
    return;
  }
  // Ranges of equal size but for the remainder, spread over the first.
  const size_t base = n / ranges, extra = n % ranges;
  auto range = [&](size_t k) {
    const size_t begin = k * base + std::min(k, extra);
    return std::pair{begin, begin + base + (k < extra ? 1 : 0)};
  };
  std::vector<std::thread> threads;
  threads.reserve(ranges - 1);
  size_t started = 1;
  try {
    for (; started < ranges; ++started) {
      threads.emplace_back([&fn, r = range(started)] { fn(r.first, r.second); });
    }
  } catch (const std::system_error&) {
    // No thread to be had (a process at its limit): the ranges not
    // started run here, after the first.
  }
  const auto first = range(0);
  fn(first.first, first.second);
  for (size_t k = started; k < ranges; ++k) {
    const auto r = range(k);
    fn(r.first, r.second);
  }
  for (std::thread& t : threads) t.join();
}

}  // namespace transtick
