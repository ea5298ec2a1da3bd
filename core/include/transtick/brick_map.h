// The brick map: which 8^3 bricks and 2^3 cells of a label volume are
// uniform, and how far each uniform cell's label reaches toward each octant,
// so that a walk crosses uniform space a box at a time.
#ifndef TRANSTICK_BRICK_MAP_H_
#define TRANSTICK_BRICK_MAP_H_

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/check.h"

namespace transtick {

// The material of each 8x8x8 brick of the whole volume, and of each 2x2x2
// cell of the mixed ones, when all its voxels share one (void included),
// else kMixed. Small on the wire (a byte per brick, 64 per mixed brick),
// so every worker holds all of it: crossing uniform space in one step is
// then the same decision on every node. In memory it takes a byte per 2^3
// cell of the whole volume, and 8 more (the reach toward each octant) per
// cell of the slab it serves.
class BrickMap {
 public:
  static constexpr int kShift = 3;
  static constexpr int kBrick = 1 << kShift;
  static constexpr uint8_t kMixed = 255;

  BrickMap() = default;
  // With `uniform_materials` false only void bricks and cells are uniform:
  // dvr samples must stay within the column they are taken in. The reach is
  // that of the cells of planes [y_begin, y_end) (y_end < 0: all; an empty
  // range: none, for a map no walk looks up, as smooth surfaces' is).
  static BrickMap Build(std::span<const uint8_t> labels, std::array<int, 3> dims,
                        bool uniform_materials, int y_begin = 0, int y_end = -1);
  // Rebuilds from the bytes of bytes() (docs/formats.md, "Brick map"), with
  // the reach of the cells of planes [y_begin, y_end) (y_end < 0: all). Fails
  // on a size that does not match the dims and the mixed bricks.
  static absl::StatusOr<BrickMap> FromBytes(std::array<int, 3> dims, std::vector<uint8_t> bytes,
                                            int y_begin = 0, int y_end = -1);
  // The same map with the reach of the cells of planes [y_begin, y_end)
  // instead: a slab's, which is all its walks look up.
  BrickMap ForSlab(int y_begin, int y_end) const;
  // The bytes the reach of the cells of planes [y_begin, y_end) takes, for
  // a volume of `dims` (MemoryBytes counts it where it is held).
  static size_t ReachBytes(std::array<int, 3> dims, int y_begin, int y_end);
  // Whether the map holds any reach.
  bool HoldsReach() const { return !reach_.empty(); }
  // Whether Reach holds the cells of planes [y_begin, y_end).
  bool ReachCovers(int y_begin, int y_end) const {
    return y_begin >= y_end ||
           (y_begin >> 1 >= row_begin_ && ((y_end - 1) >> 1) < row_begin_ + rows_);
  }

  // The brick's material, or kMixed. REQUIRES: (x, y, z) inside the volume.
  uint8_t At(int x, int y, int z) const {
    TRANSTICK_DCHECK(x >= 0 && y >= 0 && z >= 0);
    TRANSTICK_DCHECK_LT(x >> kShift, bdims_[0]);
    TRANSTICK_DCHECK_LT(y >> kShift, bdims_[1]);
    TRANSTICK_DCHECK_LT(z >> kShift, bdims_[2]);
    return bricks_[Index(x, y, z)];
  }
  // The material of the 2^3 cell holding voxel (x, y, z), or kMixed; voxels
  // past the volume's faces do not count. A cell of a uniform brick has the
  // brick's material. REQUIRES: as At.
  uint8_t Cell(int x, int y, int z) const { return cells_[CellIndex(x, y, z)]; }

