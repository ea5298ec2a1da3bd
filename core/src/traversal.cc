#include "transtick/traversal.h"

namespace transtick {

std::optional<std::array<double, 2>> IntersectBox(const Vec3& origin, const Vec3& direction,
                                                  const std::array<int, 3>& dims) {
  double t0 = -std::numeric_limits<double>::infinity();
  double t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (!MovesAlong(direction[a])) {
      if (origin[a] < 0 || origin[a] > dims[a]) return std::nullopt;
      continue;
    }
    double inv = 1.0 / direction[a];
    double ta = (0 - origin[a]) * inv, tb = (dims[a] - origin[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  t0 = std::max(t0, 0.0);
  if (!(t0 < t1)) return std::nullopt;
  return std::array<double, 2>{t0, t1};
}

std::array<int32_t, 3> CellAt(const Vec3& origin, const Vec3& direction, double t,
                              const std::array<int, 3>& dims) {
  std::array<int32_t, 3> cell;
  for (int a = 0; a < 3; ++a) {
    cell[a] = FloorClamped(origin[a] + direction[a] * t, 0, dims[a] - 1);
  }
  return cell;
}

}  // namespace transtick
