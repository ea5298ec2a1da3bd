// The cells of the trilinear field that smooth surfaces lie on, labelled by
// band, for a walk that crosses uniform space without reading a scalar.
//
// A cell of the field has its eight corners at voxel centres; cell c (per
// axis) spans [c - 0.5, c + 0.5] in index space and reads voxels c - 1 and
// c, clamped at the volume's faces, so cells 0 .. dims cover the volume. On a
// cell the field is trilinear and its extremes are at the corners: when the
// least and the greatest corner lie in one band (classification.h, Bands),
// no interval edge is crossed anywhere in the cell, and the cell is labelled
// with that band. Otherwise it is kMixed and the walk solves its cubic. A
// label is a pure function of the cell's eight corner values, so every node
// that holds a cell labels it alike.
//
// Above the labels, 2^3 groups of cells with the reach of each toward each
// octant (as BrickMap's) let a ray in band b leave a whole box of cells of
// band b in one step. They are built from the cells one node holds, and
// only decide how far a walk may jump, never what it finds: a box is
// jumped only when every cell in it has the ray's band, where the walk
// would have found nothing.
#ifndef TRANSTICK_FIELD_GRID_H_
#define TRANSTICK_FIELD_GRID_H_

#include <array>
#include <cstdint>
#include <vector>

#include "transtick/classification.h"
#include "transtick/brick_map.h"

namespace transtick {

// Immutable after construction; thread-safe for concurrent reads.
class FieldGrid {
 public:
  static constexpr uint8_t kMixed = BrickMap::kMixed;

  FieldGrid() = default;

  // Labels the cells of rows [row_begin, row_end) (cell y index) of the
  // field of `scalars`, which hold voxel planes [scalar_y_begin,
  // scalar_y_begin + scalar_planes) of a volume of `dims` (x fastest, then
  // y, then z). A band of 255 or more labels its cells kMixed.
  // REQUIRES: the planes hold rows row_begin - 1 .. row_end - 1 (clamped to
  // the volume); 0 <= row_begin < row_end <= dims[1] + 1.
  static FieldGrid Build(const std::vector<float>& scalars, std::array<int, 3> dims,
                         int scalar_y_begin, int scalar_planes, int row_begin, int row_end,
                         const Bands& bands);

  bool empty() const { return groups_.empty(); }
  // Cells per axis of the rows held: dims[0] + 1, the rows, dims[2] + 1.
  const std::array<int, 3>& cells() const { return cells_; }
  int row_begin() const { return row_begin_; }
  // Whether cell (x, y, z) (y a row of the volume) is labelled here.
  bool Holds(int x, int y, int z) const {
    return static_cast<unsigned>(x) < static_cast<unsigned>(cells_[0]) &&
           static_cast<unsigned>(y - row_begin_) < static_cast<unsigned>(cells_[1]) &&
           static_cast<unsigned>(z) < static_cast<unsigned>(cells_[2]);
  }

  // The cells in 2^3 groups: group (x >> 1, (y - row_begin) >> 1, z >> 1)
  // holds cell (x, y, z), as its cell Sub(x, y, z). A group's record holds
  // its cells' labels and its reach toward each octant (bit a set: toward
  // -a, as BrickMap::Reach): the largest r for which the box of (r + 1)^3
  // groups with it at the corner toward the octant, clipped to the grid, is
  // all of its band; 0 when its cells' bands differ. A walk reads one
  // record, one cache line, per cell. Cells of a group past the grid's
  // faces repeat a label of the group's.
  struct Group {
    uint8_t label[8];
    uint8_t reach[8];
    bool operator==(const Group&) const = default;
  };
  const std::array<int, 3>& groups() const { return group_dims_; }
  // REQUIRES: Holds(x, y, z).
  size_t GroupIndex(int x, int y, int z) const {
    return (static_cast<size_t>(z >> 1) * group_dims_[1] + ((y - row_begin_) >> 1)) *
               group_dims_[0] +
           (x >> 1);
  }
  int Sub(int x, int y, int z) const { return (x & 1) | ((y - row_begin_) & 1) << 1 | (z & 1) << 2; }
  const Group* group_data() const { return groups_.data(); }
  uint8_t Label(int x, int y, int z) const { return groups_[GroupIndex(x, y, z)].label[Sub(x, y, z)]; }

  size_t MemoryBytes() const { return groups_.size() * sizeof(Group); }
  // What Build's grid of rows [row_begin, row_end) of a volume of `dims`
  // takes: its MemoryBytes, without building it.
  static size_t MemoryBytesFor(std::array<int, 3> dims, int row_begin, int row_end) {
    if (row_end <= row_begin) return 0;
    const size_t gx = (dims[0] + 2) / 2, gy = (row_end - row_begin + 1) / 2, gz = (dims[2] + 2) / 2;
    return gx * gy * gz * sizeof(Group);
  }
  bool operator==(const FieldGrid&) const = default;  // every member equal

 private:
  std::array<int, 3> cells_ = {0, 0, 0};
  int row_begin_ = 0;
  std::array<int, 3> group_dims_ = {0, 0, 0};
  std::vector<Group> groups_;  // x fastest, then rows, then z
};

}  // namespace transtick

#endif  // TRANSTICK_FIELD_GRID_H_
