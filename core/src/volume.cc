#include "transtick/volume.h"

#include <limits>

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
  float lo = kInf;
  float hi = -kInf;
  for (float v : values) {
    if (v < lo && v != -kInf) lo = v;
    if (v > hi && v != kInf) hi = v;
  }
  if (lo > hi) return {0.0f, 0.0f};
  return {lo, hi};
}

}  // namespace transtick
