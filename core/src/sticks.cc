#include "transtick/sticks.h"

#include <cstring>
#include <map>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "coding.h"
#include "transtick/parallel.h"

namespace transtick {
namespace {

constexpr char kMagic[4] = {'T', 'S', 'B', '1'};

}  // namespace

Sticks Sticks::Encode(std::span<const uint8_t> labels, std::array<int, 3> dims, int y_begin,
                      int y_end) {
  Sticks s;
  s.dims_ = dims;
  s.y_begin_ = y_begin;
  s.y_end_ = y_end;
  const size_t nx = dims[0], ny = dims[1];
  const size_t rows = y_end > y_begin ? static_cast<size_t>(y_end - y_begin) : 0;
  // Ranges of rows on as many threads, each into sticks of its own, joined
  // in order: the same sticks and offsets as one pass.
  std::mutex mu;
  std::map<size_t, std::vector<Stick>> parts;  // by the range's first row
  s.offsets_.resize(rows * nx + 1);
  ParallelFor(rows, 8, [&](size_t row_begin, size_t row_end) {
    std::vector<Stick> sticks;
    for (size_t r = row_begin; r < row_end; ++r) {
      const int y = y_begin + static_cast<int>(r);
      for (int x = 0; x < dims[0]; ++x) {
        // Counted from the range's first stick until the ranges are joined.
        s.offsets_[r * nx + x] = static_cast<uint32_t>(sticks.size());
        const uint8_t* track = labels.data() + static_cast<size_t>(y) * nx + x;
        const size_t stride = nx * ny;
        int z = 0;
        while (z < dims[2]) {
          uint8_t m = track[z * stride];
          int begin = z;
          while (z < dims[2] && track[z * stride] == m) ++z;
          if (m != 0) {
            sticks.push_back(Stick{static_cast<uint16_t>(begin), static_cast<uint16_t>(z), m});
          }
        }
      }
    }
    std::lock_guard<std::mutex> lock(mu);
    parts[row_begin] = std::move(sticks);
  });
  size_t total = 0;
  for (const auto& [first, sticks] : parts) total += sticks.size();
  s.sticks_.reserve(total);
  auto next = parts.begin();
  for (const auto& [first, sticks] : parts) {
    ++next;
    const size_t last = next == parts.end() ? rows : next->first;
    const auto base = static_cast<uint32_t>(s.sticks_.size());
    for (size_t i = first * nx; i < last * nx; ++i) s.offsets_[i] += base;
    s.sticks_.insert(s.sticks_.end(), sticks.begin(), sticks.end());
  }
  s.offsets_[rows * nx] = static_cast<uint32_t>(s.sticks_.size());
  return s;
}

std::string Sticks::EncodeBlock(int bx, int by, int y_lo, int y_hi) const {
  const int x0 = bx * kBlockSize, x1 = std::min(x0 + kBlockSize, dims_[0]);
  const int y0 = std::max({by * kBlockSize, y_begin_, y_lo});
  const int y1 = std::min({by * kBlockSize + kBlockSize, dims_[1], y_end_, y_hi});
  std::string out(kMagic, 4);
  PutFixed16(&out, static_cast<uint16_t>(bx));
  PutFixed16(&out, static_cast<uint16_t>(by));
  for (int a = 0; a < 3; ++a) PutFixed16(&out, static_cast<uint16_t>(dims_[a]));
  PutFixed16(&out, static_cast<uint16_t>(y0));
  PutFixed16(&out, static_cast<uint16_t>(y1));
  uint32_t total = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) total += static_cast<uint32_t>(Track(x, y).size());
  PutFixed32(&out, total);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) PutVarint32(&out, static_cast<uint32_t>(Track(x, y).size()));
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      uint32_t prev_end = 0;
      for (const Stick& st : Track(x, y)) {
        PutVarint32(&out, st.begin - prev_end);
        PutVarint32(&out, static_cast<uint32_t>(st.end - st.begin - 1));
        out.push_back(static_cast<char>(st.material));
        prev_end = st.end;
      }
    }
  }
  return out;
}

std::vector<std::string> Sticks::EncodeRows(int y_lo, int y_hi) const {
  std::vector<std::string> blocks;
  for (int by = y_lo / kBlockSize; by * kBlockSize < y_hi; ++by) {
    for (int bx = 0; bx < BlocksX(); ++bx) blocks.push_back(EncodeBlock(bx, by, y_lo, y_hi));
  }
  return blocks;
}

