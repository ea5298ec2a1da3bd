#ifndef TRANSTICK_SERVICES_COMMON_HEAP_H_
#define TRANSTICK_SERVICES_COMMON_HEAP_H_

#include <chrono>

namespace transtick {

// How a daemon's heap is kept: fast while frames run, small when idle.
//
// Every allocation of 1 MB or more is its own mapping, returned to the system
// when freed. glibc otherwise raises that threshold after the first such free,
// and slabs, scenes and ray batches freed frame after frame then fragment the
// heap: a worker's RSS grew 45-100 MB over 20 jobs with the default
// (bench/soak.sh).
//
// The smaller blocks' heap keeps up to 64 MB free at its top while the daemon
// is busy, instead of the 128 KB glibc keeps once the mapping threshold is
// set: every frame frees and allocates again megabytes of sub-megabyte blocks
// (ray batches, messages, deposits), and handing them back to the system at
// once made each frame fault its pages in anew, a third of a frame on a
// virtual machine (bench/turntable.sh, 2 workers: 4.6-5.1 frames/s, 7.5-7.6
// with the 64 MB). $TRANSTICK_HEAP_KEEP_MB sets that amount (0: glibc's).
//
// Threads share at most one arena per core (glibc makes up to 8 per core):
// each arena keeps its own free blocks, and with gRPC's many threads a
// worker's idle RSS grew 25-33 MB over 100 jobs instead of 7-9 MB.
//
// A thread polls the process's CPU time every second and, the first time a
// second passes with under 1% of a core used after busy ones, returns every
// free page of every arena to the system (malloc_trim): a finished job's
// memory goes back within about a second of its end.
//
// Call first in main, before other threads start.
void TuneHeap();

// The idle detector above, apart from the clock: fed the process's CPU time at
// each poll and the time since the last, says when to trim: once per idle
// spell, the first poll that used under 1% of the interval after one that did
// not (the start counts as busy).
class IdleTrim {
 public:
  bool Poll(std::chrono::nanoseconds cpu, std::chrono::nanoseconds interval);

 private:
  std::chrono::nanoseconds last_cpu_{0};
  bool busy_ = true;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_HEAP_H_
