// Static load balancing of a frame's slabs (docs/balancing.md) as policies:
// "off" keeps the uniform cuts, "test-rays" re-cuts from a prerender of
// test rays through the same camera (the paper's section 3.4) and reuses
// the cuts for the same view, "previous-frame" re-cuts the next frame from
// this frame's costs. Used by the runner thread only.
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
  std::string mode;
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
  // After the frame: what the next frame starts from.
  virtual void Learn(const FrameResult& frame, const Layout& layout, BalanceMemory& memory,
                     BalanceReport* report);
};

// The policy named `mode` ("", "off", "test-rays", "previous-frame"), or an
// error naming the modes. `grid` is the test-ray grid (0: the default).
absl::StatusOr<std::unique_ptr<Balancer>> MakeBalancer(std::string_view mode, BalanceRule rule,
                                                       int grid);
absl::Status CheckBalanceMode(std::string_view mode);

// The view as it determines the image's rays: what balancing cuts depend on.
std::string ViewKey(const v1::View& view);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_BALANCER_H_
