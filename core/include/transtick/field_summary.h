// A summary of the whole field for a node that holds one slab of it: per
// brick of 8^3 cells of the field (field_grid.h), the band that every cell
// within one cell of the brick has, or kMixed.
//
// A node walks only its own slab's cells, so a ray in void that reaches the
// slab's plane would go on to the neighbour even when nothing lies between
// it and the volume's far face. With the summary the node sees that: when
// every brick the rest of the ray crosses has the ray's band, no cell there
// holds a root or another band (a cell's label is the band of all its
// corners, and those are the brick's), so the walks that would follow find
// nothing and the ray ends here with the deposit it would make at the
// volume's face. The margin of one cell around each brick absorbs the
// rounding of the brick walk against the cell walk: the summary only
// decides whether a ray travels on, never what it finds.
//
// Built by whoever holds the whole volume (the root), sent with every slab
// (docs/formats.md, "Field summary"): a byte per 512 cells.
#ifndef TRANSTICK_FIELD_SUMMARY_H_
#define TRANSTICK_FIELD_SUMMARY_H_

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/camera.h"
#include "transtick/classification.h"
#include "transtick/field_grid.h"
#include "transtick/vec.h"

namespace transtick {

struct RayAxes;  // isosurface.h

// A bit per pixel of an image, row by row. A value type.
class PixelMask {
 public:
  PixelMask() = default;
  PixelMask(int width, int height);  // every bit clear
  bool empty() const { return bits_.empty(); }
  int width() const { return width_; }
  int height() const { return height_; }
  // REQUIRES: the pixel lies in the image.
  bool Get(int col, int row) const {
    const size_t i = static_cast<size_t>(row) * words_per_row_ + (col >> 6);
    return (bits_[i] >> (col & 63)) & 1;
  }
  void Set(const Camera::PixelRect& r);  // the rectangle's pixels, clipped to the image
  size_t Count() const;                  // bits set

 private:
  int width_ = 0, height_ = 0;
  size_t words_per_row_ = 0;
  std::vector<uint64_t> bits_;
};

// Immutable after construction; thread-safe for concurrent reads.
class FieldSummary {
 public:
  static constexpr int kShift = 3;
  static constexpr uint8_t kMixed = FieldGrid::kMixed;

  FieldSummary() = default;

  // From the scalars of the whole volume (x fastest, then y, then z).
  // REQUIRES: values.size() == dims[0] * dims[1] * dims[2], dims positive.
  static FieldSummary Build(const std::vector<float>& values, std::array<int, 3> dims,
                            const Bands& bands);
  // From bytes() of a summary of a volume of `dims` with `bands` bands.
  // Fails, saying what is wrong, when the size is not one byte per brick or
  // a byte names no band.
  static absl::StatusOr<FieldSummary> FromBytes(std::array<int, 3> dims, int bands,
                                                std::string_view bytes);

  // Bricks per axis of a volume of `dims`: ceil((dims + 1) / 8), the field
  // having dims + 1 cells. REQUIRES: dims >= 0.
  static std::array<int, 3> BricksOf(std::array<int, 3> dims) {
    std::array<int, 3> b;
    for (int a = 0; a < 3; ++a) b[a] = static_cast<int>((int64_t{dims[a]} + 1 + 7) >> kShift);
    return b;
  }

  bool empty() const { return labels_.empty(); }
  // BricksOf the volume's dims.
  const std::array<int, 3>& brick_dims() const { return bricks_; }
  // One byte per brick, x fastest, then y, then z.
  const std::vector<uint8_t>& bytes() const { return labels_; }
  uint8_t At(int bx, int by, int bz) const {
    return labels_[(static_cast<size_t>(bz) * bricks_[1] + by) * bricks_[0] + bx];
  }

  // Whether every brick the ray origin + t * direction crosses for t in
  // [t0, t1] has `band` (false on an empty summary, a band of kMixed or
  // more, or a span that is not finite): then a walk of the field's cells
  // over that span, begun in `band`, finds no crossing.
  bool Clear(const Vec3& origin, const RayAxes& axes, double t0, double t1, int band) const;

  // The pixels of `camera`'s image whose primary rays may meet a cell of
  // another band than 0 (`camera` in the frame of the volume of `spacing`
  // that the summary describes). A pixel left clear has rays that cross
  // only bricks labelled 0: their walks find band 0 where they enter and
  // nothing after (as Clear argues), so a ray of a band without a material
  // leaves the background, as a miss does. Such a ray enters the volume
  // in a brick on its faces or crosses into a brick of another label from
  // one of band 0, so projecting the shell (the bricks not labelled 0 on
  // the faces or next to one labelled 0, diagonals included) suffices,
  // each brick by the rectangle of Camera::Bounds. Empty, meaning every
  // pixel may, when the summary is empty, has no brick of band 0, or a ray
  // may start inside the volume (a corner of it lies behind the eye's
  // plane). A shell of more than `max_boxes` bricks (by default, an
  // eighth of the image's pixels and at least 4096: what projecting them
  // costs stays well under what the void pixels save) is projected in
  // boxes of 2^3, 4^3, ... bricks, as few sizes up as make it fit: a box
  // holding a shell brick holds its rays too.
  PixelMask PixelsMeeting(const Camera& camera, const std::array<double, 3>& spacing,
                          size_t max_boxes = 0) const;

  size_t MemoryBytes() const { return labels_.size() + shell_.size() * sizeof(uint32_t); }
  bool operator==(const FieldSummary&) const = default;  // every member equal

 private:
  void FindShell();  // shell_, from labels_

  std::array<int, 3> dims_ = {0, 0, 0};  // the volume's
  std::array<int, 3> bricks_ = {0, 0, 0};
  std::vector<uint8_t> labels_;
  // The bricks PixelsMeeting projects, by index into labels_; `has_void_`
  // when some brick is labelled 0.
  std::vector<uint32_t> shell_;
  bool has_void_ = false;
};

}  // namespace transtick

#endif  // TRANSTICK_FIELD_SUMMARY_H_
