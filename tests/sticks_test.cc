#include "transtick/sticks.h"

#include <algorithm>
#include <random>
#include <span>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

std::vector<uint8_t> Labels(const Volume& v, int levels) {
  std::vector<uint8_t> labels(v.values.size());
  for (size_t i = 0; i < labels.size(); ++i)
    labels[i] = static_cast<uint8_t>(static_cast<int>(v.values[i]) % levels);
  return labels;
}

// Every voxel decodes to its label, and the spans tile each track.
void ExpectMatches(const Sticks& s, const std::vector<uint8_t>& labels,
                   const std::array<int, 3>& d) {
  for (int y = s.y_begin(); y < s.y_end(); ++y) {
    for (int x = 0; x < d[0]; ++x) {
      for (int z = 0; z < d[2]; ++z) {
        StickSpan span = s.Find(x, y, z);
        uint8_t want = labels[(static_cast<size_t>(z) * d[1] + y) * d[0] + x];
        ASSERT_EQ(span.material, want) << x << "," << y << "," << z;
        ASSERT_LE(span.begin, z);
        ASSERT_GT(span.end, z);
        // Maximal runs: the voxels just outside differ (or are the ends).
        if (span.begin > 0 && span.material != 0) {
          ASSERT_NE(labels[(static_cast<size_t>(span.begin - 1) * d[1] + y) * d[0] + x], want);
        }
      }
    }
  }
}

std::vector<std::string> AllBlocks(const Sticks& s) {
  std::vector<std::string> blocks;
  for (int by = 0; by < s.BlocksY(); ++by)
    for (int bx = 0; bx < s.BlocksX(); ++bx) blocks.push_back(s.EncodeBlock(bx, by));
  return blocks;
}

TEST(SticksTest, RandomVolumesRoundTripExhaustively) {
  // Odd sizes leave partial blocks at the edges; few levels make many short
  // runs, many levels make single-voxel sticks.
  for (auto [dims, levels, seed] : {std::tuple{std::array<int, 3>{37, 45, 29}, 2, 1u},
                                    std::tuple{std::array<int, 3>{64, 33, 50}, 3, 2u},
                                    std::tuple{std::array<int, 3>{1, 1, 1}, 2, 3u},
                                    std::tuple{std::array<int, 3>{70, 5, 3}, 255, 4u}}) {
    Volume v = MakeRandom(dims, seed, levels);
    auto labels = Labels(v, levels);
    Sticks whole = Sticks::Encode(labels, dims, 0, dims[1]);
    ExpectMatches(whole, labels, dims);
    // Serialised blocks rebuild the whole volume and any slab of it.
    auto blocks = AllBlocks(whole);
    for (auto [y0, y1] :
         {std::pair{0, dims[1]}, std::pair{0, dims[1] / 2}, std::pair{dims[1] / 3, dims[1]},
          std::pair{dims[1] / 2, dims[1] / 2 + 1}}) {
      auto slab = Sticks::FromBlocks(dims, y0, y1, levels, blocks);
      ASSERT_TRUE(slab.ok()) << slab.status();
      ExpectMatches(*slab, labels, dims);
      Sticks direct = Sticks::Encode(labels, dims, y0, y1);
      EXPECT_EQ(slab->StickCount(), direct.StickCount());
    }
  }
}

