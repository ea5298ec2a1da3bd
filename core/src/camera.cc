#include "transtick/camera.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// How far from the volume's centre (world units) an explicit view's eye and
// target may be. A double places a point at distance D to about D * 1e-16,
// so beyond this a ray's entry into any volume of a millimetre or more is
// rounding; and the lengths of longer vectors soon overflow. The same for
// every volume, so that a view is refused when it is checked, before any
// volume is read (ToCameraSpec).
constexpr double kMaxViewDistance = 1e15;

}  // namespace

absl::StatusOr<Camera> Camera::Create(const CameraSpec& spec, const Vec3& volume_extent) {
  if (spec.width < 1 || spec.height < 1 || spec.width > CameraSpec::kMaxImageSize ||
      spec.height > CameraSpec::kMaxImageSize) {
    return absl::InvalidArgumentError(absl::StrCat("image size ", spec.width, "x", spec.height,
                                                   " is outside 1x1 .. ", CameraSpec::kMaxImageSize,
                                                   "x", CameraSpec::kMaxImageSize));
  }
  if (!std::isfinite(spec.zoom) || spec.zoom < 1e-3 || spec.zoom > 1e3) {
    return absl::InvalidArgumentError(
        absl::StrCat("zoom ", spec.zoom, " is outside [0.001, 1000]"));
  }
  if (!std::isfinite(spec.fov_deg) || spec.fov_deg <= 0.5 || spec.fov_deg >= 170) {
    return absl::InvalidArgumentError(
        absl::StrCat("field of view ", spec.fov_deg, " degrees is outside (0.5, 170)"));
  }
  if (!std::isfinite(spec.azimuth_deg) || !std::isfinite(spec.elevation_deg)) {
    return absl::InvalidArgumentError("azimuth and elevation must be finite");
  }
  Camera c;
  c.projection_ = spec.projection;
  c.width_ = spec.width;
  c.height_ = spec.height;
  const double radius = 0.5 * Length(volume_extent);
  const double half_fov = 0.5 * spec.fov_deg * kDeg;
  Vec3 target{0, 0, 0};
  Vec3 up_hint{0, 1, 0};
  if (spec.view) {
    c.eye_ = spec.view->eye;
    target = spec.view->target;
    up_hint = spec.view->up;
    for (int a = 0; a < 3; ++a) {
      if (!std::isfinite(c.eye_[a]) || !std::isfinite(target[a]) || !std::isfinite(up_hint[a])) {
        return absl::InvalidArgumentError("explicit view: eye, target and up must be finite");
      }
    }
    for (const auto& [name, point] : {std::pair{"eye", c.eye_}, std::pair{"target", target}}) {
      // Not finite when the length overflows: refused too.
      if (!(Length(point) <= kMaxViewDistance)) {
        return absl::InvalidArgumentError(
            absl::StrCat("explicit view: the ", name, " (", point.x, ", ", point.y, ", ", point.z,
                         ") is more than ", kMaxViewDistance, " world units from the volume"));
      }
    }
    const double up_scale =
        std::max({std::fabs(up_hint.x), std::fabs(up_hint.y), std::fabs(up_hint.z)});
    if (up_scale == 0) return absl::InvalidArgumentError("explicit view: up is zero");
    // An up whose length overflows, or whose squares underflow, is scaled
    // to components of at most 1; any other gives the bits it always gave.
    if (const double length = Length(up_hint); !std::isfinite(length) || length < 1e-100) {
      up_hint = {up_hint.x / up_scale, up_hint.y / up_scale, up_hint.z / up_scale};
    }
  } else {
    const double az = spec.azimuth_deg * kDeg, el = spec.elevation_deg * kDeg;
    // Azimuth 0, elevation 0: the eye on +Z looking along -Z.
    Vec3 toward_eye{std::sin(az) * std::cos(el), std::sin(el), std::cos(az) * std::cos(el)};
    double distance = radius / std::sin(half_fov) * 1.05;
    c.eye_ = target + toward_eye * distance;
    // Near the poles the world's Y is no use as an up hint.
    if (std::fabs(std::cos(el)) < 1e-6) up_hint = {-std::sin(az), 0, -std::cos(az)};
  }
  Vec3 forward = target - c.eye_;
  if (Length(forward) < 1e-12) {
    return absl::InvalidArgumentError("explicit view: eye and target coincide");
  }
  c.forward_ = Normalize(forward);
  Vec3 right = Cross(c.forward_, up_hint);
  // Relative to the hint's length: a short up is as good as a long one.
  if (Length(right) < 1e-9 * Length(up_hint)) {
    return absl::InvalidArgumentError("explicit view: up is parallel to the view direction");
  }
  c.right_ = Normalize(right);
  c.up_ = Cross(c.right_, c.forward_);
  if (spec.projection == Projection::kPerspective) {
    c.half_height_ = std::tan(half_fov) / spec.zoom;
  } else {
    c.half_height_ = radius * 1.05 / spec.zoom;
  }
  return c;
}

