// The display sends an image's first rows while the frame still traces,
// when the AwaitFrame asks for them (FrameRef.early_image_bytes): rows
// whose every pixel is in, in order, within the bytes asked for, and the
// rest after `complete`. A real display on 127.0.0.1, deposits sent the
// way workers send them.
#include <grpcpp/grpcpp.h>

#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cluster.grpc.pb.h"
#include "gtest/gtest.h"
#include "nodes_fixture.h"
#include "transtick/framebuffer.h"
#include "transtick/image_io.h"
#include "transtick/ray_codec.h"

namespace transtick::testing {
namespace {

class EarlyImageTest : public NodesTest {
 protected:
  // Every pixel of a width x height image: a primary that spawned one
  // shadow ray, and the shadow ray, as 20-byte records.
  static std::vector<Deposit> Deposits(int width, int height, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<Deposit> all;
    for (uint32_t p = 0; p < static_cast<uint32_t>(width * height); ++p) {
      all.push_back(Deposit{p, RayKind::kPrimary, 1, {u(rng), u(rng), u(rng)}});
      all.push_back(Deposit{p, RayKind::kShadow, 0, {u(rng), 0, u(rng)}});
    }
    return all;
  }

  // Sends deposits [begin, end) of `all` on one stream, packed as a
  // worker packs them, in batches of `batch`.
  grpc::Status Send(uint64_t frame, const std::vector<Deposit>& all, size_t begin, size_t end,
                    size_t batch = 97) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    auto writer = display_stub_->Deposits(&ctx, &ack);
    v1::DepositBatch first;
    first.set_frame_id(frame);
    writer->Write(first);
    for (size_t at = begin; at < end; at += batch) {
      std::string records, packed;
      for (size_t i = at; i < std::min(end, at + batch); ++i) AppendDeposit(all[i], &records);
      PackDeposits(records, &packed);
      v1::DepositBatch b;
      b.set_frame_id(frame);
      b.set_packed(packed);
      writer->Write(b);
    }
    writer->WritesDone();
    return writer->Finish();
  }
};

// What an AwaitFrame received: the image's rows (floats, or bytes for
// RGB8), and how many of them came before `complete`.
struct Received {
  std::vector<float> rgb;
  std::string rgb8;
  int rows = 0;
  int early_rows = 0;
  bool complete = false;
  grpc::Status status;
};

// Adds chunk `c` of an image `width` wide in `encoding` to `got`, checking
// that it follows the rows before and holds them exactly.
void Take(const v1::ImageChunk& c, int width, v1::ImageEncoding encoding, Received* got) {
  ASSERT_EQ(c.row_begin(), got->rows);
  ASSERT_GT(c.row_end(), c.row_begin());
  const size_t values = static_cast<size_t>(c.row_end() - c.row_begin()) * width * 3;
  if (encoding == v1::RGB8) {
    ASSERT_TRUE(c.rgb().empty());
    ASSERT_EQ(c.rgb8().size(), values);
    got->rgb8 += c.rgb8();
  } else {
    ASSERT_TRUE(c.rgb8().empty());
    ASSERT_EQ(c.rgb().size(), values * 4);
    got->rgb.resize(static_cast<size_t>(c.row_end()) * width * 3);
    DecodeFloats(c.rgb(), got->rgb.data() + static_cast<size_t>(c.row_begin()) * width * 3);
  }
  got->rows = c.row_end();
}

// Reads an AwaitFrame to its end, checking that chunks come in order.
void ReadAll(grpc::ClientReader<v1::FrameProgress>& reader, int width, v1::ImageEncoding encoding,
             Received* got) {
  v1::FrameProgress p;
  while (reader.Read(&p)) {
    if (p.complete()) got->complete = true;
    if (!p.has_image()) continue;
    Take(p.image(), width, encoding, got);
    if (!got->complete) got->early_rows = p.image().row_end();
  }
  got->status = reader.Finish();
}

TEST_F(EarlyImageTest, CompleteRowsGoOutBeforeTheFrameAndTheImageIsTheSame) {
  constexpr int kWidth = 64, kHeight = 40;
  uint64_t frame = 40;
  for (v1::ImageEncoding encoding : {v1::FLOAT32, v1::RGB8, v1::IMAGE_ENCODING_DEFAULT}) {
    const uint64_t row_bytes = kWidth * (encoding == v1::RGB8 ? 3 : 12);
    // Asked for: the whole image, five rows' bytes, none.
    const uint64_t budgets[] = {1 << 20, 5 * row_bytes + 7, 0};
    for (uint64_t budget : budgets) {
      ++frame;
      SCOPED_TRACE(absl::StrCat("encoding ", encoding, ", budget ", budget));
      ASSERT_TRUE(Begin(frame, kWidth, kHeight).ok());
      const std::vector<Deposit> all = Deposits(kWidth, kHeight, static_cast<uint32_t>(frame));
      grpc::ClientContext ctx;
      ctx.set_deadline(Deadline(10));
      v1::FrameRef ref;
      ref.set_frame_id(frame);
      ref.set_early_image_bytes(budget);
      ref.set_image_encoding(encoding);
      auto reader = display_stub_->AwaitFrame(&ctx, ref);
      // The first 30 rows' deposits; the frame is not complete.
      const size_t split = static_cast<size_t>(30 * kWidth) * 2;
      ASSERT_TRUE(Send(frame, all, 0, split).ok());
      Received got;
      v1::FrameProgress p;
      if (budget >= row_bytes) {
        // Rows come before the frame completes: as many as are complete, at
        // most what was asked for.
        while (got.early_rows < std::min<int>(30, static_cast<int>(budget / row_bytes))) {
          ASSERT_TRUE(reader->Read(&p));
          ASSERT_FALSE(p.complete());
          if (!p.has_image()) continue;
          // Only rows whose pixels are all in.
          ASSERT_LE(p.image().row_end(), 30);
          Take(p.image(), kWidth, encoding, &got);
          got.early_rows = got.rows;
        }
      }
      if (budget >= 30 * row_bytes) {
        EXPECT_EQ(got.early_rows, 30);
      }
      ASSERT_TRUE(Send(frame, all, split, all.size()).ok());
      // The rest: more rows may come before `complete` as they complete.
      ReadAll(*reader, kWidth, encoding, &got);
      ASSERT_TRUE(got.status.ok()) << got.status.error_message();
      EXPECT_TRUE(got.complete);
      EXPECT_EQ(got.rows, kHeight);
      // Never more bytes early than asked for; none when none were.
      EXPECT_LE(static_cast<uint64_t>(got.early_rows) * row_bytes, budget);
      if (budget >= row_bytes) {
        EXPECT_GE(got.early_rows, std::min<int>(30, static_cast<int>(budget / row_bytes)));
      }
      // The same image as every deposit added here; in RGB8, its bytes.
      Framebuffer fb(kWidth, kHeight);
      for (const Deposit& d : all) fb.Add(d);
      const std::vector<float> want = fb.Resolve().rgb;
      if (encoding == v1::RGB8) {
        ASSERT_EQ(got.rgb8.size(), want.size());
        for (size_t i = 0; i < want.size(); ++i) {
          ASSERT_EQ(static_cast<uint8_t>(got.rgb8[i]), ToByte(want[i])) << "value " << i;
        }
      } else {
        EXPECT_EQ(got.rgb, want);
      }
    }
  }
}

TEST_F(EarlyImageTest, AnEncodingThisBuildDoesNotKnowIsRefused) {
  ASSERT_TRUE(Begin(90, 8, 8).ok());
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::FrameRef ref;
  ref.set_frame_id(90);
  ref.set_image_encoding(static_cast<v1::ImageEncoding>(7));
  auto reader = display_stub_->AwaitFrame(&ctx, ref);
  v1::FrameProgress p;
  EXPECT_FALSE(reader->Read(&p));
  const grpc::Status s = reader->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("image_encoding 7"), std::string::npos) << s.error_message();
}

}  // namespace
}  // namespace transtick::testing
