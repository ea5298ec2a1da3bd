// Cameras: perspective and orthographic, placed by an orbit (azimuth,
// elevation, zoom) about the volume's centre or by eye/target/up.
#ifndef TRANSTICK_CAMERA_H_
#define TRANSTICK_CAMERA_H_

#include <array>
#include <optional>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/vec.h"
#include "transtick/volume.h"

namespace transtick {

enum class Projection { kPerspective, kOrthographic };

struct ExplicitView {
  Vec3 eye;
  Vec3 target;
  Vec3 up = {0, 1, 0};
};

// World space puts the volume's centre at the origin, units of the volume's
// spacing, axes the world's (patient LPS, orientation.h). The tracer works in
// the volume's own frame (axes along its index axes); ToVolumeFrame below
// maps a world-space spec there. For a volume of identity direction the two
// frames are the same.
struct CameraSpec {
  static constexpr int kMaxImageSize = 8192;
  Projection projection = Projection::kPerspective;
  // Orbit view: azimuth rotates about +Y; azimuth 0 and elevation 0 look
  // along -Z (the paper's frontal view). Elevation tilts toward +Y.
  double azimuth_deg = 0;
  double elevation_deg = 0;
  double zoom = 1;  // 1 frames the volume's bounding sphere
  double fov_deg = 30;
  std::optional<ExplicitView> view;  // overrides the orbit when set
  int width = 400;
  int height = 400;
};

struct WorldRay {
  Vec3 origin;
  Vec3 direction;  // unit length
};

// The most primary rays per pixel (RenderSettings::samples).
inline constexpr int kMaxSamplesPerPixel = 64;

// Where primary ray `sample` of `samples` crosses its pixel, in [0, 1)^2: a
// fixed stratified pattern, the same on every node. One sample is the
// centre; a square number a grid of cell centres; any other number a
// Fibonacci lattice (x stratified in `samples` columns, y by the golden
// ratio), which leaves no two samples close.
// REQUIRES: 0 <= sample < samples <= kMaxSamplesPerPixel.
std::array<double, 2> SampleOffset(int sample, int samples);

// Pixels of an image, row by row: columns [first, second) of each row
// (none when first >= second).
struct ImageSpans {
  std::vector<std::pair<int, int>> rows;  // one per row of the image
  // The columns of row y; none for a row outside the image.
  std::pair<int, int> Row(int y) const {
    return static_cast<size_t>(y) < rows.size() ? rows[y] : std::pair{0, 0};
  }
  bool Contains(int x, int y) const {
    const auto [first, last] = Row(y);
    return x >= first && x < last;
  }
};

// Immutable, thread-safe.
class Camera {
 public:
  // Fails on an image size outside [1, kMaxImageSize], zoom or fov out of
  // range, or a degenerate explicit view.
  static absl::StatusOr<Camera> Create(const CameraSpec& spec, const Vec3& volume_extent);

  // The ray through the centre of pixel (px, py); py = 0 is the top row.
  WorldRay Generate(int px, int py) const { return GenerateAt(px, py, 0.5, 0.5); }
  // The ray through point (px + ox, py + oy) of the image, ox and oy in
  // [0, 1) across the pixel.
  WorldRay GenerateAt(int px, int py, double ox, double oy) const;

  // Pixels whose rays may meet the world-space box [lo, hi], at any point
  // of the pixel: the convex hull of the box's corners projected, row by
  // row, with a margin of two pixels against rounding, clipped to the
  // image. The whole image when a corner lies behind a perspective eye.
  ImageSpans Footprint(const Vec3& lo, const Vec3& hi) const;
  // The same pixels and more: the rectangle around the box's projected
  // corners, with the same margin, clipped to the image. Columns [x0, x1)
  // of rows [y0, y1), empty when x0 >= x1 or y0 >= y1; the whole image when
  // a corner lies behind a perspective eye. Cheaper than Footprint.
  struct PixelRect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  };
  PixelRect Bounds(const Vec3& lo, const Vec3& hi) const;

  int width() const { return width_; }
  int height() const { return height_; }
  Projection projection() const { return projection_; }
  const Vec3& eye() const { return eye_; }
  const Vec3& forward() const { return forward_; }
  const Vec3& right() const { return right_; }
  const Vec3& up() const { return up_; }

 private:
  // The corners of the box [lo, hi] in pixel coordinates (pixel (c, r)
  // spans [c - 0.5, c + 0.5) x [r - 0.5, r + 0.5)); false when one lies
  // behind a perspective eye or does not project to a finite point.
  bool ProjectCorners(const Vec3& lo, const Vec3& hi,
                      std::array<std::pair<double, double>, 8>* points) const;

  Projection projection_ = Projection::kPerspective;
  int width_ = 0, height_ = 0;
  Vec3 eye_, forward_, right_, up_;
  double half_height_ = 1;  // tan(fov/2) (perspective) or half the view height
};

// The camera `world` describes (in world space about the volume's centre),
// as an explicit view in the frame of a volume whose index axes point along
// `direction`: eye, target and up each multiplied by the inverse (the
// transpose) of the rotation. The light follows, being camera-relative. A
// volume of identity direction gets `world` back unchanged, bit for bit.
// Every render (in-process, and the root for its workers) maps with this,
// so all see the same doubles.
// REQUIRES: `direction` is a rotation (orthonormal, determinant +1), as the
// readers leave it (orientation.h).
absl::StatusOr<CameraSpec> ToVolumeFrame(const CameraSpec& world, const Direction& direction,
                                         const Vec3& volume_extent);

}  // namespace transtick

#endif  // TRANSTICK_CAMERA_H_
