#include "transtick/partition.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "transtick/check.h"

namespace transtick {
namespace {

// Rounds real cut positions to planes, keeping every slab at least one
// plane thick.
std::vector<int> RoundCuts(const std::vector<double>& real, int planes) {
  const int n = static_cast<int>(real.size()) - 1;
  std::vector<int> cuts(n + 1);
  cuts[0] = 0;
  cuts[n] = planes;
  for (int i = 1; i < n; ++i) {
    const int lo = cuts[i - 1] + 1;   // one plane after the previous cut
    const int hi = planes - (n - i);  // room for the slabs after this one
    cuts[i] = std::clamp(static_cast<int>(std::lround(real[i])), lo, hi);
  }
  return cuts;
}

}  // namespace

std::vector<int> UniformCuts(int planes, int slabs) {
  TRANSTICK_CHECK(slabs >= 1 && slabs <= planes);
  std::vector<int> cuts(slabs + 1);
  for (int i = 0; i <= slabs; ++i) cuts[i] = static_cast<int>(int64_t{i} * planes / slabs);
  return cuts;
}

bool ValidCuts(const std::vector<int>& cuts, int planes, int slabs) {
  if (static_cast<int>(cuts.size()) != slabs + 1 || cuts.front() != 0 || cuts.back() != planes) {
    return false;
  }
  for (size_t i = 1; i < cuts.size(); ++i) {
    if (cuts[i] <= cuts[i - 1]) return false;
  }
  return true;
}

std::vector<int> BalancedCuts(const std::vector<int>& cuts, const std::vector<double>& costs,
                              BalanceRule rule, const std::vector<std::vector<double>>& profiles) {
  const int n = static_cast<int>(costs.size());
  TRANSTICK_CHECK(n >= 1 && cuts.size() == costs.size() + 1);
  const int planes = cuts.back();
  double total = 0;
  for (double c : costs) {
    if (!std::isfinite(c) || c < 0) return cuts;
    total += c;
  }
  if (n == 1 || total <= 0) return cuts;
  std::vector<double> real(n + 1);
  real[0] = 0;
  real[n] = planes;
  if (rule == BalanceRule::kPaper) {
    // size[i] += (t_mean - t_i) / t_plane, then at least one plane each and
    // scaled back to the number of planes.
    const double mean = total / n, per_plane = total / planes;
    std::vector<double> size(n);
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      size[i] = std::max(1.0, (cuts[i + 1] - cuts[i]) + (mean - costs[i]) / per_plane);
      sum += size[i];
    }
    for (int i = 1; i < n; ++i) real[i] = real[i - 1] + size[i - 1] * planes / sum;
    return RoundCuts(real, planes);
  }
  // The cost of each plane: its slab's cost shared by the slab's profile
  // (evenly without one), with a floor so that a plane measured at zero
  // still has some (traversing empty space is not free) and the running
  // sum is strictly increasing.
  const double floor = 1e-3 * total / planes;
  std::vector<double> plane_cost(planes);
  for (int i = 0; i < n; ++i) {
    const int size = cuts[i + 1] - cuts[i];
    double weight = 0;
    const bool profiled = i < static_cast<int>(profiles.size()) &&
                          static_cast<int>(profiles[i].size()) == size;
    if (profiled) {
      for (double w : profiles[i]) {
        if (!std::isfinite(w) || w < 0) {
          weight = 0;
          break;
        }
        weight += w;
      }
    }
    for (int k = 0; k < size; ++k) {
      const double share = weight > 0 ? profiles[i][k] / weight : 1.0 / size;
      plane_cost[cuts[i] + k] = std::max(floor, costs[i] * share);
    }
  }
  double sum = 0;
  for (double c : plane_cost) sum += c;
  // Walk the running sum and place cut k where it reaches k / n of the
  // total, within a plane in proportion to its cost.
  int plane = 0;
  double before = 0;  // running sum up to plane `plane`
  for (int k = 1; k < n; ++k) {
    const double target = sum * k / n;
    while (plane < planes - 1 && before + plane_cost[plane] < target) {
      before += plane_cost[plane];
      ++plane;
    }
    real[k] = plane + std::clamp((target - before) / plane_cost[plane], 0.0, 1.0);
  }
  return RoundCuts(real, planes);
}

}  // namespace transtick
