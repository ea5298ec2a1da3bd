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
#include "transtick/classification.h"
#include "transtick/field_grid.h"
#include "transtick/vec.h"

namespace transtick {

struct RayAxes;  // isosurface.h

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

  size_t MemoryBytes() const { return labels_.size(); }

 private:
  std::array<int, 3> bricks_ = {0, 0, 0};
  std::vector<uint8_t> labels_;
};

}  // namespace transtick

#endif  // TRANSTICK_FIELD_SUMMARY_H_
