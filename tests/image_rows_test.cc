// A frame's image rows between the root and its clients: the root passes
// each row on once over a frame's attempts (RowsOnce), and a client takes a
// frame as whole only when its chunks cover every row (ImageRows), however
// the chunks repeat or overlap.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "client.h"
#include "job_runner.h"
#include "transtick/image_io.h"

namespace transtick {
namespace {

// The floats of row y of a w-wide image: a function of (y, x, channel), so
// every rendering of the frame carries the same bits.
float Value(int y, int x, int c) { return static_cast<float>(y * 1000 + x * 3 + c) * 0.25f; }
// The bytes of the same image in RGB8: every value 0 .. 255 comes up.
uint8_t Byte(int y, int x, int c) { return static_cast<uint8_t>(y * 31 + x * 7 + c * 101); }
// What a client holds for a pixel's channel of a chunk in `encoding`.
float Held(int y, int x, int c, v1::ImageEncoding encoding) {
  return encoding == v1::RGB8 ? FromByte(Byte(y, x, c)) : Value(y, x, c);
}

v1::ImageChunk Chunk(int w, int h, int begin, int end, v1::ImageEncoding encoding = v1::FLOAT32) {
  v1::ImageChunk c;
  c.set_width(w);
  c.set_height(h);
  c.set_row_begin(begin);
  c.set_row_end(end);
  std::string bytes;
  for (int y = begin; y < end; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int k = 0; k < 3; ++k) {
        if (encoding == v1::RGB8) {
          bytes.push_back(static_cast<char>(Byte(y, x, k)));
          continue;
        }
        const float v = Value(y, x, k);
        char b[4];
        std::memcpy(b, &v, 4);  // little-endian, as docs/formats.md has it
        bytes.append(b, 4);
      }
    }
  }
  (encoding == v1::RGB8 ? c.mutable_rgb8() : c.mutable_rgb())->assign(bytes);
  return c;
}

// A rendering's chunks: the rows in order, cut at random.
std::vector<v1::ImageChunk> Rendering(int w, int h, std::mt19937& rng,
                                      v1::ImageEncoding encoding = v1::FLOAT32) {
  std::vector<v1::ImageChunk> out;
  for (int y = 0; y < h;) {
    const int n = std::uniform_int_distribution<int>(1, std::max(1, h / 3))(rng);
    const int end = std::min(h, y + n);
    out.push_back(Chunk(w, h, y, end, encoding));
    y = end;
  }
  return out;
}

v1::ImageEncoding AnyEncoding(std::mt19937& rng) {
  return std::uniform_int_distribution<int>(0, 1)(rng) ? v1::RGB8 : v1::FLOAT32;
}

TEST(RowsOnceTest, EveryRowGoesOutOnceOverFailedAttempts) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 3000; ++trial) {
    const int w = std::uniform_int_distribution<int>(1, 5)(rng);
    const int h = std::uniform_int_distribution<int>(1, 40)(rng);
    const v1::ImageEncoding encoding = AnyEncoding(rng);  // a frame's, over its attempts
    // The runner's protocol: each chunk is held until the next comes, and
    // the chunk held when an attempt fails is dropped; the last attempt's
    // held chunk goes out with the statistics.
    RowsOnce once;
    std::vector<v1::ImageChunk> out;
    const int attempts = std::uniform_int_distribution<int>(1, 4)(rng);
    for (int a = 0; a < attempts; ++a) {
      const std::vector<v1::ImageChunk> chunks = Rendering(w, h, rng, encoding);
      const bool last = a + 1 == attempts;
      // A failed attempt stops after a random number of chunks.
      const size_t n =
          last ? chunks.size() : std::uniform_int_distribution<size_t>(0, chunks.size())(rng);
      std::optional<v1::ImageChunk> held;
      for (size_t i = 0; i < n; ++i) {
        if (held) {
          once.Sent(held->row_end());
          out.push_back(*std::move(held));
          held.reset();
        }
        held = once.Trim(chunks[i]);
      }
      if (last) {
        ASSERT_TRUE(held.has_value())
            << "the last attempt ends with a chunk to carry its statistics";
        out.push_back(*std::move(held));
      }
    }
    // What went out: rows 0 .. h in order, each once, with the image's bits.
    int next = 0;
    for (const v1::ImageChunk& c : out) {
      ASSERT_EQ(c.row_begin(), next) << "trial " << trial;
      ASSERT_GT(c.row_end(), c.row_begin());
      const v1::ImageChunk want = Chunk(w, h, c.row_begin(), c.row_end(), encoding);
      EXPECT_EQ(c.rgb(), want.rgb());
      EXPECT_EQ(c.rgb8(), want.rgb8());
      next = c.row_end();
    }
    EXPECT_EQ(next, h) << "trial " << trial;
  }
}