TEST(SticksTest, PartialBlocksFromSeveralSlabsRebuildAnother) {
  // Balancing: slabs that end inside a block each send the rows they hold,
  // and those partial blocks rebuild a slab cut elsewhere.
  std::array<int, 3> dims = {45, 100, 23};
  Volume v = MakeRandom(dims, 9, 3);
  auto labels = Labels(v, 3);
  std::vector<std::string> blocks;
  for (auto [y0, y1] :
       {std::pair{0, 17}, std::pair{17, 50}, std::pair{50, 51}, std::pair{51, 100}}) {
    Sticks part = Sticks::Encode(labels, dims, y0, y1);
    for (std::string& b : part.EncodeRows(y0, y1)) blocks.push_back(std::move(b));
  }
  for (auto [y0, y1] : {std::pair{0, 100}, std::pair{10, 60}, std::pair{50, 51}}) {
    auto slab = Sticks::FromBlocks(dims, y0, y1, 3, blocks);
    ASSERT_TRUE(slab.ok()) << slab.status();
    ExpectMatches(*slab, labels, dims);
  }
  // Rows asked of a slab are exactly the rows it sends.
  Sticks whole = Sticks::Encode(labels, dims, 0, dims[1]);
  auto rows = whole.EncodeRows(40, 70);
  EXPECT_TRUE(Sticks::FromBlocks(dims, 40, 70, 3, rows).ok());
  EXPECT_NE(Sticks::FromBlocks(dims, 39, 70, 3, rows).status().message().find("no block covers"),
            std::string::npos);
  EXPECT_NE(Sticks::FromBlocks(dims, 40, 71, 3, rows).status().message().find("no block covers"),
            std::string::npos);
}

// The stick or gap of a track by a plain scan, as Find did before it
// searched: the reference for every track length Find handles.
StickSpan ScanTrack(std::span<const Stick> track, int depth, int z) {
  int gap_begin = 0;
  for (const Stick& s : track) {
    if (z < s.begin) return {gap_begin, s.begin, 0};
    if (z < s.end) return {s.begin, s.end, s.material};
    gap_begin = s.end;
  }
  return {gap_begin, depth, 0};
}

TEST(SticksTest, FindAgreesWithAScanForEveryTrackLength) {
  // Track (x, 0) holds x one-voxel sticks with gaps, track (x, 1) x sticks
  // that touch (alternating materials), track (x, 2) random runs: short
  // tracks and long ones, sticks at both ends of a track and not.
  const std::array<int, 3> dims = {50, 3, 101};
  std::vector<uint8_t> labels(static_cast<size_t>(dims[0]) * dims[1] * dims[2], 0);
  auto at = [&](int x, int y, int z) -> uint8_t& {
    return labels[(static_cast<size_t>(z) * dims[1] + y) * dims[0] + x];
  };
  std::mt19937 rng(4);
  for (int x = 0; x < dims[0]; ++x) {
    for (int k = 0; k < x; ++k) at(x, 0, (x % 2) + 2 * k) = 1 + k % 3;
    for (int k = 0; k < x; ++k) at(x, 1, k) = 1 + k % 2;
    for (int z = 0; z < dims[2]; ++z) at(x, 2, z) = (rng() % 4 == 0) ? 1 + rng() % 3 : at(x, 2, z);
  }
  Sticks s = Sticks::Encode(labels, dims, 0, dims[1]);
  ExpectMatches(s, labels, dims);
  size_t longest = 0;
  for (int y = 0; y < dims[1]; ++y) {
    for (int x = 0; x < dims[0]; ++x) {
      const auto track = s.Track(x, y);
      longest = std::max(longest, track.size());
      for (int z = 0; z < dims[2]; ++z) {
        const StickSpan want = ScanTrack(track, dims[2], z);
        const StickSpan got = s.Find(x, y, z);
        ASSERT_EQ(got.begin, want.begin) << x << "," << y << "," << z;
        ASSERT_EQ(got.end, want.end) << x << "," << y << "," << z;
        ASSERT_EQ(got.material, want.material) << x << "," << y << "," << z;
      }
    }
  }
  EXPECT_GE(longest, 49u);
  EXPECT_EQ(s.Track(0, 0).size(), 0u);
  EXPECT_EQ(s.Track(7, 1).size(), 7u);
}

TEST(SticksTest, PhantomCompresses) {
  std::array<int, 3> dims = {64, 64, 64};
  Volume v = MakeSphere(dims, {32, 32, 32}, 20);
  std::vector<uint8_t> labels(v.values.size());
  for (size_t i = 0; i < labels.size(); ++i) labels[i] = v.values[i] > 50 ? 1 : 0;
  Sticks s = Sticks::Encode(labels, dims, 0, dims[1]);
  // A ball has at most one stick per track.
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) ASSERT_LE(s.Track(x, y).size(), 1u);
  size_t encoded = 0;
  for (const auto& b : AllBlocks(s)) encoded += b.size();
  EXPECT_LT(encoded, labels.size() / 20);
}

