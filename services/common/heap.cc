#include "heap.h"

#include <malloc.h>
#include <time.h>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <string>
#include <thread>

namespace transtick {

bool IdleTrim::Poll(std::chrono::nanoseconds cpu, std::chrono::nanoseconds interval) {
  const auto used = cpu - last_cpu_;
  last_cpu_ = cpu;
  if (used * 100 >= interval) {
    busy_ = true;
    return false;
  }
  const bool trim = busy_;
  busy_ = false;
  return trim;
}

namespace {

std::chrono::nanoseconds ProcessCpu() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec);
}

// $TRANSTICK_HEAP_KEEP_MB, 0 .. 2047 (mallopt takes an int of bytes); 64
// when unset or malformed.
int KeepMb() {
  constexpr int kDefault = 64;
  const char* env = std::getenv("TRANSTICK_HEAP_KEEP_MB");
  if (env == nullptr || *env == '\0') return kDefault;
  char* end = nullptr;
  const long mb = std::strtol(env, &end, 10);
  if (*end != '\0' || mb < 0 || mb > 2047) {
    std::cerr << "TRANSTICK_HEAP_KEEP_MB=" << env << " is not a number of MB in [0, 2047]; using "
              << kDefault << "\n";
    return kDefault;
  }
  return static_cast<int>(mb);
}

}  // namespace

void TuneHeap() {
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  mallopt(M_ARENA_MAX, static_cast<int>(std::max(2u, std::thread::hardware_concurrency())));
  // 0 leaves glibc's own 128 KB.
  if (const int keep = KeepMb(); keep > 0) mallopt(M_TRIM_THRESHOLD, keep << 20);
  std::thread([] {
    constexpr auto kInterval = std::chrono::seconds(1);
    IdleTrim idle;
    idle.Poll(ProcessCpu(), kInterval);
    for (;;) {
      std::this_thread::sleep_for(kInterval);
      if (idle.Poll(ProcessCpu(), kInterval)) malloc_trim(0);
    }
  }).detach();
}

}  // namespace transtick