TEST(ImageRowsTest, WholeOnlyWhenTheChunksCoverEveryRow) {
  std::mt19937 rng(11);
  // Each trial's image is held in the buffer of the one before (as the
  // client reuses a saved frame's), of another size and filled with NaN
  // here: none of its old values may survive into a whole image.
  std::vector<float> spare;
  for (int trial = 0; trial < 3000; ++trial) {
    const int w = std::uniform_int_distribution<int>(1, 4)(rng);
    const int h = std::uniform_int_distribution<int>(1, 30)(rng);
    const v1::ImageEncoding encoding = AnyEncoding(rng);
    // Chunks of up to three renderings, some lost (taken by a watcher that
    // went away), in an order where renderings follow one another.
    std::vector<v1::ImageChunk> stream;
    const int renderings = std::uniform_int_distribution<int>(1, 3)(rng);
    for (int r = 0; r < renderings; ++r) {
      for (v1::ImageChunk& c : Rendering(w, h, rng, encoding)) {
        if (std::uniform_int_distribution<int>(0, 3)(rng) > 0) stream.push_back(std::move(c));
      }
    }
    std::fill(spare.begin(), spare.end(), std::numeric_limits<float>::quiet_NaN());
    ImageRows rows(std::move(spare));
    std::vector<bool> covered(h, false);
    for (const v1::ImageChunk& c : stream) {
      if (rows.whole()) break;
      ASSERT_TRUE(rows.Add(c).ok());
      for (int y = c.row_begin(); y < c.row_end(); ++y) covered[y] = true;
      const bool all = std::find(covered.begin(), covered.end(), false) == covered.end();
      ASSERT_EQ(rows.whole(), all) << "trial " << trial;
    }
    if (rows.whole()) {
      const Image& img = rows.image();
      ASSERT_EQ(img.rgb.size(), static_cast<size_t>(w) * h * 3);
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          for (int k = 0; k < 3; ++k) {
            ASSERT_EQ(img.rgb[(static_cast<size_t>(y) * w + x) * 3 + k], Held(y, x, k, encoding));
          }
        }
      }
    }
    spare = rows.TakeBuffer();
  }
}

