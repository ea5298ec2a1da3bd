// Building a scene on every core: the loops of a build (classifying voxels,
// the field's labels and groups, the reach of brick maps, sticks) split
// into ranges that threads run at once. Each range writes only its own
// outputs, and outputs that are joined are joined in range order, so a
// build gives the same bytes on any number of threads.
#ifndef TRANSTICK_PARALLEL_H_
#define TRANSTICK_PARALLEL_H_

#include <cstddef>
#include <functional>

namespace transtick {

// The threads a build uses: by default one per core. Thread-safe; a
// process that also traces (a worker) may set it to its tracer threads.
// n < 1 restores the default.
int BuildThreads();
void SetBuildThreads(int n);

// Calls fn(begin, end) over consecutive ranges of nearly equal size that
// cover [0, n), each on a thread of its own (the calling thread takes the
// first, and any range no thread could be started for): at most
// BuildThreads() ranges, none of fewer than `grain` items unless there is
// only one. Returns when all have returned. fn must be safe to call from
// several threads at once on disjoint ranges.
void ParallelFor(size_t n, size_t grain, const std::function<void(size_t, size_t)>& fn);

}  // namespace transtick

#endif  // TRANSTICK_PARALLEL_H_
