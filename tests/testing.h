// Helpers shared by the tests: where the real data is, temporary files, and
// a small in-process dataflow over slabs.
#ifndef TRANSTICK_TESTS_TESTING_H_
#define TRANSTICK_TESTS_TESTING_H_

#include <string>
#include <vector>

#include "transtick/camera.h"
#include "transtick/framebuffer.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"

namespace transtick::testing {

// The directory of the shared real volumes ($TRANSTICK_DATA_DIR or
// ../shared/data beside the source tree).
std::string DataDir();
// A path to a real volume, or "" when it is absent (the test then skips).
std::string DataFile(const std::string& name);

// A fresh directory for this test's files.
std::string TempDir();

// Cuts `whole` into slabs at `cuts` (ascending, exclusive of 0 and ny) and
// traces every pixel as the cluster does: each slab makes its own primary
// rays and passes rays that leave it to a neighbour, both by RingLayout.
// Counts the hand-overs (one per hop) in *handoffs, and the rays that ended
// at a slab's plane with nothing ahead (TraceCounters::ended_early) in
// *ended_early.
Image RenderSlabs(const Scene& whole, const std::vector<int>& cuts, const Camera& camera,
                  const RenderSettings& settings, uint64_t* handoffs = nullptr,
                  uint64_t* ended_early = nullptr);

// Renders the whole scene on `threads` threads.
Image RenderWhole(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                  int threads = 2);

// A camera for a `size` x `size` image of a volume of `dims` (spacing 1).
Camera MakeCamera(std::array<int, 3> dims, int size, double azimuth, double elevation,
                  Projection projection = Projection::kPerspective, double zoom = 1);

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_TESTING_H_
