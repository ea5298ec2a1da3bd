// The STICKS scheme (Montani & Scopigno 1990): for each track (x, y), the runs
// of equal non-void material along z. Tracks are grouped into blocks of 32x32
// (the paper's Sticks Holder Array) that serialise to bytes; the byte format
// is written down in docs/formats.md, "Sticks block".
#ifndef TRANSTICK_STICKS_H_
#define TRANSTICK_STICKS_H_

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/check.h"

namespace transtick {

// One stick: voxels [begin, end) of a track all have `material` (never 0).
struct Stick {
  uint16_t begin;
  uint16_t end;
  uint8_t material;
  bool operator==(const Stick&) const = default;
};

// The run or void gap of a track that contains a given z.
struct StickSpan {
  int begin;
  int end;
  uint8_t material;  // 0 for a gap
};

// The sticks of the tracks whose y lies in [y_begin, y_end) (a slab along Y;
// the whole volume when y_begin = 0 and y_end = dims[1]). Immutable after
// construction; thread-safe for concurrent reads.
class Sticks {
 public:
  static constexpr int kBlockSize = 32;
  static constexpr int kMaxExtent = 65535;

  // Every member equal: the same tracks of the same rows.
  bool operator==(const Sticks&) const = default;

  Sticks() = default;

  // Encodes the tracks of `labels` (one material id per voxel, x fastest)
  // whose y lies in [y_begin, y_end).
  // REQUIRES: labels.size() == product of dims; 0 <= y_begin <= y_end <= dims[1];
  //           every dim in [1, kMaxExtent].
  static Sticks Encode(std::span<const uint8_t> labels, std::array<int, 3> dims, int y_begin,
                       int y_end);

  // Assembles the slab [y_begin, y_end) from serialised blocks (any order;
  // a block may carry only some of its rows, as a slab that holds part of it
  // encodes it; tracks outside the slab are ignored). Fails on a corrupt
  // block, a block for other dims, a material above `max_material`, or a
  // track of the slab no block covered.
  static absl::StatusOr<Sticks> FromBlocks(std::array<int, 3> dims, int y_begin, int y_end,
                                           int max_material,
                                           const std::vector<std::string>& blocks);

  // Serialises the tracks of block (bx, by) that this slab holds: x in
  // [32 bx, 32 bx + 32) and y in [32 by, 32 by + 32), clipped to the volume,
  // to [y_begin, y_end) and to [y_lo, y_hi).
  // REQUIRES: at least one row is left.
  std::string EncodeBlock(int bx, int by, int y_lo = 0, int y_hi = kMaxExtent) const;
  // Every block of rows [y_lo, y_hi), which this slab holds.
  std::vector<std::string> EncodeRows(int y_lo, int y_hi) const;

  const std::array<int, 3>& dims() const { return dims_; }
  int y_begin() const { return y_begin_; }
  int y_end() const { return y_end_; }
  int BlocksX() const { return (dims_[0] + kBlockSize - 1) / kBlockSize; }
  int BlocksY() const { return (dims_[1] + kBlockSize - 1) / kBlockSize; }

  // REQUIRES: 0 <= x < dims[0], y_begin <= y < y_end.
  std::span<const Stick> Track(int x, int y) const {
    TRANSTICK_DCHECK_GE(x, 0);
    TRANSTICK_DCHECK_LT(x, dims_[0]);
    TRANSTICK_DCHECK_GE(y, y_begin_);
    TRANSTICK_DCHECK_LT(y, y_end_);
    size_t t = TrackIndex(x, y);
    return {sticks_.data() + offsets_[t], sticks_.data() + offsets_[t + 1]};
  }

  // The stick or gap containing z. REQUIRES: as Track(), 0 <= z < dims[2].
  StickSpan Find(int x, int y, int z) const {
    TRANSTICK_DCHECK_GE(z, 0);
    TRANSTICK_DCHECK_LT(z, dims_[2]);
    const std::span<const Stick> track = Track(x, y);
    if (track.size() <= kScanMax) {
      int gap_begin = 0;
      for (const Stick& s : track) {
        if (z < s.begin) return {gap_begin, s.begin, 0};
        if (z < s.end) return {s.begin, s.end, s.material};
        gap_begin = s.end;
      }
      return {gap_begin, dims_[2], 0};
    }
    // Binary search for the first stick ending after z (a track's sticks
    // are sorted and disjoint, by construction and as FromBlocks decodes
    // them).
    const Stick* s = std::partition_point(track.data(), track.data() + track.size(),
                                          [z](const Stick& st) { return st.end <= z; });
    const int gap_begin = s == track.data() ? 0 : s[-1].end;
    if (s == track.data() + track.size()) return {gap_begin, dims_[2], 0};
    if (z < s->begin) return {gap_begin, s->begin, 0};
    return {s->begin, s->end, s->material};
  }
  uint8_t MaterialAt(int x, int y, int z) const { return Find(x, y, z).material; }

  size_t StickCount() const { return sticks_.size(); }
  // Bytes held in memory: the sticks plus one offset per track.
  size_t MemoryBytes() const {
    return sticks_.size() * sizeof(Stick) + offsets_.size() * sizeof(uint32_t);
  }

 private:
  size_t TrackIndex(int x, int y) const {
    return static_cast<size_t>(y - y_begin_) * static_cast<size_t>(dims_[0]) +
           static_cast<size_t>(x);
  }

  // Find scans tracks of at most this many sticks and searches longer
  // ones. Real tracks are short: on cthead with skin and bone, 54% hold no
  // stick, 89% at most 8, the longest 28; there a scan is as fast as this
  // hybrid and a pure binary search was 2-3% slower (render_bench az45, 1
  // thread, min ms of 5 alternated sets: scan 94.2-99.3, hybrid 93.7-96.0,
  // search 96.5-109.2). A scan costs O(sticks) per step, though, and a
  // ray walking along z through a track of noise calls Find once per stick:
  // on 200x200x300 noise (112 sticks a track) seen frontally the search
  // took the frame from 94.3 to 81.1 ms.
  static constexpr size_t kScanMax = 8;

  std::array<int, 3> dims_ = {0, 0, 0};
  int y_begin_ = 0;
  int y_end_ = 0;
  std::vector<uint32_t> offsets_;  // per track, into sticks_; one extra at the end
  std::vector<Stick> sticks_;
};

}  // namespace transtick

#endif  // TRANSTICK_STICKS_H_
