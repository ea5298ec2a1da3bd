// Static load balancing of a frame's slabs (docs/balancing.md) as policies:
// OFF keeps the uniform cuts, TEST_RAYS re-cuts from a prerender of test
// rays through the same camera (the paper's section 3.4) and reuses the
// cuts for the same view, PREVIOUS_FRAME re-cuts the next frame from this
// frame's costs. Used by the runner thread only.
#ifndef TRANSTICK_SERVICES_ROOT_BALANCER_H_
#define TRANSTICK_SERVICES_ROOT_BALANCER_H_

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "datasets.h"
#include "frame_driver.h"
#include "slabs.h"
#include "transtick/partition.h"

namespace transtick {

// What balancing did for a frame, for its statistics.
struct BalanceReport {
  std::string job_id;  // for the log
  v1::BalanceMode mode = v1::OFF;
  std::vector<std::vector<int>> cuts_before, cuts_after;
  std::map<std::string, double> test_ray_ms;  // by worker id
  double balance_ms = 0;
};

class Balancer {
 public:
  // Distributes `layout`'s slabs and runs a frame of `test` on them that
  // reports statistics only.
  using Prerender =
      std::function<absl::StatusOr<FrameResult>(const v1::View& test, Layout& layout)>;

  virtual ~Balancer() = default;

  // Sets the cuts of `layout` for a frame of `view`, from what `memory`
  // holds or from a prerender. REQUIRES: memory belongs to the layout's
  // members (Layout::Members).
  virtual absl::Status Plan(const v1::View& view, BalanceMemory& memory, Layout& layout,
                            const Prerender& prerender, BalanceReport* report) = 0;
  // Whether Learn reads the frames' work profiles, so that the workers
  // must count them (FrameSpec.work_profile; a prerender always counts).
  virtual bool LearnsFromProfiles() const { return false; }
  // After a frame of `view`: what the next frame starts from.
  virtual void Learn(const v1::View& view, const FrameResult& frame, const Layout& layout,
                     BalanceMemory& memory, BalanceReport* report);
};

// "test-rays" remembers the cuts, profile and measured costs of at most
// this many views per dataset and ring members (a few KB each), forgetting
// the oldest first.
inline constexpr size_t kMaxBalancedViews = 1024;

// The policy for `mode` (BALANCE_DEFAULT is OFF). `grid` is the test-ray
// grid (0: the default).
std::unique_ptr<Balancer> MakeBalancer(v1::BalanceMode mode, BalanceRule rule, int grid);

// The view as it determines the image's rays: what balancing cuts depend on.
std::string ViewKey(const v1::View& view);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_BALANCER_H_