std::array<double, 2> SampleOffset(int sample, int samples) {
  if (samples <= 1) return {0.5, 0.5};
  const int side = static_cast<int>(std::lround(std::sqrt(static_cast<double>(samples))));
  if (side * side == samples) {
    return {(sample % side + 0.5) / side, (sample / side + 0.5) / side};
  }
  const double y = 0.5 + sample * 0.6180339887498949;
  return {(sample + 0.5) / samples, y - std::floor(y)};
}

WorldRay Camera::GenerateAt(int px, int py, double ox, double oy) const {
  const double aspect = static_cast<double>(width_) / height_;
  const double sx = (2.0 * (px + ox) / width_ - 1.0) * aspect * half_height_;
  const double sy = (1.0 - 2.0 * (py + oy) / height_) * half_height_;
  if (projection_ == Projection::kPerspective) {
    return {eye_, Normalize(forward_ + right_ * sx + up_ * sy)};
  }
  // Orthographic: parallel rays from a plane through the eye.
  return {eye_ + right_ * sx + up_ * sy, forward_};
}

bool Camera::ProjectCorners(const Vec3& lo, const Vec3& hi,
                            std::array<std::pair<double, double>, 8>* points) const {
  const double aspect = static_cast<double>(width_) / height_;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 p{corner & 1 ? hi[0] : lo[0], corner & 2 ? hi[1] : lo[1], corner & 4 ? hi[2] : lo[2]};
    const Vec3 d = p - eye_;
    double sx = Dot(d, right_), sy = Dot(d, up_);
    if (projection_ == Projection::kPerspective) {
      const double depth = Dot(d, forward_);
      if (depth <= 1e-9 * (1 + Length(d))) return false;
      sx /= depth;
      sy /= depth;
    }
    // Generate, inverted: pixel (c, r) has its centre at (c, r).
    const double x = (sx / (aspect * half_height_) + 1.0) * 0.5 * width_ - 0.5;
    const double y = (1.0 - sy / half_height_) * 0.5 * height_ - 0.5;
    if (!std::isfinite(x) || !std::isfinite(y)) return false;
    (*points)[corner] = {x, y};
  }
  return true;
}

namespace {

constexpr double kFootprintMargin = 2;  // pixels, against rounding

// floor(v) as a pixel index clamped to [lo_limit, hi_limit] (NaN: lo_limit).
int ClampPixel(double v, int lo_limit, int hi_limit) {
  if (!(v > lo_limit)) return lo_limit;
  if (v > hi_limit) return hi_limit;
  return static_cast<int>(v);
}

}  // namespace

Camera::PixelRect Camera::Bounds(const Vec3& lo, const Vec3& hi) const {
  std::array<std::pair<double, double>, 8> points;
  if (!ProjectCorners(lo, hi, &points)) return {0, 0, width_, height_};
  double x_min = HUGE_VAL, x_max = -HUGE_VAL, y_min = HUGE_VAL, y_max = -HUGE_VAL;
  for (const auto& [x, y] : points) {
    x_min = std::min(x_min, x);
    x_max = std::max(x_max, x);
    y_min = std::min(y_min, y);
    y_max = std::max(y_max, y);
  }
  // Row r spans [r - 0.5, r + 0.5), as column c does: Footprint's bounds.
  const double m = kFootprintMargin;
  return {ClampPixel(std::floor(x_min - m), 0, width_),
          ClampPixel(std::floor(y_min - m), 0, height_),
          ClampPixel(std::ceil(x_max + m) + 1, 0, width_),
          ClampPixel(std::ceil(y_max + m) + 1, 0, height_)};
}

