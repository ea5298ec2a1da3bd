// libFuzzer entry for the batches that arrive over the network: ray batches
// on a worker's ring stream and deposit batches at the display (the input's
// layout: batch_setup.h). Each is decoded as its receiver decodes it; rays
// that pass Tracer::Validate are traced to the end on a ring of slabs of a
// small synthetic scene (fuzz_ring.h checks the rules on the way), and
// deposits are added to a framebuffer as the display adds them. Every input
// must give a status or a finished frame; a crash, out-of-bounds access,
// undefined behaviour, a hang or a large allocation is a bug.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "batch_setup.h"
#include "transtick/check.h"
#include "transtick/framebuffer.h"
#include "transtick/ray_codec.h"

namespace transtick::fuzz {
namespace {

// How far the inputs got, printed at exit with TRANSTICK_FUZZ_VERBOSE=1.
struct Tally {
  uint64_t decoded = 0, valid = 0, deposits = 0, deposit_batches = 0;
};
Tally tally;

void PrintTally() {
  uint64_t refused = 0;
  for (int c = 0; c < kBatchConfigs; ++c) refused += BatchSetup::Get().config(c).ring->refused();
  std::fprintf(stderr,
               "batch_fuzzer: %llu rays decoded, %llu passed Validate and were traced (%llu "
               "hand-offs refused); %llu deposit batches decoded, %llu deposits added\n",
               static_cast<unsigned long long>(tally.decoded),
               static_cast<unsigned long long>(tally.valid),
               static_cast<unsigned long long>(refused),
               static_cast<unsigned long long>(tally.deposit_batches),
               static_cast<unsigned long long>(tally.deposits));
}

// As Frame::ReceiveBatch: a broken batch keeps nothing; otherwise the
// records that decode are kept and the others counted. What is kept must
// pack again into the same records, in no more bytes than the input (the
// packer writes only what changed, in the shortest varints).
std::vector<RayDescriptor> DecodeAsWorker(std::string_view bytes, uint32_t pixel_limit) {
  DecodedRays decoded = DecodePackedRays(bytes, pixel_limit);
  if (decoded.broken) {
    TRANSTICK_CHECK(decoded.rays.empty());
    TRANSTICK_CHECK(!decoded.error.ok() && !decoded.error.message().empty());
    return {};
  }
  TRANSTICK_CHECK_EQ(decoded.rays.size() + decoded.invalid, decoded.records);
  TRANSTICK_CHECK_EQ(decoded.invalid == 0, decoded.error.ok());
  TRANSTICK_CHECK_LE(decoded.records * 2, bytes.size());  // a mask at least
  if (decoded.invalid == 0) {
    std::string records, packed;
    for (const RayDescriptor& r : decoded.rays) AppendRay(r, &records);
    TRANSTICK_CHECK_EQ(PackRays(records, &packed), decoded.records);
    TRANSTICK_CHECK_LE(packed.size(), bytes.size());
    DecodedRays again = DecodePackedRays(packed, pixel_limit);
    TRANSTICK_CHECK(!again.broken && again.invalid == 0);
    std::string records_again;
    for (const RayDescriptor& r : again.rays) AppendRay(r, &records_again);
    TRANSTICK_CHECK(records_again == records);
  }
  return std::move(decoded.rays);
}

void Rays(uint8_t header, std::string_view bytes) {
  BatchConfig& config = BatchSetup::Get().config(ConfigOf(header));
  FuzzRing& ring = *config.ring;
  const int slab = SlabOf(header) % ring.slabs();
  const Tracer& tracer = ring.tracer(slab);
  std::vector<Deposit> deposits;
  for (RayDescriptor& ray : DecodeAsWorker(bytes, ring.pixel_limit())) {
    ++tally.decoded;
    if (header & kRepair) Repair(*config.scene, tracer, &ray);
    if (absl::Status s = tracer.Validate(ray); !s.ok()) {
      TRANSTICK_CHECK(!s.message().empty());
      continue;
    }
    ++tally.valid;
    deposits.clear();
    ring.Run(slab, ray, FuzzRing::Origin::kPeer, &deposits);
    for (const Deposit& d : deposits) TRANSTICK_CHECK_EQ(d.pixel, ray.pixel);
  }
}

void Deposits(std::string_view bytes) {
  if (bytes.size() < 2) return;
  const int width = (static_cast<uint8_t>(bytes[0]) & 63) + 1;
  const int height = (static_cast<uint8_t>(bytes[1]) & 63) + 1;
  const uint32_t pixels = static_cast<uint32_t>(width * height);
  auto records = DecodePackedDeposits(bytes.substr(2), pixels);
  if (!records.ok()) {
    TRANSTICK_CHECK(!records.status().message().empty());
    return;
  }
  ++tally.deposit_batches;
  tally.deposits += records->size();
  Framebuffer fb(width, height);
  for (const PixelDeposits& d : *records) {
    TRANSTICK_CHECK_LT(d.pixel, pixels);
    TRANSTICK_CHECK(d.pixels >= 1 && d.pixels <= pixels - d.pixel);  // a run stays in the image
    TRANSTICK_CHECK(d.primaries > 0 || (d.shadows > 0 && d.spawned == 0));
    (void)fb.Add(d);
  }
  TRANSTICK_CHECK_LE(fb.complete_pixels(), uint64_t{pixels});
  const Image image = fb.Resolve();
  TRANSTICK_CHECK_EQ(image.rgb.size(), size_t{pixels} * 3);
}

}  // namespace
}  // namespace transtick::fuzz

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)transtick::fuzz::BatchSetup::Get();
  if (std::getenv("TRANSTICK_FUZZ_VERBOSE") != nullptr) std::atexit(transtick::fuzz::PrintTally);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & transtick::fuzz::kDepositBatch) {
    transtick::fuzz::Deposits(bytes);
  } else {
    transtick::fuzz::Rays(data[0], bytes);
  }
  return 0;
}
