#include "transtick/volume.h"

#include <limits>
#include <map>
#include <mutex>

#include "transtick/parallel.h"

namespace transtick {

std::string_view ScalarTypeName(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
      return "uint8";
    case ScalarType::kInt8:
      return "int8";
    case ScalarType::kUint16:
      return "uint16";
    case ScalarType::kInt16:
      return "int16";
    case ScalarType::kUint32:
      return "uint32";
    case ScalarType::kInt32:
      return "int32";
    case ScalarType::kFloat32:
      return "float";
    case ScalarType::kFloat64:
      return "double";
  }
  return "unknown";
}

size_t ScalarTypeSize(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
    case ScalarType::kInt8:
      return 1;
    case ScalarType::kUint16:
    case ScalarType::kInt16:
      return 2;
    case ScalarType::kUint32:
    case ScalarType::kInt32:
    case ScalarType::kFloat32:
      return 4;
    case ScalarType::kFloat64:
      return 8;
  }
  return 0;
}

std::array<float, 2> Volume::Range() const {
  // NaN compares false both ways, so NaN samples never become the min or max;
  // infinities are left out too, so that the range has a width (a dvr table
  // from -inf or to +inf was NaN throughout). A volume with no finite
  // sample reports {0, 0} like an empty one.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // In ranges on as many threads, joined in order by the same rule, so
  // that of equal extremes (-0 and +0) the first is kept, as in one pass.
  std::mutex mu;
  std::map<size_t, std::array<float, 2>> parts;  // by the range's start
  ParallelFor(values.size(), size_t{1} << 18, [&](size_t begin, size_t end) {
    float lo = kInf;
    float hi = -kInf;
    for (size_t i = begin; i < end; ++i) {
      const float v = values[i];
      if (v < lo && v != -kInf) lo = v;
      if (v > hi && v != kInf) hi = v;
    }
    std::lock_guard<std::mutex> lock(mu);
    parts[begin] = {lo, hi};
  });
  float lo = kInf;
  float hi = -kInf;
  for (const auto& [begin, part] : parts) {
    if (part[0] < lo) lo = part[0];
    if (part[1] > hi) hi = part[1];
  }
  if (lo > hi) return {0.0f, 0.0f};
  return {lo, hi};
}

}  // namespace transtick