TEST(ImageRowsTest, RefusesChunksThatDoNotFit) {
  ImageRows rows;
  ASSERT_TRUE(rows.Add(Chunk(4, 10, 0, 2)).ok());
  EXPECT_EQ(rows.Add(Chunk(5, 10, 2, 4)).code(), absl::StatusCode::kDataLoss);  // width
  EXPECT_EQ(rows.Add(Chunk(4, 11, 2, 4)).code(), absl::StatusCode::kDataLoss);  // height
  v1::ImageChunk short_rgb = Chunk(4, 10, 2, 4);
  short_rgb.mutable_rgb()->pop_back();
  EXPECT_EQ(rows.Add(short_rgb).code(), absl::StatusCode::kDataLoss);
  v1::ImageChunk past = Chunk(4, 10, 8, 10);
  past.set_row_end(11);
  EXPECT_EQ(rows.Add(past).code(), absl::StatusCode::kDataLoss);
  ImageRows empty;
  EXPECT_EQ(empty.Add(Chunk(0, 10, 0, 0)).code(), absl::StatusCode::kDataLoss);
  // RGB8 rows: exactly 3 bytes a pixel, and in one field only.
  ASSERT_TRUE(rows.Add(Chunk(4, 10, 2, 4, v1::RGB8)).ok());
  v1::ImageChunk short_rgb8 = Chunk(4, 10, 4, 6, v1::RGB8);
  short_rgb8.mutable_rgb8()->pop_back();
  EXPECT_EQ(rows.Add(short_rgb8).code(), absl::StatusCode::kDataLoss);
  v1::ImageChunk long_rgb8 = Chunk(4, 10, 4, 6, v1::RGB8);
  long_rgb8.mutable_rgb8()->push_back('x');
  EXPECT_EQ(rows.Add(long_rgb8).code(), absl::StatusCode::kDataLoss);
  v1::ImageChunk both = Chunk(4, 10, 4, 6, v1::RGB8);
  both.set_rgb(Chunk(4, 10, 4, 6).rgb());
  EXPECT_EQ(rows.Add(both).code(), absl::StatusCode::kDataLoss);
  // Float rows in the byte field: four times the bytes RGB8 rows take.
  v1::ImageChunk floats_as_bytes = Chunk(4, 10, 4, 8, v1::FLOAT32);
  floats_as_bytes.set_rgb8(floats_as_bytes.rgb());
  floats_as_bytes.clear_rgb();
  EXPECT_EQ(rows.Add(floats_as_bytes).code(), absl::StatusCode::kDataLoss);
  EXPECT_FALSE(rows.whole());
}

// RGB8 values come back through FromByte to the same file bytes: ToByte of
// what a client holds is the byte that came.
TEST(ImageRowsTest, ByteRowsGiveTheirBytesBack) {
  ImageRows rows;
  ASSERT_TRUE(rows.Add(Chunk(86, 1, 0, 1, v1::RGB8)).ok());
  ASSERT_TRUE(rows.whole());
  const Image& img = rows.image();
  for (int x = 0; x < 86; ++x) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(ToByte(img.rgb[x * 3 + k]), Byte(0, x, k));
  }
}

v1::Job JobWithOutputs(const std::vector<std::string>& outputs) {
  v1::Job job;
  v1::Dataset* d = job.add_datasets();
  for (const std::string& out : outputs) d->add_views()->set_output(out);
  return job;
}

TEST(ChooseImageEncodingTest, BytesOnlyWhenEveryOutputIsAnEightBitFile) {
  struct Case {
    std::vector<std::string> outputs;
    v1::ImageEncoding want;
  };
  const std::vector<Case> cases = {
      {{"a.png"}, v1::RGB8},
      {{"a.png", "b.JPG", "c/d.jpeg"}, v1::RGB8},
      {{""}, v1::RGB8},  // the default name is a .png
      {{"a.png", "b.exr"}, v1::FLOAT32},
      {{"a.tif"}, v1::FLOAT32},
      {{"a.hdr"}, v1::FLOAT32},
      {{"a.png", "b.tiff"}, v1::FLOAT32},
  };
  for (const Case& c : cases) {
    v1::Job job = JobWithOutputs(c.outputs);
    ChooseImageEncoding(&job);
    EXPECT_EQ(job.image_encoding(), c.want) << c.outputs[0] << " (" << c.outputs.size() << ")";
  }
  // A job that names its encoding keeps it.
  for (v1::ImageEncoding named : {v1::FLOAT32, v1::RGB8}) {
    v1::Job job = JobWithOutputs({named == v1::RGB8 ? "a.exr" : "a.png"});
    job.set_image_encoding(named);
    ChooseImageEncoding(&job);
    EXPECT_EQ(job.image_encoding(), named);
  }
}

}  // namespace
}  // namespace transtick