  // How far the cell's material reaches ahead of the 2^3 cell holding voxel
  // (x, y, z) toward `octant` (bit a set: toward -a along axis a, else +a):
  // 0 for a mixed cell, else the largest r, at most kMaxReach, for which
  // every cell of the box of (r + 1)^3 cells with this cell at its corner,
  // extending toward the octant (clipped to the volume), has its material.
  // A ray moving into the octant leaves that box in one step. Derived from
  // the bytes alone, so every node holding the brick map has the same; a
  // slab's map keeps it for the slab's planes only (ForSlab).
  // REQUIRES: as At, 0 <= octant < 8, ReachCovers(y, y + 1).
  static constexpr int kMaxReach = 254;
  int Reach(int x, int y, int z, int octant) const {
    TRANSTICK_DCHECK(ReachCovers(y, y + 1));
    return reach_[octant * reach_cells_ +
                  (static_cast<size_t>(z >> 1) * rows_ + ((y >> 1) - row_begin_)) * cdims_[0] +
                  (x >> 1)];
  }
  // The octant a direction with these axis steps (-1, 0, +1) moves into;
  // an axis it does not move along counts as +.
  static int OctantOf(const int step[3]) {
    return (step[0] < 0 ? 1 : 0) | (step[1] < 0 ? 2 : 0) | (step[2] < 0 ? 4 : 0);
  }

  // The largest material of any brick or cell (kMixed aside), 0 when all
  // are void or mixed: a scene checks that its classification has it.
  uint8_t MaxMaterial() const;

  // The serialised map: one byte per brick (x fastest), then for each mixed
  // brick in that order the materials of its 64 cells, cell (i & 3,
  // (i >> 2) & 3, i >> 4) at byte i.
  std::vector<uint8_t> bytes() const;
  const std::array<int, 3>& brick_dims() const { return bdims_; }
  size_t MemoryBytes() const { return bricks_.size() + cells_.size() + reach_.size(); }
  // Every member equal, the reach included.
  bool operator==(const BrickMap&) const = default;

 private:
  size_t Index(int x, int y, int z) const {
    return (static_cast<size_t>(z >> kShift) * bdims_[1] + (y >> kShift)) * bdims_[0] +
           (x >> kShift);
  }
  size_t CellIndex(int x, int y, int z) const {
    return (static_cast<size_t>(z >> 1) * cdims_[1] + (y >> 1)) * cdims_[0] + (x >> 1);
  }
  // Sizes the grids of bricks and cells for a volume of `dims`, all void.
  void SetDims(std::array<int, 3> dims);
  // Calls f(brick, cell) for each brick's index into bricks_ and the
  // indices into cells_ of its 64 cells, in the order bytes() writes them.
  template <typename F>
  void ForEachBrickCell(F f) const {
    size_t brick = 0;
    for (int bz = 0; bz < bdims_[2]; ++bz)
      for (int by = 0; by < bdims_[1]; ++by)
        for (int bx = 0; bx < bdims_[0]; ++bx, ++brick)
          for (int c = 0; c < 64; ++c)
            f(brick, CellIndex(8 * bx + 2 * (c & 3), 8 * by + 2 * ((c >> 2) & 3),
                               8 * bz + 2 * (c >> 4)));
  }
  // Fills cells_ of the uniform bricks.
  void FillCells();
  // Sets row_begin_, rows_ and reach_cells_ for the cells of planes
  // [y_begin, y_end). REQUIRES: cdims_ set.
  void SetReachRows(int y_begin, int y_end);
  // Fills reach_ for the cells of planes [y_begin, y_end).
  void ComputeReach(int y_begin, int y_end);

  std::array<int, 3> bdims_ = {0, 0, 0};
  std::vector<uint8_t> bricks_;
  std::array<int, 3> cdims_ = {0, 0, 0};    // 2^3 cells per axis: 4 per brick
  std::array<int, 3> cinside_ = {0, 0, 0};  // of which hold voxels of the volume
  std::vector<uint8_t> cells_;            // Cell() per 2^3 cell, x fastest
  // Reach() per octant, then per cell of rows [row_begin_, row_begin_ +
  // rows_) of cells, x fastest.
  int row_begin_ = 0;
  int rows_ = 0;
  size_t reach_cells_ = 0;  // cells per octant
  std::vector<uint8_t> reach_;
};

}  // namespace transtick

#endif  // TRANSTICK_BRICK_MAP_H_
