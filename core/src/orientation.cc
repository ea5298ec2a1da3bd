#include "transtick/orientation.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace transtick {
namespace {

using Axis = std::array<double, 3>;

double Dot(const Axis& a, const Axis& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

Axis Cross(const Axis& a, const Axis& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

Axis Scaled(const Axis& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }

Axis Minus(const Axis& a, const Axis& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

bool Finite(const Axis& a) {
  return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]);
}

absl::Status Error(const std::string& path, const std::string& message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": ", message));
}

// + 0.0 prints -0 as 0.
std::string Format(const Axis& a) {
  return absl::StrFormat("(%g, %g, %g)", a[0] + 0.0, a[1] + 0.0, a[2] + 0.0);
}

}  // namespace

bool IsIdentity(const Direction& direction) { return direction == kIdentityDirection; }

absl::Status SetOrientation(const std::string& path, const std::array<Axis, 3>& axes,
                            const Axis& origin, Volume* volume) {
  static constexpr char kName[] = "xyz";
  Direction d;
  for (int a = 0; a < 3; ++a) {
    const double length = std::sqrt(Dot(axes[a], axes[a]));
    if (!Finite(axes[a]) || !(length > 0) || !std::isfinite(length)) {
      return Error(path, absl::StrCat("orientation: the ", std::string(1, kName[a]), " axis ",
                                      Format(axes[a]), " is not a finite non-zero vector"));
    }
    d[a] = Scaled(axes[a], 1.0 / length);
  }
  if (!Finite(origin)) {
    return Error(path, absl::StrCat("orientation: origin ", Format(origin), " is not finite"));
  }
  for (int a = 0; a < 3; ++a) {
    for (int b = a + 1; b < 3; ++b) {
      const double c = Dot(d[a], d[b]);
      if (std::fabs(c) > kMaxAxisCosine) {
        return Error(path, absl::StrFormat(
                               "orientation: the %c and %c axes %s and %s are at %.3f degrees, "
                               "not orthogonal (a sheared grid is not supported)",
                               kName[a], kName[b], Format(axes[a]), Format(axes[b]),
                               std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI));
      }
    }
  }
  // Exactly orthonormal, so that the camera's mapping is a rotation.
  d[1] = Minus(d[1], Scaled(d[0], Dot(d[0], d[1])));
  d[1] = Scaled(d[1], 1.0 / std::sqrt(Dot(d[1], d[1])));
  const Axis z = Cross(d[0], d[1]);
  const bool reflection = Dot(z, d[2]) < 0;
  Axis o = origin;
  if (reflection) {
    // The same samples in the same places, indexed from the other end of x.
    const int nx = volume->dims[0];
    o = {origin[0] + d[0][0] * (nx - 1) * volume->spacing[0],
         origin[1] + d[0][1] * (nx - 1) * volume->spacing[0],
         origin[2] + d[0][2] * (nx - 1) * volume->spacing[0]};
    d[0] = Scaled(d[0], -1.0);
    const size_t rows = static_cast<size_t>(volume->dims[1]) * volume->dims[2];
    for (size_t r = 0; r < rows; ++r) {
      float* row = volume->values.data() + r * nx;
      std::reverse(row, row + nx);
    }
    volume->x_reversed = !volume->x_reversed;
  }
  d[2] = Cross(d[0], d[1]);
  // Axes that are already the identity (to rounding) stay exactly it, so
  // that their renders keep their bits.
  bool near_identity = true;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      if (std::fabs(d[a][b] - (a == b ? 1.0 : 0.0)) > 1e-12) near_identity = false;
    }
  }
  volume->direction = near_identity ? kIdentityDirection : d;
  volume->origin = o;
  return absl::OkStatus();
}

std::string OrientationCode(const Direction& direction) {
  static constexpr char kPositive[] = "LPS", kNegative[] = "RAI";
  std::string code;
  for (const Axis& axis : direction) {
    int best = 0;
    for (int w = 1; w < 3; ++w) {
      if (std::fabs(axis[w]) > std::fabs(axis[best])) best = w;
    }
    code += axis[best] >= 0 ? kPositive[best] : kNegative[best];
  }
  return code;
}

std::string DescribeOrientation(const Volume& volume) {
  std::string text = absl::StrCat("orientation ", OrientationCode(volume.direction), " (LPS world: x ",
                                  Format(volume.direction[0]), ", y ", Format(volume.direction[1]),
                                  ", z ", Format(volume.direction[2]), "), origin ",
                                  Format(volume.origin));
  if (volume.x_reversed) absl::StrAppend(&text, "; x reversed on reading (the file's axes are a reflection)");
  return text;
}

}  // namespace transtick