absl::StatusOr<Sticks> Sticks::FromBlocks(std::array<int, 3> dims, int y_begin, int y_end,
                                          int max_material,
                                          const std::vector<std::string>& blocks) {
  for (int a = 0; a < 3; ++a) {
    if (dims[a] < 1 || dims[a] > kMaxExtent) {
      return absl::InvalidArgumentError(absl::StrCat("sticks: dimension ", a, " is ", dims[a],
                                                     ", must be in [1, ", kMaxExtent, "]"));
    }
  }
  if (y_begin < 0 || y_begin > y_end || y_end > dims[1]) {
    return absl::InvalidArgumentError(
        absl::StrCat("sticks: slab [", y_begin, ", ", y_end, ") is outside [0, ", dims[1], ")"));
  }
  const size_t nx = dims[0];
  const size_t tracks = static_cast<size_t>(y_end - y_begin) * nx;
  // Decode every block into per-track stick lists, then flatten.
  std::vector<std::vector<Stick>> per_track(tracks);
  std::vector<uint8_t> seen(tracks, 0);
  const int blocks_x = (dims[0] + kBlockSize - 1) / kBlockSize;
  const int blocks_y = (dims[1] + kBlockSize - 1) / kBlockSize;
  for (size_t b = 0; b < blocks.size(); ++b) {
    Decoder in(blocks[b]);
    std::string where = absl::StrCat("sticks block ", b);
    char magic[4];
    if (!in.GetBytes(magic, 4) || std::memcmp(magic, kMagic, 4) != 0) {
      return absl::InvalidArgumentError(where + ": bad magic (not a sticks block)");
    }
    uint16_t bx, by, d[3], row_begin, row_end;
    uint32_t total;
    if (!in.GetFixed16(&bx) || !in.GetFixed16(&by) || !in.GetFixed16(&d[0]) ||
        !in.GetFixed16(&d[1]) || !in.GetFixed16(&d[2]) || !in.GetFixed16(&row_begin) ||
        !in.GetFixed16(&row_end) || !in.GetFixed32(&total)) {
      return absl::InvalidArgumentError(where + ": truncated header");
    }
    if (d[0] != dims[0] || d[1] != dims[1] || d[2] != dims[2]) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": made for a ", d[0], "x", d[1], "x",
                                                     d[2], " volume, expected ", dims[0], "x",
                                                     dims[1], "x", dims[2]));
    }
    if (bx >= blocks_x || by >= blocks_y) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": block index (", bx, ", ", by, ") out of range"));
    }
    const int x0 = bx * kBlockSize, x1 = std::min(x0 + kBlockSize, dims[0]);
    const int y0 = row_begin, y1 = row_end;
    if (y0 < by * kBlockSize || y0 >= y1 || y1 > std::min((by + 1) * kBlockSize, dims[1])) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": rows [", y0, ", ", y1,
                                                     ") are not in block row ", by));
    }
    const size_t n_tracks = static_cast<size_t>(x1 - x0) * (y1 - y0);
    std::vector<uint32_t> counts(n_tracks);
    uint64_t sum = 0;
    for (size_t i = 0; i < n_tracks; ++i) {
      if (!in.GetVarint32(&counts[i])) {
        return absl::InvalidArgumentError(where + ": truncated track counts");
      }
      sum += counts[i];
    }
    if (sum != total) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": track counts add up to ", sum, ", header says ", total));
    }
    // Each stick takes at least 3 bytes: reject absurd counts before looping.
    if (sum > in.remaining() / 3) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": ", sum, " sticks cannot fit in ", in.remaining(), " bytes"));
    }
    size_t i = 0;
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x, ++i) {
        std::vector<Stick> track;
        track.reserve(counts[i]);
        uint32_t prev_end = 0;
        for (uint32_t k = 0; k < counts[i]; ++k) {
          uint32_t gap, len_minus_1;
          uint8_t material;
          if (!in.GetVarint32(&gap) || !in.GetVarint32(&len_minus_1) || !in.GetByte(&material)) {
            return absl::InvalidArgumentError(where + ": truncated sticks");
          }
          uint64_t begin = uint64_t{prev_end} + gap;
          uint64_t end = begin + len_minus_1 + 1;
          if (end > static_cast<uint64_t>(dims[2])) {
            return absl::InvalidArgumentError(absl::StrCat(where, ": stick [", begin, ", ", end,
                                                           ") of track (", x, ", ", y,
                                                           ") runs past z = ", dims[2]));
          }
          if (k > 0 && gap == 0 && material == track.back().material) {
            return absl::InvalidArgumentError(absl::StrCat(
                where, ": track (", x, ", ", y, ") has two adjacent sticks of one material"));
          }
          if (material == 0 || material > max_material) {
            return absl::InvalidArgumentError(absl::StrCat(where, ": material ", int{material},
                                                           " is not in [1, ", max_material, "]"));
          }
          track.push_back(
              Stick{static_cast<uint16_t>(begin), static_cast<uint16_t>(end), material});
          prev_end = static_cast<uint32_t>(end);
        }
        if (y >= y_begin && y < y_end) {
          size_t t = static_cast<size_t>(y - y_begin) * nx + x;
          per_track[t] = std::move(track);
          seen[t] = 1;
        }
      }
    }
    if (in.remaining() != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": ", in.remaining(), " bytes left over after the last stick"));
    }
  }
  Sticks s;
  s.dims_ = dims;
  s.y_begin_ = y_begin;
  s.y_end_ = y_end;
  s.offsets_.reserve(tracks + 1);
  for (size_t t = 0; t < tracks; ++t) {
    if (!seen[t]) {
      return absl::InvalidArgumentError(
          absl::StrCat("sticks: no block covers track (", t % nx, ", ", y_begin + t / nx, ")"));
    }
    s.offsets_.push_back(static_cast<uint32_t>(s.sticks_.size()));
    s.sticks_.insert(s.sticks_.end(), per_track[t].begin(), per_track[t].end());
  }
  s.offsets_.push_back(static_cast<uint32_t>(s.sticks_.size()));
  return s;
}

}  // namespace transtick