TEST(SticksTest, RealVolumeRoundTrip) {
  std::string path = testing::DataFile("cthead.nrrd");
  if (path.empty()) GTEST_SKIP() << "cthead.nrrd not found";
  auto v = ReadNrrd(path);
  ASSERT_TRUE(v.ok()) << v.status();
  Classification c;
  c.materials = {{.name = "skin", .min = 600, .max = 1350},
                 {.name = "bone", .min = 1350, .max = 5000}};
  std::vector<uint8_t> labels(v->values.size());
  for (size_t i = 0; i < labels.size(); ++i) labels[i] = c.Classify(v->values[i]);
  Sticks s = Sticks::Encode(labels, v->dims, 0, v->dims[1]);
  ExpectMatches(s, labels, v->dims);
  auto slab = Sticks::FromBlocks(v->dims, 100, 160, 2, AllBlocks(s));
  ASSERT_TRUE(slab.ok()) << slab.status();
  ExpectMatches(*slab, labels, v->dims);
}

class CorruptBlockTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Volume v = MakeRandom(dims_, 7, 3);
    labels_ = Labels(v, 3);
    sticks_ = Sticks::Encode(labels_, dims_, 0, dims_[1]);
    block_ = sticks_.EncodeBlock(0, 0);
  }
  absl::Status Decode(const std::string& block) {
    return Sticks::FromBlocks(dims_, 0, dims_[1], 2, {block}).status();
  }
  std::array<int, 3> dims_ = {20, 20, 40};
  std::vector<uint8_t> labels_;
  Sticks sticks_;
  std::string block_;
};

TEST_F(CorruptBlockTest, EveryTruncationFails) {
  ASSERT_TRUE(Decode(block_).ok());
  for (size_t n = 0; n < block_.size(); ++n) {
    EXPECT_FALSE(Decode(block_.substr(0, n)).ok()) << "length " << n;
  }
}

TEST_F(CorruptBlockTest, NamesWhatIsWrong) {
  std::string bad = block_;
  bad[0] = 'X';
  EXPECT_NE(Decode(bad).message().find("magic"), std::string::npos);
  EXPECT_NE(Decode(block_ + "x").message().find("left over"), std::string::npos);
  auto other = Sticks::FromBlocks({20, 20, 41}, 0, 20, 2, {block_});
  EXPECT_NE(other.status().message().find("20x20x40"), std::string::npos);
  EXPECT_NE(Sticks::FromBlocks(dims_, 0, 20, 1, {block_}).status().message().find("material"),
            std::string::npos);
  EXPECT_NE(Sticks::FromBlocks(dims_, 0, 20, 2, {}).status().message().find("no block covers"),
            std::string::npos);
  // Rows outside the block's row of blocks (bytes 14-17: y0, y1).
  std::string rows = block_;
  rows[16] = 40;  // y1 = 40 > 32
  EXPECT_NE(Decode(rows).message().find("not in block row"), std::string::npos);
  rows = block_;
  rows[14] = rows[16];  // y0 = y1: no rows
  EXPECT_NE(Decode(rows).message().find("not in block row"), std::string::npos);
}

TEST_F(CorruptBlockTest, RandomByteFlipsNeverCrash) {
  std::mt19937 rng(11);
  int rejected = 0;
  for (int i = 0; i < 3000; ++i) {
    std::string bad = block_;
    int flips = 1 + rng() % 4;
    for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] ^= static_cast<char>(1 + rng() % 255);
    auto s = Sticks::FromBlocks(dims_, 0, dims_[1], 2, {bad});
    if (!s.ok()) {
      ++rejected;
      continue;
    }
    // Whatever decodes is a well-formed slab: spans tile every track.
    for (int y = 0; y < dims_[1]; ++y)
      for (int x = 0; x < dims_[0]; ++x)
        for (int z = 0; z < dims_[2]; ++z) {
          auto span = s->Find(x, y, z);
          ASSERT_TRUE(span.begin <= z && z < span.end && span.material <= 2);
        }
  }
  EXPECT_GT(rejected, 1500);
}

}  // namespace
}  // namespace transtick