ImageSpans Camera::Footprint(const Vec3& lo, const Vec3& hi) const {
  ImageSpans spans;
  spans.rows.assign(height_, {0, width_});  // the whole image
  std::array<std::pair<double, double>, 8> points;
  if (!ProjectCorners(lo, hi, &points)) return spans;
  // The box projects onto the convex hull of its corners (Andrew's
  // monotone chain, counterclockwise in these coordinates).
  std::sort(points.begin(), points.end());
  std::array<std::pair<double, double>, 16> hull;
  int n = 0;
  auto turn = [](const std::pair<double, double>& o, const std::pair<double, double>& a,
                 const std::pair<double, double>& b) {
    return (a.first - o.first) * (b.second - o.second) -
           (a.second - o.second) * (b.first - o.first);
  };
  for (int i = 0; i < 8; ++i) {
    while (n >= 2 && turn(hull[n - 2], hull[n - 1], points[i]) <= 0) --n;
    hull[n++] = points[i];
  }
  for (int i = 6, lower = n + 1; i >= 0; --i) {
    while (n >= lower && turn(hull[n - 2], hull[n - 1], points[i]) <= 0) --n;
    hull[n++] = points[i];
  }
  n = std::max(n - 1, 1);  // the last point repeats the first
  constexpr double kMargin = kFootprintMargin;
  for (int row = 0; row < height_; ++row) {
    // The hull's extent along x within the row's band, margin included:
    // the ends of its edges' parts in the band (and a lone point's).
    const double y_lo = row - 0.5 - kMargin, y_hi = row + 0.5 + kMargin;
    double x_min = HUGE_VAL, x_max = -HUGE_VAL;
    auto take = [&](double x) {
      x_min = std::min(x_min, x);
      x_max = std::max(x_max, x);
    };
    for (int i = 0; i < n; ++i) {
      const auto [ax, ay] = hull[i];
      const auto [bx, by] = hull[(i + 1) % n];
      if (ay >= y_lo && ay <= y_hi) take(ax);
      if (std::max(ay, by) < y_lo || std::min(ay, by) > y_hi || ay == by) continue;
      for (double y : {y_lo, y_hi}) {
        if ((y - ay) * (y - by) <= 0) take(ax + (bx - ax) * (y - ay) / (by - ay));
      }
    }
    if (x_min > x_max) {
      spans.rows[row] = {0, 0};
      continue;
    }
    spans.rows[row] = {ClampPixel(std::floor(x_min - kMargin), 0, width_),
                       ClampPixel(std::ceil(x_max + kMargin) + 1, 0, width_)};
  }
  return spans;
}

absl::StatusOr<CameraSpec> ToVolumeFrame(const CameraSpec& world, const Direction& direction,
                                         const Vec3& volume_extent) {
  if (direction == kIdentityDirection) return world;
  auto camera = Camera::Create(world, volume_extent);
  if (!camera.ok()) return camera.status();
  // Local coordinate a of a world vector w is direction[a] . w.
  auto local = [&](const Vec3& w) {
    Vec3 l;
    for (int a = 0; a < 3; ++a) {
      l[a] = direction[a][0] * w[0] + direction[a][1] * w[1] + direction[a][2] * w[2];
    }
    return l;
  };
  CameraSpec spec = world;
  ExplicitView view;
  view.eye = local(camera->eye());
  view.target = local(camera->eye() + camera->forward());
  view.up = local(camera->up());
  spec.view = view;
  spec.azimuth_deg = 0;
  spec.elevation_deg = 0;
  return spec;
}

}  // namespace transtick
