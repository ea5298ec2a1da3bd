// How a ring's slabs are cut along Y: uniformly, or re-cut from the cost
// each slab was measured to take (the paper's static load balancing,
// section 3.4). Cuts are n + 1 increasing plane indices from 0 to the
// number of planes; slab i is [cuts[i], cuts[i + 1]) and holds at least one
// plane (its ghost planes come on top).
#ifndef TRANSTICK_PARTITION_H_
#define TRANSTICK_PARTITION_H_

#include <string_view>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

// n slabs of (nearly) equal thickness. REQUIRES: 1 <= slabs <= planes.
std::vector<int> UniformCuts(int planes, int slabs);

enum class BalanceRule {
  // Each slab's cost spread over its planes by its work profile (evenly
  // without one); the running sum of cost cut into n equal parts. Exact
  // when the profile is in proportion to the cost within each slab,
  // whatever the cost is across slabs.
  kCost,
  // The 1991 rule: size[i] += (t_mean - t_i) / t_plane with t_plane =
  // sum(t) / planes, i.e. one global cost per plane.
  kPaper,
};


// New cuts for the same number of slabs and planes, from the measured cost
// of each slab under `cuts` and, for kCost, how the work was spread over
// each slab's planes (profiles[i][k] for plane cuts[i] + k; a profile that
// is missing, of another size or all zero counts as even). Returns `cuts`
// unchanged when the costs carry no information (all zero, or a negative
// or non-finite one).
// REQUIRES: cuts valid (see above); costs.size() + 1 == cuts.size().
std::vector<int> BalancedCuts(const std::vector<int>& cuts, const std::vector<double>& costs,
                              BalanceRule rule,
                              const std::vector<std::vector<double>>& profiles = {});

// True when `cuts` are valid cuts of `planes` planes into `slabs` slabs.
bool ValidCuts(const std::vector<int>& cuts, int planes, int slabs);

}  // namespace transtick

#endif  // TRANSTICK_PARTITION_H_
